"""The TUI's gloss log says the warnings stored with its run's predicted gloss.

A gloss run stores, beside its predicted ISO 2813 gloss, the warnings of those numbers
(:func:`goniolab.optics.provenance.gloss_provenance_of`'s notes: a model out of its
validity, the Kirchhoff model's energy rescale at 85 deg); the TUI's gloss log must say
them (a toast each, their count under the log), read from the stored run.
"""

from __future__ import annotations

from pathlib import Path

from tests.tui.test_lab import SIZE
from tests.tui.tui_scripted import wait_until


async def test_the_gloss_log_says_the_stored_runs_prediction_warnings(tmp_path: Path) -> None:
    from goniolab.store import RunStore
    from goniolab.tui.app import GonioApp
    from goniolab.tui.session_backend import SessionBackend
    from goniolab.tui.widgets import GlossLog
    from tests.tui.test_lab import sim_config

    # the lab's own sample model (wittmann-3: Kirchhoff at 85 deg rescales its diffuse light)
    app = GonioApp(SessionBackend(sim_config(tmp_path)), poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("g")
        log = app.query_one("#gloss-log", GlossLog)
        await wait_until(pilot, lambda: bool(log.border_subtitle), max_turns=20000)
        subtitle = str(log.border_subtitle)
        toasts = [n.message for n in app._notifications if n.title == "Gloss prediction"]
    with RunStore(tmp_path / "runs.sqlite", readonly=True) as s:
        (rec,) = [r for r in s.list_runs() if r.kind == "gloss"]
        warnings = s.get_run(rec.id).model["warnings"]
    assert warnings and any(w.startswith("G85: kirchhoff: ") for w in warnings)
    n = len(warnings)
    assert (
        subtitle == f"{n} prediction warning{'s' if n != 1 else ''} (goniolab runs show {rec.id})"
    )
    assert toasts == warnings


async def test_the_gloss_log_says_the_glossmeter_calibration_is_not_recorded(
    tmp_path: Path,
) -> None:
    """No ``gloss calibrate`` in the store: the TUI's gloss run records that, and says it."""
    from goniolab.store import RunStore
    from goniolab.tui.app import GonioApp
    from goniolab.tui.session_backend import SessionBackend
    from tests.tui.test_lab import sim_config

    app = GonioApp(SessionBackend(sim_config(tmp_path)), poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("g")

        def toasts() -> list[str]:
            return [n.message for n in app._notifications if n.title == "Glossmeter calibration"]

        await wait_until(pilot, lambda: bool(toasts()), max_turns=20000)
        said = toasts()
    with RunStore(tmp_path / "runs.sqlite", readonly=True) as s:
        (rec,) = [r for r in s.list_runs() if r.kind == "gloss"]
        cal = s.get_run(rec.id).model["glossmeter_calibration"]
    assert cal["run"] is None
    assert said == cal["warnings"]
    assert said[0].startswith("none recorded in this store for SimGlossmeter glossmeter")
