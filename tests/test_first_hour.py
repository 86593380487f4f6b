"""The first hour of a new user (issue 27, items 5-6): words that name the right thing.

- a ``.npy`` map without a sidecar passed to ``scan`` is blamed on ``--sample`` (not the
  config), and ``scan --step-um`` supplies the step (stored with the run's config);
- the message names the sidecar as missing, not as the file that lacks a step;
- a run kind reads with its article ("an alignment run", not "a align run").
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.config import configs_dir
from goniolab.store import RunStore

CFG = str(configs_dir() / "lab-sim.toml")


def _bare_npy(tmp_path: Path) -> Path:
    path = tmp_path / "bare.npy"
    rng = np.random.default_rng(3)
    np.save(path, rng.normal(0.0, 0.05, (64, 64)))  # heights in um, no sidecar
    return path


def test_a_bare_npy_names_its_missing_sidecar(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _bare_npy(tmp_path)
    assert main(["predict", "stats", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"goniolab: error: {path.name}: no lateral step in the file")
    assert "it has no sidecar bare.npy.json" in err and "--step-um" in err
    assert not (tmp_path / "bare.npy.json").exists()  # named as missing, not made


def test_scan_of_a_bare_npy_blames_the_option_not_the_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _bare_npy(tmp_path)
    store = tmp_path / "s.sqlite"
    args = ["scan", "--config", CFG, "--sample", str(path), "--store", str(store)]
    assert main([*args, "--theta-r", "40:50:10", "--time-scale", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"goniolab: error: --sample {path.name}: no lateral step"), err
    assert "lab-sim.toml" not in err and "sample.map" not in err
    assert "--step-um" in err
    assert not store.exists() or RunStore(store).list_runs() == []


@pytest.mark.slow
def test_scan_step_um_supplies_the_step_and_is_stored(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _bare_npy(tmp_path)
    store = tmp_path / "s.sqlite"
    args = ["scan", "--config", CFG, "--sample", str(path), "--store", str(store), "--json"]
    assert main([*args, "--theta-r", "40:50:10", "--time-scale", "0", "--step-um", "0.5"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["state"] == "done" and summary["readings"] == 2
    with RunStore(store) as s:
        rec = s.get_run(summary["run_id"])
    assert rec.config["sample"]["step_um"] == 0.5  # a resume rebuilds the same map


def test_scan_step_um_must_be_positive(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _bare_npy(tmp_path)
    args = ["scan", "--config", CFG, "--sample", str(path), "--step-um", "-1"]
    assert main([*args, "--store", str(tmp_path / "s")]) == 2
    assert "--step-um must be > 0, got -1" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("kind", "phrase"),
    [("align", "an alignment run"), ("gloss", "a gloss run"), ("brdf", "a brdf run")],
)
def test_a_run_kind_reads_with_its_article(kind: str, phrase: str) -> None:
    from goniolab.errors import a_run_of_kind

    assert a_run_of_kind(kind) == phrase


def test_scan_setup_errors_name_the_form_fields() -> None:
    from goniolab.errors import UserError
    from goniolab.tui.view_model import ScanSetup

    def error(**kw: float) -> str:
        base = dict(theta_i_deg=45.0, theta_r_start_deg=0.0, theta_r_stop_deg=70.0,
                    theta_r_step_deg=1.0)  # fmt: skip
        with pytest.raises(UserError) as exc:
            ScanSetup(sample="sample:wittmann-3", repeats=1, **{**base, **kw}).validate()
        return str(exc.value)

    assert error(theta_r_stop_deg=-10.0) == "scan setup: θr to must be >= θr from, got -10 < 0"
    assert error(theta_r_step_deg=0.0) == "scan setup: θr step must be > 0 deg, got 0"
    # (θi out of the lamp arm's reach is the lab's check, in goniolab scan's words:
    # tests/tui/test_setup_limits.py)
    assert error(theta_i_deg=float("nan")) == "scan setup: θi must be a finite number, got nan"


def test_plot_writes_only_where_asked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from tests._runs import make_store

    store = make_store(tmp_path / "s.sqlite")
    monkeypatch.chdir(tmp_path)
    before = set(tmp_path.iterdir())
    assert main(["plot", "1", "--store", str(store)]) == 2
    assert "--out" in capsys.readouterr().err
    assert set(tmp_path.iterdir()) == before  # no run-1.png made unasked


@pytest.mark.slow
def test_a_scan_with_colour_keeps_colour_sciences_warnings_off_stderr(tmp_path: Path) -> None:
    """issue 27: "Aligning D65 illuminant shape ..." (a ColourRuntimeWarning) leaked into
    every interactive scan; it is the library's note, kept in the log file. In a process of
    its own: pytest's warning capture would hide a leak."""
    import os
    import subprocess
    import sys

    args = ["scan", "--config", CFG, "--sample", "sample:solid-red", "--theta-r", "40:50:10"]
    args += ["--time-scale", "0", "--store", str(tmp_path / "s.sqlite")]
    code = f"import sys; from goniolab.cli import main; sys.exit(main({args!r}))"
    env = {**os.environ, "GONIOLAB_LOG_DIR": str(tmp_path / "log")}
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert "Aligning" not in done.stderr and "Warning" not in done.stderr, done.stderr
    # (whether colour-science warns at all depends on its caches; where a library warning
    # goes, log file not stderr, is tests/test_cli_warnings.py's)


def test_a_dielectric_index_outside_1_to_3_is_warned_about(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """issue 27: --n 155 (for 1.55) gave G20 = 1166 GU without a word."""
    # main() shows goniolab's own warnings as one line on stderr
    assert main(["predict", "stats", "sample:flat", "--n", "155"]) == 0
    assert "goniolab: warning: --n 155 lies outside 1.0-3.0" in capsys.readouterr().err
    assert main(["predict", "stats", "sample:flat", "--n", "1.55"]) == 0
    assert main(["predict", "stats", "sample:flat", "--n", "0.27+3.41j"]) == 0  # a metal
    assert "--n" not in capsys.readouterr().err


def test_a_step_larger_than_the_correlation_length_is_warned_about(tmp_path: Path) -> None:
    """Independent truths: white noise has no correlation between neighbours (lag-1
    autocorrelation ~ 0 < 1/e); a sine of 200 points' period has cos(2 pi / 200) ~ 1."""
    import warnings

    from goniolab.surfaces.resolve import CoarseStepWarning, resolve_map

    rng = np.random.default_rng(5)
    noise, smooth = tmp_path / "noise.npy", tmp_path / "smooth.npy"
    np.save(noise, rng.normal(0.0, 0.1, (64, 64)))
    x = np.arange(64)
    np.save(smooth, 0.1 * np.sin(2 * np.pi * (x[:, None] + x[None, :]) / 200.0))
    with pytest.warns(CoarseStepWarning, match=r"--step-um 500 .*larger than the surface's"):
        resolve_map(noise, step_um=500.0)
    with pytest.warns(CoarseStepWarning):
        resolve_map("sample:gaussian-s0.05", step_um=500.0)  # 10 um correlation length
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        resolve_map(smooth, step_um=1.0)
        resolve_map("sample:gaussian-s0.05", step_um=1.0)


def test_runs_show_counts_an_alignment_runs_readings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """issue 27: counts per run kind in every view; `runs show --json` said 0 readings for
    an alignment run (its readings are points, not gloss readings)."""
    store = tmp_path / "s.sqlite"
    with RunStore(store) as s:
        rid = s.create_run(kind="align", plan={"kind": "align", "theta_i_deg": [20.0]},
                           config={}, sample="sample:x", model={}, version="9.9")  # fmt: skip
        for k in range(5):
            s.add_point(rid, index=k, repeat=0, theta_i_deg=20.0, theta_r_deg=18.0 + k,
                        measured_theta_i_deg=20.0, measured_theta_r_deg=18.0 + k,
                        luminance_pct=1.0, raw={}, timestamp=1.0e9 + k)  # fmt: skip
        s.update_model(rid, {"alignment": {"lamp_zero_deg": -0.163, "sample_tilt_deg": 0.136}})
        s.set_status(rid, "done")
    assert main(["runs", "show", str(rid), "--store", str(store), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["summary"]["readings"] == 5
    assert main(["runs", "show", str(rid), "--store", str(store)]) == 0
    text = capsys.readouterr().out
    assert "  readings: 5 " in text and "lamp arm zero offset: -0.163 deg" in text
    assert main(["runs", "list", "--store", str(store)]) == 0
    assert "align  done                5" in capsys.readouterr().out
