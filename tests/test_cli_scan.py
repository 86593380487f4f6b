"""CLI: ``goniolab runs`` on a prepared store, and ``goniolab scan`` input errors."""

from __future__ import annotations

import asyncio
import csv
import io
import json
import math
import os
import sys
from pathlib import Path

import pytest

from goniolab.cli import build_parser, main
from goniolab.commands.scan import point_detail, read_stdin_line
from goniolab.config import configs_dir
from goniolab.scan.events import PointMeasured
from goniolab.scan.plans import BrdfPlan, parse_angles
from goniolab.store import RunStore

SIGMA_DEG = 3.0


def lobe(tr: float) -> float:
    return 40.0 * math.exp(-0.5 * ((tr - 45.0) / SIGMA_DEG) ** 2)


@pytest.fixture
def store_file(tmp_path: Path) -> Path:
    """A store with one finished 2-repeat scan 35..55 deg matching a Gaussian lobe exactly."""
    path = tmp_path / "s.sqlite"
    plan = BrdfPlan(45.0, tuple(float(t) for t in range(35, 56)), repeats=2, sample="sample:x")
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample="sample:x",
                           model={"n": 1.55}, version="t")  # fmt: skip
        for i, tr in enumerate(plan.theta_r_deg):
            for r in range(2):
                s.add_point(rid, index=i, repeat=r, theta_i_deg=45.0, theta_r_deg=tr,
                            measured_theta_i_deg=45.0, measured_theta_r_deg=tr,
                            luminance_pct=lobe(tr), raw={}, timestamp=1.0)  # fmt: skip
        s.add_predictions(rid, [(i, 45.0, tr, lobe(tr)) for i, tr in enumerate(plan.theta_r_deg)])
        s.set_status(rid, "done")
        half = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample="sample:x",
                            model={}, version="t")  # fmt: skip
        s.add_point(half, index=0, repeat=0, theta_i_deg=45.0, theta_r_deg=35.0,
                    measured_theta_i_deg=45.0, measured_theta_r_deg=35.0, luminance_pct=1.0,
                    raw={}, timestamp=2.0)  # fmt: skip
        s.set_status(half, "aborted", "aborted by the operator")
    return path


def test_runs_list_json(store_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["runs", "list", "--store", str(store_file), "--json"]) == 0
    runs = json.loads(capsys.readouterr().out)
    assert [(r["id"], r["status"], r["readings"]) for r in runs] == [
        (2, "aborted", 1),
        (1, "done", 42),
    ]


def test_runs_show_recomputes_the_summary(
    store_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["runs", "show", "1", "--store", str(store_file), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    s = doc["summary"]
    assert s["rmse_pct"] == 0.0 and s["complete"] is True
    assert s["measured_peak"]["position_deg"] == pytest.approx(45.0, abs=1e-9)
    # Gaussian FWHM = 2 sqrt(2 ln 2) sigma
    assert s["measured_peak"]["fwhm_deg"] == pytest.approx(
        2 * math.sqrt(2 * math.log(2)) * SIGMA_DEG, abs=0.1
    )
    assert main(["runs", "show", "2", "--store", str(store_file)]) == 0
    out = capsys.readouterr().out
    assert "aborted" in out and "goniolab scan resume 2" in out


def test_runs_export_csv_to_file(store_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "run1.csv"
    assert (
        main(["runs", "export", "1", "--format", "csv", "-o", str(out), "--store", str(store_file)])
        == 0
    )
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert len(rows) == 42
    assert {"theta_r_deg", "repeat", "luminance_pct", "predicted_pct"} <= set(rows[0])
    assert [(r["theta_r_deg"], r["repeat"]) for r in rows[:3]] == [
        ("35.0", "0"),
        ("35.0", "1"),
        ("36.0", "0"),
    ]


def test_missing_run_is_a_clear_error(store_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["runs", "show", "7", "--store", str(store_file)]) == 2
    err = capsys.readouterr().err
    assert "no run 7" in err and str(store_file) in err


def test_scan_without_config_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scan", "--theta-r", "0:70:1"]) == 2
    assert "--config" in capsys.readouterr().err


def test_resume_of_a_finished_run_is_refused(
    store_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scan", "resume", "1", "--store", str(store_file)]) == 2
    assert "already done" in capsys.readouterr().err


def test_runs_show_gloss_statistics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "g.sqlite"
    with RunStore(path) as s:
        rid = s.create_run(kind="gloss", plan={}, config={}, sample="", model={}, version="t")
        for k, g60 in enumerate((57.0, 58.0, 59.0)):
            s.add_gloss_reading(rid, values_gu={20: None, 60: g60, 85: None}, temperature_c=None,
                                predicted_gu=None, raw="", timestamp=float(k))  # fmt: skip
        s.set_status(rid, "done")
    assert main(["runs", "show", str(rid), "--store", str(path)]) == 0
    # mean 58.0, sample std 1.0 of 57, 58, 59
    assert "G60: 58.0 +- 1.0 GU (n = 3)" in capsys.readouterr().out


def test_unknown_sample_names_the_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = str(configs_dir() / "lab-sim.toml")
    args = ["scan", "--config", cfg, "--sample", "sample:nope", "--store", str(tmp_path / "s")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "--sample sample:nope: no built-in sample 'nope'" in err and "wittmann-3" in err


def test_unsafe_plan_is_refused_and_not_recorded(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "s.sqlite"
    cfg = str(configs_dir() / "lab-sim.toml")
    # theta_r = -40 deg at theta_i = 45 deg: arms 5 deg apart, below the 10 deg minimum
    args = [
        "scan",
        "--config",
        cfg,
        "--theta-r",
        "-40,-30",  # a lamp-side list, not an option
        "--time-scale",
        "0",
        "--store",
        str(store),
    ]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "point 0 (theta_i=45 deg, theta_r=-40 deg) is unsafe" in err and "no arm moved" in err
    with RunStore(store) as s:
        assert s.list_runs() == []


@pytest.mark.parametrize(
    ("spec", "angles"),
    [
        ("-40:-30:5", (-40.0, -35.0, -30.0)),
        ("-10,0,10", (-10.0, 0.0, 10.0)),
        ("-7.5", (-7.5,)),
        ("-20:20:10", (-20.0, -10.0, 0.0, 10.0, 20.0)),
    ],
)
def test_theta_r_may_start_on_the_lamp_side(spec: str, angles: tuple[float, ...]) -> None:
    args = build_parser().parse_args(["scan", "--config", "x.toml", "--theta-r", spec])
    assert parse_angles(args.theta_r) == angles


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["scan", "--config", "{tmp}/none.toml"], "none.toml: config file not found"),
        (["scan", "--config", "{cfg}", "--theta-r", "garbage"],
         "scan: --theta-r: list 'garbage' has a non-numeric entry"),
        (["scan", "--config", "{cfg}", "--repeats", "0"], "scan: repeats must be >= 1, got 0"),
        (["scan", "--config", "{cfg}", "--sample", "{tmp}/no.npy"],
         "--sample {tmp}/no.npy: no such file"),
        (["scan", "--config", "{cfg}", "--store", "{tmp}"], "store {tmp}: is a directory"),
        (["scan", "resume", "3", "--store", "{tmp}/none.sqlite"],
         "store {tmp}/none.sqlite: no such file"),
        (["runs", "export", "3", "--store", "{tmp}/none.sqlite"],
         "store {tmp}/none.sqlite: no such file"),
    ],
)  # fmt: skip
def test_bad_input_is_one_clear_line_with_exit_2(
    args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fill = {"tmp": str(tmp_path), "cfg": str(configs_dir() / "lab-sim.toml")}
    assert main([a.format(**fill) for a in args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("goniolab: error: ") and err.count("\n") == 1  # one line
    assert message.format(**fill) in err
    assert list(tmp_path.iterdir()) == []  # nothing created on the way


def test_runs_list_of_a_missing_store_creates_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "typo" / "s.sqlite"
    assert main(["runs", "list", "--store", str(path), "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out) == [] and f"store {path} does not exist yet" in err
    assert not (tmp_path / "typo").exists()


def test_runs_show_prints_the_plan_as_the_range_that_made_it(
    store_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["runs", "show", "1", "--store", str(store_file)]) == 0
    out = capsys.readouterr().out
    assert (
        "  plan: theta_i 45 deg, theta_r 35:55:1 deg (21 angles), repeats 2, dwell 0 s, "
        "exposure 10000 us\n"
    ) in out
    with RunStore(store_file, readonly=True) as s:
        assert BrdfPlan.from_dict(s.get_run(1).plan).theta_r_deg == parse_angles("35:55:1")


def test_runs_show_gloss_prints_the_prediction_beside_the_mean(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "g.sqlite"
    with RunStore(path) as s:
        rid = s.create_run(kind="gloss", plan={"kind": "gloss", "count": 2, "angles_deg": [60]},
                           config={}, sample="sample:x", model={"predicted_gu": {"60": 58.96}},
                           version="t")  # fmt: skip
        for k, g60 in enumerate((58.5, 59.5)):
            s.add_gloss_reading(rid, values_gu={60: g60}, temperature_c=None, predicted_gu=None,
                                raw="", timestamp=float(k))  # fmt: skip
    assert main(["runs", "show", str(rid), "--store", str(path)]) == 0
    out = capsys.readouterr().out
    # mean 59.0, sample std sqrt(0.5) = 0.707 of 58.5 and 59.5
    assert "  plan: gloss 60 deg, 2 readings\n" in out
    assert "  G60: 59.0 +- 0.7 GU (n = 2), predicted 59.0 GU\n" in out


def test_progress_detail_shows_prediction_and_residual() -> None:
    ev = PointMeasured(run_id=1, index=3, repeat=0, theta_i_deg=45.0, theta_r_deg=44.0,
                       luminance_pct=2.678, measured_theta_i_deg=45.0, measured_theta_r_deg=44.0)  # fmt: skip
    assert point_detail(ev, 2.668) == "theta_r=44 L=2.678 % pred 2.668 % res +0.010"
    assert point_detail(ev, None) == "theta_r=44 L=2.678 %"


async def test_operator_prompt_reads_a_line_and_a_cancel_ends_the_wait(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    r, w = os.pipe()
    with os.fdopen(r, "r") as stdin, os.fdopen(w, "w") as feed:
        monkeypatch.setattr(sys, "stdin", stdin)
        waiting = asyncio.create_task(read_stdin_line())
        await asyncio.sleep(0)  # the task now waits for stdin to become readable
        waiting.cancel()  # Ctrl-C twice: no thread is left blocked in readline()
        with pytest.raises(asyncio.CancelledError):
            await waiting
        feed.write("ok\n")
        feed.flush()
        assert await read_stdin_line() == "ok\n"


def test_runs_list_tells_an_interrupted_run_from_a_running_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "s.sqlite"
    with RunStore(path) as s:
        plan = BrdfPlan(45.0, (44.0, 45.0, 46.0)).to_dict()
        rid = s.create_run(kind="brdf", plan=plan, config={}, sample="", model={}, version="t")
        s.set_status(rid, "running")  # its process was killed -9: nobody claims it
        assert main(["runs", "list", "--store", str(path), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)[0]["interrupted"] is True
        with s.claim_run(rid):  # a runner is measuring it
            assert main(["runs", "list", "--store", str(path)]) == 0
            assert f"{rid:>5}  brdf   running " in capsys.readouterr().out
        assert main(["runs", "list", "--store", str(path)]) == 0
        assert f"{rid:>5}  brdf   interrupted " in capsys.readouterr().out
        assert main(["runs", "show", str(rid), "--store", str(path)]) == 0
        assert "running (interrupted: no goniolab process is measuring it)" in (
            capsys.readouterr().out
        )
