"""Signals a lab user sends a running ``goniolab``: SIGUSR1 shows where it is and goes on."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from goniolab.store import RunStore

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_sigusr1_prints_every_threads_stack_and_the_scan_goes_on(tmp_path: Path) -> None:
    store = tmp_path / "runs.sqlite"
    err_path = tmp_path / "stderr.txt"
    cmd = [sys.executable, "-m", "goniolab.cli", "scan", "--config",
           str(ROOT / "configs" / "lab-sim.toml"), "--store", str(store), "--theta-i", "45",
           "--theta-r", "40:50:5", "--time-scale", "1"]  # fmt: skip
    with err_path.open("wb") as err:
        env = {**os.environ, "GONIOLAB_LOG_DIR": str(tmp_path / "log")}
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, cwd=tmp_path, env=env)
    try:
        end = time.monotonic() + 90
        while "in store" not in err_path.read_text():  # the run exists: the loop is running
            assert proc.poll() is None, err_path.read_text()
            assert time.monotonic() < end, "the scan never started"
            time.sleep(0.05)
        proc.send_signal(signal.SIGUSR1)
        assert proc.wait(timeout=120) == 0, err_path.read_text()
    finally:
        proc.kill()
    text = err_path.read_text()
    # every thread's stack: the main thread sits in the asyncio loop
    assert "(SIGUSR1)" in text and "Thread MainThread" in text
    main = text.split("Thread MainThread", 1)[1].split("\nThread ", 1)[0]
    assert "asyncio/base_events.py" in main and "run_until_complete" in main
    log = "".join(p.read_text() for p in (tmp_path / "log").glob("goniolab.log*"))
    assert "(SIGUSR1)" in log and "Thread MainThread" in log  # and in the log file
    with RunStore(store, readonly=True) as s:  # and the scan finished every reading
        assert s.get_run(1).status == "done"
        assert s.done_keys(1) == {(k, 0) for k in range(3)}
