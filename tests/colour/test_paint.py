"""The paint layer: energy, limits, flake lobe position, and the seed's KM over a flake."""

from __future__ import annotations

import numpy as np
import pytest

from goniolab.colour.dispersion import Cauchy, Constant
from goniolab.colour.optics import fresnel_unpolarised
from goniolab.colour.paint import (
    MetallicFlakes,
    Paint,
    PaintError,
    PearlFlakes,
    PigmentLayer,
    Spectrum,
    paint_from_dict,
)
from goniolab.optics.apertures import direction

WL = np.array([450.0, 550.0, 650.0])


def _hemisphere(n_t: int = 240, n_p: int = 240) -> tuple[np.ndarray, np.ndarray]:
    t = (np.arange(n_t) + 0.5) * (np.pi / 2) / n_t
    p = (np.arange(n_p) + 0.5) * 2 * np.pi / n_p
    tt, pp = np.meshgrid(t, p, indexing="ij")
    wo = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1).reshape(-1, 3)
    dw = (np.sin(tt) * (np.pi / 2 / n_t) * (2 * np.pi / n_p)).ravel()
    return wo, dw


def _albedo(paint: Paint, theta_i: float) -> np.ndarray:
    wo, dw = _hemisphere()
    wi = np.broadcast_to(direction(theta_i, 0.0), wo.shape)
    f = paint.subsurface_brdf(wi, wo, WL)
    ci = np.cos(np.radians(theta_i))
    return fresnel_unpolarised(ci, paint.coat_n(WL)) + (f * (wo[:, 2] * dw)[:, None]).sum(0)


def white(k: float = 0.0) -> PigmentLayer:
    return PigmentLayer(Spectrum.flat(k), Spectrum.flat(5.0), 1e4, Spectrum.flat(1.0))


@pytest.mark.parametrize("theta_i", [0.0, 45.0, 70.0])
def test_lossless_white_body_conserves_energy(theta_i: float) -> None:
    # coat reflection + Saunderson body over the hemisphere = 1 for a non-absorbing body
    assert _albedo(Paint(Cauchy(1.5, 0.004), white()), theta_i) == pytest.approx(
        np.ones(3), abs=2e-3
    )


@pytest.mark.parametrize("theta_i", [15.0, 45.0, 65.0])
def test_energy_at_most_one_with_flakes(theta_i: float) -> None:
    paint = Paint(
        Constant(1.5),
        white(),
        metallic=MetallicFlakes(0.4, 6.0, 0.0),
        pearl=PearlFlakes(0.2, 6.0, film_nm=120.0),
    )
    a = _albedo(paint, theta_i)
    assert np.all(a <= 1.0 + 2e-3) and np.all(a > 0.5)


def test_zero_thickness_body_reads_the_substrate() -> None:
    body = PigmentLayer(
        Spectrum.flat(3.0), Spectrum.flat(2.0), 0.0, Spectrum((400, 700), (0.2, 0.7))
    )
    assert body.reflectance(WL) == pytest.approx([0.2 + 0.5 * 50 / 300, 0.45, 0.7 - 0.5 * 50 / 300])


@pytest.mark.parametrize("theta_i", [20.0, 45.0, 60.0])
def test_flake_lobe_is_centred_on_the_flakes_mirror_direction(theta_i: float) -> None:
    # narrow spread: the BRDF's smooth factors (1/cos, Fresnel) cannot shift the peak
    paint = Paint(Cauchy(1.5, 0.004), None, metallic=MetallicFlakes(0.5, 1.0))
    tr = np.linspace(theta_i - 10, theta_i + 10, 4001)
    wo = direction(np.abs(tr), np.where(tr >= 0, 180.0, 0.0))
    wi = np.broadcast_to(direction(theta_i, 0.0), wo.shape)
    f = paint.flake_brdf(wi, wo, np.array([550.0]))[:, 0]
    assert tr[np.argmax(f)] == pytest.approx(theta_i, abs=0.03)
    half = tr[f > 0.5 * f.max()]
    # inside the coat (Snell) the half-maximum points sit symmetrically about the
    # refracted specular direction
    n = 1.5 + 0.004 / 0.55**2
    inside = np.degrees(np.arcsin(np.sin(np.radians(half[[0, -1]])) / n))
    t_in = np.degrees(np.arcsin(np.sin(np.radians(theta_i)) / n))
    assert 0.5 * inside.sum() == pytest.approx(t_in, abs=0.02)
    # the mirror turns by twice the flake tilt and Snell widens it by n cos t'/cos t outside
    assert (half[-1] - half[0]) / 2 > 2 * 1.0


def test_flake_reflectance_is_aluminium_fresnel_in_the_binder() -> None:
    m = MetallicFlakes(0.5, 4.0)
    rho = m.reflectance(np.array([[1.0]]), np.array([1.5]), np.array([550.0]))
    n_al = m.metal.index([550.0])[0] / 1.5
    assert rho[0, 0] == pytest.approx(abs((n_al - 1) / (n_al + 1)) ** 2)


def test_pigment_over_a_flake_tints_it() -> None:
    # a red pigment of depth X' over the flake absorbs the blue end: the lobe keeps the
    # light that went to the flake and back, T^2 R_m with Kubelka's layer transmittance
    # T = b / (a sinh(bSX) + b cosh(bSX)) (JOSA 38 (1948) 448); the seed's eq. 5 also put
    # the layer's diffuse backscatter into the lobe (issue 25), which this test allowed
    body = PigmentLayer(
        Spectrum((400, 580, 620, 700), (8, 8, 0.05, 0.05)),
        Spectrum.flat(2.0),
        20.0,
        Spectrum.flat(0.5),
    )
    deep = Paint(Constant(1.5), body, metallic=MetallicFlakes(0.3, 4.0, depth_um=1.0))
    shallow = Paint(Constant(1.5), body, metallic=MetallicFlakes(0.3, 4.0, depth_um=0.0))
    wi = direction(45.0, 0.0)[None]
    wo = direction(45.0, 180.0)[None]
    wl = np.array([450.0, 650.0])
    fd, fs = deep.flake_brdf(wi, wo, wl)[0], shallow.flake_brdf(wi, wo, wl)[0]
    k, s_ = body.ks(wl)
    a = 1.0 + k / s_
    b = np.sqrt(a * a - 1.0)
    t = b / (a * np.sinh(b * s_ * 1.0) + b * np.cosh(b * s_ * 1.0))
    np.testing.assert_allclose(fd, t * t * fs, rtol=1e-12)
    assert fd[0] < 1e-3 * fd[1]  # tinted red
    # the layer's backscatter is in the diffuse body term instead: A R_l(X') more
    r_l = np.sinh(b * s_) / (a * np.sinh(b * s_) + b * np.cosh(b * s_))  # KM over black
    gain = deep.diffuse_reflectance(wl) - shallow.diffuse_reflectance(wl)
    np.testing.assert_allclose(gain, 0.3 * r_l, rtol=1e-10)


def test_paint_from_toml_tables_and_errors() -> None:
    p = paint_from_dict(
        {
            "coat": {"kind": "cauchy", "A": 1.49, "B": 0.0045},
            "body": {
                "K": {"wavelengths_nm": [400, 700], "values": [2, 0.1]},
                "S": 10,
                "thickness_um": 25,
            },
            "metallic": {"area_fraction": 0.4, "spread_deg": 6},
        }
    )
    assert p.body is not None and p.metallic is not None and p.body.thickness_um == 25
    with pytest.raises(PaintError, match=r"paint.metallic: unknown key 'spread'"):
        paint_from_dict({"metallic": {"area_fraction": 0.4, "spread": 6}})
    with pytest.raises(PaintError, match=r"paint.pearl.film_nm: missing"):
        paint_from_dict({"pearl": {"area_fraction": 0.4, "spread_deg": 6}})


def test_every_built_in_paint_builds() -> None:
    from goniolab.model_cache import paint_for
    from goniolab.surfaces.synthetic import sample_info, sample_names

    painted = [n for n in sample_names() if "paint" in sample_info(n).params]
    assert painted == ["solid-red", "white", "silver-metallic", "pearl"]
    for name in painted:
        p = paint_for(f"sample:{name}")
        assert p.body is not None
        assert np.all(p.coat_n(WL) > 1.49)
