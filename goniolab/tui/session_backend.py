"""The TUI's :class:`~goniolab.tui.view_model.Backend` over :mod:`goniolab.session`.

The same sessions as ``goniolab scan`` and ``goniolab gloss log`` (a real or simulated
:class:`~goniolab.lab_wiring.Lab`): :class:`~goniolab.session.ScanSession` for BRDF scans and
:class:`~goniolab.session.GlossSession` for glossmeter readings, every reading committed
to the :class:`~goniolab.store.RunStore` as it is taken, so a run started here stores the
same rows as one started from the CLI (and ``goniolab scan resume`` continues it). All
publish on one :class:`~goniolab.scan.events.EventBus` that the app consumes.
No Textual here.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
from collections.abc import Callable
from contextlib import AsyncExitStack
from pathlib import Path
from typing import Any

from drivers.base import GLOSS_ANGLES_DEG, DeviceError
from goniolab.app.lab_setup import (
    brdf_plan,
    check_reach,
    check_sample,
    lab_errors,
    load_config,
    open_store,
    plan_refused,
    store_location,
)
from goniolab.errors import UserError
from goniolab.optics.models import ReflectanceModel
from goniolab.scan.align import AlignPlan, AlignRunner
from goniolab.scan.events import (
    ColourPredicted,
    EventBus,
    GlossRead,
    InstrumentError,
    PointMeasured,
    PointPredicted,
    RunFinished,
    RunState,
)
from goniolab.scan.plans import DEFAULT_REPEATS, BrdfPlan, GlossPlan
from goniolab.scan.prediction import Predictor
from goniolab.scan.runner import PlanRefused, ScanRunner
from goniolab.session import GlossSession, ScanSession
from goniolab.store import RunMeta, StoreError
from goniolab.surfaces.synthetic import sample_names
from goniolab.tui.view_model import ArmState, RunIdentity, RunSummary, ScanSetup, StoredRun

__all__ = ["SessionBackend"]

_LOG = logging.getLogger(__name__)

#: The default scan of the form: the seed's in-plane sweep, theta_i = 45 deg, detector
#: 0..70 deg in 1 deg steps (Wittmann et al. 2021, sec. 2.3 and 4.2; the seed repeats 5 times),
#: repeats as everywhere else (:data:`goniolab.scan.plans.DEFAULT_REPEATS`).
DEFAULT_THETA_I_DEG = 45.0
DEFAULT_THETA_R_DEG = (0.0, 70.0, 1.0)


class SessionBackend:
    """The lab behind the TUI.

    Parameters
    ----------
    config_path
        A lab config TOML (``configs/lab-sim.toml``); read and validated here, so a bad
        file is reported (file, key, reason) before the UI starts.
    time_scale
        Sim clock scale overriding ``[lab] time_scale`` (0 = instant, tests).
    sample
        Initial sample of the form (``sample:NAME`` or ``NAME`` or a height-map path);
        default: the config's ``[sample] map``.
    store_path
        Run store file overriding ``[lab] store``.
    model
        Reflectance model of the configured sample, instead of building it from
        ``[sample] map`` (passed to :class:`~goniolab.lab_wiring.Lab`; tests use a cheap one).
    align_plan
        The sweeps of the ``a`` key's alignment (default: ``scan --plan align``'s); its
        sample and exposure are the form's and the config's.
    """

    def __init__(
        self,
        config_path: str | Path,
        *,
        time_scale: float | None = None,
        sample: str | None = None,
        store_path: str | None = None,
        model: ReflectanceModel | None = None,
        align_plan: AlignPlan | None = None,
    ) -> None:
        self._lab_model = model
        self._align_plan = align_plan or AlignPlan()
        self.config_path = Path(config_path)
        self.config = load_config(self.config_path, store_path)
        self.time_scale = time_scale
        # The config's own map is resolved (relative to the config file) by the Lab.
        self.sample = self.config.sample.map
        if sample:
            self.sample = _sample_spec(sample)
            check_sample(self.sample, given=sample)
        self.store_path = store_location(store_path, config=self.config)
        self.bus = EventBus()
        self.session: ScanSession | None = None
        self.gloss: GlossSession | None = None
        self._stack = AsyncExitStack()
        self._runner: ScanRunner | None = None
        self._align_runner: AlignRunner | None = None
        self._task: asyncio.Task[None] | None = None
        self._gloss_task: asyncio.Task[None] | None = None
        # a request while a reading is under way: the sample of the newest one, and the
        # future of the one reading that serves them all (issue 27, item 7)
        self._gloss_next: str | None = None
        self._gloss_next_done: asyncio.Future[None] | None = None
        self._gloss_runs: dict[tuple[str, RunIdentity], int] = {}
        self._scan_sample = ""
        #: Stored with every run started from now on (key i in the TUI).
        self.run_identity = RunIdentity()
        self._closed = False

    def _run_meta(self) -> RunMeta:
        """:attr:`run_identity` as the store's run metadata (the config's ``[run]`` table
        fills what it leaves empty: ScanSession.start / GlossSession.create_run)."""
        i = self.run_identity
        return RunMeta(operator=i.operator, sample_id=i.sample_id, notes=i.notes, tags=i.tags)

    # ------------------------------------------------------------------ lifecycle
    @property
    def title(self) -> str:
        lab = self.config.lab
        scale = lab.time_scale if self.time_scale is None else self.time_scale
        clock = f", sim clock x{scale:g}" if lab.mode == "sim" else ""
        return f"{lab.name} ({lab.mode}{clock})"

    async def open(self) -> None:
        """Build the lab (connect every instrument), open the store, home the goniometer."""
        try:
            store = open_store(self.store_path, exit_code=1)
            self._stack.callback(store.close)
            session = await self._stack.enter_async_context(
                ScanSession.open(
                    self.config,
                    store,
                    time_scale=self.time_scale,
                    model=self._lab_model,
                    bus=self.bus,
                )
            )
        except BaseException:
            await self._stack.aclose()
            raise
        self.session = session
        self.gloss = GlossSession.of_lab(session.lab, store, models=session.models, bus=self.bus)
        await session.home()

    async def home(self) -> None:
        """Reset both arms' alarms and home again; :meth:`open` if the lab is not built."""
        if self.session is None:
            await self.open()
            return
        if self.running:
            raise UserError("a scan is running: abort it before homing")
        await self.session.home(reset_alarms=True)

    async def close(self) -> None:
        """Abort a running scan (the runner parks the arms), then release everything."""
        self._closed = True
        if self.running:
            self.abort()
        for task in (self._task, self._gloss_task):
            if task is not None and not task.done():
                if task is self._gloss_task:
                    task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
        self._end_gloss_runs()
        await self._stack.aclose()
        self.bus.close()

    def _end_gloss_runs(self) -> None:
        """The session's gloss runs stayed ``running`` while it took readings; they end
        ``done`` with it (a run a reading failed keeps its failed state)."""
        if self.gloss is None:
            return
        store = self.gloss.store
        for run_id in self._gloss_runs.values():
            with contextlib.suppress(StoreError):
                if store.get_run(run_id).status == RunState.RUNNING.value:
                    store.set_status(run_id, RunState.DONE.value)

    # ------------------------------------------------------------------ form
    def sample_names(self) -> list[str]:
        return list(sample_names())

    def default_setup(self) -> ScanSetup:
        start, stop, step = DEFAULT_THETA_R_DEG
        return ScanSetup(
            sample=self.sample,
            theta_i_deg=DEFAULT_THETA_I_DEG,
            theta_r_start_deg=start,
            theta_r_stop_deg=stop,
            theta_r_step_deg=step,
            repeats=DEFAULT_REPEATS,
        )

    def check_setup(self, setup: ScanSetup) -> None:
        """:meth:`ScanSetup.validate`, then the plan's reach as ``goniolab scan`` refuses
        it (:func:`goniolab.app.lab_setup.check_reach`: the config's arm limits, interlock
        and park, the alignment's corrections; its words)."""
        self._plan(setup)

    def _plan(self, setup: ScanSetup) -> BrdfPlan:
        """The form's plan, checked (:meth:`check_setup`)."""
        setup.validate()
        plan = brdf_plan(
            self.config,
            sample=setup.sample,
            theta_i_deg=setup.theta_i_deg,
            theta_r_deg=tuple(setup.theta_r_values_deg()),
            repeats=setup.repeats,
            what="scan setup",
        )
        # The open lab's corrections (an alignment run here changed them since the config
        # was read); before the lab is open, the config's.
        corrections = None if self.session is None else self.session.lab.goniometer.corrections_deg
        check_reach(self.config, plan, corrections_deg=corrections)
        return plan

    @property
    def simulated(self) -> bool:
        """The instruments are simulated (in-process or served on the wire)."""
        lab = self.config.lab
        return lab.mode == "sim" or lab.start_sim_servers

    @property
    def sample_note(self) -> str:
        if self.simulated:
            return "the simulated lab measures the selected sample"
        return "place the selected sample under the instruments"

    async def predict_curve(self, setup: ScanSetup) -> list[float]:
        """The prediction of ``setup.sample`` over the sweep (model built and evaluated in
        worker threads, see :class:`~goniolab.scan.prediction.Predictor`)."""
        self.check_setup(setup)
        model = await self.model(setup.sample)
        values = await asyncio.to_thread(
            Predictor.from_config(model, self.config).predict_sync,
            setup.theta_i_deg,
            setup.theta_r_values_deg(),
        )
        return [float(v) for v in values]

    # ------------------------------------------------------------------ scans
    @property
    def running(self) -> bool:
        return self._task is not None and not self._task.done()

    def _require_open(self) -> ScanSession:
        if self.session is None:
            raise UserError("the lab is not connected", exit_code=1)
        return self.session

    async def model(self, sample: str) -> ReflectanceModel:
        """The prediction model of ``sample``: the lab's own for the configured sample,
        else :func:`goniolab.model_cache.model_for` (built in a worker thread, cached)."""
        return await self._require_open().models.get(sample)

    async def start(self, setup: ScanSetup) -> int:
        """Check the plan (every geometry and the park position), then create the run in
        the store and start the runner in a task; return the run id."""
        plan = self._plan(setup)
        session = self._require_open()
        if self.running:
            raise UserError("a scan is already running")
        # The runner's dry run would refuse these too, but only after the run is stored
        # as failed: a geometry out of the arms' reach is a form error, in the words of
        # goniolab scan (plan_refused).
        try:
            scan = await session.prepare(plan)
        except PlanRefused as exc:
            raise plan_refused(exc) from exc
        if self.running:  # started meanwhile (the model was built in a thread)
            raise UserError("a scan is already running")
        self._scan_sample = setup.sample
        self._runner = runner = session.start(scan, meta=self._run_meta())
        self._task = asyncio.get_running_loop().create_task(
            self._run(session, runner), name=f"tui-run-{runner.run_id}"
        )
        return runner.run_id

    async def align(self, sample: str) -> int:
        """Start ``scan --plan align`` for ``sample`` in a task (the CLI's default plan,
        :class:`~goniolab.scan.align.AlignPlan`); the result is saved to the lab's
        alignment state file (never the config file) and the arms correct every later move. Return the run id once the
        run is stored."""
        session = self._require_open()
        if self.running:
            raise UserError("a run is already in progress")
        spec = _sample_spec(sample) if sample else self.sample
        check_sample(spec, option="align: sample", given=sample)
        plan = dataclasses.replace(
            self._align_plan, sample=spec, exposure_us=self.config.spectro.exposure_us
        )
        loop = asyncio.get_running_loop()
        started: asyncio.Future[int] = loop.create_future()

        def on_start(runner: AlignRunner) -> None:
            self._align_runner = runner
            started.set_result(runner.run_id)

        self._scan_sample = spec
        self._task = task = loop.create_task(self._align(session, plan, on_start), name="tui-align")
        waiters: set[asyncio.Future[Any]] = {started, task}
        await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
        if started.done():
            return started.result()
        task.result()  # the error that stopped it before the run was stored
        raise UserError("the alignment ended before it started", exit_code=1)

    async def _align(
        self, session: ScanSession, plan: AlignPlan, on_start: Callable[[AlignRunner], None]
    ) -> None:
        """Run the alignment; a failure after the run was stored becomes events."""
        try:
            await session.align(plan, save_state=True, started=on_start)
        except Exception as exc:
            runner = self._align_runner
            if runner is None or runner.plan is not plan:
                raise  # not started: start() reports it
            if not isinstance(exc, UserError | DeviceError | StoreError | OSError):
                self._internal_error(runner.run_id, "alignment", exc, finished=runner.finished)
            elif not runner.aborted:  # aborted: the runner published its RunFinished(aborted)
                self._fail(runner.run_id, "lab", str(exc), finished=runner.finished)

    def _fail(self, run_id: int, device: str, reason: str, *, finished: bool = False) -> None:
        """The run failed: the fatal error on screen, and the run's end unless its runner
        has published it (``finished``: it records the failure itself)."""
        self.bus.publish(InstrumentError(run_id=run_id, device=device, message=reason, fatal=True))
        if not finished:
            self.bus.publish(
                RunFinished(run_id=run_id, state=RunState.FAILED, reason=reason, summary={})
            )

    def _internal_error(self, run_id: int, what: str, exc: Exception, *, finished: bool) -> None:
        """An error no part of the lab expected (a defect): the run ends as failed on screen
        with the error named and the traceback in the log; the readings taken stay in the
        store. Before, the task died unseen and the run looked frozen."""
        _LOG.error("%s of run %d stopped by an internal error", what, run_id, exc_info=exc)
        reason = (
            f"internal error: {type(exc).__name__}: {exc} (the traceback is in the log; "
            "the readings taken are kept)"
        )
        self._fail(run_id, "lab", reason, finished=finished)

    async def _run(self, session: ScanSession, runner: ScanRunner) -> None:
        """Run to the end; a refused plan or an unexpected error becomes events, not a crash."""
        run_id = runner.run_id
        try:
            with lab_errors():  # the one translation, as the CLI's and the API's scans
                await session.run(runner)
        except UserError as exc:  # a refused plan, an instrument, the store, a held run
            device = "goniometer" if isinstance(exc.__cause__, PlanRefused) else "lab"
            self._fail(run_id, device, str(exc))
        except OSError as exc:
            self._fail(run_id, "lab", str(exc))
        except Exception as exc:
            done = runner.state in (RunState.DONE, RunState.FAILED, RunState.ABORTED)
            self._internal_error(run_id, "scan", exc, finished=done)

    def pause(self) -> None:
        if self._runner is not None:
            self._runner.pause()

    def resume(self) -> None:
        if self._runner is not None:
            self._runner.resume()

    def abort(self) -> None:
        if self._align_runner is not None and self.running:
            self._align_runner.abort()
        if self._runner is not None:
            self._runner.abort()

    # ------------------------------------------------------------------ gloss
    @property
    def gloss_busy(self) -> bool:
        """A glossmeter reading is in progress."""
        return self._gloss_task is not None and not self._gloss_task.done()

    async def read_gloss(self, sample: str) -> asyncio.Future[None]:
        """Take one glossmeter reading (20/60/85) in the background, logged in the store;
        return a future that is done once it is stored (its exception: why it failed).

        A request while a reading is under way (the ``g`` key while ``--gloss-every``
        polls) is not refused: requests coalesce into one more reading right after the
        current one, for the newest request's sample, and share its future.

        The readings of one TUI session go into one ``gloss`` run per sample; the
        prediction of ``sample`` (ISO 2813, :func:`goniolab.scan.gloss_logger.predict_gloss`) is
        shown beside. During a scan the scan's sample lies under the instruments, so the
        reading is taken (and predicted) for that one.
        """
        self._require_open()
        loop = asyncio.get_running_loop()
        if self.gloss_busy:
            self._gloss_next = sample
            if self._gloss_next_done is None:
                self._gloss_next_done = loop.create_future()
            return self._gloss_next_done
        done: asyncio.Future[None] = loop.create_future()
        self._gloss_task = loop.create_task(self._gloss_chain(sample, done), name="tui-gloss")
        return done

    async def _gloss_chain(self, sample: str, done: asyncio.Future[None]) -> None:
        """Readings one after the other: this one, then a coalesced request, if any."""
        while True:
            try:
                await self._one_gloss(sample)
            except asyncio.CancelledError:
                for fut in (done, self._gloss_next_done):
                    if fut is not None and not fut.done():
                        fut.cancel()
                raise
            except Exception as exc:
                if not done.done():
                    done.set_exception(exc)
            else:
                if not done.done():
                    done.set_result(None)
            if self._gloss_next is None or self._gloss_next_done is None or self._closed:
                return
            sample, done = self._gloss_next, self._gloss_next_done
            self._gloss_next = self._gloss_next_done = None

    async def _one_gloss(self, sample: str) -> None:
        session = self._require_open()
        assert self.gloss is not None
        if self.running:
            sample = self._scan_sample
        prediction = await self.gloss.predict(sample, GLOSS_ANGLES_DEG)
        if not self.running and prediction.model is not None:
            await session.lab.prepare_sample(sample)  # the realistic twin's truth, in a thread
            if not self.running:  # a scan's sample stays under them
                session.lab.put_sample(prediction.model, sample)
        plan = GlossPlan(count=1, angles_deg=GLOSS_ANGLES_DEG, sample=sample)
        key = (sample, self.run_identity)  # a new identity starts a new gloss run
        run_id = self._gloss_runs.get(key)
        if run_id is None:
            run_id = self._gloss_runs[key] = self.gloss.create_run(
                plan, prediction, meta=self._run_meta()
            )
            # held while the app is open: another 'goniolab runs list' reads it as running,
            # not interrupted (a run stored as running that nobody claims)
            self._stack.enter_context(self.gloss.store.claim_run(run_id))
            # the calibration the readings rest on (gloss calibrate), in the run's record:
            # the gloss log toasts its warnings (none recorded, old) with the prediction's
            from goniolab.app.lab_gloss import record_gloss_calibration

            record_gloss_calibration(
                self.gloss.store, run_id, self.gloss.meter, plan.angles_deg,
                max_age_h=self.config.glossmeter.calibration_max_age_h,
            )  # fmt: skip
        # the session's gloss run goes on until the app closes: "running", not "done"
        await self.gloss.logger(plan, run_id, prediction, keep_running=True).run()

    # ------------------------------------------------------------------ status
    async def arm_states(self) -> tuple[ArmState, ArmState]:
        if self._closed:
            raise UserError("the lab is closed", exit_code=1)
        gonio = self._require_open().lab.goniometer
        return (
            await _arm_state("lamp", gonio.lamp),
            await _arm_state("detector", gonio.detector),
        )

    # ------------------------------------------------------------------ store
    def prediction_record(self, run_id: int) -> dict[str, Any]:
        """Run ``run_id``'s stored prediction record (``computed_by`` among it)."""
        with open_store(self.store_path, readonly=True) as store:
            model = store.get_run(run_id).model
        return model if isinstance(model, dict) else {}

    def prediction_models(self, run_id: int) -> str:
        """Which model computes the run's predicted curve, from its stored record
        (``computed_by``, :meth:`goniolab.scan.prediction.Predictor.provenance`)."""
        with open_store(self.store_path, readonly=True) as store:
            computed_by = store.get_run(run_id).model.get("computed_by") or {}
        if len(computed_by) == 1:
            return str(next(iter(computed_by)))
        return ", ".join(
            f"{m} {min(a):g}-{max(a):g} deg" for m, a in sorted(computed_by.items()) if a
        )

    def list_runs(self) -> list[RunSummary]:
        """Stored runs, newest first (own read-only connection: safe from a worker thread)."""
        with open_store(self.store_path, readonly=True) as store:
            out = []
            for rec in store.list_runs(limit=200):
                n = (
                    len(store.gloss_readings(rec.id))
                    if rec.kind == "gloss"
                    else store.count_points(rec.id)
                )
                out.append(RunSummary(rec.id, rec.created_at, rec.kind, rec.sample, rec.status, n))
            return out

    def load_run(self, run_id: int) -> StoredRun:
        """One stored run as events (own read-only connection: safe from a worker thread)."""
        with open_store(self.store_path, readonly=True) as store:
            rec = store.get_run(run_id)
            measured: list[PointMeasured] = []
            predicted: list[PointPredicted] = []
            gloss: list[GlossRead] = []
            colours: list[ColourPredicted] = []
            if rec.kind == "brdf":
                plan = BrdfPlan.from_dict(rec.plan)
                white = _stored_white_xyz(rec.config)
                for p in store.points(run_id):
                    col = p.colour
                    measured.append(
                        PointMeasured(
                            run_id=run_id,
                            timestamp=p.timestamp,
                            index=p.index,
                            repeat=p.repeat,
                            theta_i_deg=p.theta_i_deg,
                            theta_r_deg=p.theta_r_deg,
                            luminance_pct=p.luminance_pct,
                            measured_theta_i_deg=p.measured_theta_i_deg,
                            measured_theta_r_deg=p.measured_theta_r_deg,
                            lab=None if col is None else (col["L"], col["a"], col["b"]),
                            # as the live event: repeats are averaged as spectra (issue 25)
                            xyz=None if col is None else (col["X"], col["Y"], col["Z"]),
                            white_xyz=None if col is None else white,
                            quality=str(p.raw.get("quality", "unknown")),
                        )
                    )
                for index, c in sorted(store.predicted_colours(run_id).items()):
                    colours.append(
                        ColourPredicted(
                            run_id=run_id,
                            index=index,
                            theta_r_deg=plan.theta_r_deg[index],
                            lab=(c.L, c.a, c.b),
                        )
                    )
                for index, value in sorted(store.predictions(run_id).items()):
                    predicted.append(
                        PointPredicted(
                            run_id=run_id,
                            index=index,
                            theta_i_deg=plan.theta_i_deg,
                            theta_r_deg=plan.theta_r_deg[index],
                            predicted_pct=value,
                        )
                    )
            for g in store.gloss_readings(run_id):
                gloss.append(
                    GlossRead(
                        run_id=run_id,
                        timestamp=g.timestamp,
                        values_gu=g.values_gu,
                        predicted_gu=g.predicted_gu,
                        temperature_c=g.temperature_c,
                    )
                )
            summary = RunSummary(
                rec.id,
                rec.created_at,
                rec.kind,
                rec.sample,
                rec.status,
                len(measured) if rec.kind == "brdf" else len(gloss),
            )
            model = rec.model if isinstance(rec.model, dict) else {}
            return StoredRun(summary, measured, predicted, gloss, colours, model)


def _stored_white_xyz(config: dict[str, Any]) -> tuple[float, float, float] | None:
    """The white a stored run's L*a*b* is relative to (its snapshot's ``[colour]``, as
    the runner's :class:`goniolab.scan.colour.PointColour`); ``None`` for a snapshot that
    cannot say (its repeats are then averaged as L*a*b*, as ``runs colour`` does)."""
    from goniolab.colour.spectra import white_xyz
    from goniolab.scan.colour import PointColour

    try:
        x, y, z = (float(v) for v in white_xyz(PointColour.from_snapshot(config).settings))
    except (TypeError, ValueError, AttributeError):
        return None
    return (x, y, z)


#: A status read that takes longer than this shows the arm's link as lost (seconds).
STATUS_TIMEOUT_S = 2.0


async def _arm_state(name: str, axis: Any) -> ArmState:
    """One arm's status; a device error or no answer shows as a lost link with the reason."""
    try:
        async with asyncio.timeout(STATUS_TIMEOUT_S):
            st = await axis.status()
    except DeviceError as exc:
        return ArmState(name, None, False, False, None, False, exc.message)
    except TimeoutError:
        return ArmState(
            name, None, False, False, None, False, f"no status in {STATUS_TIMEOUT_S:g} s"
        )
    return ArmState(
        name,
        float(st.position_deg),
        bool(st.moving),
        bool(st.homed),
        st.alarm_code,
        True,
        "" if st.alarm_code is None else f"alarm {st.alarm_code:#x}",
    )


def _sample_spec(sample: str) -> str:
    """``NAME`` -> ``sample:NAME`` unless it looks like a path or already has the prefix."""
    if sample.startswith("sample:") or "/" in sample or "." in sample:
        return sample
    return f"sample:{sample}"
