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
    # black glass n = 1.567 at 45 deg: the unpolarised Fresnel reflectance
    want = 100 * float(fresnel(math.cos(math.radians(45.0)), 1.567))
    assert check["certified_y_pct"] == pytest.approx(want, rel=1e-6)
    assert check["ok"] and abs(check["residual_pct"]) < 0.2
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

    w = load_lab_config(cfg).sim.twin.s_weight
    r_s, r_p = fresnel_dielectric_sp(math.cos(math.radians(45.0)), 1.567)
    want = 100 * (w * float(r_s) + (1 - w) * float(r_p)
                  - float(fresnel(math.cos(math.radians(45.0)), 1.52)))  # fmt: skip
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
