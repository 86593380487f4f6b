"""The CLI in a pipeline: a reader that stops early (``| head``) ends it quietly."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

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


@pytest.mark.skipif(shutil.which("script") is None, reason="needs script(1) from util-linux")
def test_the_readme_batch_line_under_a_terminal_fills_its_file(tmp_path: Path) -> None:
    """README: ``goniolab predict gloss maps/*.sur --json > gloss.jsonl`` typed in a terminal.

    ``script`` gives the command a pty as stderr (so the rich progress bar is drawn) while
    stdout goes to the file. Issue 22.3: the bar's console wrapped ``sys.stdout`` and every
    row went to the terminal, leaving the file empty. Every map must have its JSON line in
    the file (a bad map its ``{"map", "error"}`` row), and the bar must have been drawn on
    the terminal, not in the file."""
    rng = np.random.default_rng(3)
    maps = []
    for i in range(3):
        np.save(tmp_path / f"m{i}.npy", rng.normal(0.0, 0.05, (48, 48)))
        (tmp_path / f"m{i}.npy.json").write_text('{"dx_um": 1.0, "dy_um": 1.0}')
        maps.append(f"m{i}.npy")
    maps.append("missing.npy")
    root = Path(__file__).resolve().parents[1]
    cmd = (
        f"PYTHONPATH={shlex.quote(str(root))} {shlex.quote(sys.executable)} -m goniolab.cli "
        f"predict gloss {' '.join(maps)} --json --jobs 1 > gloss.jsonl"
    )
    proc = subprocess.run(
        ["script", "-q", "-e", "-c", cmd, "/dev/null"],
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        timeout=120,
        check=False,
    )
    terminal = proc.stdout.decode("utf-8", "replace")
    assert proc.returncode == 2, terminal  # one map failed
    rows = [json.loads(line) for line in (tmp_path / "gloss.jsonl").read_text().splitlines()]
    assert sorted(r["map"] for r in rows) == sorted(maps)
    bad = [r for r in rows if "error" in r]
    assert [r["map"] for r in bad] == ["missing.npy"] and "missing.npy" in bad[0]["error"]
    for r in rows:
        if "error" not in r:
            assert 0.0 < r["G60"] < 100.0
    # the bar and the error message went to the terminal, not into the file
    assert "━" in terminal and "goniolab: error: missing.npy" in terminal
    assert "━" not in (tmp_path / "gloss.jsonl").read_text()
