"""Sparkle and graininess: the expected count of sparkling flakes against a Monte Carlo of
the flake geometry, graininess against a simulated Poisson coverage, the textured render
against the smooth one, and the automatic exposure's clipping bound."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.colour.paint import MetallicFlakes, Paint, PaintError, paint_from_dict
from goniolab.colour.paint_render import render, tabulate_brdf
from goniolab.colour.sparkle import expected_sparkles, graininess, sparkle_report
from goniolab.model_cache import paint_for

WL = np.linspace(380.0, 780.0, 21)


def _refract_out(w_in: np.ndarray, n: float) -> tuple[np.ndarray, np.ndarray]:
    xy = w_in[:, :2] * n
    s2 = np.sum(xy * xy, axis=1)
    ok = s2 < 1.0
    z = np.sqrt(np.clip(1.0 - s2, 0.0, 1.0))
    return np.column_stack([xy, z]), ok


@pytest.mark.parametrize("lamp_deg", [15.0, 30.0])
def test_expected_sparkles_match_a_monte_carlo_of_flake_mirrors(lamp_deg: float) -> None:
    """Flake normals drawn from the Beckmann law (slopes Gaussian, sd alpha / sqrt 2 per
    axis); a flake sparkles when the view ray, refracted into the coat and mirrored by the
    flake, leaves the coat within the lamp's disc. mu = N_px x that probability."""
    n, spread, radius = 1.5, 8.0, 2.0
    flakes = MetallicFlakes(0.4, spread, size_um=20.0)
    rng = np.random.default_rng(1)
    m = 4_000_000
    alpha = math.tan(math.radians(spread))
    slopes = rng.normal(0.0, alpha / math.sqrt(2.0), (m, 2))
    h = np.column_stack([-slopes, np.ones(m)])
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    v_in = np.array([0.0, 0.0, 1.0])  # camera along the normal: no refraction
    r = 2.0 * (h @ v_in)[:, None] * h - v_in
    out, ok = _refract_out(r, n)
    t = math.radians(lamp_deg)
    lamp = np.array([math.sin(t), 0.0, math.cos(t)])
    hit = ok & (out @ lamp > math.cos(math.radians(radius)))
    pixel_um = 100.0
    n_px = 0.4 * pixel_um**2 / (math.pi * 20.0**2 / 4.0)
    mc = n_px * hit.mean()
    mu = float(expected_sparkles(lamp, np.array([0.0, 0.0, 1.0]), flakes, n, radius, pixel_um))
    sigma = n_px * math.sqrt(hit.mean() / m)
    assert hit.sum() > 1000
    assert mu == pytest.approx(mc, abs=4 * sigma + 0.03 * mc)


def test_graininess_matches_a_simulated_pixel_coverage() -> None:
    paint = paint_for("sample:silver-metallic")
    fl = paint.metallic
    assert fl is not None
    pixel_um = 200.0
    g = graininess(paint, fl, pixel_um)
    # simulate: per pixel a Poisson number of flakes, coverage c = k a_f / p^2, then the
    # pixel luminance c L_f + (1 - c) L_b (flake: R T^2 through the coat twice; body: the
    # Lambertian body under uniform light), and its contrast
    a_f = math.pi * fl.size_um**2 / 4.0
    lam = fl.area_fraction * pixel_um**2 / a_f
    rng = np.random.default_rng(3)
    c = rng.poisson(lam, 400_000) * a_f / pixel_um**2
    from goniolab.colour import sparkle as sp

    n = float(paint.coat_n(np.array([550.0]))[0])
    f0 = ((n - 1.0) / (n + 1.0)) ** 2  # Fresnel at normal incidence
    l_f = sp._flake_reflectance(paint, fl, 550.0) * (1 - f0) ** 2
    lum = c * l_f + (1 - c) * _body_luminance(paint)
    sim = 100.0 * lum.std() / lum.mean()
    assert g == pytest.approx(sim, rel=0.03)


def _body_luminance(paint: Paint) -> float:
    from goniolab.colour.km import diffuse_fresnel_reflectance

    wl = np.array([550.0])
    n = float(paint.coat_n(wl)[0])
    t_o = float(paint.body_transmission(np.array([1.0]), wl)[0, 0])
    return (
        math.pi * float(paint.body_term(wl)[0]) * t_o * (1 - float(diffuse_fresnel_reflectance(n)))
    )


def test_sparkle_follows_flake_size_depth_and_spread() -> None:
    base = paint_for("sample:silver-metallic")
    fl = base.metallic
    assert fl is not None

    def rep(**kw: float) -> dict:
        return sparkle_report(replace(base, metallic=replace(fl, **kw)))["metallic"]

    small, big = rep(size_um=10.0), rep(size_um=40.0)
    # same coverage, bigger flakes: fewer sparkles, each brighter; a coarser pattern
    assert big["angles"][0]["S_a_pct"] < small["angles"][0]["S_a_pct"]
    assert big["angles"][0]["S_i"] > small["angles"][0]["S_i"]
    assert big["G"] > small["G"]
    shallow, deep = rep(depth_um=0.0), rep(depth_um=2.0)
    assert deep["angles"][1]["S_i"] < shallow["angles"][1]["S_i"]
    narrow, wide = rep(spread_deg=4.0), rep(spread_deg=15.0)
    # far from specular (lamp 75 deg) a wider spread tilts more flakes into the camera
    assert wide["angles"][2]["S_a_pct"] > narrow["angles"][2]["S_a_pct"]
    with pytest.raises(PaintError, match="size_um must be in"):
        paint_from_dict({"metallic": {"area_fraction": 0.3, "spread_deg": 5, "size_um": 0.1}})


def test_textured_render_averages_to_the_smooth_one() -> None:
    table = tabulate_brdf(paint_for("sample:silver-metallic"), 0.02, wavelengths_nm=WL)
    smooth = render(table, size=96, exposure=1.0)
    grains = render(table, size=96, exposure=1.0, sparkle=True, seed=5)
    assert grains.sparkle_pixels is not None and grains.sparkle_pixels[grains.mask].any()
    rows = slice(40, 96)  # away from the coat's highlight, where the flakes dominate
    m_s = smooth.xyz[rows][..., 1][smooth.mask[rows]].mean()
    m_g = grains.xyz[rows][..., 1][grains.mask[rows]].mean()
    assert m_g == pytest.approx(m_s, rel=0.1)
    # a smooth panel row is uniform (the bend is vertical); a sparkling row is not
    cols = smooth.mask[60]
    assert np.ptp(smooth.xyz[60, cols, 1]) < 1e-9 * smooth.xyz[60, cols, 1].mean()
    row = grains.xyz[60, cols, 1]
    assert row.std() > 0.2 * row.mean()


@pytest.mark.parametrize("name", ["silver-metallic", "white"])
def test_default_exposure_clips_at_most_one_percent(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from PIL import Image

    out = tmp_path / "p.png"
    argv = ["render", f"sample:{name}", "-o", str(out), "--size", "96", "--step-nm", "20"]
    assert main([*argv, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["exposure_auto"] is True and doc["clipped_fraction"] <= 0.01
    rgb = np.asarray(Image.open(out))
    shape = np.any(rgb > 0, axis=-1)
    saturated = np.any(rgb == 255, axis=-1) & shape
    assert saturated.sum() <= 0.01 * shape.sum() + 2  # 8-bit rounding at the edge
    assert main([*argv, "--json", "--exposure", "1", "--no-sparkle"]) == 0
    fixed = json.loads(capsys.readouterr().out)
    if name == "silver-metallic":
        assert fixed["clipped_fraction"] > 0.1  # exposure 1 burns the highlight (issue 25)
