"""The TUI's gloss log says the warnings stored with its run's predicted gloss.

A gloss run stores, beside its predicted ISO 2813 gloss, the warnings of those numbers
(:func:`goniolab.optics.provenance.gloss_provenance_of`'s notes: a model out of its
validity, the Kirchhoff model's energy rescale at 85 deg); the TUI's gloss log must say
them (a toast each, their count under the log), read from the stored run.
"""

from __future__ import annotations

import asyncio
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


async def test_the_gloss_log_holds_the_calibration_to_the_configs_age_rule(
    tmp_path: Path,
) -> None:
    """The lab config's ``[glossmeter] calibration_max_age_h`` is the TUI's rule: a
    calibration 10 h old is fine under the default 24 h and old under a 6 h rule."""
    from goniolab.cli import main
    from goniolab.store import RunStore
    from goniolab.tui.app import GonioApp
    from goniolab.tui.session_backend import SessionBackend
    from tests.tui.test_lab import sim_config

    cfg = sim_config(tmp_path)
    store = str(tmp_path / "runs.sqlite")
    argv = ["gloss", "calibrate", "--config", str(cfg), "--store", store, "--json"]
    assert await asyncio.to_thread(main, argv) == 0  # the CLI runs its own event loop
    with RunStore(store) as s:  # the record's stored time, 10 h before now
        record = dict(s.get_run(1).model["gloss_calibration"])
        record["time"] -= 10 * 3600.0
        s.update_model(1, {"gloss_calibration": record})
    text = cfg.read_text()
    cfg.write_text(text.replace("[glossmeter]\n", "[glossmeter]\ncalibration_max_age_h = 6\n", 1))

    app = GonioApp(SessionBackend(cfg), poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("g")

        def toasts() -> list[str]:
            return [n.message for n in app._notifications if n.title == "Glossmeter calibration"]

        await wait_until(pilot, lambda: bool(toasts()), max_turns=20000)
        said = toasts()
    with RunStore(store, readonly=True) as s:
        (rec,) = [r for r in s.list_runs() if r.kind == "gloss"]
        cal = s.get_run(rec.id).model["glossmeter_calibration"]
    assert cal["run"] == 1 and cal["max_age_h"] == 6.0
    assert said == cal["warnings"]
    assert len(said) == 1 and "is 10.0 h old at the run's start, older than 6 h" in said[0]
