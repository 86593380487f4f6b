"""Rough edges a newcomer met (issue 14, item 7): .npy sidecars, one-line argparse errors,
negative angle ranges."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.surfaces import HeightMapError, load_heightmap
from goniolab.surfaces.npy import HeightUnitsWarning


def _npy(tmp_path: Path, z: np.ndarray, sidecar: object) -> Path:
    path = tmp_path / "map.npy"
    np.save(path, z)
    (tmp_path / "map.npy.json").write_text(json.dumps(sidecar))
    return path


Z = np.arange(12, dtype=np.float64).reshape(3, 4) * 0.01


@pytest.mark.parametrize(
    ("sidecar", "steps"),
    [
        ({"step_um": 0.5}, (0.5, 0.5)),
        ({"dx_um": 0.5}, (0.5, 0.5)),  # dy defaults to dx, as in the CSV header
        ({"dx_um": 0.5, "dy_um": 0.25}, (0.5, 0.25)),
    ],
)
def test_sidecar_steps(tmp_path: Path, sidecar: object, steps: tuple[float, float]) -> None:
    hm = load_heightmap(_npy(tmp_path, Z, sidecar))
    assert (hm.dx_um, hm.dy_um) == steps
    np.testing.assert_array_equal(hm.z_um, Z)


def test_sidecar_z_unit_and_scale(tmp_path: Path) -> None:
    hm = load_heightmap(_npy(tmp_path, Z, {"step_um": 1.0, "z_unit": "nm", "z_scale": 2.0}))
    np.testing.assert_allclose(hm.z_um, Z * 2.0 * 1e-3, rtol=1e-12)
    assert hm.meta["z_stored_unit"] == "2 nm"


@pytest.mark.parametrize(
    ("sidecar", "reason"),
    [
        ({"dy_um": 0.5}, "dy_um needs dx_um"),
        ({"z_unit": "nm"}, "no lateral step: give dx_um"),
        ({"step_um": 1, "dx_um": 1}, "not both"),
        ({"step_um": "1"}, "step_um must be a number"),
        ({"step_um": 1, "zunit": "nm"}, "unknown key 'zunit'"),
        ({"step_um": 1, "z_unit": "furlong"}, "unknown z unit"),
        ([1, 2], "must be a JSON object"),
    ],
)
def test_a_bad_sidecar_is_one_clear_error(tmp_path: Path, sidecar: object, reason: str) -> None:
    with pytest.raises(HeightMapError) as exc:
        load_heightmap(_npy(tmp_path, Z, sidecar))
    text = str(exc.value)
    assert reason in text and "map.npy.json" in text and "KeyError" not in text


def test_nanometres_read_as_micrometres_are_warned_about(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    z_nm = rng.normal(0.0, 200.0, (32, 32))  # Sq 200 "um", slopes ~ 280 over 1 um steps
    with pytest.warns(HeightUnitsWarning, match='"z_unit": "nm"'):
        load_heightmap(_npy(tmp_path, z_nm, {"step_um": 1.0}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_heightmap(_npy(tmp_path, z_nm, {"step_um": 1.0, "z_unit": "nm"}))


def test_argparse_errors_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scan", "--bogus"]) == 2
    assert main(["predict", "brdf"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all(e.startswith("goniolab: error: goniolab") for e in err)
    assert "unrecognized arguments: --bogus" in err[0] and "MAP" in err[1]


def test_a_negative_angle_range_needs_no_equals(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["predict", "brdf", "sample:flat", "--theta-i", "0", "--theta-r", "-20:20:10"]
    assert main([*argv, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["theta_r_deg"] == [-20, -10, 0, 10, 20]


def test_a_three_angle_grid_reports_no_fwhm(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["predict", "brdf", "sample:wittmann-1", "--theta-r", "40,45,50", "--point"]
    assert main([*argv, "--json"]) == 0
    peak = json.loads(capsys.readouterr().out)["peak"]
    assert peak["position_deg"] == pytest.approx(45.0, abs=0.5)
    assert peak["fwhm_deg"] is None and "not resolved" in peak["fwhm_note"]
    assert main(argv) == 0
    assert "FWHM not resolved by this angle grid" in capsys.readouterr().out
    # a grid that samples the peak does give its width
    assert main(["predict", "brdf", "sample:wittmann-1", "--theta-r", "30:60:0.5", "--json"]) == 0
    fine = json.loads(capsys.readouterr().out)["peak"]
    assert fine["fwhm_deg"] is not None and "fwhm_note" not in fine


def test_help_explains_slope_method(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["predict", "gloss", "--help"])
    assert "squares plane through 3 x 3 points" in " ".join(capsys.readouterr().out.split())
