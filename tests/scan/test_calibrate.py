"""``goniolab calibrate``: a calibration record later runs cite (issue 21)."""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.config import configs_dir
from goniolab.optics.fresnel import fresnel
from goniolab.scan.calibration import calibration_notices, latest_calibration
from goniolab.store import RunStore


def _config(tmp_path: Path, standards: str | None = None) -> Path:
    text = (configs_dir() / "lab-sim.toml").read_text()
    for key in ("lamp_zero_range_deg", "detector_zero_range_deg", "sample_tilt_range_deg"):
        text = text.replace(f"# {key} = 0.5", f"{key} = 0.0")
    text = re.sub(r'(?m)^store = ""', f'store = "{tmp_path / "runs.sqlite"}"', text)
    if standards is not None:
        (tmp_path / "standards.toml").write_text(standards)
    path = tmp_path / "lab.toml"
    path.write_text(text)
    return path


def _fresnel_sp(theta_deg: float, n: float) -> tuple[float, float]:
    """R_s, R_p of a dielectric from air in Fresnel's sine and tangent forms (Born & Wolf,
    Principles of Optics, sec. 1.5.2, eqs. 21a-b), with Snell's law for the refraction."""
    i = math.radians(theta_deg)
    t = math.asin(math.sin(i) / n)
    return (math.sin(t - i) / math.sin(t + i)) ** 2, (math.tan(t - i) / math.tan(t + i)) ** 2


def test_the_glass_at_45_deg_by_hand() -> None:
    # the numbers the check is held to, ISO 2813 black glass n = 1.567 at 45 deg
    r_s, r_p = _fresnel_sp(45.0, 1.567)
    assert r_s == pytest.approx(0.107796, abs=1e-6) and r_p == pytest.approx(0.011620, abs=1e-6)
    # a detector answering 51 % to s light reads it 0.096 points above the unpolarised value
    assert 100 * (0.51 * r_s + 0.49 * r_p - 0.5 * (r_s + r_p)) == pytest.approx(0.0962, abs=1e-4)
    assert 50 * (r_s + r_p) == pytest.approx(5.971, abs=5e-4)
    s60, p60 = _fresnel_sp(60.0, 1.567)  # and at 60 deg: the whole 0.2 % tolerance
    assert 100 * 0.01 * (s60 - p60) == pytest.approx(0.198, abs=5e-4)
    assert float(fresnel(math.cos(math.radians(45.0)), 1.567)) == pytest.approx(
        0.5 * (r_s + r_p), rel=1e-12
    )


def _json(args: list[str]) -> tuple[int, dict[str, object], str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(args)
    return code, (json.loads(out.getvalue()) if code == 0 else {}), err.getvalue()


def test_calibrate_reads_the_check_standard_against_its_certificate(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    code, rec, err = _json(["calibrate", "--config", str(cfg), "--time-scale", "0", "--json"])
    assert code == 0, err
    check = rec["check"]
    assert isinstance(check, dict)
    # black glass n = 1.567 at 45 deg as the twin's detector reads it: it answers w = 51 %
    # to s light ([sim.twin] s_weight; no alignment has fitted w in this store)
    from goniolab.config import load_lab_config

    w = load_lab_config(cfg).sim.twin.s_weight
    assert w == 0.51
    r_s, r_p = _fresnel_sp(45.0, 1.567)
    assert check["certified_y_pct"] == pytest.approx(100 * (w * r_s + (1 - w) * r_p), rel=1e-6)
    assert check["certified_unpolarised_y_pct"] == pytest.approx(50 * (r_s + r_p), rel=1e-6)
    assert check["s_weight"] == w and check["polarisation"]["source"] == "configured"
    assert "R = w R_s + (1 - w) R_p of n = 1.567" in check["weighting"]
    assert "[sim.twin] s_weight" in check["weighting"]
    # the twin's glass on an aligned seat (seed 1) reads the weighted certificate to 0.012 %;
    # held to the unpolarised certificate it was 0.108 % off
    assert check["ok"] and abs(check["residual_pct"]) < 0.05
    assert check["measured_y_pct"] - check["certified_unpolarised_y_pct"] > 0.05
    assert check["certificate"] == "SIM-BG-0001"
    mirror = rec["mirror"]
    assert isinstance(mirror, dict) and mirror["certificate"] == "SIM-MIR-0001"
    # a scan afterwards cites it (and says nothing: fresh, check ok)
    code, scan, err = _json(["scan", "--config", str(cfg), "--theta-r", "40,45", "--repeats",
                             "1", "--time-scale", "0", "--json"])  # fmt: skip
    assert code == 0 and "calibration" not in err
    with RunStore(str(tmp_path / "runs.sqlite")) as store:
        cite = store.get_run(int(scan["run_id"])).model["calibration"]  # type: ignore[call-overload]
        assert cite["run"] == rec["run_id"] and cite["check_ok"] is True
        latest = latest_calibration(store)
        assert latest is not None and latest.id == rec["run_id"]
        # 25 h later the same record is too old for the default 24 h
        t = float(latest.model["calibration"]["time"])
        _, notes = calibration_notices(latest, max_age_h=24.0, now=t + 25 * 3600)
        assert notes == [
            f"the calibration (run {latest.id}) is 25.0 h old, older than 24 h: run goniolab "
            "calibrate"
        ]


def test_a_check_standard_off_its_certificate_is_reported_by_later_runs(tmp_path: Path) -> None:
    # a certificate that disagrees with the glass on the seat (n = 1.52 certified, 1.567
    # placed): the record says it missed, and every later run warns
    text = (configs_dir() / "standards.toml").read_text().replace("n = 1.567", "n = 1.52")
    cfg = _config(tmp_path, standards=text)
    code, rec, err = _json(["calibrate", "--config", str(cfg), "--time-scale", "0", "--json"])
    assert code == 0
    check = rec["check"]
    assert isinstance(check, dict) and not check["ok"]
    # the twin's spectro answers w = 51 % to s light ([sim.twin] s_weight, 2 % polarisation
    # dependence): it reads the placed glass as w R_s + (1 - w) R_p
    from goniolab.config import load_lab_config
    from goniolab.optics.fresnel import fresnel_dielectric_sp

    # ... and the certificate's glass (n = 1.52) the same way (the assertion held it to the
    # unpolarised 1.52 value before the check weighted the certificate)
    w = load_lab_config(cfg).sim.twin.s_weight
    r_s, r_p = fresnel_dielectric_sp(math.cos(math.radians(45.0)), 1.567)
    c_s, c_p = _fresnel_sp(45.0, 1.52)
    want = 100 * (w * float(r_s) + (1 - w) * float(r_p) - (w * c_s + (1 - w) * c_p))
    assert check["residual_pct"] == pytest.approx(want, abs=0.1)
    assert "missed its certificate" in err
    code, _, err = _json(["scan", "--config", str(cfg), "--theta-r", "40", "--repeats", "1",
                          "--time-scale", "0", "--json"])  # fmt: skip
    assert code == 0
    assert "check standard (black_glass, certificate SIM-BG-0001) missed its certificate" in err
    assert np.isfinite(want)


def test_a_calibration_run_exports_and_is_not_resumed(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    code, rec, _ = _json(["calibrate", "--config", str(cfg), "--time-scale", "0", "--json"])
    assert code == 0
    store = str(tmp_path / "runs.sqlite")
    out = tmp_path / "cal.nc"
    assert main(["runs", "export", str(rec["run_id"]), "--store", store, "-o", str(out)]) == 0
    import xarray as xr

    with xr.open_dataset(out) as ds:
        assert ds.sizes["reading"] == 6  # 3 mirror + 3 check readings
        assert json.loads(ds.attrs["calibration_json"])["check"]["ok"] is True
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["scan", "resume", str(rec["run_id"]), "--store", store])
    assert code == 2 and "is a calibration: it cannot be resumed" in err.getvalue()


def test_runs_list_and_show_describe_a_calibration_run(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    code, rec, _ = _json(["calibrate", "--config", str(cfg), "--time-scale", "0", "--json"])
    assert code == 0
    store = str(tmp_path / "runs.sqlite")
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["runs", "list", "--store", store, "--json"]) == 0
    doc = json.loads(out.getvalue())
    row = (doc["runs"] if isinstance(doc, dict) else doc)[0]
    assert row["kind"] == "calibration" and row["readings"] == 6
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["runs", "show", str(rec["run_id"]), "--store", store]) == 0
    assert "readings: 6 (the result: the model's calibration record)" in out.getvalue()


def _align_run(store: RunStore, s_weight: float, sigma: float) -> int:
    """A finished alignment run whose black-glass fit found ``s_weight`` (``sigma`` NaN:
    two incidences, w assumed 0.5 rather than fitted)."""
    run_id = store.create_run(kind="align", plan={"kind": "align"}, config={}, sample="",
                              model={}, version="test")  # fmt: skip
    fit = {"s_weight": s_weight, "s_weight_sigma": sigma}
    store.update_model(run_id, {"alignment": {"standard_fit": fit}})
    store.set_status(run_id, "done")
    return run_id


def test_calibrate_reads_the_certificate_with_the_alignments_fitted_s_weight(
    tmp_path: Path,
) -> None:
    # the alignment the arms apply ([alignment] run) fitted w = 0.53: the check's certified
    # value is 0.53 R_s + 0.47 R_p, and the output says where w came from
    with RunStore(str(tmp_path / "runs.sqlite")) as store:
        run = _align_run(store, 0.53, 0.0012)
    cfg = _config(tmp_path)
    cfg.write_text(cfg.read_text() + f"\n[alignment]\nrun = {run}\n")
    code, rec, err = _json(["calibrate", "--config", str(cfg), "--time-scale", "0", "--json"])
    assert code == 0, err
    check = rec["check"]
    assert isinstance(check, dict)
    r_s, r_p = _fresnel_sp(45.0, 1.567)
    assert check["certified_y_pct"] == pytest.approx(100 * (0.53 * r_s + 0.47 * r_p), rel=1e-6)
    pol = check["polarisation"]
    assert pol["source"] == "fitted" and pol["alignment_run"] == run
    assert pol["s_weight"] == 0.53 and pol["s_weight_sigma"] == 0.0012
    assert f"fitted by the black-glass sweeps of alignment run {run}" in check["weighting"]
    # the text output names the weighting too
    out, err2 = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err2):
        assert main(["calibrate", "--config", str(cfg), "--time-scale", "0"]) == 0
    text = out.getvalue()
    assert (
        "certified value read as: R = w R_s + (1 - w) R_p of n = 1.567 (Fresnel) at 45 deg, "
        in text
    )
    assert f"w = 0.5300 +/- 0.0012 fitted by the black-glass sweeps of alignment run {run}" in text
    assert f"(unpolarised {50 * (r_s + r_p):.3f} %)" in text


def test_the_s_weight_comes_from_a_fit_else_the_twin_else_is_assumed(tmp_path: Path) -> None:
    from goniolab.scan.calibration import UNPOLARISED, detector_polarisation

    with RunStore(str(tmp_path / "runs.sqlite")) as store:
        fitted = _align_run(store, 0.5095, 0.001)
        two_incidences = _align_run(store, 0.5, math.nan)
        p = detector_polarisation(store, alignment_run=fitted, simulated_s_weight=0.51)
        assert (p.s_weight, p.source, p.alignment_run) == (0.5095, "fitted", fitted)
        p = detector_polarisation(store, alignment_run=two_incidences, simulated_s_weight=0.51)
        assert (p.s_weight, p.source) == (0.51, "configured")
        assert f"alignment run {two_incidences} fitted no w" in p.note
        p = detector_polarisation(store, alignment_run=two_incidences)
        assert (p.s_weight, p.source) == (0.5, "assumed")
        assert detector_polarisation(store, alignment_run=0) is UNPOLARISED
        p = detector_polarisation(store, alignment_run=999)  # not in this store
        assert (p.s_weight, p.source) == (0.5, "assumed") and "999" in p.note


def test_a_table_certificate_is_held_as_it_is() -> None:
    from goniolab.scan.standards import Standard

    table = Standard(name="white_tile", certificate="T", certified_on="2026-01-01",
                     model="table", tolerance=0.01, wavelength_nm=(380.0, 780.0),
                     reflectance_table=(0.8, 0.9))  # fmt: skip
    assert not table.splits_polarisation
    np.testing.assert_allclose(
        table.reflectance([380.0, 580.0], 45.0, s_weight=0.55), [0.8, 0.85], rtol=1e-12
    )
    glass = Standard(name="black_glass", certificate="G", certified_on="2026-01-01",
                     model="fresnel", tolerance=0.002, n=1.567)  # fmt: skip
    r_s, r_p = _fresnel_sp(60.0, 1.567)
    np.testing.assert_allclose(
        glass.reflectance([550.0], 60.0, s_weight=0.51), [0.51 * r_s + 0.49 * r_p], rtol=1e-12
    )


def test_a_park_that_fails_after_the_calibration_is_kept_with_its_record(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from drivers.base import DeviceTimeout
    from drivers.goniometer import TwoArmGoniometer

    async def stuck(self: TwoArmGoniometer, timeout_s: float) -> None:
        raise DeviceTimeout("no answer within 1 s", device="lamp")

    monkeypatch.setattr(TwoArmGoniometer, "park", stuck)
    cfg = _config(tmp_path)
    code, rec, err = _json(["calibrate", "--config", str(cfg), "--time-scale", "0", "--json"])
    assert code == 0, err
    said = "parking failed: lamp: no answer within 1 s"
    assert f"warning: {said}" in err
    assert rec["warnings"] == [said]
    with RunStore(str(tmp_path / "runs.sqlite")) as store:
        run = store.get_run(int(rec["run_id"]))  # type: ignore[call-overload]
        assert run.status == "done" and run.reason == said
        assert run.model["calibration"]["warnings"] == [said]
