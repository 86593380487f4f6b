"""Use cases on a lab: scan, resume, align, calibrate, reset alarms (issue 24).

Each use case takes the lab config loaded once by the face
(:func:`goniolab.app.lab_setup.load_config`), a plan built by
:func:`goniolab.app.lab_setup.brdf_plan` (the one builder of the CLI, the notebook API, the
TUI and the bluesky face) and a store opened by :func:`goniolab.app.lab_setup.open_store`;
it opens the lab through :class:`goniolab.session.ScanSession`, runs it and returns a typed
result that says where its numbers come from (the config file, the store, the
prediction's models). Library errors a user can fix leave here as
:class:`goniolab.errors.UserError` (one family; each face translates it once).

The faces talk to a running use case through three small hooks, so none of them needs
the session: ``notify(text)`` (a line for the operator), a
:class:`goniolab.progress.Reporter` (progress; :func:`report_events` feeds it from the
run's events) and ``on_start(runner)`` (the runner, to abort or pause it). Nothing heavy
is imported with this module.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from goniolab.app.lab_setup import (
    Notify,
    SpecimenHook,
    check_reach,
    lab_errors,
    quiet,
    resume_config,
    started_with,
    with_model,
)
from goniolab.errors import UserError

if TYPE_CHECKING:  # loaded when a use case runs
    import asyncio

    from goniolab.config import LabConfig
    from goniolab.lab_wiring import Lab
    from goniolab.progress import Reporter
    from goniolab.scan.alarm import ArmAlarm
    from goniolab.scan.align import AlignPlan, AlignResult
    from goniolab.scan.events import PointMeasured, RunState
    from goniolab.scan.plans import BrdfPlan
    from goniolab.scan.runner import ScanRunner
    from goniolab.session import PreparedScan
    from goniolab.store import RunMeta, RunStore

__all__ = [
    "AlignOutcome",
    "CalibrationOutcome",
    "ScanOutcome",
    "ServedLab",
    "align",
    "calibrate",
    "check_plan",
    "home_arms",
    "open_lab",
    "point_detail",
    "report_events",
    "reset_alarms",
    "resume",
    "scan",
    "serve_simulated_lab",
]


# --------------------------------------------------------------------------- progress
def point_detail(ev: PointMeasured, predicted_pct: float | None) -> str:
    """Progress detail of a reading: angle, luminance, prediction and residual."""
    text = f"theta_r={ev.theta_r_deg:g} L={ev.luminance_pct:.3f} %"
    if predicted_pct is not None:
        text += f" pred {predicted_pct:.3f} % res {ev.luminance_pct - predicted_pct:+.3f}"
    if ev.quality in ("saturated", "under_noise_floor"):
        text += f" [{ev.quality.replace('_', ' ').upper()}]"
    return text


async def report_events(queue: asyncio.Queue[Any], reporter: Reporter) -> None:
    """Feed a run's events to ``reporter`` until the bus closes: each
    :class:`~goniolab.scan.events.Progress` as a step (its ETA, already wall seconds
    measured from the run's own rates, :class:`goniolab.scan.eta.EtaEstimator`; NaN while
    not known: the reporter then measures the pace), the last reading as the detail,
    instrument faults and warnings as messages."""
    from goniolab.scan.events import (
        InstrumentError,
        PointMeasured,
        PointPredicted,
        Progress,
        RunFinished,
    )

    detail = ""
    predicted: dict[int, float] = {}
    started = False
    while (ev := await queue.get()) is not None:
        if isinstance(ev, PointPredicted):
            predicted[ev.index] = ev.predicted_pct
        elif isinstance(ev, PointMeasured):
            pred = ev.predicted_pct if ev.predicted_pct is not None else predicted.get(ev.index)
            detail = point_detail(ev, pred)
        elif isinstance(ev, Progress):
            if not started:
                reporter.start(ev.total)
                started = True
            eta = ev.eta_s if math.isfinite(ev.eta_s) else None
            reporter.advance(ev.done, total=ev.total, eta_s=eta, detail=detail)
        elif isinstance(ev, InstrumentError):
            reporter.message(
                f"goniolab: {'fault' if ev.fatal else 'warning'}: {ev.device}: {ev.message}"
            )
        elif isinstance(ev, RunFinished):
            return


@contextlib.asynccontextmanager
async def _reporting(session: Any, reporter: Reporter | None) -> AsyncIterator[None]:
    """Run :func:`report_events` beside the body; the bus is closed and the reporter
    finished after it."""
    import asyncio

    task = None
    if reporter is not None:
        task = asyncio.create_task(report_events(session.bus.subscribe(), reporter))
    try:
        yield
    finally:
        session.bus.close()
        if task is not None:
            await task
            reporter.finish()  # type: ignore[union-attr]


# --------------------------------------------------------------------------- scan
@dataclass(frozen=True)
class ScanOutcome:
    """A scan's end: the stored run, its state and summary, and where its numbers come
    from (the config file, the store, the prediction model of each angle)."""

    run_id: int
    state: RunState
    reason: str
    summary: dict[str, Any]
    store: str
    config_source: str
    plan: BrdfPlan
    #: the run's ``model`` column: the predictor, the calibration cited, ``computed_by``
    model: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """``goniolab scan --json``: run id, state, reason and the summary."""
        return {"run_id": self.run_id, "state": self.state.value, "reason": self.reason,
                **self.summary}  # fmt: skip


async def _scan_on(
    cfg: LabConfig,
    store: RunStore,
    plan: BrdfPlan,
    *,
    run_id: int | None,
    time_scale: float | None,
    adaptive: bool,
    meta: RunMeta | None,
    reporter: Reporter | None,
    notify: Notify,
    on_start: Callable[[ScanRunner], None] | None,
    operator: SpecimenHook | None,
    model: Any = None,
) -> ScanOutcome:
    from goniolab.progress import format_eta
    from goniolab.session import ScanSession

    async with ScanSession.open(
        cfg, store, sample=plan.sample, time_scale=time_scale, operator=operator, model=model
    ) as session:
        if adaptive and run_id is None:
            plan = await session.adaptive_plan(plan)
            steps = [b - a for a, b in zip(plan.theta_r_deg, plan.theta_r_deg[1:], strict=False)]
            notify(
                f"adaptive sampling: {plan.n_geometries} angles "
                f"{plan.theta_r_deg[0]:g}..{plan.theta_r_deg[-1]:g} deg, "
                f"{min(steps):.2f} to {max(steps):.2f} deg apart"
            )
        # refuse an unsafe plan before any motion, and before a new run is even recorded
        # (the runner checks again); a resumed run checks only the readings still to take
        prepared = await session.prepare(plan, run_id)
        scale = session.clock_scale
        check = prepared.check
        lab_time = "" if scale == 1.0 else f" ({check.eta_s:.2f} s of lab clock)"
        # the motion model knows moves, dwells and exposures, not the computing and the
        # links (issue 27: "ETA 27 s" before a scan of 47 s); an instant sim clock takes no
        # wall time for the lab's. The live ETA measures the run (goniolab.scan.eta).
        if scale > 0:
            eta = f"motion and exposures {format_eta(check.eta_s / scale)}{lab_time}"
        else:
            eta = f"motion and exposures{lab_time}"
        homed = await session.homed()
        notify(
            f"{check.n_readings} readings, {check.n_moves} moves; {eta}, "
            "the live ETA measures the rest"
            + ("" if homed else " (after homing the arms, which is not estimated)")
        )
        runner = session.start(prepared, meta=meta)
        notify(f"run {runner.run_id} in store {store.location}")
        logging.getLogger("goniolab").info("run %d in store %s", runner.run_id, store.location)
        if on_start is not None:
            on_start(runner)
        async with _reporting(session, reporter):
            result = await session.run(runner)
        model_col = store.get_run(runner.run_id).model
    return ScanOutcome(
        run_id=result.run_id,
        state=result.state,
        reason=result.reason,
        summary=result.summary,
        store=store.location,
        config_source=cfg.source,
        plan=plan,
        model=dict(model_col),
    )


async def scan(
    cfg: LabConfig,
    store: RunStore,
    plan: BrdfPlan,
    *,
    time_scale: float | None = None,
    model: str | None = None,
    adaptive: bool = False,
    meta: RunMeta | None = None,
    reporter: Reporter | None = None,
    notify: Notify = quiet,
    on_start: Callable[[ScanRunner], None] | None = None,
    operator: SpecimenHook | None = None,
    reflectance_model: Any = None,
) -> ScanOutcome:
    """Scan ``plan`` on the lab of ``cfg`` into ``store``: open the lab (the plan's sample
    under the instruments), home, refuse an unsafe plan before anything moves or is stored,
    record the run (with ``meta`` over the config's ``[run]``), take and store every
    reading, park. ``model`` overrides ``[sample] model``; ``adaptive`` places the angles
    where the predicted curve bends. ``on_start`` gets the runner once the run is stored
    (abort it there). A run that ends failed or aborted is returned, not raised.

    Raises
    ------
    UserError
        The plan refused, an instrument unreachable, the store refusing the run.
    """
    if not adaptive:  # (an adaptive plan's angles are chosen, then checked, on the lab)
        # out of the arms' reach: refused in the dry run's words before any instrument is
        # reached (a typo'd sweep needs no lab); the session's dry run checks again
        check_reach(cfg, plan)
    with lab_errors("scan"):
        return await _scan_on(
            with_model(cfg, model), store, plan, run_id=None, time_scale=time_scale,
            adaptive=adaptive, meta=meta, reporter=reporter, notify=notify,
            on_start=on_start, operator=operator, model=reflectance_model,
        )  # fmt: skip


async def resume(
    store: RunStore,
    run_id: int,
    *,
    config: str | None = None,
    use_current_config: bool = False,
    time_scale: float | None = None,
    reporter: Reporter | None = None,
    notify: Notify = quiet,
    on_start: Callable[[ScanRunner], None] | None = None,
    operator: SpecimenHook | None = None,
    live: LabConfig | None = None,
) -> ScanOutcome:
    """Continue the stored scan ``run_id`` with its stored plan and config
    (:func:`resume_config`) and the model it started with; the readings stored are kept.

    Raises
    ------
    UserError
        No such run, a run that is no scan or is done, a config changed since, an
        alignment or a calibration (run them again), or what :func:`scan` raises.
    """
    from goniolab.scan.plans import BrdfPlan
    from goniolab.session import resume_target
    from goniolab.store import StoreError

    try:  # no such run, a damaged row: the user's to fix (exit 2)
        rec = store.get_run(run_id)
    except StoreError as exc:
        raise UserError(str(exc)) from exc
    with lab_errors("scan resume"):
        if rec.kind in ("align", "calibration"):
            what = "an alignment" if rec.kind == "align" else "a calibration"
            raise UserError(
                f"run {rec.id} is {what}: it cannot be resumed, run it again "
                f"({'scan --plan align' if rec.kind == 'align' else 'calibrate'})"
            )
        done = store.count_points(rec.id)
        resume_target(rec, None, done, need_file=False)
        cfg = resume_config(rec, config, use_current_config, live=live, notify=notify)
        # the run goes on with the model it started with (a `scan --model` override
        # included), so the predictions still to compute are that model's, not the config's
        cfg = with_model(cfg, started_with(rec))
        notify(f"resuming run {rec.id}: {done} readings stored")
        plan = BrdfPlan.from_dict(rec.plan)
        return await _scan_on(
            cfg, store, plan, run_id=rec.id, time_scale=time_scale, adaptive=False,
            meta=None, reporter=reporter, notify=notify, on_start=on_start,
            operator=operator,
        )  # fmt: skip


# --------------------------------------------------------------------------- align
@dataclass(frozen=True)
class AlignOutcome:
    """An alignment's stored run, its result and where it was saved (``state_file``:
    the lab's alignment state file, empty when stored with the run only)."""

    run_id: int
    result: AlignResult
    config_source: str
    store: str

    def as_dict(self) -> dict[str, Any]:
        """``goniolab scan --plan align --json``."""
        return {"run_id": self.run_id, "state": "done", "config_written": False,
                **self.result.as_dict()}  # fmt: skip


async def align(
    cfg: LabConfig,
    store: RunStore,
    plan: AlignPlan,
    *,
    time_scale: float | None = None,
    save_state: bool = True,
    reporter: Reporter | None = None,
    operator: SpecimenHook | None = None,
) -> AlignOutcome:
    """Find the arms' zero offsets and the sample's tilt (:meth:`ScanSession.align`): the
    black-glass standard, then the sample; saved to the lab's alignment state file when
    ``save_state`` (never the config file).

    Raises
    ------
    UserError
        The alignment failed or was aborted (the run says why), an instrument unreachable.
    """
    from goniolab.session import ScanSession

    with lab_errors("scan --plan align"):
        async with (
            ScanSession.open(
                cfg, store, sample=plan.sample, time_scale=time_scale, operator=operator
            ) as session,
            _reporting(session, reporter),
        ):
            run_id, result = await session.align(plan, save_state=save_state)
    return AlignOutcome(run_id, result, cfg.source, store.location)


# --------------------------------------------------------------------------- calibrate
@dataclass(frozen=True)
class CalibrationOutcome:
    """A calibration's stored run and its record (:mod:`goniolab.scan.calibration`)."""

    run_id: int
    record: dict[str, Any]
    config_source: str
    store: str


async def calibrate(
    cfg: LabConfig,
    store: RunStore,
    *,
    theta_deg: float = 45.0,
    repeats: int = 3,
    time_scale: float | None = None,
    operator: SpecimenHook | None = None,
    notify: Notify = quiet,
) -> CalibrationOutcome:
    """Read the reference mirror and the black-glass check standard against their
    certificates at the specular geometry ``theta_deg``, store a ``calibration`` run that
    later runs cite, park the arms.

    Raises
    ------
    UserError
        The calibration failed (the run is marked failed with the reason), no operator to
        place the standards on a real lab, an instrument unreachable.
    """
    from drivers.base import DeviceError
    from goniolab import __version__
    from goniolab.scan.calibration import (
        CalibrationRefused,
        detector_polarisation,
        run_calibration,
    )
    from goniolab.scan.colour import PointColour
    from goniolab.scan.events import RunState
    from goniolab.session import ScanSession, config_snapshot, home_timeout_s

    with lab_errors("calibrate"):
        async with ScanSession.open(
            cfg, store, time_scale=time_scale, operator=operator
        ) as session:
            mirror, check = session.standard("mirror"), session.standard("black_glass")
            plan = {"kind": "calibration", "theta_deg": theta_deg, "repeats": repeats,
                    "check": check.name}  # fmt: skip
            run_id = store.create_run(
                kind="calibration", plan=plan, config=config_snapshot(cfg), sample="",
                model={}, version=__version__,
            )  # fmt: skip
            hook = session.lab.place_specimen or session.operator
            if hook is None:
                raise UserError("a calibration needs an operator to place the standards")
            # the check standard is read as the chain reads it: the detector's s-weight
            simulated = cfg.lab.mode == "sim" or cfg.lab.start_sim_servers
            polarisation = detector_polarisation(
                store,
                alignment_run=cfg.alignment.run,
                simulated_s_weight=cfg.sim.twin.s_weight if simulated else None,
            )
            try:
                if not await session.homed():
                    await session.home()
                record = await run_calibration(
                    goniometer=session.lab.goniometer, spectro=session.lab.spectro,
                    place=hook, store=store, run_id=run_id, mirror=mirror, check=check,
                    settings=PointColour.from_config(cfg).settings, theta_deg=theta_deg,
                    repeats=repeats, exposure_us=cfg.spectro.exposure_us,
                    move_timeout_s=cfg.goniometer.move_timeout_s, polarisation=polarisation,
                )  # fmt: skip
            except (CalibrationRefused, DeviceError) as exc:
                store.set_status(run_id, RunState.FAILED.value, str(exc))
                raise UserError(f"calibration run {run_id} failed: {exc}", exit_code=1) from exc
            finally:
                park_problem = ""
                try:
                    await session.lab.goniometer.park(home_timeout_s(cfg))
                except DeviceError as exc:
                    park_problem = f"parking failed: {exc}"
                    notify(f"warning: {park_problem}")
            if park_problem:  # said, and kept with the record (--json, the stored run)
                record["warnings"] = [park_problem]
                store.update_model(run_id, {"calibration": record})
            store.set_status(run_id, RunState.DONE.value, park_problem)
    return CalibrationOutcome(run_id, record, cfg.source, store.location)


# --------------------------------------------------------------------------- lab
@contextlib.asynccontextmanager
async def open_lab(
    cfg: LabConfig, *, sample: str = "", time_scale: float | None = None
) -> AsyncIterator[Lab]:
    """The lab of ``cfg`` (``sample`` under the instruments of a simulated one), connected,
    closed after; an instrument that cannot be reached is a :class:`UserError`."""
    from goniolab.lab_wiring import Lab
    from goniolab.session import with_sample

    with lab_errors():
        async with Lab.from_config(with_sample(cfg, sample), time_scale=time_scale) as lab:
            yield lab


async def home_arms(lab: Lab) -> None:
    """Home both arms of an open lab unless they have their reference (what a scan does
    first; the time allowed: :func:`goniolab.session.home_timeout_s`)."""
    from typing import cast

    from goniolab.session import ScanSession
    from goniolab.store import RunStore

    session = ScanSession(lab, cast(RunStore, None))  # homing stores nothing
    with lab_errors():
        if not await session.homed():
            await session.home()


async def reset_alarms(cfg: LabConfig) -> list[ArmAlarm]:
    """Read both arms' controller alarms, reset the alarmed ones and read them again
    (:func:`goniolab.scan.alarm.reset_alarms`); nothing moves."""
    from goniolab.scan.alarm import reset_alarms as reset

    async with open_lab(cfg) as lab:
        with lab_errors():
            return await reset(lab.goniometer)


@dataclass(frozen=True)
class ServedLab:
    """A simulated lab served on the wire: its clock scale and each device's endpoint."""

    time_scale: float
    endpoints: dict[str, dict[str, Any]]


@contextlib.asynccontextmanager
async def serve_simulated_lab(
    cfg: LabConfig, *, time_scale: float | None = None
) -> AsyncIterator[ServedLab]:
    """Serve the simulated instruments of ``cfg`` (Modbus TCP / RTU controllers, pty serial
    devices; ``goniolab sim serve``) until the block ends.

    Raises
    ------
    UserError
        A port cannot be opened.
    """
    import asyncio

    from drivers.timing import SimClock
    from goniolab.lab_wiring import build_sim_instruments, build_sim_server, sample_model

    scale = cfg.lab.time_scale if time_scale is None else time_scale
    model = await asyncio.to_thread(sample_model, cfg)
    server = build_sim_server(cfg, build_sim_instruments(cfg, model, SimClock(scale)))
    try:
        try:
            await server.start()
        except OSError as exc:
            raise UserError(f"cannot start the simulated lab: {exc}", exit_code=1) from None
        yield ServedLab(scale, server.endpoints())
    finally:
        await server.stop()


async def check_plan(lab: Lab, plan: BrdfPlan, *, what: str = "scan") -> PreparedScan:
    """What :func:`scan` does before its first move, on a lab another face drives (the
    bluesky plan): the session's dry run of every geometry and the park position from
    where the arms stand, and the plan's prediction model with its provenance. Nothing
    moves, nothing is stored.

    Raises
    ------
    UserError
        ``plan refused (no arm moved): ...``: a geometry out of the arms' reach.
    """
    from typing import cast

    from goniolab.session import ScanSession
    from goniolab.store import RunStore

    # a new run reads nothing from the store: the session's dry run needs none
    session = ScanSession(lab, cast(RunStore, None))
    with lab_errors(what):
        return await session.prepare(plan)
