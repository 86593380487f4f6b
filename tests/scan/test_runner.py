"""The runner state machine on fake instruments and the sim clock (instant, no sleeps)."""

from __future__ import annotations

import asyncio
import math
import threading
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import pytest

from drivers.base import DeviceError, DeviceTimeout, Goniometer, ProtocolError, SpectroReading
from drivers.timing import SimClock
from goniolab.optics.apertures import Cone
from goniolab.scan.eta import WallTime
from goniolab.scan.events import (
    ArmsMoved,
    Event,
    EventBus,
    InstrumentError,
    PointMeasured,
    PointPredicted,
    Progress,
    RunFinished,
    RunState,
    StateChanged,
)
from goniolab.scan.plans import MIRROR_INDEX, BrdfPlan, parse_angles
from goniolab.scan.prediction import Predictor
from goniolab.scan.runner import ArmMotion, PlanRefused, ScanRunner, dry_run
from goniolab.scan.standards import Standard
from goniolab.store import RunStore
from sim.truth import luminance_weights

from .conftest import LOBE_AMPLITUDE_PCT, LOBE_SIGMA_DEG, FakeLab

MOTION = ArmMotion(20.0, 40.0, 20.0, 40.0)


def as_goniometer(lab: FakeLab) -> Goniometer:
    """The fake satisfies the Goniometer protocol structurally; its arms are FakeAxis
    instances (mutable protocol attributes are invariant for mypy)."""
    return cast(Goniometer, lab.goniometer)


def make_runner(
    lab: FakeLab, store: RunStore, plan: BrdfPlan, run_id: int | None = None, **kw: object
) -> tuple[ScanRunner, EventBus]:
    if run_id is None:
        run_id = store.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample=plan.sample,
                                  model={}, version="test")  # fmt: skip
    bus = EventBus()

    async def specimen(which: str) -> None:
        lab.spectro.specimen = which

    runner = ScanRunner(
        goniometer=as_goniometer(lab), spectro=lab.spectro, clock=lab.clock, plan=plan, store=store,
        run_id=run_id, bus=bus, motion=MOTION,
        predictor=Predictor(lab.model, Cone(6.0), Cone(6.0)),
        park_deg=lab.goniometer.park_deg,
        # the ETA measured on the instant lab clock: its seconds are the fake instruments'
        **{"specimen_hook": specimen, "wall": WallTime(lab.clock.now, 1.0), **kw},  # type: ignore[arg-type]
    )  # fmt: skip
    return runner, bus


async def drive(
    runner: ScanRunner, bus: EventBus, on_event: Callable[[Event], None]
) -> list[Event]:
    """Run while a subscriber reacts to each event as a UI would (commands, not awaits)."""
    q = bus.subscribe()
    seen: list[Event] = []

    async def consume() -> None:
        while True:
            ev = await q.get()
            if ev is None:
                return
            seen.append(ev)
            on_event(ev)
            if isinstance(ev, RunFinished):
                return

    task = asyncio.create_task(consume())
    await runner.run()
    await task
    return seen


def test_dry_run_eta_is_the_trapezoid_sum(fake_lab: FakeLab) -> None:
    plan = BrdfPlan(45.0, (0.0, 10.0, 20.0), repeats=2, dwell_s=0.5, exposure_us=10000)
    dr = dry_run(plan.points(), as_goniometer(fake_lab), MOTION, start_deg=(0.0, 0.0),
                 dwell_s=0.5, reading_time_s=0.01)  # fmt: skip
    # lamp 0->45 at v=20, a=40: 45/20 + 20/40 = 2.75 s (detector stays at 0);
    # detector 0->10 and 10->20: v^2/a = 10 deg, so 10/20 + 20/40 = 1.0 s each;
    # 3 dwells of 0.5 s; 6 readings of 0.01 s.
    assert dr.eta_s == pytest.approx(2.75 + 1.0 + 1.0 + 3 * 0.5 + 6 * 0.01, abs=1e-12)
    assert dr.n_moves == 3 and dr.n_readings == 6
    # a short, triangular move: 2 sqrt(d/a) for d < v^2/a
    dr2 = dry_run(BrdfPlan(45.0, (20.0, 22.5)).points(), as_goniometer(fake_lab), MOTION,
                  start_deg=(45.0, 20.0), dwell_s=0.0, reading_time_s=0.0)  # fmt: skip
    assert dr2.eta_s == pytest.approx(2 * (2.5 / 40.0) ** 0.5, abs=1e-12)


@pytest.mark.parametrize(
    ("angles", "bad", "why"),
    [
        ("-60:0:10", "point 1 (theta_i=45 deg, theta_r=-50 deg)", "separation 5 deg"),
        ("60,75", "point 1 (theta_i=45 deg, theta_r=75 deg)", "outside the limits"),
    ],
)
def test_unsafe_plan_is_refused_before_any_motion(
    fake_lab: FakeLab, store: RunStore, angles: str, bad: str, why: str
) -> None:
    plan = BrdfPlan(45.0, parse_angles(angles))
    runner, _ = make_runner(fake_lab, store, plan)
    with pytest.raises(PlanRefused) as exc:
        asyncio.run(runner.run())
    assert bad in str(exc.value) and why in str(exc.value)
    assert fake_lab.goniometer.moves == []
    assert fake_lab.spectro.n_reads == 0


async def test_full_run_stores_every_reading_and_matches_the_model(
    fake_lab: FakeLab, store: RunStore
) -> None:
    plan = BrdfPlan(45.0, parse_angles("35:55:1"), repeats=3, sample="sample:fake")
    runner, bus = make_runner(fake_lab, store, plan)
    events = await drive(runner, bus, lambda ev: None)
    assert runner.state is RunState.DONE
    assert store.count_points(runner.run_id) == 21 * 3
    assert store.get_run(runner.run_id).status == "done"
    assert fake_lab.goniometer.home_calls == 1  # not homed at start -> homed once
    assert fake_lab.goniometer.park_calls == 1
    assert (fake_lab.goniometer.lamp.pos_deg, fake_lab.goniometer.detector.pos_deg) == (45.0, 45.0)
    # one move per geometry plus the park move
    assert len(fake_lab.goniometer.moves) == 21 + 1
    # predictions computed in a worker thread, never on the loop's thread
    assert fake_lab.model.threads and threading.get_ident() not in fake_lab.model.threads
    assert fake_lab.model.calls[0][2] == Cone(6.0)
    assert len([e for e in events if isinstance(e, PointPredicted)]) == 21
    assert len([e for e in events if isinstance(e, PointMeasured)]) == 63
    s = runner_summary(events)
    # the fake spectro reads exactly the model's lobe: zero residual, same peak
    assert s["rmse_pct"] == pytest.approx(0.0, abs=1e-12)
    assert s["measured_peak"]["position_deg"] == pytest.approx(45.0, abs=1e-9)
    assert s["measured_peak"]["amplitude_pct"] == pytest.approx(LOBE_AMPLITUDE_PCT, rel=1e-12)
    # FWHM of a Gaussian: 2 sqrt(2 ln 2) sigma = 7.06 deg, from 1-deg samples (linear interp.)
    assert s["measured_peak"]["fwhm_deg"] == pytest.approx(2.3548 * LOBE_SIGMA_DEG, abs=0.1)
    assert s["hint"] is None and s["complete"] is True
    states = [e.state for e in events if isinstance(e, StateChanged)]
    assert states == [RunState.RUNNING, RunState.DONE]


def runner_summary(events: list[Event]) -> dict[str, Any]:
    fin = [e for e in events if isinstance(e, RunFinished)]
    assert len(fin) == 1
    return fin[0].summary


async def test_tilted_sample_gives_the_misalignment_hint(
    fake_lab: FakeLab, store: RunStore
) -> None:
    # a sample tilt tau = 1 deg rotates the mirror direction by 2 tau = 2 deg
    fake_lab.spectro.shift_deg = 2.0
    plan = BrdfPlan(45.0, parse_angles("30:60:1"))
    runner, bus = make_runner(fake_lab, store, plan)
    s = runner_summary(await drive(runner, bus, lambda ev: None))
    assert s["peak_offset_deg"] == pytest.approx(2.0, abs=0.05)
    assert "tilted by about 1.0" in str(s["hint"])
    assert "2.0" in str(s["hint"])
    assert s["rmse_pct"] > 1.0


async def test_pause_then_resume_removes_arms_moved_by_hand(
    fake_lab: FakeLab, store: RunStore
) -> None:
    plan = BrdfPlan(45.0, (40.0, 45.0, 50.0), repeats=3)
    runner, bus = make_runner(fake_lab, store, plan)
    gonio = fake_lab.goniometer

    def on_event(ev: Event) -> None:
        if isinstance(ev, PointMeasured) and (ev.index, ev.repeat) == (1, 0):
            runner.pause()
        if isinstance(ev, StateChanged) and ev.state is RunState.PAUSED:
            gonio.detector.pos_deg = 47.0  # someone nudged the detector arm while paused
            runner.resume()

    events = await drive(runner, bus, on_event)
    assert runner.state is RunState.DONE
    states = [e.state for e in events if isinstance(e, StateChanged)]
    assert states == [RunState.RUNNING, RunState.PAUSED, RunState.RUNNING, RunState.DONE]
    # 3 geometry moves + one re-move to (45, 45) after resume + park
    assert gonio.moves == [(45.0, 40.0), (45.0, 45.0), (45.0, 45.0), (45.0, 50.0), (45.0, 45.0)]
    # the readings after resume are at the planned geometry again: the lobe's peak value
    pts = {(p.index, p.repeat): p for p in store.points(runner.run_id)}
    assert pts[(1, 1)].luminance_pct == pytest.approx(LOBE_AMPLITUDE_PCT, rel=1e-12)
    assert pts[(1, 1)].measured_theta_r_deg == 45.0


async def test_resume_without_drift_does_not_move(fake_lab: FakeLab, store: RunStore) -> None:
    plan = BrdfPlan(45.0, (40.0, 45.0), repeats=2)
    runner, bus = make_runner(fake_lab, store, plan)

    def on_event(ev: Event) -> None:
        if isinstance(ev, PointMeasured) and (ev.index, ev.repeat) == (0, 0):
            runner.pause()
        if isinstance(ev, StateChanged) and ev.state is RunState.PAUSED:
            runner.resume()

    await drive(runner, bus, on_event)
    assert fake_lab.goniometer.moves == [(45.0, 40.0), (45.0, 45.0), (45.0, 45.0)]


async def test_abort_parks_and_a_second_runner_completes_exactly_once(
    fake_lab: FakeLab, store: RunStore
) -> None:
    plan = BrdfPlan(45.0, parse_angles("40:50:1"), repeats=2)
    runner, bus = make_runner(fake_lab, store, plan)

    def on_event(ev: Event) -> None:
        if isinstance(ev, PointMeasured) and (ev.index, ev.repeat) == (4, 1):
            runner.abort()

    events = await drive(runner, bus, on_event)
    assert runner.state is RunState.ABORTED
    assert store.get_run(runner.run_id).status == "aborted"
    # the subscriber sees events at its own pace: the abort lands between two readings
    # at most a few readings after (4, 1); every reading taken is stored
    n_stored = store.count_points(runner.run_id)
    assert n_stored == len([e for e in events if isinstance(e, PointMeasured)])
    assert 10 <= n_stored < 22
    assert fake_lab.goniometer.park_calls == 1
    assert runner_summary(events)["complete"] is False
    # continue the same run: only the missing readings are taken
    reads_before = fake_lab.spectro.n_reads
    runner2, bus2 = make_runner(fake_lab, store, plan, run_id=runner.run_id)
    await drive(runner2, bus2, lambda ev: None)
    assert runner2.state is RunState.DONE
    assert fake_lab.spectro.n_reads - reads_before == 22 - n_stored
    keys = [(p.index, p.repeat) for p in store.points(runner.run_id)]
    assert keys == [(i, r) for i in range(11) for r in range(2)]
    # predictions were already stored: not recomputed for the resumed run
    assert len(fake_lab.model.calls) == 2  # 11 geometries in chunks of 8


async def test_fault_mid_scan_parks_and_keeps_points(fake_lab: FakeLab, store: RunStore) -> None:
    fake_lab.goniometer.fail_on_move = 4  # the 4th geometry's move stalls
    plan = BrdfPlan(45.0, parse_angles("40:50:1"), repeats=2)
    runner, bus = make_runner(fake_lab, store, plan)
    events = await drive(runner, bus, lambda ev: None)
    assert runner.state is RunState.FAILED
    rec = store.get_run(runner.run_id)
    assert rec.status == "failed" and "excessive position deviation" in rec.reason
    assert "detector" in rec.reason
    assert store.count_points(runner.run_id) == 6  # geometries 0..2 kept
    assert fake_lab.goniometer.stop_calls == 1 and fake_lab.goniometer.park_calls == 1
    errs = [e for e in events if isinstance(e, InstrumentError)]
    assert errs and errs[0].fatal and errs[0].device == "detector"


async def test_failed_park_is_reported_not_raised(fake_lab: FakeLab, store: RunStore) -> None:
    gonio = fake_lab.goniometer

    async def broken_park(timeout_s: float) -> None:
        raise DeviceError("no answer", device="lamp")

    gonio.park = broken_park  # type: ignore[method-assign]
    plan = BrdfPlan(45.0, (44.0, 45.0, 46.0))
    runner, bus = make_runner(fake_lab, store, plan)
    await drive(runner, bus, lambda ev: None)
    assert runner.state is RunState.DONE
    assert "parking failed: lamp: no answer" in store.get_run(runner.run_id).reason


async def test_mirror_reference_sets_the_100_percent_level(
    fake_lab: FakeLab, store: RunStore
) -> None:
    plan = BrdfPlan(45.0, (44.0, 45.0, 46.0), repeats=2, mirror_reference=True)
    runner, bus = make_runner(fake_lab, store, plan)
    # a mirror certified flat at 90 %: the mirror reading (80 % of the instrument's own
    # reference) is 90 % of a perfect mirror (issue 21: it used to count as 100 %)
    runner.mirror_standard = Standard(
        "mirror", "TEST-1", "2026-01-01", "table", 0.01,
        wavelength_nm=(380.0, 780.0), reflectance_table=(0.9, 0.9),
    )  # fmt: skip
    await drive(runner, bus, lambda ev: None)
    pts = {(p.index, p.repeat): p for p in store.points(runner.run_id)}
    assert pts[(MIRROR_INDEX, 0)].luminance_pct == 80.0
    # sample reading = raw / mirror level (80 %) x certified 90 %, channel by channel
    assert pts[(1, 0)].luminance_pct == pytest.approx(LOBE_AMPLITUDE_PCT / 80.0 * 90.0, rel=1e-9)
    assert pts[(1, 0)].raw["luminance_pct"] == pytest.approx(LOBE_AMPLITUDE_PCT, rel=1e-12)
    assert pts[(1, 0)].raw["absolute_values"] == pytest.approx([LOBE_AMPLITUDE_PCT / 80 * 90] * 41)
    ref = pts[(1, 0)].raw["reference"]
    assert (ref["certificate"], ref["method"]) == ("TEST-1", "spectral")
    assert fake_lab.spectro.specimen == "sample"


async def test_homed_arms_are_not_rehomed(fake_lab: FakeLab, store: RunStore) -> None:
    fake_lab.goniometer.lamp.homed = fake_lab.goniometer.detector.homed = True
    runner, bus = make_runner(fake_lab, store, BrdfPlan(45.0, (44.0, 45.0, 46.0)))
    events = await drive(runner, bus, lambda ev: None)
    assert fake_lab.goniometer.home_calls == 0
    moved = [e for e in events if isinstance(e, ArmsMoved) and not e.moving]
    assert [(e.theta_i_deg, e.theta_r_deg) for e in moved] == [
        (45.0, 44.0),
        (45.0, 45.0),
        (45.0, 46.0),
    ]


async def test_eta_equals_the_time_the_run_takes_on_the_lab_clock(
    fake_lab: FakeLab, store: RunStore
) -> None:
    # homed arms at (0, 0): the run is moves + dwells + exposures, exactly what the dry run sums
    fake_lab.goniometer.lamp.homed = fake_lab.goniometer.detector.homed = True
    plan = BrdfPlan(45.0, parse_angles("10:40:5"), repeats=3, dwell_s=0.25, exposure_us=20000)
    runner, bus = make_runner(fake_lab, store, plan)
    events = await drive(runner, bus, lambda ev: None)
    progress = [e for e in events if isinstance(e, Progress)]
    # the whole run, up to the arms at park, is what the first estimate said
    assert progress[0].eta_s == pytest.approx(fake_lab.clock.now(), abs=1e-9)
    # after the last reading only the park move (45, 40) -> (45, 45) is left: 5 deg,
    # triangular at 40 deg/s^2, 2 sqrt(5 / 40) s
    assert progress[-1].eta_s == pytest.approx(2 * (5 / 40) ** 0.5, abs=1e-9)
    assert progress[-1].done == progress[-1].total == 21
    etas = [p.eta_s for p in progress]
    assert etas == sorted(etas, reverse=True)


async def test_cancelled_run_parks_and_is_marked_aborted(
    fake_lab: FakeLab, store: RunStore
) -> None:
    plan = BrdfPlan(45.0, parse_angles("30:60:1"), repeats=2)
    runner, bus = make_runner(fake_lab, store, plan)
    q = bus.subscribe()
    task = asyncio.create_task(runner.run())
    while True:  # wait, event by event, for the third reading
        ev = await q.get()
        if isinstance(ev, PointMeasured) and (ev.index, ev.repeat) == (1, 0):
            break
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    rec = store.get_run(runner.run_id)
    assert rec.status == "aborted" and rec.reason == "cancelled"
    assert fake_lab.goniometer.park_calls == 1
    assert 3 <= store.count_points(runner.run_id) < 62


async def test_eta_stretches_by_the_observed_slowdown(fake_lab: FakeLab, store: RunStore) -> None:
    g = fake_lab.goniometer
    g.lamp.homed = g.detector.homed = True
    g.lamp.pos_deg, g.detector.pos_deg = 45.0, 45.0  # already at the only geometry: no move
    fake_lab.spectro.overhead_s = 0.03  # each reading really takes 0.01 + 0.03 s
    plan = BrdfPlan(45.0, (45.0,), repeats=4, exposure_us=10000)
    runner, bus = make_runner(fake_lab, store, plan, reading_time_s=0.01)
    events = await drive(runner, bus, lambda ev: None)
    etas = [e.eta_s for e in events if isinstance(e, Progress)]
    # before any reading: the plain estimate 4 x 0.01 s; then the remaining readings at
    # the observed 0.04 s each: 3 x 0.04, 2 x 0.04, 1 x 0.04, 0
    assert etas == pytest.approx([0.04, 0.12, 0.08, 0.04, 0.0], abs=1e-9)


async def test_a_pause_leaves_the_runs_eta_unchanged(fake_lab: FakeLab, store: RunStore) -> None:
    """issue 27: the ETA doubled after a pause. A run paused for 100 s of the (ETA's) clock
    after every reading from its second on reports, reading by reading, the ETAs of the
    same run unpaused, on a slow spectro (0.03 s beyond each exposure) that the ETA has to
    learn."""
    from .conftest import FakeGoniometer, FakeSpectro

    def lab() -> FakeLab:
        clock = SimClock(0)
        gonio = FakeGoniometer(clock)
        gonio.lamp.homed = gonio.detector.homed = True
        spectro = FakeSpectro(gonio, clock)
        spectro.overhead_s = 0.03
        return FakeLab(clock=clock, goniometer=gonio, spectro=spectro, model=fake_lab.model)

    plan = BrdfPlan(45.0, parse_angles("30:60:5"), dwell_s=0.25)

    async def etas(paused_s: float) -> list[float]:
        the_lab = lab()
        runner, bus = make_runner(the_lab, store, plan)
        waits: list[asyncio.Task[None]] = []

        async def hold() -> None:
            await the_lab.clock.sleep(paused_s)
            runner.resume()

        def on_event(ev: Event) -> None:
            if paused_s and isinstance(ev, PointMeasured) and ev.index >= 1:
                runner.pause()
            if isinstance(ev, StateChanged) and ev.state is RunState.PAUSED:
                waits.append(asyncio.create_task(hold()))

        events = await drive(runner, bus, on_event)
        assert runner.state is RunState.DONE and (bool(waits) == bool(paused_s))
        return [e.eta_s for e in events if isinstance(e, Progress)]

    plain, paused = await etas(0.0), await etas(100.0)
    assert paused == pytest.approx(plain, abs=1e-9)
    assert plain[2] > plain[-2] > 0.0  # and it counts down


async def test_at_an_instant_clock_the_eta_is_the_readings_computing(
    fake_lab: FakeLab, store: RunStore
) -> None:
    """issue 27: at --time-scale 0 the lab's sleeps take no wall time, and the ETA read
    "0 s" through the 15-20 s of the twin's computing. Here each reading computes 0.4 s of
    wall time (a fake wall clock), everything else none: the ETA is "?" (NaN) before two
    readings were timed, then 0.4 s per reading left."""
    g = fake_lab.goniometer
    g.lamp.homed = g.detector.homed = True
    wall = [0.0]
    measure = fake_lab.spectro.measure

    async def computing_measure() -> SpectroReading:
        wall[0] += 0.4
        return await measure()

    fake_lab.spectro.measure = computing_measure  # type: ignore[method-assign]
    plan = BrdfPlan(45.0, parse_angles("10:40:10"), repeats=2, dwell_s=0.5)
    runner, bus = make_runner(fake_lab, store, plan, wall=WallTime(lambda: wall[0], 0.0))
    events = await drive(runner, bus, lambda ev: None)
    etas = [e.eta_s for e in events if isinstance(e, Progress)]
    assert math.isnan(etas[0]) and math.isnan(etas[1])  # "?" until two readings were timed
    assert etas[2:] == pytest.approx([0.4 * (7 - k) for k in range(1, 8)], abs=1e-9)


async def test_unexpected_error_parks_marks_failed_and_surfaces(
    fake_lab: FakeLab, store: RunStore
) -> None:
    async def bad_exposure(exposure_us: int) -> None:
        raise ValueError("spectro: exposure 10000 us outside [500, 5000] us")

    fake_lab.spectro.set_exposure_us = bad_exposure  # type: ignore[method-assign]
    runner, _ = make_runner(fake_lab, store, BrdfPlan(45.0, (44.0, 45.0, 46.0)))
    with pytest.raises(ValueError, match="outside"):
        await runner.run()
    rec = store.get_run(runner.run_id)
    assert rec.status == "failed" and "internal error" in rec.reason
    assert fake_lab.goniometer.park_calls == 1


async def test_abort_during_a_move_stops_the_arms_and_takes_no_reading(
    fake_lab: FakeLab, store: RunStore
) -> None:
    g = fake_lab.goniometer
    g.lamp.homed = g.detector.homed = True  # arms homed at (0, 0)
    runner, bus = make_runner(fake_lab, store, BrdfPlan(45.0, parse_angles("30:60:1")))

    def abort_on_first_move(ev: Event) -> None:
        if isinstance(ev, ArmsMoved) and ev.moving:
            runner.abort()

    events = await drive(runner, bus, abort_on_first_move)
    fin = next(e for e in events if isinstance(e, RunFinished))
    assert fin.state is RunState.ABORTED and "during a move" in fin.reason
    assert store.count_points(runner.run_id) == 0 and fake_lab.spectro.n_reads == 0
    assert g.stop_calls >= 1 and g.park_calls == 1
    # the move to (45, 30) never ran: the lab clock shows only the park move from (0, 0),
    # the trapezoid 45 deg at 20 deg/s, 40 deg/s^2: 45/20 + 20/40 = 2.75 s
    assert fake_lab.clock.now() == pytest.approx(2.75, abs=1e-12)
    assert store.get_run(runner.run_id).status == "aborted"


async def test_resume_after_a_crash_in_the_mirror_phase_puts_the_sample_back(
    fake_lab: FakeLab, store: RunStore
) -> None:
    plan = BrdfPlan(45.0, (44.0, 45.0, 46.0), repeats=2, mirror_reference=True)
    rid = store.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample="", model={},
                           version="test")  # fmt: skip
    for r in range(2):  # a process stored both mirror readings, then died: mirror still in place
        store.add_point(rid, index=MIRROR_INDEX, repeat=r, theta_i_deg=45.0, theta_r_deg=45.0,
                        measured_theta_i_deg=45.0, measured_theta_r_deg=45.0, luminance_pct=80.0,
                        raw={"luminance_pct": 80.0}, timestamp=0.0)  # fmt: skip
    fake_lab.spectro.specimen = "mirror"
    runner, bus = make_runner(fake_lab, store, plan, run_id=rid)
    await drive(runner, bus, lambda ev: None)
    pts = {(p.index, p.repeat): p for p in store.points(rid)}
    assert len(pts) == 8
    # the sample's lobe at 45 deg, relative to the stored mirror level 80 %, times the
    # certified mirror's luminance (these stored mirror readings carry no spectrum: the
    # scalar fallback, said in the reading's provenance)
    cert = runner.mirror_standard
    assert cert is not None and cert.certificate == "SIM-MIR-0001"  # the shipped file
    r = 0.88 + 0.04 * (np.arange(380.0, 781.0, 10.0) - 380.0) / 400.0
    y_cert = 100 * float(np.dot(luminance_weights(), r))
    assert pts[(1, 1)].luminance_pct == pytest.approx(LOBE_AMPLITUDE_PCT / 80.0 * y_cert, rel=1e-4)
    assert pts[(1, 1)].raw["reference"]["method"].startswith("scalar (the reference readings")
    assert fake_lab.spectro.specimen == "sample"


async def test_abort_while_waiting_for_the_operator_to_place_the_mirror(
    fake_lab: FakeLab, store: RunStore
) -> None:
    plan = BrdfPlan(45.0, (44.0, 45.0, 46.0), mirror_reference=True)
    never = asyncio.Event()
    asked: list[str] = []

    async def operator_away(which: str) -> None:
        asked.append(which)
        asyncio.get_running_loop().call_soon(runner.abort)  # Ctrl-C during the prompt
        await never.wait()

    runner, bus = make_runner(fake_lab, store, plan, specimen_hook=operator_away)
    seen = await drive(runner, bus, lambda ev: None)
    fin = next(e for e in seen if isinstance(e, RunFinished))
    assert asked == ["mirror"]
    assert fin.state is RunState.ABORTED and fin.reason.endswith("while placing the mirror")
    assert fake_lab.spectro.n_reads == 0 and store.count_points(runner.run_id) == 0
    assert fake_lab.goniometer.park_calls == 1


async def test_abort_during_homing_stops_and_does_not_park(
    fake_lab: FakeLab, store: RunStore
) -> None:
    g = fake_lab.goniometer

    async def slow_home(timeout_s: float) -> None:  # a 30 s home search
        g.home_calls += 1
        await fake_lab.clock.sleep(30.0)
        g.lamp.homed = g.detector.homed = True

    g.home = slow_home  # type: ignore[method-assign]
    runner, bus = make_runner(fake_lab, store, BrdfPlan(45.0, (44.0, 45.0, 46.0)))
    seen = await drive(runner, bus, lambda ev: runner.abort() if isinstance(ev, Progress) else None)
    fin = next(e for e in seen if isinstance(e, RunFinished))
    assert fin.state is RunState.ABORTED and "during homing" in fin.reason
    assert "not parked" in fin.reason  # unreferenced arms are only stopped
    assert g.home_calls == 1 and g.stop_calls >= 1 and g.park_calls == 0 and g.moves == []
    assert fake_lab.clock.now() == 0.0 and fake_lab.spectro.n_reads == 0


class _FlakySpectro:
    """Wraps the fake spectro: the listed measure() calls (1-based) fail with ``exc``."""

    def __init__(self, inner: Any, failing_calls: set[int], exc: Exception) -> None:
        self.inner = inner
        self.name = inner.name
        self.failing_calls = failing_calls
        self.exc = exc
        self.calls = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    async def measure(self) -> Any:
        self.calls += 1
        if self.calls in self.failing_calls:
            raise self.exc
        return await self.inner.measure()


async def test_transient_reading_faults_are_retried_and_reported(
    fake_lab: FakeLab, store: RunStore
) -> None:
    # calls 2 and 3 (the second reading, twice) and call 5 (the third reading) time out
    flaky = _FlakySpectro(fake_lab.spectro, {2, 3, 5}, DeviceTimeout("no reply", device="spectro"))
    fake_lab.spectro = flaky  # type: ignore[assignment]
    plan = BrdfPlan(45.0, parse_angles("44:46:1"), repeats=1)
    runner, bus = make_runner(fake_lab, store, plan, reading_retries=2)
    events = await drive(runner, bus, lambda ev: None)
    assert runner.state is RunState.DONE
    assert store.count_points(runner.run_id) == 3  # every reading stored once
    assert flaky.calls == 6  # 3 readings + 3 retries
    warnings = [e for e in events if isinstance(e, InstrumentError)]
    assert [e.fatal for e in warnings] == [False, False, False]
    assert "retry 1 of 2" in warnings[0].message and "retry 2 of 2" in warnings[1].message


async def test_a_reading_that_keeps_failing_fails_the_run(
    fake_lab: FakeLab, store: RunStore
) -> None:
    flaky = _FlakySpectro(fake_lab.spectro, {2, 3, 4}, ProtocolError("garbled", device="spectro"))
    fake_lab.spectro = flaky  # type: ignore[assignment]
    plan = BrdfPlan(45.0, parse_angles("44:46:1"), repeats=1)
    runner, bus = make_runner(fake_lab, store, plan, reading_retries=2)
    events = await drive(runner, bus, lambda ev: None)
    assert runner.state is RunState.FAILED
    assert store.count_points(runner.run_id) == 1  # the first reading is kept
    assert "garbled" in store.get_run(runner.run_id).reason
    assert [e.fatal for e in events if isinstance(e, InstrumentError)] == [False, False, True]
