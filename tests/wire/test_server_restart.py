"""A controller restart mid-scan, on the wire (issue 21: "a controller restart loses the scan").

The simulated lab is served by ``goniolab sim serve`` in a process of its own (the arms on
Modbus TCP, the STIL spectro on a pty behind a stable symlink), the scan runs the real
drivers in another. Mid-scan the server is frozen and killed, which takes the controllers
and the spectro off the line at once, and started again (its start takes a few seconds) (a controller's
restart takes 7-20 s). The scan must wait (and say so in its events), reopen the links, and
store every point exactly once.

Deterministic: each step waits on what the processes say (the server's "serving" line,
the scan's progress and its "waiting up to" event), never on a sleep racing the scan.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from goniolab.store import RunStore
from tests.scan.test_integration import NOISELESS, REPO, lab_config

pytestmark = [pytest.mark.wire, pytest.mark.slow]

ANGLES = [30.0 + 3.0 * k for k in range(11)]  # --theta-r 30:60:3
WAIT_S = 180.0


def _serve(config: Path, log: Path) -> subprocess.Popen[str]:
    """``goniolab sim serve`` at real time; returns once it says it is serving."""
    with log.open("a") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "goniolab.cli", "sim", "serve", "--config", str(config),
             "--json", "--time-scale", "1"],
            cwd=REPO, stdout=subprocess.PIPE, stderr=err, text=True,
        )  # fmt: skip
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line, f"the sim server did not start: {log.read_text()}"
    json.loads(line)  # {"serving": ...}
    return proc


def _stop(proc: subprocess.Popen[str]) -> None:
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=10)


def _wait_for(proc: subprocess.Popen[bytes], err_path: Path, pattern: str) -> str:
    end = time.monotonic() + WAIT_S
    while True:
        text = err_path.read_text(errors="replace")
        m = re.search(pattern, text)
        if m:
            return m.group(0)
        assert proc.poll() is None, f"the scan ended before {pattern!r}: {text}"
        assert time.monotonic() < end, f"never saw {pattern!r}: {text}"
        time.sleep(0.05)


def test_a_scan_waits_for_a_restarted_sim_server_and_stores_every_point_once(
    tmp_path: Path,
) -> None:
    served = lab_config(tmp_path, base="lab-sim-wire.toml", sim=NOISELESS, name="served.toml")
    client = tmp_path / "client.toml"
    client.write_text(
        served.read_text().replace("start_sim_servers = true", "start_sim_servers = false")
    )
    store, err_path, server_log = tmp_path / "s.sqlite", tmp_path / "err.txt", tmp_path / "srv"
    server = _serve(served, server_log)
    scan: subprocess.Popen[bytes] | None = None
    try:
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "GONIOLAB_LOG_DIR": str(tmp_path / "log")}
        with err_path.open("wb") as err:
            scan = subprocess.Popen(
                [sys.executable, "-m", "goniolab.cli", "scan", "--config", str(client),
                 "--theta-i", "45", "--theta-r", "30:60:3", "--repeats", "1", "--json",
                 "--store", str(store)],
                cwd=REPO, stdout=subprocess.PIPE, stderr=err, env=env,
            )  # fmt: skip
        _wait_for(scan, err_path, r"\] [3-9]/11 ETA")  # readings taken, the scan going on
        # freeze the server at once (the scan cannot finish behind our back: every move
        # and reading needs it), then kill it: the controllers and the spectro are gone,
        # their sockets and pty closed by the kernel as by a power cut
        server.send_signal(signal.SIGSTOP)
        server.kill()
        server.wait(timeout=30)
        said = _wait_for(scan, err_path, r"[^\n]*waiting up to \d+ s[^\n]*")
        server = _serve(served, server_log)  # back, a restart later
        out, _ = scan.communicate(timeout=WAIT_S)
        text = err_path.read_text(errors="replace")
        assert scan.returncode == 0, text
    finally:
        if scan is not None and scan.poll() is None:
            scan.kill()
        _stop(server)
    summary = json.loads(out)
    assert summary["state"] == "done" and summary["readings"] == 11, summary
    assert "reconnecting" in said, said
    with RunStore(store, readonly=True) as s:
        points = s.points(summary["run_id"])
    assert sorted(p.index for p in points) == list(range(11))  # each point once
    assert sorted(p.theta_r_deg for p in points) == ANGLES  # unique and complete
    assert all(p.repeat == 0 for p in points)
    # each reading at its own geometry, before and after the restart: the arms stood where
    # the plan says, and the noiseless ideal twin's readings are the model's
    for p in points:
        assert p.measured_theta_r_deg == pytest.approx(p.theta_r_deg, abs=0.01)
        assert p.measured_theta_i_deg == pytest.approx(45.0, abs=0.01)
    assert summary["rmse_pct"] < 1e-2 * summary["predicted_peak"]["amplitude_pct"]
