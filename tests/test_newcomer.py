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
    # one prefix, then the command (issue 27: "goniolab: error: goniolab: ..." doubled it)
    assert len(err) == 2 and all(e.startswith("goniolab: error: ") for e in err)
    assert not any(e.startswith("goniolab: error: goniolab") for e in err)
    assert err[0].startswith("goniolab: error: scan: unrecognized arguments: --bogus")
    assert err[1].startswith("goniolab: error: predict brdf: ") and "MAP" in err[1]


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        # an unknown option before a value: argparse blamed `scan resume` for the value
        (
            ["scan", "--theta_r", "0:70:1"],
            "scan: unrecognized arguments: --theta_r (did you mean --theta-r?)",
        ),
        (["predict", "brdf", "sample:flat", "--modle", "facet"], "(did you mean --model?)"),
        (["scna"], "invalid choice: 'scna'"),
        (["scna"], "(did you mean 'scan'?)"),
        (["runs", "lst"], "(did you mean 'list'?)"),
        (["samples", "save", "wittman-3", "x.sur"], "(did you mean 'wittmann-3'?)"),
    ],
)
def test_typos_get_a_did_you_mean(
    capsys: pytest.CaptureFixture[str], argv: list[str], said: str
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert said in err and err.count("\n") == 1, err


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


def test_predict_gloss_prints_a_table_with_units(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", "gloss", "sample:wittmann-3", "--model", "facet", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert main(["predict", "gloss", "sample:wittmann-3", "--model", "facet"]) == 0
    lines = capsys.readouterr().out.splitlines()[1:]
    g60 = next(line for line in lines if line.strip().startswith("G60"))
    assert f"{rep['G60']:.1f}  GU" in g60 and "facet model" in g60
    text = "\n".join(lines)
    assert "haze index HI (ASTM D4039)" in text and "GU, G60 - G20" in text
    assert f"{rep['e430']['doi']:.1f}  of 100, 100 (Rs - R0.3) / Rs" in text
    assert f"{rep['d523_angle']}  deg (20 if G60 > 70, 85 if G60 < 10)" in text
    # every line with a number says what it is and in which unit
    numbered = [line for line in lines if not line.rstrip().endswith(":")]
    assert len(numbered) == 11
    assert all("GU" in line or "deg (" in line or "of 100" in line for line in numbered)


def test_a_negative_doi_is_printed_with_a_note(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """DOI = 100 (Rs - R0.3) / Rs is negative when the 0.3 deg off-specular reading exceeds
    the specular one (a surface with no distinct image): printed, never without a note."""
    import dataclasses

    import goniolab.optics.gloss_standards as gs

    real = gs.gloss_report

    def negative_doi(model: object) -> gs.GlossReport:
        rep = real(model)  # type: ignore[arg-type]
        return dataclasses.replace(rep, e430=dataclasses.replace(rep.e430, doi=-12.5))

    monkeypatch.setattr(gs, "gloss_report", negative_doi)
    assert main(["predict", "gloss", "sample:wittmann-3", "--model", "facet"]) == 0
    out = capsys.readouterr().out
    assert "-12.5  of 100" in out
    assert "note: DOI < 0: the 0.3 deg off-specular reading exceeds the specular one" in out


@pytest.mark.slow
def test_scan_takes_a_negative_theta_r_range(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``scan --theta-r -20:20:1`` (no ``=``): 41 geometries, stored, first -20 deg."""
    from goniolab.store import RunStore
    from tests.twin_configs import ideal_config

    cfg = ideal_config(tmp_path)
    text = cfg.read_text()
    assert "limits_deg = [0.0, 70.0]" in text
    cfg.write_text(text.replace("limits_deg = [0.0, 70.0]", "limits_deg = [-70.0, 70.0]"))
    store = tmp_path / "runs.sqlite"
    argv = ["scan", "--config", str(cfg), "--store", str(store), "--theta-i", "60",
            "--theta-r", "-20:20:1", "--time-scale", "0", "--json"]  # fmt: skip
    assert main(argv) == 0, capsys.readouterr().err
    with RunStore(store) as s:
        (run,) = s.list_runs()
        angles = [p.theta_r_deg for p in s.points(run.id)]
    assert len(angles) == 41 and angles[0] == -20.0 and angles[-1] == 20.0


def test_cli_tui_api_and_bluesky_default_repeats_agree() -> None:
    """One default: goniolab.scan.plans.DEFAULT_REPEATS (the TUI said 3, the CLI 1)."""
    import inspect

    from goniolab import api
    from goniolab.cli import build_parser
    from goniolab.scan.plans import DEFAULT_REPEATS, BrdfPlan
    from goniolab.tui.session_backend import SessionBackend

    cfg = Path(__file__).resolve().parents[1] / "configs" / "lab-sim.toml"
    assert SessionBackend(str(cfg)).default_setup().repeats == DEFAULT_REPEATS
    scan = build_parser().parse_args(["scan", "--config", str(cfg)])
    assert scan.repeats == DEFAULT_REPEATS
    assert inspect.signature(api.run_scan).parameters["repeats"].default == DEFAULT_REPEATS
    assert BrdfPlan(45.0, (40.0,)).repeats == DEFAULT_REPEATS == 1
