"""One scan session and one gloss session over a lab, shared by the CLI and the TUI.

``goniolab scan`` (and ``scan resume``), ``goniolab gloss log`` and the TUI's backend
wire the same parts here, so a run started from either stores the same rows:

* :class:`ScanSession`: open the lab, home the arms, refuse an unsafe plan before anything
  is stored (every geometry *and* the park position, :func:`~goniolab.scan.runner.dry_run`),
  put the plan's sample under the instruments (simulated lab), record the run with the
  config it ran with (``_source`` names the file, so ``goniolab scan resume RUN`` needs no
  ``--config``), and run it (:class:`~goniolab.scan.runner.ScanRunner`: every reading
  stored as it is taken, the arms parked at the end, on an abort or a fault); a stored
  run that is not done is resumed the same way (:func:`resume_target`).
* :class:`GlossSession`: the sample's ISO 2813 prediction, a ``gloss`` run in the store,
  readings taken or received by :class:`~goniolab.scan.gloss_logger.GlossLogger` (which
  reconnects after a timeout or a lost link).

No UI here: the callers show the :class:`~goniolab.scan.events.EventBus` events and turn the
errors into their own messages.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.base import DeviceError, Glossmeter
from drivers.timing import Clock
from goniolab import __version__
from goniolab.config import LabConfig
from goniolab.errors import UserError, a_run_of_kind
from goniolab.lab_wiring import Lab
from goniolab.optics.models import ReflectanceModel
from goniolab.scan.align import AlignAborted, AlignPlan, AlignResult, AlignRunner
from goniolab.scan.colour import PointColour
from goniolab.scan.events import EventBus, RunState
from goniolab.scan.gloss_logger import GlossLogger, predict_gloss
from goniolab.scan.plans import BrdfPlan, GlossPlan, PlanError
from goniolab.scan.prediction import Predictor
from goniolab.scan.runner import ArmMotion, DryRun, PlanRefused, RunResult, ScanRunner, dry_run
from goniolab.scan.standards import Standard
from goniolab.store import RunMeta, RunRecord, RunStore

__all__ = [
    "HOME_TIMEOUT_MOVES",
    "GlossPrediction",
    "GlossSession",
    "PreparedScan",
    "SampleModels",
    "ScanSession",
    "check_sample",
    "config_meta",
    "config_snapshot",
    "home_timeout_s",
    "resume_target",
    "with_sample",
]

#: Homing (and parking, which may follow a home search) may take this many move timeouts.
HOME_TIMEOUT_MOVES = 4.0

#: Swaps the specimen ("mirror" or "sample") and returns once it lies under the instruments.
SpecimenHook = Callable[[str], Awaitable[None]]


def home_timeout_s(cfg: LabConfig) -> float:
    """Time allowed to home (or park) both arms: ``HOME_TIMEOUT_MOVES`` x
    ``[goniometer] move_timeout_s`` (120 s with the default 30 s)."""
    return HOME_TIMEOUT_MOVES * cfg.goniometer.move_timeout_s


def with_sample(cfg: LabConfig, sample: str) -> LabConfig:
    """``cfg`` with ``[sample] map`` set to ``sample``: in a simulated lab that is the sample
    under the instruments, in a real lab the one the prediction is made for."""
    if not sample or sample == cfg.sample.map:
        return cfg
    return cfg.model_copy(update={"sample": cfg.sample.model_copy(update={"map": sample})})


def config_snapshot(cfg: LabConfig) -> dict[str, Any]:
    """The config stored with a run: every key, and ``_source``, the absolute path of the
    file it was read from (what ``scan resume`` opens when no ``--config`` is given)."""
    snap: dict[str, Any] = cfg.model_dump(mode="json")
    snap["_source"] = str(Path(cfg.source).resolve()) if cfg.source else ""
    return snap


def config_meta(cfg: LabConfig | dict[str, Any], meta: RunMeta | None = None) -> RunMeta:
    """The run metadata of the config's ``[run]`` table with ``meta``'s fields over it
    (a command-line ``--operator`` wins over the config's; tags of both are kept)."""
    base = RunMeta()
    if isinstance(cfg, LabConfig):
        r = cfg.run
        base = RunMeta(operator=r.operator, sample_id=r.sample_id, notes=r.notes, tags=r.tags)
    return base if meta is None else base.merged(meta)


def check_sample(spec: str, *, option: str = "--sample", given: str = "") -> None:
    """Raise :class:`UserError` naming ``option`` and the value as ``given`` (default:
    ``spec``) when ``spec`` (``sample:NAME`` or a height-map path) names no built-in
    sample or no file."""
    arg = f"{option} {given or spec}"
    if spec.startswith("sample:"):
        from goniolab.surfaces.synthetic import sample_names

        name = spec.removeprefix("sample:")
        names = sample_names()
        if name not in names:
            raise UserError(f"{arg}: no built-in sample {name!r} (known: {', '.join(names)})")
    elif not Path(spec).is_file():
        raise UserError(f"{arg}: no such file (use sample:NAME or a height-map path)")


class SampleModels:
    """The reflectance model of each sample spec, built once in a worker thread.

    Parameters
    ----------
    n
        Refractive index of samples not in ``known`` (the config's ``[sample] n``).
    known
        Models already built, by spec (the lab's own model of its ``[sample] map``).
    """

    def __init__(
        self,
        n: complex | float,
        known: dict[str, ReflectanceModel] | None = None,
        *,
        model: str = "auto",
        wavelength_nm: float | None = None,
    ):
        self.n = n
        self.model = model
        self.wavelength_nm = wavelength_nm
        self._models: dict[str, ReflectanceModel] = dict(known or {})

    @classmethod
    def of_lab(cls, lab: Lab) -> SampleModels:
        """The lab's model for its configured sample; other samples with its index and
        the ``[sample]`` model and wavelength."""
        s = lab.config.sample
        return cls(s.n, {s.map: lab.model}, model=s.model, wavelength_nm=s.wavelength_nm)

    async def get(self, sample: str) -> ReflectanceModel:
        """The model of ``sample`` (:func:`goniolab.model_cache.model_for`, cached)."""
        if sample not in self._models:
            from goniolab.model_cache import model_for

            self._models[sample] = await asyncio.to_thread(
                model_for,
                sample,
                n=self.n,
                model=self.model,
                wavelength_nm=self.wavelength_nm,
            )
        return self._models[sample]


@dataclass(frozen=True, slots=True)
class PreparedScan:
    """A plan that passed the dry run, with its prediction model; nothing stored yet
    unless ``run_id`` (a run being resumed) is set."""

    plan: BrdfPlan
    run_id: int | None
    check: DryRun
    model: ReflectanceModel
    predictor: Predictor
    #: which model computes the prediction at each geometry, and its notes
    #: (:meth:`goniolab.scan.prediction.Predictor.provenance`)
    provenance: dict[str, Any] = field(default_factory=dict)


class ScanSession:
    """BRDF scans on an open lab: home, dry run, store, run, park, resume.

    Parameters
    ----------
    lab
        An open :class:`~goniolab.lab_wiring.Lab` with its goniometer and spectro.
    store
        The run store.
    bus
        Where the runner publishes (default: a new one).
    models
        Prediction models by sample (default: the lab's, :meth:`SampleModels.of_lab`).
    operator
        Asks the operator to swap mirror and sample for a mirror reference on a real lab
        (a simulated lab swaps them itself).
    """

    def __init__(
        self,
        lab: Lab,
        store: RunStore,
        *,
        bus: EventBus | None = None,
        models: SampleModels | None = None,
        operator: SpecimenHook | None = None,
    ) -> None:
        self.lab = lab
        self.store = store
        self.bus = EventBus() if bus is None else bus
        self.models = SampleModels.of_lab(lab) if models is None else models
        self.operator = operator

    @classmethod
    @asynccontextmanager
    async def open(
        cls,
        config: LabConfig,
        store: RunStore,
        *,
        sample: str = "",
        time_scale: float | None = None,
        model: ReflectanceModel | None = None,
        bus: EventBus | None = None,
        operator: SpecimenHook | None = None,
    ) -> AsyncIterator[ScanSession]:
        """Open the lab of ``config`` (with ``sample`` under the instruments), close it after."""
        lab_cfg = with_sample(config, sample)
        async with Lab.from_config(lab_cfg, time_scale=time_scale, model=model) as lab:
            yield cls(lab, store, bus=bus, operator=operator)

    @property
    def config(self) -> LabConfig:
        """The lab's config."""
        return self.lab.config

    @property
    def clock_scale(self) -> float:
        """Lab-clock seconds per wall second (a sim clock's scale, 1 for a real lab)."""
        return float(getattr(self.lab.clock, "scale", 1.0))

    async def homed(self) -> bool:
        """Both arms have their reference."""
        g = self.lab.goniometer
        return bool((await g.lamp.status()).homed and (await g.detector.status()).homed)

    async def home(self, *, reset_alarms: bool = False) -> None:
        """Home both arms (after resetting their alarms when asked)."""
        g = self.lab.goniometer
        if reset_alarms:
            for axis in (g.lamp, g.detector):
                await axis.reset_alarm()
        await g.home(home_timeout_s(self.config))

    async def prepare(self, plan: BrdfPlan, run_id: int | None = None) -> PreparedScan:
        """Dry-run the readings still to take (all of them for a new run) from where the
        arms stand, and build the sample's prediction model. Nothing moves, nothing is
        stored.

        Raises
        ------
        PlanRefused
            A geometry of the plan, or the park position, is out of the arms' reach.
        """
        g = self.config.goniometer
        done = set() if run_id is None else self.store.done_keys(run_id)
        start = await self.lab.goniometer.positions_deg()
        check = dry_run(
            [pt for pt in plan.points() if pt.key not in done],
            self.lab.goniometer,
            ArmMotion.from_config(g),
            start_deg=(float(start[0]), float(start[1])),
            dwell_s=plan.dwell_s,
            reading_time_s=plan.exposure_us * 1e-6,
            park_deg=(g.park.theta_i_deg, g.park.theta_r_deg),
        )
        model = await self.models.get(plan.sample)
        await self.lab.prepare_sample(plan.sample)  # the realistic twin's truth, in a thread
        predictor = Predictor.from_config(model, self.config)
        provenance = await asyncio.to_thread(
            predictor.provenance, plan.theta_i_deg, plan.theta_r_deg
        )
        return PreparedScan(plan, run_id, check, model, predictor, provenance)

    async def adaptive_plan(self, plan: BrdfPlan) -> BrdfPlan:
        """``plan`` with its detector angles placed where the predicted curve bends
        (:func:`goniolab.scan.adaptive.adaptive_angles`): as many angles, from the
        smallest to the largest of ``plan.theta_r_deg``, ``sampling = "adaptive"``.

        Raises
        ------
        UserError
            The range cannot hold that many angles 0.05 deg apart, or the prediction is
            not finite on it.
        """
        import dataclasses

        from goniolab.scan.adaptive import adaptive_angles

        model = await self.models.get(plan.sample)
        predictor = Predictor.from_config(model, self.config)
        ti = plan.theta_i_deg

        def predict(theta_r_deg: Any) -> Any:
            return predictor.predict_sync(ti, [float(t) for t in theta_r_deg])

        lo, hi = min(plan.theta_r_deg), max(plan.theta_r_deg)
        try:
            angles = await asyncio.to_thread(adaptive_angles, lo, hi, plan.n_geometries, predict)
        except ValueError as exc:
            raise UserError(f"--adaptive: {exc}") from None
        return dataclasses.replace(plan, theta_r_deg=angles, sampling="adaptive")

    async def prepare_resume(self, run_id: int) -> PreparedScan:
        """:meth:`prepare` for the stored plan of ``run_id``."""
        return await self.prepare(BrdfPlan.from_dict(self.store.get_run(run_id).plan), run_id)

    def start(self, scan: PreparedScan, *, meta: RunMeta | None = None) -> ScanRunner:
        """Put the plan's sample under the instruments (simulated lab), record a new run
        in the store (with the config's ``[run]`` metadata, ``meta``'s fields over it), and
        return its runner (call :meth:`run`)."""
        plan, cfg = scan.plan, self.config
        hook = self._specimen_hook() if plan.mirror_reference else None
        self.lab.put_sample(scan.model, plan.sample)
        from goniolab.scan.calibration import calibration_notices, latest_calibration

        cite, notices = calibration_notices(
            latest_calibration(self.store), max_age_h=cfg.spectro.calibration_max_age_h
        )
        run_id = scan.run_id
        if run_id is None:
            run_id = self.store.create_run(
                kind="brdf",
                plan=plan.to_dict(),
                config=config_snapshot(with_sample(cfg, plan.sample)),
                sample=plan.sample,
                model={
                    **scan.predictor.describe(),
                    "calibration": cite,
                    **scan.provenance,
                },
                version=__version__,
                meta=config_meta(cfg, meta),
            )
        g = cfg.goniometer
        return ScanRunner(
            goniometer=self.lab.goniometer,
            spectro=self.lab.spectro,
            clock=self.lab.clock,
            plan=plan,
            store=self.store,
            run_id=run_id,
            bus=self.bus,
            motion=ArmMotion.from_config(g),
            predictor=scan.predictor,
            move_timeout_s=g.move_timeout_s,
            home_timeout_s=home_timeout_s(cfg),
            park_deg=(g.park.theta_i_deg, g.park.theta_r_deg),
            specimen_hook=hook,
            point_colour=PointColour.from_config(cfg),
            mirror_standard=self.standard("mirror") if plan.mirror_reference else None,
            reconnect_window_s=cfg.lab.reconnect_window_s,
            # what the prediction cannot answer for is said when the run starts (issue 20)
            notices=(*notices, *(f"prediction: {w}" for w in scan.provenance.get("warnings", []))),
        )

    def standard(self, name: str) -> Standard:
        """The lab's certified standard ``name`` (``[spectro] standards``)."""
        from goniolab.scan.standards import load_standards, standards_path

        cfg = self.config
        return load_standards(standards_path(cfg.source, cfg.spectro.standards)).get(name)

    async def run(self, runner: ScanRunner) -> RunResult:
        """Run to the end (done, aborted or failed: the arms are parked).

        Raises
        ------
        PlanRefused
            The runner's own dry run refused the plan (the arms moved meanwhile); the run
            is marked ``failed`` with the reason, nothing moved.
        goniolab.store.RunBusy
            Another runner holds the run; nothing moved.
        """
        try:
            return await runner.run()
        except PlanRefused as exc:
            self.store.set_status(
                runner.run_id, RunState.FAILED.value, f"plan refused (no arm moved): {exc}"
            )
            raise

    async def align(
        self,
        plan: AlignPlan,
        *,
        save_state: bool = True,
        started: Callable[[AlignRunner], None] | None = None,
    ) -> tuple[int, AlignResult]:
        """Run an alignment (:mod:`goniolab.scan.align`): home the arms if needed, measure
        the black-glass standard and the sample (swapped by the simulated lab, or by the
        operator), store the readings and the result with a new ``align`` run, save it to
        the lab's alignment state file when ``save_state`` (beside the store,
        :func:`goniolab.config.alignment_state_path`; the config file is never rewritten)
        before the run is marked done, and park the arms. The lab's
        goniometer then corrects every move with the result (later scans of this session
        see the requested angles). ``started`` gets the runner before its first reading
        (the TUI keeps it to abort).

        Raises
        ------
        UserError
            The alignment failed (an instrument fault, no peak found; the run is marked
            ``failed`` with the reason) or was aborted (marked ``aborted``).
        """
        from goniolab.config import write_alignment_state
        from goniolab.scan.align_reach import check_align_reach

        cfg = self.config
        try:  # an incidence the arms cannot sweep is refused before any run or motion
            check_align_reach(plan, cfg.goniometer)
        except PlanError as exc:
            raise UserError(f"scan --plan align: {exc}") from exc
        model = await self.models.get(plan.sample)
        await self.lab.prepare_sample(plan.sample)
        self.lab.put_sample(model, plan.sample)
        predictor = Predictor.from_config(model, cfg)
        run_id = self.store.create_run(
            kind="align",
            plan=plan.to_dict(),
            config=config_snapshot(with_sample(cfg, plan.sample)),
            sample=plan.sample,
            model=predictor.describe(),
            version=__version__,
            meta=config_meta(cfg),
        )
        hook = self.lab.place_specimen or self.operator
        if hook is None:
            raise UserError("an alignment needs an operator to place the standard and the sample")
        runner = AlignRunner(
            goniometer=self.lab.goniometer,
            spectro=self.lab.spectro,
            clock=self.lab.clock,
            plan=plan,
            predictor=predictor,
            place_specimen=hook,
            store=self.store,
            run_id=run_id,
            bus=self.bus,
            move_timeout_s=cfg.goniometer.move_timeout_s,
            standard=self.standard("black_glass"),
            motion=ArmMotion.from_config(cfg.goniometer),
        )

        def save(result: AlignResult) -> str:
            if not save_state:
                return ""
            path = write_alignment_state(
                cfg,
                {
                    "lamp_zero_deg": round(result.lamp_zero_deg, 4),
                    "detector_zero_deg": round(result.detector_zero_deg, 4),
                    "sample_tilt_deg": round(result.sample_tilt_deg, 4),
                    "run": run_id,
                },
                note=f"goniolab scan --plan align, run {run_id}",
            )
            return str(path)

        runner.persist = save
        if started is not None:
            started(runner)
        try:
            if not await self.homed():
                await self.home()
            result = await runner.run()
        except AlignAborted as exc:
            raise UserError(f"align run {run_id} {exc}", exit_code=1) from exc
        except (DeviceError, RuntimeError, ValueError) as exc:
            self.store.set_status(run_id, RunState.FAILED.value, str(exc))
            raise UserError(f"align run {run_id} failed: {exc}", exit_code=1) from exc
        finally:
            with contextlib.suppress(DeviceError):
                await self.lab.goniometer.park(home_timeout_s(cfg))
        self.lab.goniometer.corrections_deg = result.corrections_deg()
        return run_id, result

    def _specimen_hook(self) -> SpecimenHook:
        if self.lab.place_specimen is not None:  # a simulated lab swaps the specimen itself
            return self.lab.place_specimen
        if self.operator is None:
            raise UserError("a mirror reference needs an operator to swap mirror and sample")
        return self.operator


def resume_target(
    rec: RunRecord, config_path: str | None, done_readings: int, *, need_file: bool = True
) -> str:
    """The config file to resume the stored run ``rec`` with: ``config_path`` when given,
    else the one the run was started with (its ``_source``); ``need_file=False`` only
    checks that the run can be resumed (``scan resume`` uses the run's stored config).

    Raises
    ------
    UserError
        The run is no scan, is already done, or names no config file that still exists.
    """
    if rec.kind != "brdf":
        raise UserError(f"run {rec.id} is {a_run_of_kind(rec.kind)}; only scans can be resumed")
    if rec.status == RunState.DONE.value:
        raise UserError(f"run {rec.id} is already done ({done_readings} readings)")
    if not need_file:
        return config_path or ""
    path = config_path or rec.config.get("_source", "")
    if not path:
        raise UserError(f"run {rec.id}: no config file recorded; pass --config FILE")
    if not Path(path).exists():
        raise UserError(f"run {rec.id}: config {path} no longer exists; pass --config FILE")
    return str(path)


@dataclass(frozen=True, slots=True)
class GlossPrediction:
    """A sample's model and its ISO 2813 gloss (both ``None`` without a sample)."""

    model: ReflectanceModel | None
    gloss_gu: dict[int, float] | None
    #: the model that computed each predicted gloss (``{60: "facet", 85: "kirchhoff"}``)
    #: and the notes of those numbers (:func:`goniolab.optics.provenance.gloss_provenance_of`)
    models: dict[int, str] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def describe(self) -> dict[str, Any]:
        """The ``model`` column of a gloss run."""
        if self.model is None:
            return {}
        out: dict[str, Any] = {"model": type(self.model).__name__, "predicted_gu": self.gloss_gu}
        if self.models:
            out["computed_by"] = {str(a): m for a, m in self.models.items()}
            out["warnings"] = list(self.warnings)
        return out


class GlossSession:
    """Glossmeter readings logged in the store beside the sample's predicted gloss.

    Parameters
    ----------
    meter, clock
        A connected glossmeter and the lab clock (backoff and interval waits).
    store
        The run store.
    config
        The lab config (stored with each run, ``[sample] map`` set to the run's sample),
        or what describes a meter opened without one (port, protocol).
    models
        Prediction models by sample; ``None``: no prediction.
    bus
        Where the logger publishes (default: a new one).
    """

    def __init__(
        self,
        meter: Glossmeter,
        clock: Clock,
        store: RunStore,
        *,
        config: LabConfig | dict[str, Any],
        models: SampleModels | None = None,
        bus: EventBus | None = None,
    ) -> None:
        self.meter = meter
        self.clock = clock
        self.store = store
        self.config = config
        self.models = models
        self.bus = EventBus() if bus is None else bus

    @classmethod
    def of_lab(
        cls,
        lab: Lab,
        store: RunStore,
        *,
        models: SampleModels | None = None,
        bus: EventBus | None = None,
    ) -> GlossSession:
        """The glossmeter of an open lab."""
        models = SampleModels.of_lab(lab) if models is None else models
        return cls(lab.glossmeter, lab.clock, store, config=lab.config, models=models, bus=bus)

    @classmethod
    @asynccontextmanager
    async def open(
        cls,
        config: LabConfig,
        store: RunStore,
        *,
        sample: str = "",
        time_scale: float | None = None,
        bus: EventBus | None = None,
    ) -> AsyncIterator[GlossSession]:
        """Open only the glossmeter of ``config`` (it works while the goniometer is off)."""
        lab_cfg = with_sample(config, sample)
        async with Lab.from_config(
            lab_cfg, time_scale=time_scale, instruments=("glossmeter",)
        ) as lab:
            yield cls.of_lab(lab, store, bus=bus)

    async def predict(self, sample: str, angles_deg: tuple[int, ...]) -> GlossPrediction:
        """The model of ``sample`` and its gloss at ``angles_deg`` (worker threads)."""
        if not sample or self.models is None:
            return GlossPrediction(None, None)
        model = await self.models.get(sample)
        from goniolab.optics.provenance import gloss_provenance_of

        gloss = await predict_gloss(model, angles_deg)
        prov = await asyncio.to_thread(gloss_provenance_of, model, angles_deg)
        notes = tuple(dict.fromkeys(f"G{a}: {n}" for a, p in prov.items() for n in p.notes))
        return GlossPrediction(model, gloss, {a: p.model for a, p in prov.items()}, notes)

    def create_run(
        self, plan: GlossPlan, prediction: GlossPrediction, *, meta: RunMeta | None = None
    ) -> int:
        """Record a new ``gloss`` run for ``plan`` (with the config's ``[run]`` metadata,
        ``meta``'s fields over it); return its id."""
        config = (
            config_snapshot(with_sample(self.config, plan.sample))
            if isinstance(self.config, LabConfig)
            else dict(self.config)
        )
        return self.store.create_run(
            kind="gloss",
            plan=plan.to_dict(),
            config=config,
            sample=plan.sample,
            model=prediction.describe(),
            version=__version__,
            meta=config_meta(self.config, meta),
        )

    def logger(
        self,
        plan: GlossPlan,
        run_id: int,
        prediction: GlossPrediction,
        *,
        mode: str = "measure",
        interval_s: float = 0.0,
        keep_running: bool = False,
    ) -> GlossLogger:
        """The logger of ``plan`` into run ``run_id`` (call its ``run()``; ``stop()`` ends it;
        ``keep_running``: the run stays ``running`` after it, for more readings)."""
        return GlossLogger(
            meter=self.meter,
            store=self.store,
            run_id=run_id,
            bus=self.bus,
            clock=self.clock,
            plan=plan,
            predicted_gu=prediction.gloss_gu,
            predicted_models=prediction.models,
            mode=mode,
            interval_s=interval_s,
            keep_running=keep_running,
        )

    async def start(
        self,
        plan: GlossPlan,
        *,
        mode: str = "measure",
        interval_s: float = 0.0,
        meta: RunMeta | None = None,
    ) -> GlossLogger:
        """Predict ``plan.sample``, record a new run (with ``meta``), and return its logger."""
        prediction = await self.predict(plan.sample, plan.angles_deg)
        run_id = self.create_run(plan, prediction, meta=meta)
        return self.logger(plan, run_id, prediction, mode=mode, interval_s=interval_s)
