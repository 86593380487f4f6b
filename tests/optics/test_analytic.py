"""Analytic microfacet models (Walter et al. 2007, Heitz 2014, Mihalik eqs. 12-14)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import integrate, stats

from goniolab.optics.analytic import (
    KINDS,
    AnalyticModel,
    beckmann_d,
    beckmann_g1,
    beckmann_lambda,
    ggx_d,
    ggx_g1,
    ggx_lambda,
    ward_lobe,
)
from goniolab.optics.apertures import (
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    direction,
    integrate_brdf,
)
from goniolab.optics.fresnel import fresnel_dielectric

F64 = NDArray[np.float64]
#: A near-perfect conductor: Fresnel reflectance ~1 at every angle, so albedo tests see D and G only.
MIRROR_N = complex(1.0, 1e4)


@pytest.mark.parametrize("d_fn", [beckmann_d, ggx_d])
@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
def test_distribution_projected_area_is_one(
    d_fn: Callable[[float, float], F64], alpha: float
) -> None:
    # int D(h) cos th dOmega = 2 pi int_0^{pi/2} D(th) cos th sin th dth = 1 (Walter eq. 4).
    def g(t: float) -> float:
        return float(d_fn(math.cos(t), alpha)) * math.cos(t) * math.sin(t)

    val, _ = integrate.quad(g, 0.0, math.pi / 2, points=[alpha, 3 * alpha], limit=200)
    assert 2 * math.pi * val == pytest.approx(1.0, rel=1e-6)


def _lambda_from_slopes(pdf: Callable[[float], float], theta_deg: float) -> float:
    """Smith Lambda from the marginal slope density (docs/PHYSICS.md, "Masking and shadowing"; Heitz 2014 eq. 65).

    Lambda(w) = E[max(0, cos t - sin t p)] / cos t - 1 = E[max(0, 1 - tan t p)] - 1.
    """
    a = math.tan(math.radians(theta_deg))
    val, _ = integrate.quad(lambda p: (1.0 - a * p) * pdf(p), -np.inf, 1.0 / a, limit=200)
    return val - 1.0


@pytest.mark.parametrize("alpha", [0.1, 0.4, 1.0])
@pytest.mark.parametrize("theta_deg", [20.0, 60.0, 85.0])
def test_beckmann_smith_lambda_matches_the_slope_space_integral(
    alpha: float, theta_deg: float
) -> None:
    # Beckmann: per-axis slopes are normal with sigma = alpha / sqrt(2).
    pdf = stats.norm(scale=alpha / math.sqrt(2)).pdf
    expected = _lambda_from_slopes(pdf, theta_deg)
    cos_t = math.cos(math.radians(theta_deg))
    assert float(beckmann_lambda(cos_t, alpha)) == pytest.approx(expected, rel=1e-6, abs=1e-9)
    # The exact G1 of docs/PHYSICS.md / Walter eq. 27, written out independently.
    u = 1.0 / (alpha * math.tan(math.radians(theta_deg)))
    g1 = 2.0 / (1.0 + math.erf(u) + math.exp(-(u**2)) / (u * math.sqrt(math.pi)))
    assert float(beckmann_g1(cos_t, alpha)) == pytest.approx(g1, rel=1e-12)
    assert g1 == pytest.approx(1.0 / (1.0 + expected), rel=1e-6)


@pytest.mark.parametrize("alpha", [0.1, 0.4, 1.0])
@pytest.mark.parametrize("theta_deg", [20.0, 60.0, 85.0])
def test_ggx_lambda_matches_the_slope_space_integral(alpha: float, theta_deg: float) -> None:
    # GGX slope density P22 = 1 / (pi a^2 (1 + r^2/a^2)^2); its marginal is
    # P2(p) = a^2 / (2 (a^2 + p^2)^{3/2}).
    def pdf(p: float) -> float:
        return alpha**2 / (2.0 * (alpha**2 + p**2) ** 1.5)

    expected = _lambda_from_slopes(pdf, theta_deg)
    cos_t = math.cos(math.radians(theta_deg))
    assert float(ggx_lambda(cos_t, alpha)) == pytest.approx(expected, rel=1e-6)
    tan_t = math.tan(math.radians(theta_deg))
    g1_walter = 2.0 / (1.0 + math.sqrt(1.0 + alpha**2 * tan_t**2))
    assert float(ggx_g1(cos_t, alpha)) == pytest.approx(g1_walter, rel=1e-12)


def test_masking_is_one_at_normal_incidence() -> None:
    assert float(beckmann_g1(1.0, 0.5)) == 1.0
    assert float(ggx_g1(1.0, 0.5)) == 1.0


def _random_upper(rng: np.random.Generator, n: int) -> F64:
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("n", [1.55, complex(0.27, 3.41)])
def test_reciprocity(kind: str, n: complex) -> None:
    rng = np.random.default_rng(7)
    wi, wo = _random_upper(rng, 500), _random_upper(rng, 500)
    m = AnalyticModel(kind, alpha=0.3, n=n)
    np.testing.assert_allclose(m.brdf(wi, wo), m.brdf(wo, wi), rtol=1e-12, atol=0)
    assert np.all(m.brdf(wi, wo) >= 0)


def _albedo(
    f: Callable[[F64, F64], F64], theta_i_deg: float, n_t: int = 400, n_p: int = 400
) -> float:
    """int f(wi, wo) cos(to) dOmega_o over the hemisphere, midpoint rule in (t, p)."""
    t = (np.arange(n_t) + 0.5) * (math.pi / 2 / n_t)
    p = (np.arange(n_p) + 0.5) * (2 * math.pi / n_p)
    tt, pp = np.meshgrid(t, p, indexing="ij")
    wo = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1)
    wi = np.broadcast_to(direction(theta_i_deg, 0.0), wo.shape)
    vals = f(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(tt.shape)
    dA = (math.pi / 2 / n_t) * (2 * math.pi / n_p)
    return float(np.sum(vals * np.cos(tt) * np.sin(tt)) * dA)


@pytest.mark.parametrize("kind", ["beckmann", "ggx"])
@pytest.mark.parametrize("alpha", [0.2, 0.6])
def test_directional_albedo_at_most_one(kind: str, alpha: float) -> None:
    m = AnalyticModel(kind, alpha=alpha, n=MIRROR_N)
    albedos = [_albedo(m.brdf, t) for t in (0.0, 45.0, 75.0)]
    assert all(a <= 1.0 + 2e-3 for a in albedos), albedos
    # At normal incidence, facets tilted beyond 45 deg send light below the horizon: the
    # projected-area fraction P(tan th_h > 1) is exp(-1/a^2) (Beckmann) and a^2/(1 + a^2)
    # (GGX); masking on the way out only removes more.
    lost = math.exp(-1 / alpha**2) if kind == "beckmann" else alpha**2 / (1 + alpha**2)
    assert albedos[0] <= 1.0 - lost + 2e-3
    if alpha == 0.2:  # little masking: the bound is nearly reached
        assert albedos[0] == pytest.approx(1.0 - lost, abs=0.015)


def test_ward_normalisation() -> None:
    # Ward (1992) normalises the lobe at normal incidence: albedo -> 1 for small s.
    assert _albedo(lambda a, b: ward_lobe(a, b, 0.05), 0.0) == pytest.approx(1.0, abs=0.01)
    # Off normal its albedo is close to cos(theta_i): the lobe loses energy toward grazing,
    # which is why Mihalik's Ward fits read so low at 85 deg (Mihalik table 2).
    got = _albedo(lambda a, b: ward_lobe(a, b, 0.05), 60.0)
    assert got == pytest.approx(math.cos(math.radians(60.0)), rel=0.03)


def test_specular_peak_value_beckmann() -> None:
    # At the mirror direction h = n: f = F(ti) G1(ti)^2 / (4 pi a^2 cos^2 ti) (Walter eq. 20, 25).
    alpha, ti = 0.1, 30.0
    m = AnalyticModel("beckmann", alpha=alpha, n=1.5)
    c = math.cos(math.radians(ti))
    g1 = float(beckmann_g1(c, alpha))
    expected = float(fresnel_dielectric(c, 1.5)) * g1**2 / (4 * math.pi * alpha**2 * c**2)
    assert m.brdf_point(ti, ti) == pytest.approx(expected, rel=1e-12)
    assert m.brdf_inplane(ti, [ti, -ti])[0] == pytest.approx(expected, rel=1e-12)
    # Lamp side and below the horizon.
    assert m.brdf_inplane(ti, [-ti])[0] < expected * 1e-10
    assert m.brdf_point(ti, 95.0) == 0.0


def test_gloss_of_a_smooth_black_glass_surface_is_100() -> None:
    # alpha -> 0 with the black-glass index: the ISO 2813 definition gives 100 GU at every
    # geometry (Mihalik eq. 17); the receptor grid adapts to the narrow lobe.
    g = AnalyticModel("beckmann", alpha=0.002, n=1.567).gloss()
    for t in (20, 60, 85):
        assert g[t] == pytest.approx(100.0, abs=0.3)
    # docs/PHYSICS.md truth for n = 1.55: 95.4 / 97.3 / 99.8.
    g155 = AnalyticModel("beckmann", alpha=0.002, n=1.55).gloss()
    assert [round(g155[t], 1) for t in (20, 60, 85)] == pytest.approx([95.4, 97.3, 99.8], abs=0.3)


def test_adaptive_receptor_grid_matches_a_brute_force_grid() -> None:
    # A narrow lobe at 85 deg is 0.1 deg wide out of the plane; a fixed 16 x 16 grid over the
    # 6 deg receptor aliases it, the adaptive grid agrees with a 32 x 300 brute-force sum.
    m = AnalyticModel("beckmann", alpha=0.01, n=1.55)
    rec = ISO2813_RECEPTOR[85]
    brute = integrate_brdf(m.brdf, 85.0, 85.0, ISO2813_SOURCE, rec, n_receptor=(32, 300))
    assert m.reflected_fraction(85.0, 85.0, ISO2813_SOURCE, rec) == pytest.approx(brute, rel=2e-3)


def test_rougher_is_less_glossy_and_wider() -> None:
    g = [AnalyticModel("ggx", alpha=a).gloss() for a in (0.02, 0.05, 0.1)]
    for t in (20, 60, 85):
        assert g[0][t] > g[1][t] > g[2][t]
    lum = AnalyticModel("beckmann", alpha=0.1).luminance_pct(45.0, [35.0, 45.0, 55.0])
    assert lum[1] > lum[0] and lum[1] > lum[2]


def test_bad_parameters_are_named() -> None:
    with pytest.raises(ValueError, match=r"unknown analytic model kind 'phong'.*beckmann"):
        AnalyticModel("phong", alpha=0.1)
    with pytest.raises(ValueError, match="alpha"):
        AnalyticModel("ggx", alpha=0.0)
    with pytest.raises(ValueError, match="85"):
        AnalyticModel("ggx", alpha=0.1).gloss((45,))


def test_cook_torrance_vcavity_by_hand() -> None:
    """Cook-Torrance at a geometry where the V-cavity term binds (docs/PHYSICS.md, "Analytic comparison models"; Mihalik eq. 12).

    ti = 80, wo in plane at 40 deg on the lamp side: h is 60 deg from the normal and both
    directions make 20 deg with h, so G = min(1, 2 cos 60 cos 40 / cos 20, 2 cos 60 cos 80
    / cos 20) = cos 80 / cos 20 = 0.185; f = D_Beckmann(60 deg) G F(cos 20) / (4 cos 80 cos 40).
    """
    alpha, n = 0.5, 1.5
    m = AnalyticModel("cook-torrance", alpha=alpha, n=n)
    c60 = math.cos(math.radians(60.0))
    tan2 = math.tan(math.radians(60.0)) ** 2
    d = math.exp(-tan2 / alpha**2) / (math.pi * alpha**2 * c60**4)
    c20 = math.cos(math.radians(20.0))
    g = math.cos(math.radians(80.0)) / c20
    f_expected = (
        d
        * g
        * float(fresnel_dielectric(c20, n))
        / (4.0 * math.cos(math.radians(80.0)) * math.cos(math.radians(40.0)))
    )
    assert m.brdf_inplane(80.0, [-40.0])[0] == pytest.approx(f_expected, rel=1e-12)
    # Beckmann with its Smith masking differs there: the two shadowing terms are not the same.
    assert AnalyticModel("beckmann", alpha=alpha, n=n).brdf_inplane(80.0, [-40.0])[0] != (
        pytest.approx(f_expected, rel=1e-3)
    )
