"""The colour use cases (goniolab.app.colours, colour_fit, sample_maps) called directly,
against numbers that do not come from goniolab: the ASTM E2194 geometry, Fresnel and the
CIE 1976 lightness of a spectrally flat reflectance, a sample written and read back."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from goniolab.app.colour_fit import FitOptions, fit_colour
from goniolab.app.colours import ColourOptions, load_paint_file, predict_colour, runs_colour
from goniolab.app.predictions import SurfaceRequest, heightmap_of
from goniolab.app.sample_maps import list_samples, save_sample
from goniolab.errors import UserError
from goniolab.surfaces.synthetic import make_sample
from tests._runs import make_store


def fresnel_unpolarised(theta_deg: float, n: float) -> float:
    """Born & Wolf, Principles of Optics, sec. 1.5.2, eqs. 21a-b (unpolarised light)."""
    ci = math.cos(math.radians(theta_deg))
    ct = math.sqrt(1.0 - (math.sin(math.radians(theta_deg)) / n) ** 2)
    rs = (ci - n * ct) / (ci + n * ct)
    rp = (n * ci - ct) / (n * ci + ct)
    return 0.5 * (rs * rs + rp * rp)


def test_a_clear_coat_on_black_is_black_off_specular_at_the_e2194_angles() -> None:
    pred = predict_colour(SurfaceRequest("sample:flat"), ColourOptions())
    rows = pred.doc["geometries"]
    # ASTM E2194: aspecular angle = theta_i - theta_r at theta_i = 45 deg
    assert [r["aspecular_deg"] for r in rows] == [-15.0, 15.0, 25.0, 45.0, 75.0, 110.0]
    assert [r["theta_r_deg"] for r in rows] == [60.0, 30.0, 20.0, 0.0, -30.0, -65.0]
    # a flat coat sends no light off specular and the black beneath returns none
    assert all(r["L"] == 0.0 and max(r["reflectance_factor"]) == 0.0 for r in rows)
    assert pred.doc["model"]["paint"]["coat"] == {"kind": "constant", "n": 1.55, "k": 0.0}
    assert pred.notes == []


def test_the_specular_gloss_of_a_clear_coat_is_fresnel_and_its_lightness_cie_1976() -> None:
    opts = ColourOptions(theta_r_deg="45", scale="mirror")
    row = predict_colour(SurfaceRequest("sample:flat"), opts).doc["geometries"][0]
    factor = np.asarray(row["reflectance_factor"])
    assert np.ptp(factor) < 1e-12  # a constant-index coat: the same at every wavelength
    assert factor[0] == pytest.approx(fresnel_unpolarised(45.0, 1.55), rel=5e-3)
    y = float(factor[0])  # a flat spectrum: Y / Yn = the factor, under any illuminant
    assert row["L"] == pytest.approx(116.0 * y ** (1.0 / 3.0) - 16.0, abs=1e-6)  # CIE 15 eq. 8.1
    # grey: no hue (to the rounding of the tabulated ASTM E308 weights against the white)
    assert abs(row["a"]) < 0.01 and abs(row["b"]) < 0.01


def test_colour_input_errors_are_one_line_each(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="--compare takes the geometries from its file"):
        predict_colour(
            SurfaceRequest("sample:flat"), ColourOptions(compare="x.csv", theta_r_deg="45")
        )
    bad = tmp_path / "paint.toml"
    bad.write_text("coat = [")
    with pytest.raises(UserError, match=r"paint.toml: TOML syntax error: "):
        load_paint_file(str(bad))


def test_colour_of_a_run_needs_a_scan(tmp_path: Path) -> None:
    store = make_store(tmp_path / "s.sqlite")
    with pytest.raises(UserError) as err:
        runs_colour(2, store=store)
    assert str(err.value) == "run 2 is a gloss run: colour needs a scan (brdf) run"
    with pytest.raises(UserError, match=r"no run 9$"):
        runs_colour(9, store=store)
    with pytest.raises(UserError) as err:
        fit_colour(2, FitOptions(), store=store)
    assert str(err.value) == "run 2 is a gloss run: a colour fit needs a scan run"


def test_a_saved_sample_reads_back_exactly(tmp_path: Path) -> None:
    names = [i.name for i in list_samples()]
    assert "flat" in names and "wittmann-3" in names
    out = tmp_path / "w3.npy"
    saved = save_sample("sample:wittmann-3", out, size=64, seed=3, step_um=2.0)
    assert saved.shape == (64, 64) and saved.as_dict()["field_um"] == [128.0, 128.0]
    back = heightmap_of(str(out))
    truth = make_sample("wittmann-3", size=64, seed=3, step_um=2.0)
    np.testing.assert_array_equal(back.z_um, truth.z_um)
    assert (back.dx_um, back.dy_um) == (2.0, 2.0)
    with pytest.raises(UserError, match="exists; pass --force to overwrite it"):
        save_sample("wittmann-3", out, size=64)
