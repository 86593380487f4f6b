"""Integration: the runner and the CLI on the simulated lab (sim clock at scale 0, no sleeps).

In-process sims and the wire sims (real drivers over Modbus TCP and ptys), a fault injected
through ``[sim.faults]``, and a SIGKILLed subprocess resumed to exactly one row per reading.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.config import configs_dir
from goniolab.store import RunStore
from sim.truth import luminance_weights
from tests.twin_configs import ideal

REPO = Path(__file__).resolve().parents[2]


def lab_config(
    tmp_path: Path,
    *,
    base: str = "lab-sim.toml",
    sim: dict[str, str] | None = None,
    faults: dict[str, str] | None = None,
    name: str = "lab.toml",
    twin: str = "ideal",
) -> Path:
    """Copy a shipped lab config with [sim] keys and [sim.faults] entries replaced
    (the ideal twin unless ``twin="realistic"``)."""
    text = (configs_dir() / base).read_text()
    if twin == "ideal":
        text = ideal(text)
    for key, value in (sim or {}).items():
        text, n = re.subn(rf"(?m)^{key}\s*=.*$", f"{key} = {value}", text, count=1)
        assert n == 1, key
    head, sep, tail = text.partition("[sim.faults]")
    assert sep, "config has no [sim.faults] table"
    extra = "".join(f"{k} = {v}\n" for k, v in (faults or {}).items())
    text = head + sep + "\n" + extra + tail.split("\n", 1)[1]
    # bare profile names resolve under the shipped configs directory, wherever the copy is
    if base == "lab-sim-wire.toml":
        # private endpoints: tests running in parallel must not share a port or a pty link
        text = text.replace("port = 5020", f"port = {free_tcp_port()}")
        text = text.replace("/tmp/goniolab-sim/", f"{tmp_path}/sim/")
        # the first reading builds the facet model's tables in the server (seconds on a
        # loaded CI machine): a generous reply timeout keeps that from reading as a fault
        head, sep, tail = text.partition("[spectro]")
        text = head + sep + re.sub(r"(?m)^timeout_s\s*=.*$", "timeout_s = 60.0", tail, count=1)
    path = tmp_path / name
    path.write_text(text)
    return path


def free_tcp_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


NOISELESS = {"noise_pct": "0.0"}


def test_scan_on_the_in_process_sim_matches_the_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = lab_config(tmp_path, sim=NOISELESS)
    store = tmp_path / "s.sqlite"
    code, out, err = run_cli(
        ["scan", "--config", str(cfg), "--theta-i", "45", "--theta-r", "38:52:1",
         "--repeats", "2", "--time-scale", "0", "--json", "--store", str(store)],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    summary = json.loads(out)  # stdout holds the summary JSON and nothing else
    assert summary["state"] == "done" and summary["readings"] == 30
    # the sim reads the same facet model through the same cones: residuals vanish
    peak = summary["predicted_peak"]["amplitude_pct"]
    assert summary["rmse_pct"] < 1e-3 * peak
    assert summary["peak_offset_deg"] == pytest.approx(0.0, abs=0.05)
    assert summary["hint"] is None
    assert "ETA" in err and "30/30" in err
    with RunStore(store) as s:
        run = s.get_run(summary["run_id"])
        assert run.status == "done" and run.sample == "sample:wittmann-3"
        assert s.count_points(run.id) == 30
        assert len(s.predictions(run.id)) == 15
        assert run.config["goniometer"]["source_cone_deg"] == 6.0


def test_sample_tilt_shifts_the_peak_by_twice_the_tilt(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Wittmann et al. 2021, sec. 5.2-5.3: a tilt tau moves the specular peak by 2 tau.
    cfg = lab_config(tmp_path, sim={**NOISELESS, "sample_tilt_deg": "1.0"})
    code, out, err = run_cli(
        ["scan", "--config", str(cfg), "--theta-r", "38:56:1", "--time-scale", "0", "--json",
         "--store", str(tmp_path / "s.sqlite")],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    s = json.loads(out)
    assert s["peak_offset_deg"] == pytest.approx(2.0, abs=0.25)
    assert "tilted by about 1.0" in s["hint"]


def test_fault_mid_scan_fails_keeps_points_and_parks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = lab_config(tmp_path, faults={"detector_stall_at_deg": "47.2"})
    store = tmp_path / "s.sqlite"
    code, out, err = run_cli(
        ["scan", "--config", str(cfg), "--theta-r", "40:55:1", "--repeats", "2",
         "--time-scale", "0", "--json", "--store", str(store)],
        capsys,
    )  # fmt: skip
    assert code == 1
    s = json.loads(out)
    assert s["state"] == "failed"
    assert "detector" in s["reason"]
    # the move 47 -> 48 deg stops at 47.2 (0.8 deg > the 0.5 deg stall tolerance):
    # geometries 40..47 (8 x 2 readings) are kept
    assert s["readings"] == 16
    with RunStore(store) as st:
        run = st.get_run(s["run_id"])
        assert run.status == "failed" and st.count_points(run.id) == 16
    assert f"goniolab scan resume {s['run_id']}" in err


def _kill_mid_scan(cfg: Path, store: Path, total: int) -> int:
    """Start a scan in a subprocess, SIGKILL it once progress shows, return stored rows."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "goniolab.cli", "scan", "--config", str(cfg), "--theta-r", "0:70:2",
         "--repeats", "2", "--time-scale", "0", "--store", str(store)],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    assert proc.stderr is not None
    killed = False
    for line in proc.stderr:  # blocking reads of the progress lines: no sleeps, no timing
        m = re.search(r"\] (\d+)/(\d+) ETA", line)
        if m and 0 < int(m.group(1)) < total:
            os.kill(proc.pid, signal.SIGKILL)
            killed = True
            break
    proc.wait()
    assert killed, "the scan finished before it could be killed"
    assert proc.returncode == -signal.SIGKILL
    with RunStore(store) as s:
        return s.count_points(1)


@pytest.mark.slow
def test_kill_9_then_resume_stores_every_reading_exactly_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = lab_config(tmp_path)
    store = tmp_path / "s.sqlite"
    total = 36 * 2
    n_before = _kill_mid_scan(cfg, store, total)
    assert 0 < n_before < total
    with RunStore(store) as s:
        assert s.get_run(1).status == "running"  # killed: nobody could record anything else
    code, out, err = run_cli(
        ["scan", "resume", "1", "--store", str(store), "--time-scale", "0", "--json"], capsys
    )
    assert code == 0, err
    summary = json.loads(out)
    assert summary["state"] == "done" and summary["readings"] == total
    with RunStore(store) as s:
        keys = [(p.index, p.repeat) for p in s.points(1)]
        assert keys == [(i, r) for i in range(36) for r in range(2)]
        assert s.get_run(1).status == "done"


@pytest.mark.wire
def test_scan_through_the_wire_sims(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = lab_config(tmp_path, base="lab-sim-wire.toml", sim=NOISELESS)
    code, out, err = run_cli(
        ["scan", "--config", str(cfg), "--theta-r", "40:50:2", "--time-scale", "0", "--json",
         "--store", str(tmp_path / "s.sqlite")],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    s = json.loads(out)
    assert s["state"] == "done" and s["readings"] == 6
    # steps_per_deg = 1000 on the wire: the STIL reply carries the luminance with its own
    # resolution, so compare with a tolerance well below the peak
    assert s["rmse_pct"] < 1e-2 * s["predicted_peak"]["amplitude_pct"]


def test_gloss_log_from_the_sim_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = lab_config(tmp_path, sim=NOISELESS)
    store = tmp_path / "s.sqlite"
    code, out, err = run_cli(
        ["gloss", "log", "--config", str(cfg), "--count", "3", "--json", "--time-scale", "0",
         "--store", str(store)],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    *lines, stats = [json.loads(x) for x in out.splitlines()]
    assert [x["seq"] for x in lines] == [0, 1, 2]
    # the last line: n, mean and sample std (ddof = 1) of the three readings per geometry
    for angle in ("20", "60", "85"):
        vals = [x["values_gu"][angle] for x in lines]
        mean = sum(vals) / 3
        std = (sum((v - mean) ** 2 for v in vals) / 2) ** 0.5
        assert stats["statistics"][angle] == {
            "n": 3,
            "mean_gu": pytest.approx(mean, abs=1e-12),
            "std_gu": pytest.approx(std, abs=1e-12),
        }
    assert stats["state"] == "done" and stats["readings"] == 3
    for x in lines:
        # noiseless sim: the meter reads the model's gloss to its 0.1 GU resolution
        for angle in ("20", "60", "85"):
            assert x["values_gu"][angle] == pytest.approx(x["predicted_gu"][angle], abs=0.051)
    with RunStore(store) as s:
        assert len(s.gloss_readings(lines[0]["run_id"])) == 3


async def test_fault_parks_the_arms_on_the_sim_lab(tmp_path: Path) -> None:
    from goniolab.config import load_lab_config
    from goniolab.lab_wiring import Lab
    from goniolab.optics.apertures import Cone
    from goniolab.scan.events import EventBus, RunState
    from goniolab.scan.plans import BrdfPlan, parse_angles
    from goniolab.scan.prediction import Predictor
    from goniolab.scan.runner import ArmMotion, ScanRunner

    cfg = load_lab_config(lab_config(tmp_path, faults={"detector_stall_at_deg": "47.2"}))
    plan = BrdfPlan(45.0, parse_angles("40:55:1"), sample=cfg.sample.map)
    with RunStore(tmp_path / "s.sqlite") as store:
        async with Lab.from_config(cfg, time_scale=0) as lab:
            rid = store.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample=plan.sample,
                                   model={}, version="t")  # fmt: skip
            runner = ScanRunner(
                goniometer=lab.goniometer, spectro=lab.spectro, clock=lab.clock, plan=plan,
                store=store, run_id=rid, bus=EventBus(), motion=ArmMotion(20.0, 40.0, 20.0, 40.0),
                predictor=Predictor(lab.model, Cone(6.0), Cone(6.0)), park_deg=(45.0, 45.0),
            )  # fmt: skip
            result = await runner.run()
            assert result.state is RunState.FAILED
            assert store.count_points(rid) == 8
            # parked: 47.2 -> 45 does not cross the obstacle; within the stall tolerance
            ti, tr = await lab.goniometer.positions_deg()
            assert (ti, tr) == pytest.approx((45.0, 45.0), abs=0.01)


def test_ctrl_c_aborts_parks_and_says_how_to_resume(tmp_path: Path) -> None:
    cfg = lab_config(tmp_path)
    store = tmp_path / "s.sqlite"
    proc = subprocess.Popen(
        [sys.executable, "-m", "goniolab.cli", "scan", "--config", str(cfg), "--theta-r", "0:70:2",
         "--repeats", "2", "--time-scale", "0", "--store", str(store)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    assert proc.stderr is not None and proc.stdout is not None
    for line in proc.stderr:
        if re.search(r"\] [1-9]\d*/72 ETA", line):
            proc.send_signal(signal.SIGINT)
            break
    err = proc.stderr.read()
    out = proc.stdout.read()
    assert proc.wait() == 130
    assert "goniolab scan resume 1" in err
    assert "run 1: aborted" in out
    with RunStore(store) as s:
        run = s.get_run(1)
        assert run.status == "aborted"
        assert 0 < s.count_points(1) < 72


def test_gloss_log_survives_garbled_replies(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = lab_config(
        tmp_path, sim=NOISELESS, faults={"devices": '["glossmeter"]', "garble_rate": "0.4"}
    )
    store = tmp_path / "s.sqlite"
    code, out, err = run_cli(
        ["gloss", "log", "--config", str(cfg), "--count", "6", "--time-scale", "0", "--store",
         str(store)],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    assert "warning: glossmeter" in err  # each garbled reply is reported ...
    with RunStore(store) as s:  # ... and the six readings are all stored
        rows = s.gloss_readings(1)
        assert len(rows) == 6
        assert all(r.values_gu[60] is not None for r in rows)
    assert "G60: mean" in out


def test_mirror_reference_on_the_sim(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = lab_config(tmp_path, sim=NOISELESS)
    code, out, err = run_cli(
        ["scan", "--config", str(cfg), "--theta-r", "42:48:2", "--repeats", "2", "--mirror-reference",
         "--time-scale", "0", "--json", "--store", str(tmp_path / "s.sqlite")],
        capsys,
    )  # fmt: skip
    assert code == 0, err
    s = json.loads(out)
    # the simulated reference mirror is protected aluminium (88-92 %, configs/standards.toml):
    # its Y at the specular geometry (equal 6 deg cones) is the certificate's, about 89.8 %
    # (it used to read 100 %: the mirror counted as perfect, issue 21)
    r = 0.88 + 0.04 * (np.arange(380.0, 781.0, 10.0) - 380.0) / 400.0
    assert s["mirror_pct"] == pytest.approx(100 * float(np.dot(luminance_weights(), r)), rel=1e-9)
    assert s["readings"] == (4 + 1) * 2
    assert s["rmse_pct"] < 1e-3 * s["predicted_peak"]["amplitude_pct"]


@pytest.mark.wire
def test_gloss_log_from_a_port_without_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = lab_config(tmp_path, base="lab-sim-wire.toml", sim=NOISELESS)
    server = subprocess.Popen(
        [sys.executable, "-m", "goniolab.cli", "sim", "serve", "--config", str(cfg), "--json",
         "--time-scale", "0"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert server.stdout is not None
        endpoints = json.loads(server.stdout.readline())["endpoints"]
        port = endpoints["glossmeter"]["port"]
        code, out, err = run_cli(
            ["gloss", "log", "--port", port, "--protocol", "zgm1120", "--count", "2", "--json", "--timeout", "60",
             "--sample", "sample:wittmann-3", "--store", str(tmp_path / "s.sqlite")],
            capsys,
        )  # fmt: skip
    finally:
        server.send_signal(signal.SIGINT)
        server.wait()
    assert code == 0, err
    *lines, stats = [json.loads(x) for x in out.splitlines()]
    assert len(lines) == 2 and stats["readings"] == 2
    for x in lines:
        # the ZGM1120 reports 0.1 GU: the noiseless sim reads the prediction to that resolution
        assert x["values_gu"]["60"] == pytest.approx(x["predicted_gu"]["60"], abs=0.051)
