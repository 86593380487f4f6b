"""Snapshot tests of the main screens (fixed size, scripted events, fixed timestamps).

Update after an intended visual change with ``pytest tests/tui --snapshot-update`` and
review the SVGs in ``tests/tui/__snapshots__``.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from textual.pilot import Pilot
from textual.widgets import DataTable

from goniolab.scan.events import RunState
from goniolab.tui.app import GonioApp
from goniolab.tui.screens import RunsScreen
from tests.tui.tui_scripted import ScriptedBackend, settle, wait_until

SIZE = (140, 42)


def _finished_app() -> tuple[GonioApp, ScriptedBackend]:
    backend = ScriptedBackend(gated=False)
    return GonioApp(backend, poll_hz=0, autostart=True), backend


async def _wait_done(pilot: Pilot[int], app: GonioApp) -> None:
    """The run is done *and* its "run 1 done" toast is up: StateChanged(done) arrives before
    RunFinished, so clearing the toasts at the state alone raced the RunFinished toast."""
    await wait_until(pilot, lambda: app.run_state is RunState.DONE)
    await wait_until(pilot, lambda: any(n.title == "Scan" for n in app._notifications))


@pytest.mark.parametrize("size", [(80, 24), (120, 35), (140, 42), (200, 60)])
def test_main_screen_after_scan(snap_compare: Callable[..., bool], size: tuple[int, int]) -> None:
    # 80 x 24, the default of most terminals, up to a large one (issue 27 item 1): the
    # plots first, the form behind f under 120 columns, the status line always there
    app, backend = _finished_app()

    async def run_before(pilot: Pilot[int]) -> None:
        await _wait_done(pilot, app)
        backend.publish_gloss(5, 61.25)
        backend.publish_gloss(9, 57.5)
        await wait_until(pilot, lambda: len(app.comparison.gloss) == 3)
        await settle(pilot, app)
        app.clear_notifications()
        await settle(pilot, app)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


def test_main_screen_log_view_and_timeout(snap_compare: Callable[..., bool]) -> None:
    app, backend = _finished_app()

    async def run_before(pilot: Pilot[int]) -> None:
        await _wait_done(pilot, app)
        app.clear_notifications()
        await pilot.press("l")
        backend.publish_timeout()
        await wait_until(pilot, lambda: len(app._notifications) == 1)
        await settle(pilot, app)

    assert snap_compare(app, terminal_size=SIZE, run_before=run_before)


def test_runs_browser(snap_compare: Callable[..., bool]) -> None:
    app, _backend = _finished_app()

    async def run_before(pilot: Pilot[int]) -> None:
        await _wait_done(pilot, app)
        app.clear_notifications()
        await pilot.press("r")
        await wait_until(pilot, lambda: isinstance(app.screen, RunsScreen))
        screen = app.screen
        assert isinstance(screen, RunsScreen)
        await wait_until(pilot, lambda: screen.query_one("#runs", DataTable).row_count == 1)
        await pilot.press("enter")
        await wait_until(pilot, lambda: screen.loaded_run == 1)
        await settle(pilot, app)

    assert snap_compare(app, terminal_size=SIZE, run_before=run_before)
