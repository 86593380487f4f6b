"""Pilot-driven tests of the TUI against the scripted backend (events from known curves)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from textual.widgets import DataTable, Input, Select, Static
from textual_plot import PlotWidget

from goniolab.scan.events import InstrumentError, RunState
from goniolab.tui.app import GonioApp
from goniolab.tui.screens import RunsScreen
from goniolab.tui.widgets import ComparisonPanel, GlossLog, MetricsTable, ScanForm, StatusPanel
from tests.tui.tui_scripted import (
    AMP_PCT,
    PEAK_DEG,
    PRED_SCALE,
    PREVIEW_SCALE,
    SIGMA_DEG,
    ScriptedBackend,
    gaussian_pct,
    settle,
    wait_until,
)

SIZE = (140, 42)


def notes(app: GonioApp) -> list[str]:
    return [f"{n.title}: {n.message}" for n in app._notifications]


def plot_xy(app: GonioApp, label: str) -> tuple[np.ndarray, np.ndarray]:
    plot = app.query_one("#live", ComparisonPanel).main_plot
    ds = plot._datasets[plot._labels.index(label)]
    return np.asarray(ds.x), np.asarray(ds.y)


def cell(table: DataTable[str], row: str, col: str) -> str:
    return str(table.get_cell(row, col))


async def test_scan_points_appear_in_plot_and_metrics() -> None:
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.RUNNING)
        await backend.release(3)
        await wait_until(pilot, lambda: app.comparison.n_readings == 9)
        await settle(pilot, app)
        x, y = plot_xy(app, "measured")
        assert x.tolist() == [10.0, 12.0, 14.0]
        np.testing.assert_allclose(y, [gaussian_pct(t) for t in (10.0, 12.0, 14.0)])
        xp, yp = plot_xy(app, "predicted")
        np.testing.assert_allclose(yp, [PRED_SCALE * gaussian_pct(t) for t in xp])
        status = app.query_one(StatusPanel)
        arms = status.query_one("#arms", DataTable)
        assert cell(arms, "detector", "angle") == "14.00"
        assert "3/11" in str(status.query_one("#run-state", Static).render())
        # 10..14 deg is the rising flank of the peak at 20 deg: its maximum (the last
        # reading) is no peak, and the predictions received so far are the same flank:
        # no peak metrics yet on either side.
        table = app.query_one("#live", ComparisonPanel).query_one(MetricsTable)
        for row in ("amplitude", "position", "fwhm"):
            assert cell(table, row, "measured") == "-"
            assert cell(table, row, "predicted") == "-"

        await backend.release(100)
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await settle(pilot, app)
        table = app.query_one("#live", ComparisonPanel).query_one(MetricsTable)
        # Grid 10..30 step 2 hits the peak at 20 deg exactly.
        assert cell(table, "amplitude", "measured") == f"{AMP_PCT:.2f}"
        assert cell(table, "amplitude", "predicted") == f"{PRED_SCALE * AMP_PCT:.2f}"
        assert cell(table, "position", "measured") == f"{PEAK_DEG:.1f}"
        # FWHM from linear interpolation on the 2-deg grid, within 0.1 deg of 2 sqrt(2 ln 2) s.
        fwhm = float(cell(table, "fwhm", "measured"))
        assert fwhm == pytest.approx(2 * math.sqrt(2 * math.log(2)) * SIGMA_DEG, abs=0.1)
        # measured mean = g, predicted = 0.9 g -> RMSE = 0.1 * rms(g) over the grid.
        grid = np.arange(10.0, 30.1, 2.0)
        rmse = (1 - PRED_SCALE) * math.sqrt(np.mean([gaussian_pct(t) ** 2 for t in grid]))
        assert float(cell(table, "rmse", "measured")) == pytest.approx(rmse, abs=1e-3)
        assert any("run 1 done" in n for n in notes(app))


async def test_pause_resume_and_abort() -> None:
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.RUNNING)
        await backend.release(2)
        await wait_until(pilot, lambda: app.comparison.n_readings == 6)
        await pilot.press("space")
        await backend.release(1)  # the runner reaches the next point and honours the pause
        await wait_until(pilot, lambda: app.run_state is RunState.PAUSED)
        assert app.comparison.n_readings == 6
        await pilot.press("space")
        await wait_until(pilot, lambda: app.comparison.n_readings == 9)
        assert app.run_state is RunState.RUNNING
        await pilot.press("x")
        await backend.release(1)
        await wait_until(pilot, lambda: app.run_state is RunState.ABORTED)
        assert app.comparison.n_readings == 9
        assert any("run 1 aborted" in n for n in notes(app))
        # Nothing running any more: space and x only warn.
        await pilot.press("space")
        assert notes(app)[-1] == "Scan: no scan running"


async def test_instrument_timeout_is_a_notification_not_a_crash() -> None:
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        backend.publish_timeout()
        await wait_until(pilot, lambda: any("spectro error" in n for n in notes(app)))
        assert app.is_running
        assert "no reply to 'MEASURE' within 2.0 s" in notes(app)[-1]
        # A retrying device reports every failure: one toast for the burst, not five;
        # the fatal error that ends the retries is shown too.
        for _ in range(4):
            backend.publish_timeout()
        backend.bus.publish(
            InstrumentError(run_id=0, device="spectro", message="gave up", fatal=True)
        )
        await wait_until(pilot, lambda: any("gave up" in n for n in notes(app)))
        assert [n for n in notes(app) if n.startswith("spectro error")] == [
            "spectro error: no reply to 'MEASURE' within 2.0 s",
            "spectro error (fatal): gave up",
        ]


async def test_homing_timeout_shows_banner_and_blocks_start() -> None:
    backend = ScriptedBackend(fail_open=True)
    app = GonioApp(backend, poll_hz=0, autostart=True)
    async with app.run_test(size=SIZE) as pilot:
        banner = app.query_one("#banner", Static)
        await wait_until(pilot, lambda: banner.has_class("shown"))
        assert "lamp: no answer to homing within 30.0 s" in str(banner.render())
        await pilot.press("s")
        assert notes(app)[-1] == "Scan: the lab is not ready (not homed)"
        assert backend.setups == []
        # The fault cleared: h homes again, the banner goes, a scan can start.
        backend.fail_open = False
        await pilot.press("h")
        await wait_until(pilot, app.ready.is_set)
        assert backend.homings == 1
        assert not banner.has_class("shown")
        assert str(app.query_one("#run-state", Static).render()) == "run: idle (homed)"
        await pilot.press("s")
        await wait_until(pilot, lambda: len(backend.setups) == 1)


async def test_bad_form_value_names_the_field() -> None:
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        app.query_one("#theta_r_step_deg", Input).value = "0"
        await pilot.press("s")
        await wait_until(pilot, lambda: bool(notes(app)))
        assert "θr step must be > 0 deg" in notes(app)[-1]
        assert backend.setups == []


async def test_autostart_and_form_values_reach_the_backend() -> None:
    backend = ScriptedBackend(gated=False)
    app = GonioApp(backend, poll_hz=0, autostart=True)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        assert backend.setups[0].sample == "sample:wittmann-3"
        assert backend.setups[0].theta_r_values_deg() == list(np.arange(10.0, 30.1, 2.0))
        assert app.comparison.n_readings == 11 * 3


async def test_command_palette_offers_abort() -> None:
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.RUNNING)
        await pilot.press("ctrl+p")
        await pilot.press(*"abort scan")
        await settle(pilot, app)
        await pilot.press("enter")
        await backend.release(1)
        await wait_until(pilot, lambda: app.run_state is RunState.ABORTED)
        assert app.comparison.n_readings == 0


async def test_gloss_log_and_runs_browser() -> None:
    backend = ScriptedBackend(gated=False)
    app = GonioApp(backend, poll_hz=0, autostart=True)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        # autostart took one gloss reading (scripted: G60 = 61.0 at T0 + 1 s)
        assert backend.gloss_samples == ["sample:wittmann-3"]
        backend.publish_gloss(5, 61.25)
        log = app.query_one("#gloss-log", GlossLog)
        await wait_until(pilot, lambda: log.row_count == 2)
        assert log.get_row_at(0)[:3] == ["00:00:01", "-", "61.0"]
        assert log.get_row_at(1) == ["00:00:05", "-", "61.2", "-", "30.0", "58.0", "90.0"]
        metrics = app.query_one("#live", ComparisonPanel).query_one(MetricsTable)
        await settle(pilot, app)
        assert cell(metrics, "g60", "delta") == "3.2"

        await pilot.press("r")
        await wait_until(pilot, lambda: isinstance(app.screen, RunsScreen))
        screen = app.screen
        assert isinstance(screen, RunsScreen)
        runs = screen.query_one("#runs", DataTable)
        await wait_until(pilot, lambda: runs.row_count == 1)
        await pilot.press("enter")
        await wait_until(pilot, lambda: screen.loaded_run == 1)
        plot = screen.query_one(ComparisonPanel).main_plot
        assert isinstance(plot, PlotWidget)
        x = plot._datasets[plot._labels.index("measured")].x
        assert list(x) == list(np.arange(10.0, 30.1, 2.0))
        table = screen.query_one(MetricsTable)
        assert cell(table, "amplitude", "measured") == f"{AMP_PCT:.2f}"
        await pilot.press("escape")
        await wait_until(pilot, lambda: not isinstance(app.screen, RunsScreen))


async def test_gloss_every_fills_the_log_while_idle() -> None:
    """``gloss_every_s`` polls the glossmeter on a timer; every reading lands in the log."""
    backend = ScriptedBackend(gated=False)
    app = GonioApp(backend, poll_hz=0, gloss_every_s=0.02)
    async with app.run_test(size=SIZE) as pilot:
        log = app.query_one("#gloss-log", GlossLog)
        await wait_until(pilot, lambda: log.row_count >= 3, max_turns=20000)
        # one reading per tick, in order (scripted meter: G60 = 60 + k for reading k)
        assert backend.gloss_samples[:3] == ["sample:wittmann-3"] * 3
        assert [log.get_row_at(k)[2] for k in range(3)] == ["61.0", "62.0", "63.0"]


async def test_no_gloss_polling_by_default() -> None:
    backend = ScriptedBackend(gated=False)
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: app.ready.is_set())
        for _ in range(50):
            await pilot.pause()
        assert backend.gloss_samples == []


async def test_sample_picker_changes_the_prediction_and_a_new_scan_clears_old_metrics() -> None:
    backend = ScriptedBackend(gated=False)
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        grid = np.arange(10.0, 30.1, 2.0)  # the scripted default sweep
        note = str(app.query_one("#sample-note", Static).render())
        assert note == "the scripted lab measures the selected sample"
        # Between scans the plot shows the selected sample's prediction, and a new pick
        # redraws it: scripted truth PREVIEW_SCALE[sample] x 0.9 x the Gaussian.
        for name in ("wittmann-3", "wittmann-1", "flat"):
            if name != "wittmann-3":
                app.query_one("#sample", Select).value = name
            spec = f"sample:{name}"

            def shown(spec: str = spec) -> bool:
                return app.comparison.sample == spec

            await wait_until(pilot, shown)
            await settle(pilot, app)
            x, y = plot_xy(app, "predicted")
            assert x.tolist() == grid.tolist()
            scale = PREVIEW_SCALE[f"sample:{name}"] * PRED_SCALE
            np.testing.assert_allclose(y, [scale * gaussian_pct(t) for t in grid])
        table = app.query_one("#live", ComparisonPanel).query_one(MetricsTable)
        assert cell(table, "amplitude", "predicted") == f"{2.0 * PRED_SCALE * AMP_PCT:.2f}"

        # A full scan of "flat", then a second one of 24..30 deg (no peak inside: the
        # maximum is at its first point): the first scan's metrics must not linger.
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await settle(pilot, app)
        assert backend.setups[-1].sample == "sample:flat"
        assert cell(table, "amplitude", "measured") == f"{AMP_PCT:.2f}"
        app.query_one("#theta_r_start_deg", Input).value = "24"
        for _ in range(5):
            await pilot.pause()
        assert app.comparison.n_readings == 33  # editing the next sweep keeps the result
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_id == 2 and app.run_state is RunState.DONE)
        await settle(pilot, app)
        x, _ = plot_xy(app, "measured")
        assert x.tolist() == [24.0, 26.0, 28.0, 30.0]
        for row in ("amplitude", "position", "fwhm"):
            assert cell(table, row, "measured") == "-"


async def test_layout_fits_120x35_nothing_cut_off() -> None:
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=(120, 35)) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.pause()
        arms = app.query_one("#arms", DataTable)
        metrics = app.query_one(MetricsTable)
        for table in (arms, metrics):
            # The whole table is on screen: no horizontal scrolling, no row hidden.
            assert table.virtual_size.width <= table.content_region.width, table
            assert table.virtual_size.height <= table.content_region.height, table
            assert table.region.right <= 120
        left = app.query_one("#left")
        status = app.query_one(StatusPanel)
        assert status.region.bottom <= left.region.bottom  # the run line and border show
        # Every fixed-width status cell holds its longest value.
        for key, longest in (("angle", "-80.00"), ("motion", "moving"), ("link", "lost")):
            assert arms.columns[key].width >= len(longest)  # type: ignore[index]


async def test_status_panel_follows_the_arms_while_homing() -> None:
    # poll_hz > 0: the arms are polled from the start, not only once homed.
    backend = ScriptedBackend(hold_open=True)
    app = GonioApp(backend, poll_hz=100.0)
    async with app.run_test(size=SIZE) as pilot:
        arms = app.query_one("#arms", DataTable)
        run_line = app.query_one("#run-state", Static)
        backend.position = (12.5, 3.0)  # the arms on their way to the reference
        await wait_until(pilot, lambda: cell(arms, "lamp", "angle") == "12.50", max_turns=10**5)
        assert cell(arms, "detector", "angle") == "3.00"
        assert str(run_line.render()) == "run: idle (homing...)"
        assert not app.ready.is_set()
        backend.position = (0.0, 0.0)
        backend.homed.set()
        await wait_until(pilot, app.ready.is_set)
        await wait_until(pilot, lambda: cell(arms, "lamp", "angle") == "0.00", max_turns=10**5)
        assert str(run_line.render()) == "run: idle (homed)"


async def test_single_key_commands_work_while_a_form_field_has_focus() -> None:
    # Typing a value and pressing s starts the scan with that value; x aborts from the
    # field too (letters are no part of a number, so the field does not take them).
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        field = app.query_one("#theta_i_deg", Input)
        field.focus()
        await pilot.press("end", "backspace", "backspace", "3", "5", ".", "5", "s")
        await wait_until(pilot, lambda: len(backend.setups) == 1)
        assert backend.setups[0].theta_i_deg == 35.5
        assert app.focused is field and field.value == "35.5"
        await wait_until(pilot, lambda: app.run_state is RunState.RUNNING)
        await pilot.press("x")
        await backend.release(1)
        await wait_until(pilot, lambda: app.run_state is RunState.ABORTED)
        assert field.value == "35.5"


async def test_a_aligns_reports_the_result_and_keeps_its_readings_off_the_curve() -> None:
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("a", "a")  # the second confirms
        await wait_until(pilot, lambda: app.run_state is RunState.RUNNING)
        assert backend.setups[-1].sample == "sample:wittmann-3"  # the form's sample
        await pilot.press("space")
        assert notes(app)[-1] == "Align: an alignment cannot pause (x aborts it)"
        await pilot.press("s")
        assert notes(app)[-1] == "Scan: a scan is already running"
        await backend.release(3)
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        assert app.comparison.n_readings == 0  # the sweeps of the standard are no BRDF curve
        assert notes(app)[-1] == (
            "Align: run 1: lamp zero +0.125 deg, detector zero -0.250 deg, sample tilt "
            "+0.500 deg; saved to /srv/lab/lab.alignment.toml, later moves corrected"
        )
        run_line = str(app.query_one(StatusPanel).query_one("#run-state", Static).render())
        assert "run 1 (align): done  3/3" in run_line
        # a scan afterwards is a BRDF run again: its points are the curve
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_kind == "brdf" and app.run_id == 2)
        await backend.release(100)
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        assert app.comparison.n_readings == 33


async def test_the_first_frame_comes_before_the_lab_then_the_lab_replaces_it() -> None:
    """Given a function that builds the backend (the CLI's: its modules and the config take
    ~0.4 s), the app paints its title and "opening the lab..." first and builds the lab in
    a thread; lab keys do nothing meanwhile; then the lab's widgets replace the notice."""
    import threading

    backend = ScriptedBackend()
    gate = threading.Event()
    calls: list[str] = []

    def build() -> ScriptedBackend:
        calls.append(threading.current_thread().name)
        assert gate.wait(30)
        return backend

    app = GonioApp(build, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: bool(calls))
        assert calls[0] != threading.main_thread().name  # off the event loop
        assert "opening the lab" in str(app.query_one("#boot", Static).render())
        assert app.title == "goniolab" and not app.query(ScanForm)
        await pilot.press("s")  # refused while the lab opens: no error, nothing started
        assert backend.setups == [] and app.run_state is RunState.IDLE
        gate.set()
        await wait_until(pilot, app.ready.is_set)
        assert not app.query("#boot") and app.query(ScanForm)
        assert app.sub_title == backend.title
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.RUNNING)


async def test_a_lab_that_cannot_be_built_ends_the_app_with_its_error() -> None:
    from goniolab.errors import UserError

    def build() -> ScriptedBackend:
        raise UserError("lab.toml: lab.name: field required")

    app = GonioApp(build, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: app.boot_error is not None)
        await pilot.pause()
    assert app.return_code == 2
    assert str(app.boot_error) == "lab.toml: lab.name: field required"


async def test_quitting_while_the_lab_opens_leaves_cleanly() -> None:
    import threading

    gate = threading.Event()

    def build() -> ScriptedBackend:
        gate.wait(30)
        return ScriptedBackend()

    app = GonioApp(build, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.pause()
        await pilot.press("q")
        await pilot.pause()
        gate.set()
    assert app.return_code == 0


async def test_layout_follows_the_terminal_size() -> None:
    """Issue 27 item 1: at 80 x 24 the plots take the screen and the status line says the
    run and the lab; f swaps the form in; below 80 x 24 a message says what is needed."""
    from textual.widgets import Static

    from goniolab.scan.events import RunState
    from goniolab.tui.app import GonioApp
    from goniolab.tui.widgets import StatusLine
    from tests.tui.tui_scripted import ScriptedBackend, wait_until

    app = GonioApp(ScriptedBackend(gated=False), poll_hz=0, autostart=True)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await pilot.pause()
        left, live = app.query_one("#left"), app.query_one("#live")
        assert not left.display and live.display
        assert live.size.width == 80 and live.size.height >= 10
        line = str(app.query_one(StatusLine).render())
        # both arms within the 78 columns shown (the words "lamp" and "detector" were in
        # the string while the detector's part was cut off the screen)
        assert "done" in line and "θi 20.00" in line and "θr " in line and len(line) <= 78
        await pilot.press("f")
        await pilot.pause()
        assert left.display and not live.display
        await pilot.press("f")
        await pilot.pause()
        assert not left.display and live.display
        await pilot.resize_terminal(70, 20)
        await pilot.pause()
        note = app.query_one("#too-small", Static)
        assert note.display and "at least 80 x 24" in str(note.render())
        assert "70 x 20" in str(note.render())
        assert not app.query_one("#top").display
        await pilot.resize_terminal(160, 50)
        await pilot.pause()
        assert left.display and live.display and not note.display
        assert left.size.width == 50


async def test_a_asks_for_confirmation_and_not_while_a_field_is_edited() -> None:
    # issue 22: the single key a started an alignment, even while a form field had focus
    backend = ScriptedBackend()
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("a")
        assert "press a again to start" in notes(app)[-1]
        assert backend.setups == []  # nothing started yet
        app.query_one(ScanForm).query(Select).first().focus()
        await pilot.pause()
        await pilot.press("a")
        assert notes(app)[-1] == (
            "Align: a form field is being edited: leave it (Esc) before aligning"
        )
        assert backend.setups == []
        await pilot.press("escape")
        await pilot.press("a", "a")
        await wait_until(pilot, lambda: app.run_state is RunState.RUNNING)
        assert len(backend.setups) == 1
        await backend.release(3)
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)


async def test_the_end_of_a_run_says_how_many_warnings_it_stored_and_how_many_were_held() -> None:
    # A burst of one device's warnings shows one toast; the run's end says how many
    # warnings the run stored and that the burst's others were not shown as they came.
    backend = ScriptedBackend()
    backend.run_warnings = ["spectro: reading retried (4 times)"]
    app = GonioApp(backend, poll_hz=0)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.RUNNING)
        for _ in range(4):
            backend.bus.publish(
                InstrumentError(run_id=1, device="spectro", message="reading retried", fatal=False)
            )
        await backend.release(11)
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await wait_until(pilot, lambda: any(n.startswith("Scan: run 1 done") for n in notes(app)))
        assert [n for n in notes(app) if n.startswith("spectro error")] == [
            "spectro error: reading retried"
        ]
        assert notes(app)[-1] == (
            "Scan: run 1 done; 1 warning stored with the run (goniolab runs show 1); 3 of its "
            "messages were not shown as they came"
        )


@pytest.mark.parametrize(("rows", "shown"), [(35, False), (39, False), (40, True), (42, True)])
async def test_the_side_plot_gives_way_when_it_would_get_three_rows(rows: int, shown: bool) -> None:
    """Under 40 rows the metrics, the colour table and its note (18 rows of the right
    column) leave the side plot 4-8 rows, 2 of them its border (3 at 120 x 32: one tick
    label): it is hidden, and ``l`` says why instead of switching an invisible plot
    silently. From 40 rows it shows, 9 rows or more."""
    app = GonioApp(ScriptedBackend(gated=False), poll_hz=0)
    async with app.run_test(size=(140, rows)) as pilot:
        await wait_until(pilot, app.ready.is_set)
        side = app.query_one("#live", ComparisonPanel).side_plot
        await pilot.pause()
        assert side.display is shown
        if shown:
            assert side.region.height >= 9  # the border's 2 rows and 7 or more of plot
        await pilot.press("l")
        await pilot.pause()
        said = [n for n in notes(app) if n.startswith("Side plot: ")]
        if shown:
            assert said == []
        else:
            assert said == [
                "Side plot: the side plot (log10 of both curves) is hidden in a window under "
                "40 rows: enlarge the window to see it"
            ]


@pytest.mark.parametrize("width", [120, 140, 170])
async def test_the_arm_table_fits_its_panel_with_signed_angles(width: int) -> None:
    """A detector at -75.50 deg (configs/lab-sim-multiangle.toml's range is -80..80): each
    column keeps a gap after its widest value and the table fits its panel without a
    horizontal scroll at the -medium (120-159 columns) and wide layouts."""
    app = GonioApp(ScriptedBackend(gated=False), poll_hz=0)
    async with app.run_test(size=(width, 42)) as pilot:
        await wait_until(pilot, app.ready.is_set)
        panel = app.query_one(StatusPanel)
        panel.show_angles(-45.0, -75.5, True)
        await pilot.pause()
        arms = panel.query_one("#arms", DataTable)
        widest = {"angle": "-89.99", "motion": "moving", "homed": "homed", "link": "lost"}
        for key, text in widest.items():
            assert arms.columns[key].width > len(text), key  # type: ignore[index]
        assert max(len(str(r.label)) for r in arms.rows.values()) > len("detector")
        assert cell(arms, "detector", "angle") == "-75.50"
        assert arms.virtual_size.width <= arms.scrollable_content_region.width


async def test_gloss_log_scrollbar_shows_the_scroll_it_appears_at() -> None:
    """The race of the 80 x 24 snapshot: the log scrolled to its last row in the refresh
    that made it overflow, before its scrollbar was shown; textual moves the thumb only
    while the bar is shown, so the thumb stayed at the top beside the bottom rows."""
    backend = ScriptedBackend(gated=False)
    app = GonioApp(backend, poll_hz=0, autostart=True)
    async with app.run_test(size=(80, 24)) as pilot:
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        log = app.query_one("#gloss-log", GlossLog)
        for t_s in (5, 9, 13):
            backend.publish_gloss(t_s, 60.0)
        await wait_until(pilot, lambda: log.row_count == 4)
        await settle(pilot, app)
        assert log.max_scroll_y > 0  # the log overflows at this size
        # the order of the race, forced: the thumb at the top, the bar hidden, the table
        # scrolled to its end, the bar shown
        log.scroll_y = 0
        assert log.vertical_scrollbar.position == 0
        log.show_vertical_scrollbar = False
        log.scroll_y = log.max_scroll_y
        log.show_vertical_scrollbar = True
        assert log.vertical_scrollbar.position == log.max_scroll_y
