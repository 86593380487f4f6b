"""``goniolab render`` (issue 11, item 6): the picture of a metallic shows flop, of a solid
none; pixels agree with the virtual goniometer's reading; the PNG is what was asked."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.colour.paint_render import (
    PANEL_HALF_ANGLE_DEG,
    _directions,
    _rusinkiewicz,
    render,
    tabulate_brdf,
)
from goniolab.colour.spectra import (
    ColourSettings,
    colour_module,
    spectra_to_xyz,
    standard_grid_nm,
    xyz_to_colour,
)
from goniolab.colour.spectral import SpectralPredictor, reflectance_factor_scale
from goniolab.model_cache import paint_for

WL = standard_grid_nm(20.0)


def _l_star(y: np.ndarray) -> np.ndarray:
    t = np.asarray(y) / 100.0
    return np.where(t > 216 / 24389, 116.0 * np.cbrt(t) - 16.0, 24389 / 27 * t)


def test_half_difference_angles_round_trip() -> None:
    # Rusinkiewicz's (theta_h, theta_d, phi_d) of (wi, wo) give back directions with the same
    # elevations and the same angle between them (phi_h is dropped: the BRDF is isotropic)
    rng = np.random.default_rng(2)
    v = rng.normal(size=(200, 2, 3))
    v[..., 2] = np.abs(v[..., 2]) + 0.05
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    wi, wo = v[:, 0], v[:, 1]
    normal = np.tile([0.0, 0.0, 1.0], (200, 1))
    th, td, pd, ci, co = _rusinkiewicz(normal, wi, wo)
    assert ci == pytest.approx(wi[:, 2]) and co == pytest.approx(wo[:, 2])
    wi2, wo2 = _directions(th, td, pd)
    assert wi2[:, 2] == pytest.approx(wi[:, 2], abs=1e-9)
    assert wo2[:, 2] == pytest.approx(wo[:, 2], abs=1e-9)
    assert np.sum(wi2 * wo2, -1) == pytest.approx(np.sum(wi * wo, -1), abs=1e-9)


@pytest.mark.parametrize("name", ["silver-metallic", "pearl"])
def test_centre_of_the_panel_reads_like_the_e2194_45_degree_reading(name: str) -> None:
    # the panel's centre row is theta_i = 45, theta_r = 0 (45 deg aspecular): its reflectance
    # factor must equal the spectral predictor's cone-integrated reading there (another
    # integration of the same paint: 6 deg cones, quadrature, no table)
    paint = paint_for(f"sample:{name}")
    size = 65  # an odd size puts a pixel row exactly on the panel's axis
    pic = render(tabulate_brdf(paint, 0.03, wavelengths_nm=WL), size=size)
    c = size // 2
    assert pic.aspecular_deg[c, c] == pytest.approx(45.0, abs=1e-6)
    l_render = _l_star(pic.xyz[c, c, 1] / pic.cos_i[c, c])
    sp = SpectralPredictor(None, paint, wavelengths_nm=WL)
    factors = sp.spectrum_pct(45.0, [0.0]) / 100.0 * reflectance_factor_scale([0.0], 6.0)[:, None]
    l_gonio = xyz_to_colour(spectra_to_xyz(WL, factors))[0, 3]
    assert l_render == pytest.approx(l_gonio, abs=1.5)


def _png_factor_lightness(png: Path, size: int) -> tuple[np.ndarray, np.ndarray]:
    """L* of the reflectance factor down the centre column of a panel PNG, with each row's
    aspecular angle, from the documented geometry alone (normal tilt b per row, key lamp 45
    deg above the view axis: theta_i = 45 - b, aspecular = 45 - 2 b)."""
    from PIL import Image

    img = Image.open(png)
    assert img.format == "PNG" and img.size == (size, size) and img.mode == "RGB"
    rgb = np.asarray(img, dtype=np.float64) / 255.0
    colour = colour_module()
    xyz = colour.sRGB_to_XYZ(rgb[:, size // 2], ColourSettings().validated().white_xy) * 100.0
    y_img = -(((np.arange(size) + 0.5) / size) * 2.0 - 1.0)
    b = np.degrees(np.arcsin(y_img * math.sin(math.radians(PANEL_HALF_ANGLE_DEG))))
    cos_i = np.cos(np.radians(45.0 - b))
    return _l_star(xyz[:, 1] / cos_i), 45.0 - 2.0 * b


def test_metallic_panel_shows_flop_and_a_solid_none(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spread = {}
    for name in ("silver-metallic", "solid-red"):
        out = tmp_path / f"{name}.png"
        # exposure 1 and no sparkle: the PNG holds the documented physical scale
        assert main(["render", f"sample:{name}", "--out", str(out), "--size", "64",
                     "--step-nm", "20", "--json", "--exposure", "1",
                     "--no-sparkle"]) == 0  # fmt: skip
        doc = json.loads(capsys.readouterr().out)
        assert doc["output"] == str(out.resolve()) and doc["size"] == 64
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        lf, aspecular = _png_factor_lightness(out, 64)
        away = (aspecular >= 25.0) & (aspecular <= 95.0)  # off the gloss, lamp not grazing
        assert away.sum() > 20
        spread[name] = float(np.ptp(lf[away]))
    assert spread["silver-metallic"] > 30.0  # flop: lightness falls away from the highlight
    assert spread["solid-red"] < 4.0  # a solid keeps its lightness (the lamp's cos taken out)
    assert spread["silver-metallic"] > 8.0 * spread["solid-red"]


def test_second_lamp_adds_light_and_the_sphere_has_a_black_background() -> None:
    table = tabulate_brdf(paint_for("sample:white"), 0.03, wavelengths_nm=WL)
    one = render(table, shape="sphere", size=32, lamps=1)
    two = render(table, shape="sphere", size=32, lamps=2)
    assert np.all(two.xyz[..., 1] >= one.xyz[..., 1] - 1e-9)
    assert np.sum(two.xyz[..., 1]) > 1.05 * np.sum(one.xyz[..., 1])
    assert np.all(one.srgb[0, 0] == 0.0) and not one.mask[0, 0] and one.mask[16, 16]


def test_render_bad_input_is_one_line_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cases = [
        (["--out", str(tmp_path / "x.jpg")], "written as PNG"),
        (["--out", str(tmp_path / "no" / "x.png")], "no such directory"),
        (["--out", str(tmp_path / "x.png"), "--size", "4"], "--size 4"),
        (["--out", str(tmp_path / "x.png"), "--illuminant", "D66"], "unknown illuminant"),
        (["--out", str(tmp_path / "x.png"), "--observer", "7"], "unknown observer"),
        (["--out", str(tmp_path / "x.png"), "--exposure", "0"], "--exposure 0"),
    ]
    for extra, message in cases:
        assert main(["render", "sample:white", *extra]) == 2, extra
        err = capsys.readouterr().err
        assert err.startswith("goniolab: error:") and message in err, (extra, err)
    assert not (tmp_path / "x.png").exists()
