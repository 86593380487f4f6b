"""The TUI over the real stack: Lab (in-process sim, instant clock), ScanRunner, RunStore.

The simulated lab reads a noise-free, perfectly aligned Beckmann surface; the prediction
comes from the same model through the same apertures, so the truth is that measured and
predicted agree to rounding, point by point.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import re
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from textual.pilot import Pilot
from textual.widgets import DataTable, Input, Select, Static

from goniolab.config import load_lab_config
from goniolab.model_cache import model_for
from goniolab.optics.analytic import AnalyticModel
from goniolab.optics.apertures import Cone
from goniolab.scan.align import AlignPlan
from goniolab.scan.events import RunState
from goniolab.scan.plans import DEFAULT_REPEATS
from goniolab.store import RunStore
from goniolab.tui.app import GonioApp
from goniolab.tui.screens import RunsScreen
from goniolab.tui.session_backend import SessionBackend
from goniolab.tui.widgets import ComparisonPanel, GlossLog, MetricsTable, StatusPanel
from tests.tui.tui_scripted import settle, wait_until
from tests.twin_configs import ideal

REPO = Path(__file__).resolve().parents[2]
SIZE = (140, 42)
ALPHA = 0.1  # Beckmann total rms slope of the simulated sample


def sim_config(tmp_path: Path, *, faults: str = "") -> Path:
    """configs/lab-sim.toml with the ideal twin, an instant clock, no noise and a temporary
    store."""
    text = ideal((REPO / "configs" / "lab-sim.toml").read_text())
    text = re.sub(r"(?m)^time_scale = .*$", "time_scale = 0.0", text)
    text = re.sub(r"(?m)^store = .*$", f'store = "{tmp_path / "runs.sqlite"}"', text)
    text = re.sub(r"(?m)^noise_pct = .*$", "noise_pct = 0.0", text)
    text = text.replace("[sim.faults]", "[sim.faults]\n" + faults)
    path = tmp_path / "lab.toml"
    path.write_text(text)
    return path


def make_app(tmp_path: Path, *, faults: str = "", autostart: bool = False) -> GonioApp:
    backend = SessionBackend(
        sim_config(tmp_path, faults=faults), model=AnalyticModel("beckmann", alpha=ALPHA)
    )
    return GonioApp(backend, autostart=autostart, poll_hz=0)


async def set_form(pilot: Pilot[int], app: GonioApp, **values: str) -> None:
    for key, value in values.items():
        app.query_one(f"#{key}", Input).value = value
    await pilot.pause()


async def test_scan_on_the_sim_lab_measured_equals_predicted(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        arms = app.query_one(StatusPanel).query_one("#arms", DataTable)
        assert str(arms.get_cell("lamp", "homed")) == "yes"
        assert str(arms.get_cell("detector", "link")) == "ok"
        await set_form(
            pilot,
            app,
            theta_i_deg="20",
            theta_r_start_deg="10",
            theta_r_stop_deg="30",
            theta_r_step_deg="2",
            repeats="2",
        )
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await wait_until(pilot, lambda: len(app.comparison.predicted) == 11)
        await settle(pilot, app)
        a = app.comparison.arrays()
        assert a.theta_r_deg.tolist() == list(np.arange(10.0, 30.1, 2.0))
        assert a.n_readings.tolist() == [2] * 11
        # Independent truth: the model's own in-plane luminance through the 6-deg cones.
        truth = AnalyticModel("beckmann", alpha=ALPHA).luminance_pct(
            20.0, a.theta_r_deg, source=Cone(6.0), detector=Cone(6.0)
        )
        np.testing.assert_allclose(a.mean_pct, truth, rtol=1e-9)
        np.testing.assert_allclose(a.predicted_pct, truth, rtol=1e-9)
        plot = app.query_one("#live", ComparisonPanel).main_plot
        ds = plot._datasets[plot._labels.index("measured")]
        np.testing.assert_allclose(ds.y, truth, rtol=1e-9)
        metrics = app.query_one("#live", ComparisonPanel).query_one(MetricsTable)
        assert str(metrics.get_cell("rmse", "measured")) == "0.000"
        assert str(metrics.get_cell("position", "measured")) == "20.0"  # specular
        # Every reading is in the store.
        with RunStore(tmp_path / "runs.sqlite") as store:
            assert store.count_points(app.run_id) == 22
            assert store.get_run(app.run_id).status == "done"


async def test_pause_resume_abort_on_the_sim_lab(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    total = 11 * 2
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await set_form(
            pilot,
            app,
            theta_r_start_deg="0",
            theta_r_stop_deg="40",
            theta_r_step_deg="4",
            repeats="2",
        )

        # Run 1: pause, nothing measured while paused, resume to the end.
        # The actions of keys s and space, back to back: a Pilot key press waits for the
        # app to go idle, and on the instant clock the whole scan may be over by then.
        app.action_start_scan()
        app.action_toggle_pause()  # honoured before the first reading
        await wait_until(pilot, lambda: app.run_state is RunState.PAUSED)
        paused_at = app.comparison.n_readings
        assert paused_at == 0
        for _ in range(20):
            await pilot.pause()
        assert app.comparison.n_readings == paused_at
        await pilot.press("space")
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        assert app.comparison.n_readings == total
        first = app.run_id

        # Run 2: pause, then abort while paused: the run stops where it was, arms parked.
        app.action_start_scan()
        app.action_toggle_pause()
        await wait_until(pilot, lambda: app.run_state is RunState.PAUSED)
        stopped_at = app.comparison.n_readings
        await pilot.press("x")
        await wait_until(pilot, lambda: app.run_state is RunState.ABORTED)
        assert app.comparison.n_readings == stopped_at < total
        with RunStore(tmp_path / "runs.sqlite") as store:
            assert store.get_run(first).status == "done"
            assert store.count_points(first) == total
            assert store.get_run(app.run_id).status == "aborted"
            assert store.count_points(app.run_id) == stopped_at
        await app.poll_once()
        arms = app.query_one(StatusPanel).query_one("#arms", DataTable)
        assert str(arms.get_cell("lamp", "angle")) == "45.00"  # config park 45/45
        assert str(arms.get_cell("detector", "angle")) == "45.00"


async def test_gloss_reading_and_runs_browser_on_the_sim_lab(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await set_form(
            pilot, app, theta_r_start_deg="10", theta_r_stop_deg="30", theta_r_step_deg="5"
        )
        await pilot.press("g", "s")
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        log = app.query_one("#gloss-log", GlossLog)
        await wait_until(pilot, lambda: log.row_count == 1)
        gloss = AnalyticModel("beckmann", alpha=ALPHA).gloss((20, 60, 85))
        row = log.get_row_at(0)
        # Noise-free sim meter: reads the model's gloss (0.1 GU resolution); predicted beside.
        for k, angle in enumerate((20, 60, 85)):
            assert float(row[1 + k]) == pytest.approx(gloss[angle], abs=0.051)
            assert float(row[4 + k]) == pytest.approx(gloss[angle], abs=0.051)
        await pilot.press("r")
        await wait_until(pilot, lambda: isinstance(app.screen, RunsScreen))
        screen = app.screen
        assert isinstance(screen, RunsScreen)
        runs = screen.query_one("#runs", DataTable)
        await wait_until(pilot, lambda: runs.row_count == 2)  # the brdf run and the gloss run
        kinds = {str(runs.get_row_at(i)[2]) for i in range(2)}
        assert kinds == {"brdf", "gloss"}
        brdf_row = next(i for i in range(2) if str(runs.get_row_at(i)[2]) == "brdf")
        runs.move_cursor(row=brdf_row)
        await pilot.press("enter")
        await wait_until(pilot, lambda: screen.loaded_run == app.run_id)
        reopened = screen.comparison.arrays()
        live = app.comparison.arrays()
        np.testing.assert_allclose(reopened.mean_pct, live.mean_pct)
        np.testing.assert_allclose(reopened.predicted_pct, live.predicted_pct)


async def test_instrument_timeout_during_scan_is_reported(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The spectro never answers: the run fails with the device named, the app keeps running.
    app = make_app(tmp_path, faults='devices = ["spectro"]\ntimeout_rate = 1.0\n')
    # every toast shown, not the ones still on screen: the fatal one expires after 10 s,
    # and parking the arms after the failure may take longer than that on a loaded machine
    titles: list[str] = []
    notify = app.notify

    def record(message: str, *, title: str = "", **kwargs: Any) -> None:
        titles.append(title)
        notify(message, title=title, **kwargs)

    monkeypatch.setattr(app, "notify", record)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.FAILED)
        assert "spectro error (fatal)" in titles
        assert app.query_one("#banner").has_class("shown")
        assert app.is_running


async def test_arm_alarm_fails_the_run_and_shows_in_the_status_panel(tmp_path: Path) -> None:
    # The detector controller raises alarm 0x30 when it passes 52 deg (beyond the park
    # position, so homing does not cross it): the run fails with the reason kept, the
    # status panel shows the alarm, the app keeps running.
    app = make_app(tmp_path, faults="detector_alarm_at_deg = 52.0\nalarm_code = 48\n")
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await set_form(
            pilot, app, theta_r_start_deg="40", theta_r_stop_deg="60", theta_r_step_deg="5"
        )
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.FAILED)
        # 40, 45, 50 deg measured before the alarm, the form's default repeats each
        assert app.comparison.n_readings == 3 * DEFAULT_REPEATS
        await app.poll_once()
        arms = app.query_one(StatusPanel).query_one("#arms", DataTable)
        assert str(arms.get_cell("detector", "alarm")) == "0x30"
        assert str(arms.get_cell("lamp", "alarm")) == "-"
        # The reason in full under the table (the cell is 5 wide), naming the arm.
        note = str(app.query_one(StatusPanel).query_one("#arm-note", Static).render())
        assert note == "detector: alarm 0x30"
        assert app.query_one("#banner").has_class("shown")
        assert app.is_running


async def test_quit_during_a_scan_aborts_it_and_exits(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        app.action_start_scan()
        app.action_toggle_pause()
        await wait_until(pilot, lambda: app.run_state is RunState.PAUSED)
        await pilot.press("q")
        await wait_until(pilot, lambda: app.return_code is not None)
    assert app.return_code == 0
    with RunStore(tmp_path / "runs.sqlite") as store:
        run = store.get_run(app.run_id)
        assert (run.status, run.reason) == ("aborted", "aborted by the operator")


async def test_the_sim_lab_measures_the_sample_picked_in_the_form(tmp_path: Path) -> None:
    # The config's sample is a Beckmann surface; picking wittmann-1 puts that sample under
    # the simulated spectro and glossmeter: readings follow wittmann-1's model, the one the
    # config's [sample] model names (default auto).
    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        note = str(app.query_one("#sample-note", Static).render())
        assert note == "the simulated lab measures the selected sample"
        await set_form(
            pilot, app, theta_r_start_deg="40", theta_r_stop_deg="50", theta_r_step_deg="5"
        )
        app.query_one("#sample", Select).value = "wittmann-1"
        theta = np.array([40.0, 45.0, 50.0])
        facet = model_for("sample:wittmann-1", n=1.55, model="auto")
        truth = facet.luminance_pct(45.0, theta, source=Cone(6.0), detector=Cone(6.0))
        beckmann = AnalyticModel("beckmann", alpha=ALPHA).luminance_pct(
            45.0, theta, source=Cone(6.0), detector=Cone(6.0)
        )
        assert abs(truth[1] - beckmann[1]) > 0.5 * truth[1]  # the two samples differ
        # Before the scan, the preview shows the picked sample's prediction.
        await wait_until(pilot, lambda: app.comparison.sample == "sample:wittmann-1")
        np.testing.assert_allclose(app.comparison.arrays().predicted_pct, truth, rtol=1e-9)
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await wait_until(pilot, lambda: len(app.comparison.predicted) == 3)
        a = app.comparison.arrays()
        # The noise-free sim reads one geometry at a time; the facet model's one-angle
        # path and its batch path (the prediction) agree to 0.1 % (measured: 0.07 %).
        per_point = [
            float(facet.luminance_pct(45.0, np.array([t]), source=Cone(6.0), detector=Cone(6.0))[0])
            for t in theta
        ]
        np.testing.assert_allclose(a.mean_pct, per_point, rtol=1e-9)
        np.testing.assert_allclose(a.predicted_pct, truth, rtol=1e-9)
        np.testing.assert_allclose(a.mean_pct, truth, rtol=1e-3)
        await pilot.press("g")
        log = app.query_one("#gloss-log", GlossLog)
        await wait_until(pilot, lambda: log.row_count == 1)
        gloss = facet.gloss((20, 60, 85))
        row = log.get_row_at(0)
        for k, angle in enumerate((20, 60, 85)):
            assert float(row[1 + k]) == pytest.approx(gloss[angle], abs=0.051)
            assert float(row[4 + k]) == pytest.approx(gloss[angle], abs=0.051)
        with RunStore(tmp_path / "runs.sqlite") as store:
            assert store.get_run(app.run_id).sample == "sample:wittmann-1"


async def test_alarm_while_homing_shows_and_h_resets_and_homes_again(tmp_path: Path) -> None:
    # The detector passes 30 deg on its way from park (45) to its reference: alarm 0x30
    # (injected once). The lab is not ready, the arms' state shows the alarm; h resets
    # the alarm and homes again.
    app = make_app(tmp_path, faults="detector_alarm_at_deg = 30.0\nalarm_code = 48\n")
    async with app.run_test(size=SIZE) as pilot:
        banner = app.query_one("#banner", Static)
        await wait_until(pilot, lambda: banner.has_class("shown"))
        assert "detector" in str(banner.render()) and "0x30" in str(banner.render())
        arms = app.query_one(StatusPanel).query_one("#arms", DataTable)
        await wait_until(pilot, lambda: str(arms.get_cell("detector", "alarm")) == "0x30")
        await pilot.press("h")
        await wait_until(pilot, app.ready.is_set)
        await app.poll_once()
        assert str(arms.get_cell("detector", "alarm")) == "-"
        assert str(arms.get_cell("detector", "angle")) == "0.00"  # at its reference
        assert not banner.has_class("shown")


async def test_geometry_out_of_reach_is_a_form_error(tmp_path: Path) -> None:
    # Beyond the detector's limits (from the config), and arms closer than the minimum
    # separation (theta_i 5, theta_r 0: 5 deg apart): refused before a run is stored.
    cfg = load_lab_config(sim_config(tmp_path))
    lo_deg, hi_deg = cfg.goniometer.detector.limits_deg
    min_sep_deg = cfg.goniometer.min_separation_deg
    first_out = math.floor(hi_deg) + 1
    cases = [
        (
            {
                "theta_i_deg": "45",
                "theta_r_start_deg": f"{max(lo_deg, 0.0):g}",
                "theta_r_stop_deg": f"{hi_deg + 5:g}",
            },
            f"(theta_i=45 deg, theta_r={first_out} deg) is unsafe",
            "detector arm limits",
        ),
        (
            {
                "theta_i_deg": f"{min_sep_deg / 2:g}",
                "theta_r_start_deg": "0",
                "theta_r_stop_deg": "20",
            },
            f"(theta_i={min_sep_deg / 2:g} deg, theta_r=0 deg) is unsafe",
            "apart",
        ),
    ]
    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        for form, where, why in cases:
            await set_form(pilot, app, theta_r_step_deg="1", **form)
            app.clear_notifications()
            await pilot.press("s")
            await wait_until(
                pilot, lambda: any(n.title == "Scan setup" for n in app._notifications)
            )
            note = next(n.message for n in app._notifications if n.title == "Scan setup")
            assert where in note and why in note, note
        assert not app.query_one("#banner").has_class("shown")
        with RunStore(tmp_path / "runs.sqlite") as store:
            assert store.list_runs() == []


async def test_colour_columns_swatch_and_colour_plot(tmp_path: Path) -> None:
    from goniolab.tui.widgets import ColourSwatch, ColourTable

    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await set_form(
            pilot, app, theta_i_deg="45", theta_r_start_deg="30", theta_r_stop_deg="50",
            theta_r_step_deg="10", repeats="1",
        )  # fmt: skip
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await wait_until(pilot, lambda: len(app.comparison.predicted_lab) == 3)
        await settle(pilot, app)
        c = app.comparison.colour_arrays()
        a = app.comparison.arrays()
        # L* of each reading from its luminance: the grey sample's spectrum is near-flat,
        # a reflectance factor Y = lum / 100 / (sin^2 3 deg cos theta_r) (CIE 15 eq. 8.1)
        y = (
            a.mean_pct
            / 100.0
            / (math.sin(math.radians(3.0)) ** 2 * np.cos(np.radians(a.theta_r_deg)))
        )
        np.testing.assert_allclose(c.measured_lab[:, 0], 116.0 * np.cbrt(y) - 16.0, atol=0.3)
        np.testing.assert_allclose(c.measured_lab[:, 0], c.predicted_lab[:, 0], atol=0.3)
        table = app.query_one(ColourTable)
        assert table.row_count == 4  # three points and the din6175-2 overall verdict
        assert str(table.get_cell_at((3, 0))) == "overall"
        assert str(table.get_cell_at((3, 10))) in ("PASS", "FAIL")
        assert str(table.get_cell_at((3, 8))) == "prov."  # din6175-2's limits: provisional
        assert str(table.get_cell_at((1, 2))) == f"{c.measured_lab[1, 0]:.1f}"
        # the E2194 aspecular angle (theta_i - theta_r) and dE00 against colour-science
        import colour

        assert str(table.get_cell_at((0, 1))) == f"{45.0 - c.theta_r_deg[0]:.0f}"
        de00 = colour.delta_E(c.measured_lab[1], c.predicted_lab[1], "CIE 2000")
        assert str(table.get_cell_at((1, 9))) == f"{float(de00):.2f}".replace("-0.00", "0.00")
        swatch = str(app.query_one(ColourSwatch).render())
        assert f"L* {c.measured_lab[2, 0]:.1f}" in swatch  # the last point read
        await pilot.press("c")
        panel = app.query_one("#live", ComparisonPanel)
        assert panel.plot_mode == "L*"
        plot = panel.main_plot
        ds = plot._datasets[plot._labels.index("measured L*")]
        np.testing.assert_allclose(ds.y, c.measured_lab[:, 0])
        await pilot.press("c")
        assert panel.plot_mode == "a*b*" and "measured b*" in panel.main_plot._labels


#: The align tests' plan: 104 readings instead of the default 288 (fewer events).
ALIGN_PLAN = AlignPlan(
    theta_i_deg=(20.0, 60.0), coarse_span_deg=4.0, fine_step_deg=0.5, fine_span_deg=4.0
)


def align_app(path: Path) -> tuple[SessionBackend, GonioApp]:
    """The TUI on the sim lab of ``path`` with a narrow Beckmann sample (FWHM ~5 deg: the
    align sweeps bracket it) and :data:`ALIGN_PLAN`."""
    backend = SessionBackend(
        path, model=AnalyticModel("beckmann", alpha=0.02), align_plan=ALIGN_PLAN
    )
    return backend, GonioApp(backend, poll_hz=0)


def hook_spectro(monkeypatch: pytest.MonkeyPatch, before: Callable[[int], Awaitable[None]]) -> None:
    """Every simulated spectro reading first awaits ``before(k)`` (k = 1, 2, ...: it may
    hold the reading or raise), then reads."""
    from sim.instruments import SimSpectro

    real = SimSpectro.measure
    calls = 0

    async def measure(self: SimSpectro) -> Any:
        nonlocal calls
        calls += 1
        await before(calls)
        return await real(self)

    monkeypatch.setattr(SimSpectro, "measure", measure)


async def defect_from_the_third(k: int) -> None:
    """An exception no part of the lab expects, from the third reading on."""
    if k > 2:
        raise ZeroDivisionError("a defect")


@pytest.mark.slow
@pytest.mark.timeout(300)  # 104 twin readings, and a cold twin cache on a fresh machine
async def test_a_aligns_the_sim_lab_writes_alignment_and_corrects_the_arms(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the ideal twin with known misalignments ([sim] offsets) and a narrow Beckmann sample
    # (align_app); abort first, then align to the end
    path = sim_config(tmp_path)
    text = path.read_text()
    for key, value in (
        ("sample_tilt_deg", 0.3),
        ("lamp_zero_offset_deg", -0.4),
        ("detector_zero_offset_deg", 0.2),
    ):
        text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", text)
    path.write_text(text)
    # The first alignment is held at its fourth spectro reading until x is pressed: the
    # twin at time scale 0 can otherwise finish all 104 readings between two turns of a
    # loaded test loop, and x then finds no run to abort (the hang of the full suite).
    held, release = asyncio.Event(), asyncio.Event()

    async def hold_the_fourth(k: int) -> None:
        if k == 4:
            held.set()
            await release.wait()

    hook_spectro(monkeypatch, hold_the_fourth)
    backend, app = align_app(path)
    # every toast shown (one may expire before a loaded loop looks)
    shown: list[str] = []
    notify = app.notify

    def record(message: str, **kwargs: Any) -> None:
        shown.append(message)
        notify(message, **kwargs)

    monkeypatch.setattr(app, "notify", record)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("a", "a")  # the second confirms
        await wait_until(pilot, held.is_set, max_turns=100_000)
        await pilot.press("x")
        release.set()
        await wait_until(pilot, lambda: app.run_state is RunState.ABORTED, max_turns=100_000)
        assert 3 <= app.progress[0] < 104
        assert "[alignment]" not in path.read_text()
        await wait_until(pilot, lambda: not backend.running)
        await pilot.press("a", "a")  # the second confirms
        await wait_until(
            pilot,
            lambda: app.run_id == 2 and app.run_state is RunState.DONE and not backend.running,
            max_turns=100_000,
        )
        assert app.comparison.n_readings == 0
        assert any("run 2: lamp zero -0.4" in m for m in shown)
        # saved beside the store, the tracked config untouched (issue 22)
        assert path.read_text() == text
        assert any(f"saved to {tmp_path / 'lab.alignment.toml'}" in m for m in shown)
        got = load_lab_config(path).alignment
        assert got.loaded_from == str(tmp_path / "lab.alignment.toml")
        assert got.run == 2
        assert got.lamp_zero_deg == pytest.approx(-0.4, abs=0.02)
        assert got.detector_zero_deg == pytest.approx(0.2, abs=0.02)
        assert got.sample_tilt_deg == pytest.approx(0.3, abs=0.02)
        assert backend.session is not None
        assert backend.session.lab.goniometer.corrections_deg == pytest.approx(
            got.corrections_deg(), abs=1e-4
        )
    with RunStore(tmp_path / "runs.sqlite") as store:
        assert [store.get_run(r).status for r in (1, 2)] == ["aborted", "done"]


async def test_an_internal_error_fails_the_run_on_screen_and_keeps_the_readings(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A defect (an exception no part of the lab expects, here from the third reading on)
    # ends the run as failed with the error named; the app runs on, and the two readings
    # taken are in the store (a failed run resumes).
    hook_spectro(monkeypatch, defect_from_the_third)
    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await set_form(pilot, app, repeats="1")
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.FAILED, max_turns=20_000)
        messages = [n.message for n in app._notifications]
        assert any("internal error: ZeroDivisionError: a defect" in m for m in messages)
        assert app.is_running
    with RunStore(tmp_path / "runs.sqlite") as store:
        assert len(store.points(app.run_id)) == 2
        run = store.get_run(app.run_id)
        assert run.status == "failed" and "ZeroDivisionError: a defect" in run.reason


async def test_an_internal_error_fails_the_alignment_on_screen(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the same defect in an alignment: it used to kill the task unseen, the run stayed
    # "running" on screen and in the store (the full suite's align test waited forever)
    hook_spectro(monkeypatch, defect_from_the_third)
    path = sim_config(tmp_path)
    backend, app = align_app(path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await pilot.press("a", "a")  # the second confirms
        await wait_until(pilot, lambda: app.run_state is RunState.FAILED, max_turns=20_000)
        await wait_until(pilot, lambda: not backend.running)
        messages = [n.message for n in app._notifications]
        assert any("internal error: ZeroDivisionError: a defect" in m for m in messages)
        assert "[alignment]" not in path.read_text()
    with RunStore(tmp_path / "runs.sqlite") as store:
        run = store.get_run(1)
        assert (
            run.status == "failed" and run.reason == "internal error: ZeroDivisionError: a defect"
        )


async def test_gloss_requests_while_one_reads_are_coalesced_not_refused(tmp_path: Path) -> None:
    """issue 27, item 7: under `make run` (a reading every 5 s) `g` was refused "already in
    progress" most of the time. Requests during a reading join one more reading after it."""
    backend = SessionBackend(sim_config(tmp_path), model=AnalyticModel("beckmann", alpha=ALPHA))
    await backend.open()
    try:
        sample = backend.sample
        first = await backend.read_gloss(sample)
        second = await backend.read_gloss(sample)  # while the first is under way
        third = await backend.read_gloss(sample)
        assert second is third and first is not second
        await asyncio.wait_for(asyncio.gather(first, second), timeout=60)
        with RunStore(tmp_path / "runs.sqlite", readonly=True) as store:
            (run,) = [r for r in store.list_runs() if r.kind == "gloss"]
            assert len(store.gloss_readings(run.id)) == 2  # the first, and one for both others
        assert not backend.gloss_busy
        fourth = await backend.read_gloss(sample)  # idle again: a reading of its own
        assert fourth is not second
        await asyncio.wait_for(fourth, timeout=60)
    finally:
        await backend.close()


async def test_autostart_takes_the_gloss_reading_before_the_scan(tmp_path: Path) -> None:
    """The README: once homed, the app takes a gloss reading, then starts the form's scan.

    The form's sweep is cut to its first three angles: the order of the first reading and
    the first point does not depend on its length, and the default 71 points took two
    minutes of the suite (test_scan_on_the_sim_lab_measured_equals_predicted scans in full).
    """
    app = make_app(tmp_path, autostart=True)
    default = app.backend.default_setup()
    short = dataclasses.replace(
        default,
        theta_r_stop_deg=default.theta_r_start_deg + 2 * default.theta_r_step_deg,
    )
    app.backend.default_setup = lambda: short  # type: ignore[method-assign]
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: app.run_state is RunState.DONE, max_turns=20000)
    with RunStore(tmp_path / "runs.sqlite", readonly=True) as store:
        runs = {r.kind: r for r in store.list_runs()}
        (reading,) = store.gloss_readings(runs["gloss"].id)
        first_point = min(p.timestamp for p in store.points(runs["brdf"].id))
    assert reading.timestamp < first_point


async def test_the_sessions_gloss_run_reads_running_until_the_app_closes(tmp_path: Path) -> None:
    """issue 27: the TUI's gloss run (one per sample, a reading every few seconds) read
    `done` after each reading while the session was still recording."""
    backend = SessionBackend(sim_config(tmp_path), model=AnalyticModel("beckmann", alpha=ALPHA))
    await backend.open()
    try:
        await asyncio.wait_for(await backend.read_gloss(backend.sample), timeout=60)
        with RunStore(tmp_path / "runs.sqlite", readonly=True) as store:
            (run,) = [r for r in store.list_runs() if r.kind == "gloss"]
            assert run.status == RunState.RUNNING.value
            assert store.is_claimed(run.id) is True  # running, not "interrupted"
    finally:
        await backend.close()
    with RunStore(tmp_path / "runs.sqlite", readonly=True) as store:
        assert store.get_run(run.id).status == RunState.DONE.value
        assert len(store.gloss_readings(run.id)) == 1


async def test_run_identity_dialog_is_stored_with_the_next_runs(tmp_path: Path) -> None:
    """Issue 22 item 4: operator, physical sample id, notes and tags from the TUI (key i)
    are stored with the next scan and gloss run; Esc leaves them unchanged."""
    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: app.ready.is_set())
        await pilot.press("i")
        await pilot.pause()
        for field, text in (("operator", "ada"), ("sample_id", "LIMS-7"),
                            ("notes", "2nd coat"), ("tags", "q3, wet, q3")):  # fmt: skip
            app.screen.query_one(f"#{field}", Input).value = text
        app.screen.query_one("#tags", Input).focus()
        await pilot.press("enter")
        await pilot.pause()
        assert app.backend.run_identity.tags == ("q3", "wet")
        await pilot.press("i")
        await pilot.pause()
        app.screen.query_one("#operator", Input).value = "mallory"
        await pilot.press("escape")  # cancelled: unchanged
        await pilot.pause()
        assert app.backend.run_identity.operator == "ada"
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.DONE, max_turns=20000)
        await pilot.press("g")
        await wait_until(pilot, lambda: len(app.comparison.gloss) >= 1, max_turns=20000)
        # the run line names the model of the predicted curve (issue 20)
        await wait_until(pilot, lambda: bool(app.prediction_note), max_turns=20000)
        assert app.prediction_note == "analytic-beckmann"
        assert "(predicted by analytic-beckmann)" in str(
            app.query_one("#run-state", Static).render()
        )
        # the gloss log names the model of the predicted gloss (issue 20)
        title = str(app.query_one("#gloss-log", GlossLog).border_title)
        assert "predicted by G20 analytic-beckmann" in title, title
    with RunStore(tmp_path / "runs.sqlite", readonly=True) as s:
        runs = [s.get_run(r) for r in (1, 2)]
    assert {r.kind for r in runs} == {"brdf", "gloss"}
    for r in runs:
        assert (r.operator, r.sample_id, r.notes, r.tags) == ("ada", "LIMS-7", "2nd coat",
                                                              ("q3", "wet"))  # fmt: skip
