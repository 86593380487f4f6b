"""Snapshot tests of the main screens (fixed size, scripted events, fixed timestamps).

Update after an intended visual change with ``pytest tests/tui --snapshot-update`` and
review the SVGs in ``tests/tui/__snapshots__``.
"""

from __future__ import annotations

from collections.abc import Callable

from textual.pilot import Pilot
from textual.widgets import DataTable
from tui_scripted import ScriptedBackend

from goniolab.scan.events import RunState
from goniolab.tui.app import GonioApp
from goniolab.tui.screens import RunsScreen

SIZE = (140, 42)


async def _wait(pilot: Pilot[int], cond: Callable[[], bool]) -> None:
    for _ in range(400):
        if cond():
            return
        await pilot.pause()
    raise AssertionError("condition not reached")


def _finished_app() -> tuple[GonioApp, ScriptedBackend]:
    backend = ScriptedBackend(gated=False)
    return GonioApp(backend, poll_hz=0, autostart=True), backend


def test_main_screen_after_scan(snap_compare: Callable[..., bool]) -> None:
    app, backend = _finished_app()

    async def run_before(pilot: Pilot[int]) -> None:
        await _wait(pilot, lambda: app.run_state is RunState.DONE)
        backend.publish_gloss(5, 61.25)
        backend.publish_gloss(9, 57.5)
        await _wait(pilot, lambda: len(app.comparison.gloss) == 3)
        await pilot.pause()
        app.clear_notifications()
        await pilot.pause()

    assert snap_compare(app, terminal_size=SIZE, run_before=run_before)


def test_main_screen_log_view_and_timeout(snap_compare: Callable[..., bool]) -> None:
    app, backend = _finished_app()

    async def run_before(pilot: Pilot[int]) -> None:
        await _wait(pilot, lambda: app.run_state is RunState.DONE)
        app.clear_notifications()
        await pilot.press("l")
        backend.publish_timeout()
        await _wait(pilot, lambda: len(app._notifications) == 1)
        await pilot.pause()

    assert snap_compare(app, terminal_size=SIZE, run_before=run_before)


def test_runs_browser(snap_compare: Callable[..., bool]) -> None:
    app, _backend = _finished_app()

    async def run_before(pilot: Pilot[int]) -> None:
        await _wait(pilot, lambda: app.run_state is RunState.DONE)
        app.clear_notifications()
        await pilot.press("r")
        await _wait(pilot, lambda: isinstance(app.screen, RunsScreen))
        screen = app.screen
        assert isinstance(screen, RunsScreen)
        await _wait(pilot, lambda: screen.query_one("#runs", DataTable).row_count == 1)
        await pilot.press("enter")
        await _wait(pilot, lambda: screen.loaded_run == 1)
        await pilot.pause()

    assert snap_compare(app, terminal_size=SIZE, run_before=run_before)
