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

Before any motion, :func:`dry_run` checks every geometry with
``Goniometer.check_geometry`` (soft limits + arm-separation interlock) and estimates the run
time from the trapezoidal motion model (:func:`drivers.timing.trapezoid_duration_s`,
Biagiotti & Melchiorri sec. 3.2) plus dwell and reading time and the final park move
(a home search is controller-specific and not estimated).

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
from typing import Any, TypeVar

from drivers.base import (
    DeviceError,
    DeviceFault,
    DeviceTimeout,
    Disconnected,
    Goniometer,
    InterlockError,
    LimitError,
    ProtocolError,
    Spectrocolorimeter,
    SpectroReading,
)
from drivers.timing import Clock, trapezoid_duration_s
from goniolab.config import GoniometerConfig
from goniolab.scan.alarm import failure_reason
from goniolab.scan.colour import PointColour
from goniolab.scan.events import (
    ArmsMoved,
    ColourPredicted,
    EventBus,
    InstrumentError,
    PointMeasured,
    PointPredicted,
    Progress,
    RunFinished,
    RunStarted,
    RunState,
    StateChanged,
)
from goniolab.scan.exposure import (
    EXCLUDED_QUALITY,
    AutoExposure,
    quality_of_raw,
    reading_quality,
)
from goniolab.scan.plans import MIRROR_INDEX, BrdfPlan, PlanPoint
from goniolab.scan.prediction import Predictor
from goniolab.scan.reference import SpectralReference
from goniolab.scan.sanity import check_reading
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
    "reachable_range",
]

#: Called with "mirror" before the mirror reference readings and "sample" after them;
#: returns once the operator (or the simulated lab) has swapped the specimen.
SpecimenHook = Callable[[str], Awaitable[None]]

_T = TypeVar("_T")

#: A reading's colour computed in less than this (once colour-science is loaded, ~0.1 ms)
#: is computed on the event loop next time; longer ones go to a worker thread.
_INLINE_COLOUR_S = 1e-3


def _timed(fn: Callable[..., _T], *args: Any) -> tuple[_T, float]:
    """``fn(*args)`` and the seconds it took."""
    t0 = time.perf_counter()
    return fn(*args), time.perf_counter() - t0


def _describe(exc: BaseException) -> str:
    """``Type: message`` of an unexpected error (``struct.error: argument out of range``),
    the message alone for a :class:`~drivers.base.DeviceError` (it names its device)."""
    if isinstance(exc, DeviceError):
        return str(exc)
    kind = type(exc)
    name = (
        kind.__qualname__
        if kind.__module__ == "builtins"
        else f"{kind.__module__}.{kind.__qualname__}"
    )
    text = str(exc)
    return f"{name}: {text}" if text else name


class PlanRefused(Exception):
    """The dry run found a geometry the goniometer must not reach (names point and reason).

    ``what`` is ``"park position"``, ``"mirror reference"`` or ``"point N"``; ``cause``
    the goniometer's refusal (soft limits or arm-separation interlock).
    """

    def __init__(
        self,
        what: str,
        theta_i_deg: float,
        theta_r_deg: float,
        cause: DeviceError,
        reach: str = "",
    ) -> None:
        self.what = what
        self.theta_i_deg = theta_i_deg
        self.theta_r_deg = theta_r_deg
        self.reason = cause.message + (f"; {reach}" if reach else "")
        super().__init__(
            f"{what} (theta_i={theta_i_deg:g} deg, theta_r={theta_r_deg:g} deg) is unsafe: {cause}"
            + (f"; {reach}" if reach else "")
        )

    @property
    def out_of_reach(self) -> str:
        """The refusal as a form error: the geometry first, then the reason."""
        where = "the park position: " if self.what == "park position" else ""
        return (
            f"{where}theta_i {self.theta_i_deg:g} deg, theta_r {self.theta_r_deg:g} deg is "
            f"out of the goniometer's reach: {self.reason}"
        )


class _Aborted(Exception):
    """An abort ends the run's readings; ``reason`` says where it arrived."""

    def __init__(self, during: str = "") -> None:
        super().__init__(during)
        self.reason = "aborted by the operator" + (f" {during}" if during else "")


@dataclass(slots=True)
class _Eta:
    """Time left in a run: the dry-run estimate of the readings still to take (and of the
    final park move), stretched by how much slower than estimated the run has been so far
    (bus latency, polling, commits)."""

    point_times_s: list[float]
    park_s: float
    t_start_s: float = 0.0
    estimated_done_s: float = 0.0

    @property
    def total_s(self) -> float:
        """The dry run's estimate of the whole rest of the run."""
        return math.fsum(self.point_times_s) + self.park_s

    def start(self, now_s: float) -> None:
        """The first reading is about to be taken (lab clock)."""
        self.t_start_s = now_s

    def left_after(self, k: int, now_s: float) -> float:
        """Estimated lab-clock seconds left once reading ``k`` (0-based) is stored."""
        self.estimated_done_s += self.point_times_s[k]
        elapsed_s = now_s - self.t_start_s
        slowdown = elapsed_s / self.estimated_done_s if self.estimated_done_s > 0 else 1.0
        return (math.fsum(self.point_times_s[k + 1 :]) + self.park_s) * max(1.0, slowdown)


@dataclass(frozen=True, slots=True)
class ArmMotion:
    """Speed and acceleration of both arms (config ``[goniometer.lamp|detector]``)."""

    lamp_speed_deg_s: float
    lamp_accel_deg_s2: float
    detector_speed_deg_s: float
    detector_accel_deg_s2: float

    @classmethod
    def from_config(cls, goniometer: GoniometerConfig) -> ArmMotion:
        """The arms' speeds and accelerations of a lab config's ``[goniometer]``."""
        lamp, det = goniometer.lamp, goniometer.detector
        return cls(lamp.speed_deg_s, lamp.accel_deg_s2, det.speed_deg_s, det.accel_deg_s2)

    def move_time_s(self, start: tuple[float, float], target: tuple[float, float]) -> float:
        """Time of a two-arm move; the arms move together, so the slower arm sets it."""
        t_lamp = trapezoid_duration_s(
            target[0] - start[0], self.lamp_speed_deg_s, self.lamp_accel_deg_s2
        )
        t_det = trapezoid_duration_s(
            target[1] - start[1], self.detector_speed_deg_s, self.detector_accel_deg_s2
        )
        return max(t_lamp, t_det)


@dataclass(frozen=True, slots=True)
class DryRun:
    """Result of :func:`dry_run`: every reading's estimated duration and the total."""

    n_readings: int
    n_moves: int
    point_times_s: tuple[float, ...]
    #: The move from the last geometry to the park position that ends the run.
    park_s: float = 0.0

    @property
    def eta_s(self) -> float:
        """Estimated run time in seconds of lab clock, the final park move included."""
        return math.fsum(self.point_times_s) + self.park_s


def reachable_range(goniometer: Goniometer) -> str:
    """The requested angles the arms can reach once the alignment corrections are added
    (``""`` without corrections): a sweep to a limit that an alignment moved is refused
    with this range rather than failing mid-run."""
    corr = getattr(goniometer, "corrections_deg", (0.0, 0.0))
    if not any(corr):
        return ""
    parts = []
    for axis, c, label in ((goniometer.lamp, corr[0], "theta_i"), (goniometer.detector, corr[1], "theta_r")):  # fmt: skip
        lo, hi = axis.limits_deg
        parts.append(f"{label} {lo - c:.3f}..{hi - c:.3f} deg")
    return (
        f"with the alignment corrections (lamp {corr[0]:+.3f}, detector {corr[1]:+.3f} deg) the "
        f"arms reach {', '.join(parts)}"
    )


def dry_run(
    points: Sequence[PlanPoint],
    goniometer: Goniometer,
    motion: ArmMotion,
    *,
    start_deg: tuple[float, float],
    dwell_s: float,
    reading_time_s: float,
    park_deg: tuple[float, float] | None = None,
) -> DryRun:
    """Check every geometry before any motion and estimate the run time.

    Parameters
    ----------
    points
        The readings still to take, in order.
    goniometer
        Its ``check_geometry`` raises :class:`~drivers.base.LimitError` or
        :class:`~drivers.base.InterlockError` for an unsafe geometry; nothing moves.
    motion
        Arm speeds and accelerations for the trapezoidal move times.
    start_deg
        Arm positions (theta_i, theta_r) before the first move.
    dwell_s, reading_time_s
        Settling time after each move and time of one reading (exposure + transfer).
    park_deg
        The park geometry, checked too (a fault or an abort drives there).

    Returns
    -------
    DryRun
        Per-reading time: move (first repeat of a geometry only) + dwell + reading; and
        the final move to ``park_deg`` (0 without one).

    Raises
    ------
    PlanRefused
        Naming the first unsafe point, its geometry and the goniometer's reason.
    """
    if park_deg is not None:
        try:
            goniometer.check_geometry(*park_deg)
        except (LimitError, InterlockError) as exc:
            reach = reachable_range(goniometer) if isinstance(exc, LimitError) else ""
            raise PlanRefused("park position", *park_deg, exc, reach) from exc
    times: list[float] = []
    pos = start_deg
    moves = 0
    checked: set[tuple[float, float]] = set()
    for p in points:
        target = (p.theta_i_deg, p.theta_r_deg)
        if target not in checked:
            try:
                goniometer.check_geometry(*target)
            except (LimitError, InterlockError) as exc:
                what = "mirror reference" if p.index == MIRROR_INDEX else f"point {p.index}"
                reach = reachable_range(goniometer) if isinstance(exc, LimitError) else ""
                raise PlanRefused(what, *target, exc, reach) from exc
            checked.add(target)
        t = reading_time_s
        if target != pos:
            t += motion.move_time_s(pos, target) + dwell_s
            moves += 1
            pos = target
        times.append(t)
    park_s = 0.0 if park_deg is None else motion.move_time_s(pos, park_deg)
    return DryRun(n_readings=len(points), n_moves=moves, point_times_s=tuple(times), park_s=park_s)


@dataclass(slots=True)
class RunResult:
    """What a finished :meth:`ScanRunner.run` returns (also published as RunFinished)."""

    run_id: int
    state: RunState
    reason: str
    summary: dict[str, Any] = field(default_factory=dict)


class ScanRunner:
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
        Duration of one reading for the ETA (default: the exposure time).
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
        self.bus = bus
        self.motion = motion
        self.predictor = predictor
        self.move_timeout_s = move_timeout_s
        self.home_timeout_s = home_timeout_s
        self.park_deg = park_deg
        self.reading_time_s = plan.exposure_us * 1e-6 if reading_time_s is None else reading_time_s
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
        #: missed check standard (:func:`goniolab.scan.calibrate.calibration_notices`)
        self.notices = tuple(notices)
        self.point_colour = point_colour if point_colour is not None else PointColour()
        if plan.mirror_reference and mirror_standard is None:
            from goniolab.scan.standards import load_standards, standards_path

            # the shipped certificate; its file is cited in every reading it references
            mirror_standard = load_standards(standards_path("")).get("mirror")
        #: the certified mirror the reference readings are divided by (docs/CALIBRATION.md)
        self.mirror_standard = mirror_standard
        self._reference: SpectralReference | None = None
        #: the last colour took under _INLINE_COLOUR_S: compute the next on the loop
        self._colour_inline = False
        if plan.mirror_reference and specimen_hook is None:
            raise ValueError("a plan with a mirror reference needs a specimen_hook")
        self._state = RunState.IDLE
        self._pause_requested = False
        self._abort_requested = False
        self._abort_by = ""
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
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="store",
                    message=f"the run's state ({state.value}) could not be recorded: {exc}",
                    fatal=False,
                )
            )
        self.bus.publish(StateChanged(run_id=self.run_id, state=state, reason=reason))

    async def _checkpoint(self) -> bool:
        """Honour pause/abort between readings; ``False`` means stop."""
        if self._abort_requested:
            return False
        if self._pause_requested:
            self._set_state(RunState.PAUSED)
            while self._pause_requested and not self._abort_requested:
                self._wake.clear()
                await self._wake.wait()
            if self._abort_requested:
                return False
            self._set_state(RunState.RUNNING)
            self._verify_position = True
        return True

    async def _abortable(self, aw: Awaitable[_T], during: str) -> _T:
        """Await ``aw`` unless :meth:`abort` is called first: then cancel it and raise
        :class:`_Aborted` saying ``during`` what."""
        work = asyncio.ensure_future(aw)
        aborted = asyncio.ensure_future(self._abort_event.wait())
        try:
            await asyncio.wait({work, aborted}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            aborted.cancel()
            if not work.done():  # an abort, or a cancellation from outside
                work.cancel()
                with contextlib.suppress(asyncio.CancelledError, DeviceError):
                    await work
        if work.cancelled():
            raise _Aborted(during)
        return work.result()

    async def _move(self, target: tuple[float, float]) -> None:
        """Move to ``target``; a move that meets a transient fault (an arm's timeout or
        garbled frame, or a lost link: then the arms' connections are reopened first) is
        made again from where the arms stopped, up to ``move_retries`` times (see
        :meth:`_retry`). The goniometer stops both arms on any error and plans every move
        from the positions it reads, so a retry keeps the interlock."""
        self.bus.publish(
            ArmsMoved(run_id=self.run_id, theta_i_deg=target[0], theta_r_deg=target[1], moving=True)
        )
        self._target = None  # somewhere between two geometries until the move is done
        measured = await self._retry(
            f"moving to theta_i={target[0]:g}, theta_r={target[1]:g} deg",
            lambda: self._abortable(
                self.goniometer.move_to(target[0], target[1], self.move_timeout_s),
                "during a move",
            ),
            self._reconnect_arms,
            self.move_retries,
            "goniometer",
        )
        self._measured_deg = (float(measured[0]), float(measured[1]))
        self._target = target
        self.bus.publish(
            ArmsMoved(
                run_id=self.run_id,
                theta_i_deg=self._measured_deg[0],
                theta_r_deg=self._measured_deg[1],
                moving=False,
            )
        )

    async def _ensure_position(self, target: tuple[float, float]) -> bool:
        """Move to ``target`` if needed; return True when a move happened."""
        if self._target != target:
            await self._move(target)
            return True
        if self._verify_position:
            self._verify_position = False
            ti, tr = await self._arm_positions("checking the arm positions")
            if (
                abs(ti - target[0]) > self.position_tolerance_deg
                or abs(tr - target[1]) > self.position_tolerance_deg
            ):
                await self._move(target)
                return True
            self._measured_deg = (float(ti), float(tr))
        return False

    async def _arm_positions(self, what: str) -> tuple[float, float]:
        """Both arms' positions, read again after a transient fault (see :meth:`_retry`)."""
        return await self._retry(
            what, self.goniometer.positions_deg, self._reconnect_arms, self.move_retries,
            "goniometer",
        )  # fmt: skip

    async def _arms_homed(self) -> bool:
        lamp = await self.goniometer.lamp.status()
        det = await self.goniometer.detector.status()
        return lamp.homed and det.homed

    async def _ensure_homed(self) -> None:
        homed = await self._retry(
            "reading the arms' status", self._arms_homed, self._reconnect_arms,
            self.move_retries, "goniometer",
        )  # fmt: skip
        if not homed:  # the goniometer plans homing from where the arms stand: a retry is safe
            await self._retry(
                "homing", lambda: self.goniometer.home(self.home_timeout_s),
                self._reconnect_arms, self.move_retries, "goniometer",
            )  # fmt: skip

    async def _park(self) -> str:
        """Stop and park the arms, best effort (each step retried after a transient fault,
        :meth:`_retry`); returns "" or what went wrong.

        After an interrupted homing the arms are only stopped: their positions are not
        referenced, so no move is made.
        """
        problems: list[str] = []
        # a timeout, a garbled frame or a lost link (reopened first) is tried again, as in
        # a move: a link that dropped just before the end must not leave the arms unparked
        try:
            await self._retry(
                "stopping the arms", self.goniometer.stop, self._reconnect_arms,
                self.move_retries, "goniometer",
            )  # fmt: skip
        except Exception as exc:  # best effort: any failure is reported, never raised
            problems.append(f"stopping the arms failed: {_describe(exc)}")
        if self._homing_interrupted:
            self._target = None
            problems.append("homing interrupted: arms stopped, not parked; home them before use")
            return "; ".join(problems)
        try:
            await self._retry(
                "parking the arms", lambda: self.goniometer.park(self.home_timeout_s),
                self._reconnect_arms, self.move_retries, "goniometer",
            )  # fmt: skip
        except Exception as exc:  # a bug or a dead link must not leave the run 'running'
            problems.append(
                f"parking failed: {_describe(exc)}; arms not parked: check them before use"
            )
        self._target = None
        return "; ".join(problems)

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

    async def _colour_of(
        self, reading: SpectroReading, p: PlanPoint, absolute: Sequence[float] | None
    ) -> tuple[dict[str, float] | None, str]:
        """The reading's colour (computed in a worker thread), or why there is none.

        A spectrum colour cannot be computed from (wrong length, NaN, negative values, a grid
        short of 380-780 nm) is reported as a non-fatal instrument error; the reading is
        stored all the same, without colour.
        """
        from goniolab.colour.spectra import ColourError

        # referenced to the certified mirror: the absolute spectrum (no further scaling)
        spectrum = reading.values if absolute is None else tuple(absolute)
        args = (reading.wavelengths_nm, spectrum, p.theta_r_deg, None)
        measured = self.point_colour.measured
        try:
            if self._colour_inline:
                # a few hundred multiply-adds once colour-science is loaded: a worker
                # thread's hand-off would cost more than the work (issue 13: the sequencer's
                # overhead per reading); a spectrum that takes longer sends it back
                values, took_s = _timed(measured, *args)
            else:
                values, took_s = await asyncio.to_thread(lambda: _timed(measured, *args))
            self._colour_inline = took_s < _INLINE_COLOUR_S
        except (ColourError, ValueError) as exc:
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="spectro",
                    message=f"point {p.index}, repeat {p.repeat}: no colour: {exc} "
                    "(reading stored without colour)",
                    fatal=False,
                )
            )
            return None, str(exc)
        return values.as_dict(), ""

    async def _read_spectro(self, p: PlanPoint) -> SpectroReading:
        """One spectro reading, taken again after a transient fault (timeout, garbled reply,
        an implausible value (:mod:`goniolab.scan.sanity`), a lost link: then the port is
        reopened first) up to ``reading_retries`` times; each retry is reported, nothing is
        stored twice."""

        async def read() -> SpectroReading:
            if self.plan.auto_exposure:
                reading, self._exposure_us = await self._auto.read(self.spectro, self._exposure_us)
            else:
                reading = await self.spectro.measure()
            return check_reading(reading)  # an implausible Y is read again, never stored

        reading = await self._retry(
            f"point {p.index}, repeat {p.repeat}", read, self._reconnect_spectro,
            self.reading_retries, "spectro",
        )  # fmt: skip
        if reading.stale_lines:  # a late or repeated answer was dropped: say so
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="spectro",
                    message=f"point {p.index}, repeat {p.repeat}: dropped {reading.stale_lines} "
                    "reply line(s) of an earlier request (a late or repeated answer); the "
                    "reading kept is the answer to this point's own request",
                    fatal=False,
                )
            )
        return reading

    async def _retry(
        self,
        what: str,
        op: Callable[[], Awaitable[_T]],
        reconnect: Callable[[int], Awaitable[None]],
        retries: int,
        device: str,
    ) -> _T:
        """``await op()``, again after a transient fault (:class:`DeviceTimeout`,
        :class:`ProtocolError`, :class:`Disconnected`: then ``reconnect(attempt)`` first) up
        to ``retries`` times, each retry published as a non-fatal :class:`InstrumentError`
        saying ``what`` was being done; the last failure propagates (and fails the run)."""
        attempt = 0
        lost_since: float | None = None
        reconnects = 0
        while True:
            try:
                return await op()
            except (DeviceTimeout, ProtocolError, Disconnected) as exc:
                lost = isinstance(exc, Disconnected)
                now = self.clock.now()
                if lost:
                    lost_since = now if lost_since is None else lost_since
                    away_s = now - lost_since
                    if reconnects and away_s >= self.reconnect_window_s:
                        raise Disconnected(
                            f"{exc.message} (link away {away_s:.3g} s, longer than the "
                            f"reconnect window of {self.reconnect_window_s:g} s)",
                            device=exc.device or device,
                        ) from exc
                    note = (
                        f"reconnecting, link lost {away_s:.3g} s ago, waiting up to "
                        f"{self.reconnect_window_s:g} s"
                        if reconnects
                        else f"retry {attempt + 1} of {retries}, reconnecting"
                    )
                    self.bus.publish(
                        InstrumentError(
                            run_id=self.run_id,
                            device=exc.device or device,
                            message=f"{exc} ({what}: {note})",
                            fatal=False,
                        )
                    )
                    await reconnect(reconnects)
                    reconnects += 1
                    continue
                if attempt == retries:
                    raise
                self.bus.publish(
                    InstrumentError(
                        run_id=self.run_id,
                        device=exc.device or device,
                        message=f"{exc} ({what}: retry {attempt + 1} of {retries})",
                        fatal=False,
                    )
                )
                attempt += 1

    async def _reconnect_arms(self, attempt: int) -> None:
        """Reopen both arms' links after a lost one (on the wire they share a server, a
        dropped link may take both) after ``reconnect_backoff_s`` (doubling) of lab clock;
        a failed reopen is reported and the next attempt finds the link closed."""
        await self.clock.sleep(min(2.0, self.reconnect_backoff_s * 2**attempt))
        for axis in (self.goniometer.lamp, self.goniometer.detector):
            with contextlib.suppress(DeviceError):
                await axis.close()
            try:
                await axis.connect()
            except DeviceError as exc:
                self.bus.publish(InstrumentError.reconnect_failed(self.run_id, exc, "goniometer"))

    async def _reconnect_spectro(self, attempt: int) -> None:
        """Close the spectro's link, wait (``reconnect_backoff_s``, doubling with each
        attempt, on the lab clock), reopen it and set the exposure again (the plan's, or the
        one auto-exposure arrived at). A failed
        reopen is reported; the next attempt finds the link closed and tries again."""
        with contextlib.suppress(DeviceError):
            await self.spectro.close()
        await self.clock.sleep(min(2.0, self.reconnect_backoff_s * 2**attempt))
        try:
            await self.spectro.connect()
            await self.spectro.set_exposure_us(self._exposure_us)  # the plan's, or auto's
        except DeviceError as exc:
            self.bus.publish(InstrumentError.reconnect_failed(self.run_id, exc, "spectro"))

    def _mirror_level(self) -> float | None:
        vals = [p.luminance_pct for p in self.store.points(self.run_id) if p.index == MIRROR_INDEX]
        if len(vals) < self.plan.repeats:
            return None
        return math.fsum(vals) / len(vals)

    def _load_reference(self) -> SpectralReference | None:
        """The mirror reference of the run (its repeats averaged as spectra) once all its
        readings are stored, else ``None``."""
        if not self.plan.mirror_reference or self.mirror_standard is None:
            return None
        rows = [p for p in self.store.points(self.run_id) if p.index == MIRROR_INDEX]
        if len(rows) < self.plan.repeats:
            return None
        usable = [p for p in rows if quality_of_raw(p.raw) not in EXCLUDED_QUALITY]
        if not usable:
            flags = sorted({quality_of_raw(p.raw) for p in rows})
            raise DeviceFault(
                f"every mirror reference reading is flagged ({', '.join(flags)}): the "
                "reference cannot be used"
                + ("" if self.plan.auto_exposure else "; --auto-exposure adapts the exposure"),
                device="spectro",
            )
        rows = usable
        readings = [
            (
                list(p.raw.get("wavelengths_nm") or ()),
                list(p.raw.get("values") or ()),
                float(p.raw.get("luminance_pct", p.luminance_pct)),
            )
            for p in rows
        ]
        return SpectralReference.from_readings(
            self.mirror_standard, self.plan.theta_i_deg, readings, self.point_colour.settings
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
            self.bus.publish(
                InstrumentError(run_id=self.run_id, device="calibration", message=note, fatal=False)
            )
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
            why = await self._park_and_record(RunState.FAILED, f"internal error: {_describe(exc)}")
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

    async def _dry_run(self, todo: Sequence[PlanPoint]) -> _Eta:
        """:func:`dry_run` of ``todo`` from where the arms stand (raises PlanRefused)."""
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
        return _Eta(list(check.point_times_s), check.park_s)

    async def _measure(self, todo: Sequence[PlanPoint], eta: _Eta) -> tuple[RunState, str]:
        """Home if needed, then take the readings of ``todo`` in order, each stored before
        the next; an abort ends the loop with its reason. A DeviceError propagates."""
        try:
            try:
                await self._abortable(self._ensure_homed(), "during homing")
            except _Aborted:
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
            eta.start(self.clock.now())
            for k, p in enumerate(todo):
                await self._go_to(p)
                await self._take_reading(p)
                self._publish_progress(eta.left_after(k, self.clock.now()))
            state, reason = RunState.DONE, ""
        except _Aborted as stop:
            state, reason = RunState.ABORTED, stop.reason
            if self._abort_by:
                reason = reason.replace("by the operator", f"by {self._abort_by}", 1)
        if self._specimen == "mirror":
            assert self.specimen_hook is not None
            await self.specimen_hook("sample")
        return state, reason

    async def _go_to(self, p: PlanPoint) -> None:
        """Everything before reading ``p``: honour a pause or an abort, put the specimen
        ``p`` needs under the instruments, move the arms there and let them settle.

        Raises
        ------
        _Aborted
            With the reason, when an abort arrives (a move is stopped where it is).
        """
        if not await self._checkpoint():
            raise _Aborted("")
        want = "mirror" if p.index == MIRROR_INDEX else "sample"
        if want != self._specimen:
            assert self.specimen_hook is not None
            await self._abortable(self.specimen_hook(want), f"while placing the {want}")
            self._specimen = want
        if await self._ensure_position((p.theta_i_deg, p.theta_r_deg)):
            await self.clock.sleep(self.plan.dwell_s)

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
                quality=quality,
            )
        )

    def _referenced(
        self, reading: SpectroReading, p: PlanPoint
    ) -> tuple[float, tuple[float, ...] | None, dict[str, Any]]:
        """A sample reading referenced to the certified mirror (once the mirror's readings
        are all stored; :class:`~goniolab.scan.reference.SpectralReference`):
        ``(luminance %, absolute spectrum % or None, provenance)``; a mirror reading or a
        run without reference as read."""
        raw_pct = float(reading.luminance_pct)
        if p.index == MIRROR_INDEX or not self.plan.mirror_reference:
            return raw_pct, None, {}
        if self._reference is None:
            self._mirror_pct = self._mirror_level()
            self._reference = self._load_reference()
        if self._reference is None:
            return raw_pct, None, {}
        absolute, lum, info = self._reference.apply(reading.wavelengths_nm, reading.values, raw_pct)
        if info["method"] != "spectral":
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="spectro",
                    message=f"point {p.index}, repeat {p.repeat}: mirror reference applied "
                    f"as a scalar: {info['method']}",
                    fatal=False,
                )
            )
        return lum, absolute, info

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
                raise _Aborted(
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
            problem = f"summary failed: {_describe(exc)}"
            reason = f"{reason}; {problem}" if reason else problem
        self._set_state(state, reason)
        self.bus.publish(
            RunFinished(run_id=self.run_id, state=state, reason=reason, summary=summary)
        )
        return RunResult(run_id=self.run_id, state=state, reason=reason, summary=summary)
