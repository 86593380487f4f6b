"""Every termination of a long-running command is an abort (issue 23, item 3).

SIGTERM (``systemctl stop``, ``docker stop``, ``timeout``), SIGHUP (a dropped ssh session)
and a second Ctrl-C used to kill ``goniolab scan`` and ``gloss log`` on the spot: a moving
arm kept going, nothing was parked and the run stayed ``running``. Each test here starts
the real command in a subprocess with the lab clock at real time (the arms take seconds
per move), sends the signal while the scan runs and checks what a lab would: the exit
within a bounded time, the run stored ``aborted`` with the signal as its reason, and, on
the wire (the simulated controllers in a process of their own that outlives the scan),
the arms standing at the park position.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from goniolab.store import RunStore
from tests.scan.test_integration import NOISELESS, REPO, lab_config

pytestmark = pytest.mark.slow

EXIT_WITHIN_S = 60.0


def _start(args: list[str], err_path: Path, tmp_path: Path) -> subprocess.Popen[bytes]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "GONIOLAB_LOG_DIR": str(tmp_path / "log")}
    with err_path.open("wb") as err:
        return subprocess.Popen(
            [sys.executable, "-m", "goniolab.cli", *args],
            cwd=REPO, stdout=subprocess.DEVNULL, stderr=err, env=env,
        )  # fmt: skip


def _wait_for(proc: subprocess.Popen[bytes], err_path: Path, pattern: str) -> None:
    end = time.monotonic() + 120
    while not re.search(pattern, err_path.read_text(errors="replace")):
        assert proc.poll() is None, err_path.read_text()
        assert time.monotonic() < end, f"never saw {pattern!r}: {err_path.read_text()}"
        time.sleep(0.05)


def _scan_args(cfg: Path, store: Path) -> list[str]:
    # 0..70 deg in 10 deg steps at real time: seconds per move, the arms are moving
    return ["scan", "--config", str(cfg), "--theta-i", "45", "--theta-r", "0:70:10",
            "--time-scale", "1", "--store", str(store)]  # fmt: skip


def _stopped(proc: subprocess.Popen[bytes], err_path: Path) -> int:
    try:
        return proc.wait(timeout=EXIT_WITHIN_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise AssertionError(
            f"did not exit within {EXIT_WITHIN_S} s: {err_path.read_text()}"
        ) from None


@pytest.mark.parametrize(
    ("signals", "said"),
    [
        ([signal.SIGTERM], "aborted by SIGTERM"),
        ([signal.SIGHUP], "aborted by SIGHUP"),
        ([signal.SIGINT, signal.SIGINT], "aborted by Ctrl-C (SIGINT)"),
        ([signal.SIGTERM, signal.SIGTERM], "aborted by SIGTERM"),
    ],
)
def test_a_signal_aborts_the_scan_and_parks(
    tmp_path: Path, signals: list[signal.Signals], said: str
) -> None:
    cfg = lab_config(tmp_path, sim=NOISELESS)
    store, err_path = tmp_path / "s.sqlite", tmp_path / "err.txt"
    proc = _start(_scan_args(cfg, store), err_path, tmp_path)
    try:
        _wait_for(proc, err_path, r"\] [1-9]\d*/\d+ ETA")  # a reading taken, arms moving on
        for sig in signals:
            proc.send_signal(sig)
            time.sleep(0.05)
        code = _stopped(proc, err_path)
    finally:
        proc.kill()
    text = err_path.read_text()
    assert code == 130, text
    with RunStore(store, readonly=True) as s:
        run = s.get_run(1)
        assert run.status == "aborted", (run.status, run.reason)
        assert said in run.reason, run.reason
        assert "park" not in run.reason  # a park problem would be appended to the reason
        assert 0 < s.count_points(1) < 8  # what was measured stays, the rest is resumable


@pytest.fixture(scope="module")
def wire_lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The simulated controllers in a ``goniolab sim serve`` process of their own, one for
    the module's wire tests (its start and its first reading, which builds the facet model's
    tables, cost more CPU than a test's scan; each test's scan moves the arms off the park
    position before its signal): yields the client's config."""
    tmp = tmp_path_factory.mktemp("wire")
    served = lab_config(tmp, base="lab-sim-wire.toml", sim=NOISELESS, name="served.toml")
    client = tmp / "client.toml"
    client.write_text(
        served.read_text().replace("start_sim_servers = true", "start_sim_servers = false")
    )
    server = subprocess.Popen(
        [sys.executable, "-m", "goniolab.cli", "sim", "serve", "--config", str(served), "--json",
         "--time-scale", "1"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    try:
        assert server.stdout is not None
        json.loads(server.stdout.readline())  # serving
        yield client
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(timeout=30)


@pytest.mark.wire
@pytest.mark.parametrize(
    "signals",
    [[signal.SIGTERM], [signal.SIGHUP], [signal.SIGINT, signal.SIGINT]],
    ids=["TERM", "HUP", "INT-twice"],
)
def test_a_signal_parks_the_arms_of_the_wire_lab(
    tmp_path: Path, signals: list[signal.Signals], wire_lab: Path
) -> None:
    from goniolab.config import load_lab_config
    from goniolab.lab_wiring import Lab

    client = wire_lab
    store, err_path = tmp_path / "s.sqlite", tmp_path / "err.txt"
    proc = _start(_scan_args(client, store), err_path, tmp_path)
    try:
        _wait_for(proc, err_path, r"\] [1-9]\d*/\d+ ETA")
        for sig in signals:
            proc.send_signal(sig)
            time.sleep(0.05)
        code = _stopped(proc, err_path)
    finally:
        proc.kill()
    assert code == 130, err_path.read_text()
    # the controllers outlive the scan: where did it leave the arms?
    cfg = load_lab_config(client)

    async def positions() -> tuple[float, float]:
        async with Lab.from_config(cfg) as lab:
            return await lab.goniometer.positions_deg()

    import asyncio

    ti, tr = asyncio.run(positions())
    park = cfg.goniometer.park
    assert (ti, tr) == (
        pytest.approx(park.theta_i_deg, abs=0.01),
        pytest.approx(park.theta_r_deg, abs=0.01),
    )
    with RunStore(store, readonly=True) as s:
        run = s.get_run(1)
        assert run.status == "aborted" and signals[0].name in run.reason, run.reason


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["TERM", "HUP"])
def test_a_signal_ends_a_gloss_log_as_aborted(tmp_path: Path, sig: signal.Signals) -> None:
    cfg = lab_config(tmp_path, sim=NOISELESS)
    store, err_path = tmp_path / "s.sqlite", tmp_path / "err.txt"
    proc = _start(
        ["gloss", "log", "--config", str(cfg), "--interval", "0.2", "--time-scale", "1",
         "--store", str(store)],
        err_path, tmp_path,
    )  # fmt: skip
    try:
        end = time.monotonic() + 120
        while True:  # two readings stored: the log is running
            time.sleep(0.1)
            assert proc.poll() is None, err_path.read_text()
            assert time.monotonic() < end, err_path.read_text()
            if "in store" in err_path.read_text():  # the run (and its tables) exist
                with RunStore(store, readonly=True) as s:
                    if len(s.gloss_readings(1)) >= 2:
                        break
        proc.send_signal(sig)
        code = _stopped(proc, err_path)
    finally:
        proc.kill()
    with RunStore(store, readonly=True) as s:
        run = s.get_run(1)
        assert run.status == "aborted", (run.status, run.reason)
        assert f"stopped by {sig.name}" in run.reason
    # a log ends as the operator's stop does (exit 0: every reading taken is stored), but
    # the stored run says it did not end as meant, and why
    assert code == 0, err_path.read_text()
    assert f"aborted (stopped by {sig.name}" in err_path.read_text()
