"""The scan runner: a state machine that moves the arms, reads the detector and stores each point.

States (:class:`~goniolab.scan.events.RunState`)::

    idle --start--> running --pause--> paused --resume--> running --> done
                       |                  |
                       +--abort-----------+--> aborted   (arms parked)
                       +--DeviceError--------> failed    (arms parked, reason kept)

Pause, resume and abort are commands (plain method calls, safe from any task on the loop).
Pause is honoured *between* readings; abort also interrupts a move (the arms are stopped
where they are, then parked), homing (the arms are only stopped: unreferenced) and a wait
for the operator to swap the specimen, but never a reading: a reading in progress is
completed and stored. Resume re-reads the arm positions and re-moves them when they
drifted or were moved by hand while paused. A fault (any :class:`drivers.base.DeviceError`)
stops the arms, parks them (best effort) and marks the run ``failed`` with the reason; every
reading measured before the fault stays in the store.

Every reading is committed to the store *before* the next one is taken (no buffering), and
readings are keyed by (plan index, repeat) with a UNIQUE constraint, so
:meth:`ScanRunner.run` on an interrupted run (also after the process was killed) measures
exactly the missing readings.

The runner publishes events on an :class:`~goniolab.scan.events.EventBus`
(``publish`` never waits on a subscriber) and never imports a UI.

Before any motion, :func:`~goniolab.scan.dryrun.dry_run` checks every geometry and estimates
the run time. This module holds the state machine, the run loop, the storing of each reading
(through a store outage) and the end of a run (park, summary, record); the rest lives in one
room each: the dry run in :mod:`goniolab.scan.dryrun`, the time left (from the measured
rates of moves, dwells and readings) in :mod:`goniolab.scan.eta`, the arm moves and the
retries through transient faults in :mod:`goniolab.scan.moves`, the reading path (spectro
read, mirror reference, colour) in :mod:`goniolab.scan.spectro_readings`.

One runner at a time measures a run: :meth:`ScanRunner.run` holds
:meth:`goniolab.store.RunStore.claim_run` (a lock the kernel drops when the process dies).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from drivers.base import DeviceError, Goniometer, Spectrocolorimeter
from drivers.timing import Clock
from goniolab.scan.alarm import failure_reason
from goniolab.scan.colour import PointColour
from goniolab.scan.dryrun import (
    ArmMotion,
    DryRun,
    PlanRefused,
    dry_run,
    reachable_range,
)
from goniolab.scan.eta import EtaEstimator, PointParts, WallTime
from goniolab.scan.events import (
    ColourPredicted,
    EventBus,
    InstrumentError,
    PointMeasured,
    PointPredicted,
    Progress,
    RecordingBus,
    RunFinished,
    RunStarted,
    RunState,
    StateChanged,
    WarningLog,
)
from goniolab.scan.exposure import EXCLUDED_QUALITY, AutoExposure, reading_quality
from goniolab.scan.moves import Aborted, describe_error
from goniolab.scan.plans import MIRROR_INDEX, BrdfPlan, PlanPoint
from goniolab.scan.prediction import Predictor
from goniolab.scan.reference import SpectralReference
from goniolab.scan.spectro_readings import SpectroReadings
from goniolab.scan.standards import Standard
from goniolab.scan.summary import summarize_brdf
from goniolab.store import RunStore, StoreError, StoreUnavailable

__all__ = [
    "ArmMotion",
    "DryRun",
    "PlanRefused",
    "RunResult",
    "ScanRunner",
    "dry_run",
    "notice_event",
    "reachable_range",
]

#: Called with "mirror" before the mirror reference readings and "sample" after them;
#: returns once the operator (or the simulated lab) has swapped the specimen.
SpecimenHook = Callable[[str], Awaitable[None]]


@dataclass(slots=True)
class RunResult:
    """What a finished :meth:`ScanRunner.run` returns (also published as RunFinished)."""

    run_id: int
    state: RunState
    reason: str
    summary: dict[str, Any] = field(default_factory=dict)


def notice_event(run_id: int, note: str) -> InstrumentError:
    """A notice a run starts with, as a warning of the device it concerns: the prediction's
    notes (``"prediction: ..."``, :meth:`goniolab.session.ScanSession.start`) are the
    model's, the others the calibration's (:func:`goniolab.scan.calibration.
    calibration_notices`)."""
    head, sep, text = note.partition(": ")
    if sep and head == "prediction":
        return InstrumentError(run_id=run_id, device="model", message=text, fatal=False)
    return InstrumentError(run_id=run_id, device="calibration", message=note, fatal=False)


class ScanRunner(SpectroReadings):
    """Run (or continue) one stored BRDF scan.

    Parameters
    ----------
    goniometer, spectro, clock
        The lab's instruments and clock (``lab.goniometer``, ``lab.spectro``, ``lab.clock``).
    plan
        The plan; its readings already in the store for ``run_id`` are skipped.
    store, run_id
        The run store and the id of the run (created by the caller with the plan).
    bus
        Where events are published.
    motion
        Arm speeds/accelerations for the ETA.
    predictor
        Model predictions for each geometry (``None``: no comparison).
    move_timeout_s, home_timeout_s
        Timeouts of one move and of homing (also used for parking).
    park_deg
        Park geometry (theta_i, theta_r) after the run, an abort or a fault.
    reading_time_s
        Duration of one reading for the ETA's prior (default: the exposure time).
    wall
        The clock the ETA is measured on (default: wall time against ``clock``'s scale,
        :meth:`goniolab.scan.eta.WallTime.of`); the ETA starts from the motion model and
        follows the measured rates of moves, dwells and readings
        (:class:`goniolab.scan.eta.EtaEstimator`).
    position_tolerance_deg
        After a resume, arms further than this from the current target are re-moved.
    specimen_hook
        Swaps mirror and sample for the mirror reference (``None`` when the plan has none).
    misalignment_threshold_deg
        Peak offset above which the summary carries a misalignment hint.
    reading_retries
        A reading that times out, comes back garbled or loses the link
        (:class:`drivers.base.DeviceTimeout`, :class:`drivers.base.ProtocolError`,
        :class:`drivers.base.Disconnected`: the port is reopened first) is taken again up
        to this many times, each retry reported as a non-fatal
        :class:`~goniolab.scan.events.InstrumentError`; an alarm or the last failed retry
        fails the run.
    move_retries
        A move that times out, gets a garbled frame or loses an arm's link is made again
        (from where the stopped arms stand, links reopened first after a loss) up to this
        many times, each retry reported as a non-fatal ``InstrumentError``.
    reconnect_backoff_s
        Lab-clock wait before reopening a lost spectro or arm link (doubles with each
        attempt, at most 2 s).
    reconnect_window_s
        A lost link (:class:`drivers.base.Disconnected`: a controller or sim server
        restarting) is reopened again and again, the scan waiting and saying so, for up to
        this many lab-clock seconds since it was lost (a restart takes 7-20 s); the
        operation then continues where it was (the reading or move not yet stored is taken
        again: no point lost or repeated). Losses do not count against the retries.
    """

    def __init__(
        self,
        *,
        goniometer: Goniometer,
        spectro: Spectrocolorimeter,
        clock: Clock,
        plan: BrdfPlan,
        store: RunStore,
        run_id: int,
        bus: EventBus,
        motion: ArmMotion,
        predictor: Predictor | None = None,
        move_timeout_s: float = 30.0,
        home_timeout_s: float = 120.0,
        park_deg: tuple[float, float] | None = None,
        reading_time_s: float | None = None,
        position_tolerance_deg: float = 0.05,
        specimen_hook: SpecimenHook | None = None,
        misalignment_threshold_deg: float = 0.5,
        reading_retries: int = 2,
        move_retries: int = 2,
        reconnect_backoff_s: float = 0.5,
        point_colour: PointColour | None = None,
        store_outage_s: float = 600.0,
        mirror_standard: Standard | None = None,
        reconnect_window_s: float = 30.0,
        notices: Sequence[str] = (),
        wall: WallTime | None = None,
    ) -> None:
        if reading_retries < 0:
            raise ValueError(f"reading_retries must be >= 0, got {reading_retries}")
        if move_retries < 0:
            raise ValueError(f"move_retries must be >= 0, got {move_retries}")
        self.goniometer = goniometer
        self.spectro = spectro
        self.clock = clock
        self.plan = plan
        self.store = store
        self.run_id = run_id
        #: the run's warnings as they are published (stored with the run, in its summary)
        self.warnings = WarningLog(run_id)
        self.bus: EventBus = RecordingBus(bus, self.warnings)
        self.motion = motion
        self.predictor = predictor
        self.move_timeout_s = move_timeout_s
        self.home_timeout_s = home_timeout_s
        self.park_deg = park_deg
        self.reading_time_s = plan.exposure_us * 1e-6 if reading_time_s is None else reading_time_s
        self.wall = WallTime.of(clock) if wall is None else wall
        self.position_tolerance_deg = position_tolerance_deg
        self.specimen_hook = specimen_hook
        self.misalignment_threshold_deg = misalignment_threshold_deg
        self.reading_retries = reading_retries
        self.move_retries = move_retries
        self.reconnect_backoff_s = reconnect_backoff_s
        #: how long a run waits, paused with the arms parked, for a store that cannot take
        #: a reading (a database down, a full disk) before it fails
        self.store_outage_s = store_outage_s
        if not (math.isfinite(reconnect_window_s) and reconnect_window_s >= 0):
            raise ValueError(f"reconnect_window_s must be >= 0, got {reconnect_window_s}")
        self.reconnect_window_s = reconnect_window_s
        #: warnings published (non-fatal) when the run starts: the calibration's age, a
        #: missed check standard (:func:`goniolab.scan.calibration.calibration_notices`)
        self.notices = tuple(notices)
        self.point_colour = point_colour if point_colour is not None else PointColour()
        if plan.mirror_reference and mirror_standard is None:
            from goniolab.scan.standards import load_standards, standards_path

            # the shipped certificate; its file is cited in every reading it references
            mirror_standard = load_standards(standards_path("")).get("mirror")
        #: the certified mirror the reference readings are divided by (docs/CALIBRATION.md)
        self.mirror_standard = mirror_standard
        self._reference: SpectralReference | None = None
        #: the last colour took under INLINE_COLOUR_S: compute the next on the loop
        self._colour_inline = False
        if plan.mirror_reference and specimen_hook is None:
            raise ValueError("a plan with a mirror reference needs a specimen_hook")
        self._state = RunState.IDLE
        self._pause_requested = False
        self._abort_requested = False
        self._abort_by = ""
        #: the run's ETA while its readings are taken (pauses are left out of its pace)
        self._eta: EtaEstimator | None = None
        self._wake = asyncio.Event()
        self._abort_event = asyncio.Event()
        self._homing_interrupted = False
        self._verify_position = False
        self._predicted: dict[int, float] = {}
        self._specimen: str | None = None  # what lies under the instruments (None: unknown)
        self._mirror_pct: float | None = None
        self._n_done = 0
        self._total = 0
        self._target: tuple[float, float] | None = None
        self._measured_deg: tuple[float, float] = (math.nan, math.nan)
        self._auto = AutoExposure()
        self._exposure_us = plan.exposure_us

    # ------------------------------------------------------------------ commands
    @property
    def state(self) -> RunState:
        """The current state."""
        return self._state

    def pause(self) -> None:
        """Ask the run to pause after the current reading."""
        if self._state in (RunState.IDLE, RunState.RUNNING):
            self._pause_requested = True

    def resume(self) -> None:
        """Continue a paused run (arm positions are re-checked before the next reading)."""
        self._pause_requested = False
        self._wake.set()

    def abort(self, by: str = "") -> None:
        """Stop the run: a move in progress is interrupted (the arms are stopped where they
        are), a reading in progress is completed and stored; then the arms are parked and
        the run is marked ``aborted``. ``by`` says who asked when it was not the operator
        (``"SIGTERM"``); it goes into the stored reason."""
        if by and not self._abort_requested:
            self._abort_by = by
        self._abort_requested = True
        self._abort_event.set()
        self._wake.set()

    # ------------------------------------------------------------------ helpers
    def _set_state(self, state: RunState, reason: str = "") -> None:
        self._state = state
        try:
            self.store.set_status(self.run_id, state.value, reason)
        except StoreError as exc:  # the store is down: say so, the run's own state holds
            self.bus.publish(InstrumentError.state_not_recorded(self.run_id, state, exc))
        self.bus.publish(StateChanged(run_id=self.run_id, state=state, reason=reason))

    async def _checkpoint(self) -> bool:
        """Honour pause/abort between readings; ``False`` means stop."""
        if self._abort_requested:
            return False
        if self._pause_requested:
            self._set_state(RunState.PAUSED)
            if self._eta is not None:
                self._eta.pause()
            while self._pause_requested and not self._abort_requested:
                self._wake.clear()
                await self._wake.wait()
            if self._eta is not None:
                self._eta.resume()
            if self._abort_requested:
                return False
            self._set_state(RunState.RUNNING)
            self._verify_position = True
        return True

    async def _predict_all(self) -> None:
        """Predict every geometry not yet predicted, chunk by chunk, in worker threads."""
        if self.predictor is None:
            return
        self._predicted.update(self.store.predictions(self.run_id))
        todo = [i for i in range(self.plan.n_geometries) if i not in self._predicted]
        ti = self.plan.theta_i_deg
        for start in range(0, len(todo), self.predictor.chunk):
            idx = todo[start : start + self.predictor.chunk]
            trs = [self.plan.theta_r_deg[i] for i in idx]
            values = await self.predictor.predict(ti, trs)
            rows = [(i, ti, tr, float(v)) for i, tr, v in zip(idx, trs, values, strict=True)]
            self.store.add_predictions(self.run_id, rows)
            for i, _, tr, v in rows:
                self._predicted[i] = v
                self.bus.publish(
                    PointPredicted(
                        run_id=self.run_id, index=i, theta_i_deg=ti, theta_r_deg=tr, predicted_pct=v
                    )
                )

    async def _predict_colours(self, after: asyncio.Task[None]) -> None:
        """Predict the colour (spectrum and L*a*b*) of every geometry that has none yet.

        Runs beside the luminance predictions; a run that ends done waits for it, a failed or
        aborted one drops it (``scan resume`` predicts the rest).
        """
        if self.predictor is None or self.predictor.spectral is None:
            return
        try:
            await asyncio.shield(after)  # the rows the colours are stored in
        except Exception:
            return  # the luminance prediction failed; the runner reports that
        have = set(self.store.predicted_colours(self.run_id))
        todo = [i for i in range(self.plan.n_geometries) if i not in have]
        ti = self.plan.theta_i_deg
        for start in range(0, len(todo), self.predictor.chunk):
            idx = todo[start : start + self.predictor.chunk]
            trs = [self.plan.theta_r_deg[i] for i in idx]
            colours = await self.predictor.predict_colour(ti, trs)
            if colours is None:
                return
            self.store.add_predicted_colours(self.run_id, list(zip(idx, colours, strict=True)))
            for i, tr, c in zip(idx, trs, colours, strict=True):
                self.bus.publish(
                    ColourPredicted(
                        run_id=self.run_id, index=i, theta_r_deg=tr, lab=(c.L, c.a, c.b)
                    )
                )

    # ------------------------------------------------------------------ run
    async def run(self) -> RunResult:
        """Take every reading of the plan not yet in the store; return the final state.

        Raises
        ------
        PlanRefused
            From the dry run, before any motion (the run stays resumable).
        goniolab.store.RunBusy
            Another runner holds the run (:meth:`RunStore.claim_run`); nothing moved.
        """
        with self.store.claim_run(self.run_id):
            return await self._run()

    async def _run(self) -> RunResult:
        all_points = self.plan.points()
        done = self.store.done_keys(self.run_id)
        todo = [p for p in all_points if p.key not in done]
        eta = await self._dry_run(todo)
        self._n_done, self._total = len(all_points) - len(todo), len(all_points)
        self.bus.publish(
            RunStarted(
                run_id=self.run_id,
                kind="brdf",
                total_points=self._total,
                plan=self.plan.to_dict(),
                sample=self.plan.sample,
            )
        )
        for note in self.notices:
            self.bus.publish(notice_event(self.run_id, note))
        self._set_state(RunState.RUNNING)
        self._publish_progress(eta.total_s)
        predict_task = asyncio.create_task(self._predict_all(), name=f"predict-run-{self.run_id}")
        colour_task = asyncio.create_task(
            self._predict_colours(predict_task), name=f"predict-colour-run-{self.run_id}"
        )
        # What lies under the instruments: the sample at the start of a new run; unknown
        # when a mirror-referenced run resumes (a crash may have left the mirror in
        # place), so the hook confirms the specimen before the first reading.
        self._specimen = "sample" if not (self.plan.mirror_reference and done) else None
        try:
            state, reason = await self._measure(todo, eta)
        except StoreError as exc:  # the store stayed unavailable, or refused a write
            state, reason = RunState.FAILED, f"store: {exc}"
            self.bus.publish(
                InstrumentError(run_id=self.run_id, device="store", message=str(exc), fatal=True)
            )
        except DeviceError as exc:
            state, reason = RunState.FAILED, failure_reason(exc)  # with a latched alarm's cure
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id, device=exc.device, message=exc.message, fatal=True
                )
            )
        except asyncio.CancelledError:
            # Cancelled from outside (the process is shutting down): park, record, re-raise.
            predict_task.cancel()
            colour_task.cancel()
            why = f"aborted by {self._abort_by}, quit at once" if self._abort_by else "cancelled"
            await asyncio.shield(self._park_and_record(RunState.ABORTED, why))
            raise
        except Exception as exc:
            # Not an instrument fault (a bug, a full disk): still leave the arms parked (or
            # say they are not) and the run failed and resumable, then let the error surface.
            predict_task.cancel()
            colour_task.cancel()
            why = await self._park_and_record(
                RunState.FAILED, f"internal error: {describe_error(exc)}"
            )
            self.bus.publish(
                RunFinished(run_id=self.run_id, state=RunState.FAILED, reason=why, summary={})
            )
            raise
        finish = asyncio.ensure_future(self._finish(state, reason, predict_task, colour_task))
        try:
            return await asyncio.shield(finish)
        except asyncio.CancelledError:
            # quit at once while the run ends (a second Ctrl-C, SIGTERM during the park):
            # the predictions are dropped, the park and the run's record are awaited
            predict_task.cancel()
            colour_task.cancel()
            with contextlib.suppress(Exception, asyncio.CancelledError):
                await finish
            raise

    async def _dry_run(self, todo: Sequence[PlanPoint]) -> EtaEstimator:
        """:func:`dry_run` of ``todo`` from where the arms stand (raises PlanRefused); its
        parts are the priors of the run's ETA."""
        start_deg = await self._arm_positions("reading the arm positions")
        check = dry_run(
            todo,
            self.goniometer,
            self.motion,
            start_deg=(float(start_deg[0]), float(start_deg[1])),
            dwell_s=self.plan.dwell_s,
            reading_time_s=self.reading_time_s,
            park_deg=self.park_deg,
        )
        park_x = None if self.park_deg is None else check.park_s
        return EtaEstimator(check.parts, park_x, self.wall)

    async def _measure(self, todo: Sequence[PlanPoint], eta: EtaEstimator) -> tuple[RunState, str]:
        """Home if needed, then take the readings of ``todo`` in order, each stored before
        the next; an abort ends the loop with its reason. A DeviceError propagates."""
        try:
            try:
                await self._abortable(self._ensure_homed(), "during homing")
            except Aborted:
                self._homing_interrupted = True
                raise
            await self._retry(
                "setting the exposure",
                lambda: self.spectro.set_exposure_us(self.plan.exposure_us),
                self._reconnect_spectro,
                self.reading_retries,
                "spectro",
            )
            self._mirror_pct = self._mirror_level()
            self._reference = self._load_reference()
            self._eta = eta
            eta.begin_point()
            for k, p in enumerate(todo):
                await self._go_to(p, eta, eta.points[k])
                with eta.part("reading", eta.points[k].reading_lab_s):
                    await self._take_reading(p)
                self._publish_progress(eta.end_point(k))
            state, reason = RunState.DONE, ""
        except Aborted as stop:
            state, reason = RunState.ABORTED, stop.reason
            if self._abort_by:
                reason = reason.replace("by the operator", f"by {self._abort_by}", 1)
        if self._specimen == "mirror":
            assert self.specimen_hook is not None
            await self.specimen_hook("sample")
        return state, reason

    async def _go_to(self, p: PlanPoint, eta: EtaEstimator, parts: PointParts) -> None:
        """Everything before reading ``p``: honour a pause or an abort, put the specimen
        ``p`` needs under the instruments, move the arms there and let them settle (the
        move and the dwell timed for the ETA, ``parts`` their model sizes; the specimen
        swap is an operator's time, left out of it).

        Raises
        ------
        Aborted
            With the reason, when an abort arrives (a move is stopped where it is).
        """
        if not await self._checkpoint():
            raise Aborted("")
        want = "mirror" if p.index == MIRROR_INDEX else "sample"
        if want != self._specimen:
            assert self.specimen_hook is not None
            eta.pause()
            try:
                await self._abortable(self.specimen_hook(want), f"while placing the {want}")
            finally:
                eta.resume()
            self._specimen = want
        target = (p.theta_i_deg, p.theta_r_deg)
        move_x = parts.move_x
        if move_x is None:  # a move the dry run did not plan (the arms were moved meanwhile)
            move_x = 0.0 if self._target is None else self.motion.move_time_s(self._target, target)
        mark = eta.start_part()
        if await self._ensure_position(target):
            eta.finish_part("move", move_x, mark)
            mark = eta.start_part()
            await self.clock.sleep(self.plan.dwell_s)
            eta.finish_part("dwell", self.plan.dwell_s, mark)

    async def _take_reading(self, p: PlanPoint) -> None:
        """Read ``p`` (with retries), scale it by the mirror level, store it, publish it."""
        reading = await self._read_spectro(p)
        raw_pct = float(reading.luminance_pct)
        value, absolute, reference = self._referenced(reading, p)
        quality = reading_quality(reading)
        if quality in EXCLUDED_QUALITY:
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="spectro",
                    message=f"point {p.index}, repeat {p.repeat} (theta_r {p.theta_r_deg:g} "
                    f"deg): reading {quality.replace('_', ' ')} at {reading.exposure_us} us "
                    "(stored, flagged, left out of averages and fits"
                    + ("" if self.plan.auto_exposure else "; --auto-exposure adapts the exposure")
                    + ")",
                    fatal=False,
                )
            )
        colour, colour_error = await self._colour_of(reading, p, absolute)
        ts = time.time()
        await self._store_reading(p, lambda: self.store.add_point(
            self.run_id,
            index=p.index,
            repeat=p.repeat,
            theta_i_deg=p.theta_i_deg,
            theta_r_deg=p.theta_r_deg,
            measured_theta_i_deg=self._measured_deg[0],
            measured_theta_r_deg=self._measured_deg[1],
            luminance_pct=value,
            raw={
                "luminance_pct": raw_pct,
                "exposure_us": reading.exposure_us,
                "wavelengths_nm": list(reading.wavelengths_nm),
                "values": list(reading.values),
                "mirror_pct": self._mirror_pct,
                "peak_fraction": reading.peak_fraction,
                "quality": quality,
                "clock_s": self.clock.now(),
                **({"reference": reference} if reference else {}),
                **({"absolute_values": list(absolute)} if absolute is not None else {}),
            },
            timestamp=ts,
            colour=colour,
            colour_error=colour_error,
        ))  # fmt: skip
        self._n_done += 1
        self.bus.publish(
            PointMeasured(
                run_id=self.run_id,
                timestamp=ts,
                index=p.index,
                repeat=p.repeat,
                theta_i_deg=p.theta_i_deg,
                theta_r_deg=p.theta_r_deg,
                luminance_pct=value,
                measured_theta_i_deg=self._measured_deg[0],
                measured_theta_r_deg=self._measured_deg[1],
                predicted_pct=self._predicted.get(p.index),
                lab=None if colour is None else (colour["L"], colour["a"], colour["b"]),
                xyz=None if colour is None else (colour["X"], colour["Y"], colour["Z"]),
                white_xyz=None if colour is None else self._white_xyz(),
                quality=quality,
            )
        )

    def _white_xyz(self) -> tuple[float, float, float]:
        """The white of the run's colour settings (what its L*a*b* is relative to)."""
        from goniolab.colour.spectra import white_xyz

        x, y, z = (float(v) for v in white_xyz(self.point_colour.settings))
        return (x, y, z)

    async def _store_reading(self, p: PlanPoint, write: Callable[[], None]) -> None:
        """Commit reading ``p`` with ``write``. When the store cannot take it
        (:class:`~goniolab.store.StoreUnavailable`: a database down or frozen, a full disk,
        a lock held by another program) the run pauses with the arms parked, says why,
        and tries again with a growing delay (0.5 s doubling to 10 s, each try in a worker
        thread so that Ctrl-C stays live) until the store takes the reading (the run goes
        on: the next move re-checks the arms) or ``store_outage_s`` passes (the store
        error ends the run as failed) or an abort arrives.

        A try whose commit reached the store but whose answer was lost finds the reading
        already stored (a unique-key refusal for a key now in the store): that counts as
        stored.
        """
        try:
            write()
            return
        except StoreUnavailable as exc:
            first = exc
        self.bus.publish(
            InstrumentError(
                run_id=self.run_id,
                device="store",
                message=f"{first}; the run pauses with the arms parked until the store is back",
                fatal=False,
            )
        )
        if self._eta is not None:  # an outage is not the run's pace
            self._eta.pause()
        park_problem = await self._park()
        self._verify_position = True  # the arms left the geometry: the next move checks
        self._set_state(RunState.PAUSED, f"store unavailable: {first}" + (
            f"; {park_problem}" if park_problem else ""))  # fmt: skip
        deadline = time.monotonic() + self.store_outage_s
        delay = 0.5
        last: StoreError = first
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise StoreUnavailable(
                    f"{last} (waited {self.store_outage_s:g} s with the arms parked; "
                    f"the reading at index {p.index}, repeat {p.repeat} was not stored)"
                )
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._abort_event.wait(), timeout=min(delay, left))
            if self._abort_requested:
                raise Aborted(
                    f"aborted while the store was unavailable ({last}); the reading at "
                    f"index {p.index}, repeat {p.repeat} was not stored"
                )
            delay = min(10.0, delay * 2)
            try:
                await asyncio.to_thread(write)
                break
            except StoreUnavailable as exc:
                last = exc
            except Exception:
                if p.key in await asyncio.to_thread(self.store.done_keys, self.run_id):
                    break  # the lost answer's commit: stored once
                raise
        # a restarted server dropped the claim with its connection: take it again (the
        # server answers now, so this cannot hang)
        await asyncio.to_thread(self.store.ensure_claim, self.run_id)
        if self._eta is not None:
            self._eta.resume()
        self.bus.publish(
            InstrumentError(
                run_id=self.run_id,
                device="store",
                message="the store is back: the reading is stored, the run goes on",
                fatal=False,
            )
        )
        self._set_state(RunState.RUNNING)

    def _publish_progress(self, eta_s: float) -> None:
        self.bus.publish(
            Progress(run_id=self.run_id, done=self._n_done, total=self._total, eta_s=eta_s)
        )

    async def _park_and_record(self, state: RunState, why: str) -> str:
        """After an error that ends the run at once: park (best effort), record the state
        with ``why`` and what went wrong parking; return that reason."""
        park_problem = await self._park()
        reason = why + (f"; {park_problem}" if park_problem else "")
        self._set_state(state, reason)
        return reason

    async def _settle(self, task: asyncio.Task[None], what: str) -> None:
        """Wait for a background prediction; its failure is reported, never fatal: a model
        failure must not lose the run."""
        try:
            await task
        except asyncio.CancelledError:
            me = asyncio.current_task()
            if me is not None and me.cancelling():
                raise
            # the prediction itself was dropped (quit at once): nothing to report
        except Exception as exc:
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id, device="model", message=f"{what} failed: {exc}", fatal=False
                )
            )

    def _keep_warnings(self, summary: dict[str, Any]) -> None:
        """The run's warnings into its summary (``--json``, the TUI's end of run) and its
        stored record (``run_warnings`` of the model, a resumed run's added to the earlier
        ones): every fallback the user was told of live stays with the run."""
        lines = self.warnings.lines()
        if not lines:
            return
        summary["warnings"] = lines
        try:
            earlier = self.store.get_run(self.run_id).model.get("run_warnings") or []
            kept = [*earlier, *(w for w in lines if w not in earlier)]
            self.store.update_model(self.run_id, {"run_warnings": kept})
        except StoreError as exc:
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id, device="store",
                    message=f"the run's warnings could not be stored: {exc}", fatal=False,
                )
            )  # fmt: skip

    async def _finish(
        self,
        state: RunState,
        reason: str,
        predict_task: asyncio.Task[None],
        colour_task: asyncio.Task[None],
    ) -> RunResult:
        """Park, wait for the predictions, summarise, record and publish the end."""
        park_problem = await self._park()
        if park_problem:
            reason = f"{reason}; {park_problem}" if reason else park_problem
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id, device="goniometer", message=park_problem, fatal=False
                )
            )
        await self._settle(predict_task, "prediction")
        if state is RunState.DONE:
            await self._settle(colour_task, "colour prediction")
        else:
            colour_task.cancel()
        try:
            summary = summarize_brdf(
                self.plan,
                self.store.points(self.run_id),
                self.store.predictions(self.run_id),
                misalignment_threshold_deg=self.misalignment_threshold_deg,
            )
        except Exception as exc:  # every reading is stored: the run keeps its state
            summary = {}
            problem = f"summary failed: {describe_error(exc)}"
            reason = f"{reason}; {problem}" if reason else problem
        self._keep_warnings(summary)
        self._set_state(state, reason)
        self.bus.publish(
            RunFinished(run_id=self.run_id, state=state, reason=reason, summary=summary)
        )
        return RunResult(run_id=self.run_id, state=state, reason=reason, summary=summary)
