"""One session for the CLI and the TUI (goniolab.session): the same plan run from
``goniolab scan`` and from the TUI's backend stores the same rows, and a run started in
the TUI resumes from the CLI with no ``--config``.

Both run on the in-process simulated lab (instant clock, seeded noise): the truth is the
other path's rows, reading for reading, except what is a time stamp or an id.
"""

from __future__ import annotations

import asyncio
import dataclasses
import re
from pathlib import Path
from typing import Any

import pytest

from goniolab.cli import main
from goniolab.config import configs_dir
from goniolab.scan.events import RunFinished, RunState, StateChanged
from goniolab.store import RunStore
from goniolab.tui.session_backend import SessionBackend
from goniolab.tui.view_model import ScanSetup
from tests.twin_configs import ideal

#: theta_i 30 deg, detector 20..40 deg in 5 deg steps, 2 repeats: 10 readings.
CLI_PLAN = ["--theta-i", "30", "--theta-r", "20:40:5", "--repeats", "2"]
SETUP = dict(
    theta_i_deg=30.0, theta_r_start_deg=20.0, theta_r_stop_deg=40.0, theta_r_step_deg=5.0, repeats=2
)


def sim_config(tmp_path: Path) -> Path:
    """configs/lab-sim.toml with the ideal twin and an instant clock (noise kept: seeded, so
    reproducible). The realistic twin's arms have backlash, so a reading depends on the
    arms' history (the TUI homes them, the CLI finds them at park): identical rows are a
    property of the plumbing, checked with the ideal twin."""
    text = ideal((configs_dir() / "lab-sim.toml").read_text())
    text = re.sub(r"(?m)^time_scale = .*$", "time_scale = 0.0", text)
    path = tmp_path / "lab.toml"
    path.write_text(text)
    return path


async def _until(q: asyncio.Queue[Any], want: type, **fields: Any) -> Any:
    while True:
        ev = await asyncio.wait_for(q.get(), timeout=60)
        if isinstance(ev, want) and all(getattr(ev, k) == v for k, v in fields.items()):
            return ev


async def _tui_scan(cfg: Path, store: Path, *, abort: bool = False) -> int:
    """Run (or start, pause and abort) the scan through the TUI's backend; its run id."""
    backend = SessionBackend(cfg, store_path=str(store))
    await backend.open()
    try:
        q = backend.bus.subscribe()
        run_id = await backend.start(ScanSetup(sample=backend.sample, **SETUP))
        if abort:
            backend.pause()  # honoured before the first reading
            await _until(q, StateChanged, state=RunState.PAUSED)
            backend.abort()
        await _until(q, RunFinished, run_id=run_id)
    finally:
        await backend.close()
    return run_id


def _rows(store: Path, run_id: int) -> dict[str, Any]:
    """A run's rows without ids (its UUID too) and time stamps (wall clock and lab clock)."""
    with RunStore(store) as s:
        run = s.get_run(run_id).as_dict()
        for key in ("id", "uuid", "created_at", "updated_at", "finished_at"):
            run.pop(key)
        points = [
            dataclasses.replace(p, timestamp=0.0, raw={**p.raw, "clock_s": None})
            for p in s.points(run_id)
        ]
        return {
            "run": run,
            "points": points,
            "predictions": s.predictions(run_id),
            "predicted_colours": s.predicted_colours(run_id),
        }


@pytest.mark.slow  # builds the facet model of the configured sample (cached afterwards)
def test_cli_and_tui_store_identical_rows(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = sim_config(tmp_path)
    cli_store, tui_store = tmp_path / "cli.sqlite", tmp_path / "tui.sqlite"
    code = main(["scan", "--config", str(cfg), *CLI_PLAN, "--store", str(cli_store), "--json"])
    assert code == 0, capsys.readouterr().err
    tui_run = asyncio.run(_tui_scan(cfg, tui_store))
    cli_rows, tui_rows = _rows(cli_store, 1), _rows(tui_store, tui_run)
    # each run's config names the store it was written to (the alignment state lives
    # beside it: load_lab_config(store=)); everything else is identical
    assert cli_rows["run"]["config"]["lab"].pop("store") == str(cli_store.resolve())
    assert tui_rows["run"]["config"]["lab"].pop("store") == str(tui_store.resolve())
    assert len(cli_rows["points"]) == 10 and len(cli_rows["predictions"]) == 5
    assert all(p.colour is not None for p in cli_rows["points"])  # colour columns compared too
    assert cli_rows["run"]["status"] == "done"
    assert cli_rows["run"]["config"]["_source"] == str(cfg.resolve())
    assert tui_rows == cli_rows


def test_scan_resume_continues_a_tui_run_without_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = sim_config(tmp_path)
    store = tmp_path / "runs.sqlite"
    run_id = asyncio.run(_tui_scan(cfg, store, abort=True))
    with RunStore(store) as s:
        assert s.get_run(run_id).status == "aborted" and s.count_points(run_id) == 0
    capsys.readouterr()
    code = main(["scan", "resume", str(run_id), "--store", str(store), "--json"])
    assert code == 0, capsys.readouterr().err
    with RunStore(store) as s:
        assert s.get_run(run_id).status == "done"
        assert sorted(s.done_keys(run_id)) == [(i, r) for i in range(5) for r in range(2)]
