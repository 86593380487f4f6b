"""The CLI in a pipeline: a reader that stops early (``| head``) ends it quietly."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from goniolab.scan.plans import BrdfPlan
from goniolab.store import RunStore


def _store_with_a_run(path: Path) -> None:
    plan = BrdfPlan(45.0, tuple(float(t) for t in range(0, 71)), repeats=3, sample="sample:x")
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample="sample:x",
                           model={}, version="t")  # fmt: skip
        for i, tr in enumerate(plan.theta_r_deg):
            for r in range(3):
                s.add_point(rid, index=i, repeat=r, theta_i_deg=45.0, theta_r_deg=tr,
                            measured_theta_i_deg=45.0, measured_theta_r_deg=tr,
                            luminance_pct=1.0, raw={}, timestamp=1.0)  # fmt: skip
        s.set_status(rid, "done")


def test_runs_export_into_a_closed_pipe_exits_quietly(tmp_path: Path) -> None:
    """``goniolab runs export 1 | head -0``: the reader is gone before the first byte. The
    pipe's read end is closed before the command starts, so every write fails with EPIPE
    (Python ignores SIGPIPE): no traceback, exit status 141 (128 + SIGPIPE, what a C tool
    killed by SIGPIPE reports to the shell)."""
    store = tmp_path / "s.sqlite"
    _store_with_a_run(store)
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "goniolab.cli", "runs", "export", "1", "--store", str(store)],
            stdout=write_end,
            stderr=subprocess.PIPE,
            timeout=60,
            check=False,
        )
    finally:
        os.close(write_end)
    assert proc.stderr.decode() == ""
    assert proc.returncode == 141
