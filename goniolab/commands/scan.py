"""``goniolab scan``: run an in-plane BRDF scan; ``goniolab scan resume RUN`` continues one.

Progress (a plain-text bar with the ETA) goes to stderr, the summary to stdout at the end;
``--json`` prints only the summary JSON on stdout. Ctrl-C asks the runner to stop: a move
in progress is interrupted (a reading in progress is finished and stored), the arms are
parked, the run is marked ``aborted`` and the command prints how to resume it. A second
Ctrl-C cancels at once (the arms are still parked, best effort).

``goniolab scan --plan align`` runs the alignment instead (:mod:`goniolab.scan.align`, via
:meth:`goniolab.session.ScanSession.align`): the black-glass standard, then the sample, at
two or more incidences; it prints the arms' zero offsets and the sample's tilt, stores them
with the run and saves them to the lab's alignment state file beside the store (never the
config file: :func:`goniolab.config.alignment_state_path`; ``--no-write-config`` stores them
with the run only), whose values correct every later move.
``--auto-exposure`` adapts the spectro's exposure to each reading
(:mod:`goniolab.scan.exposure`). ``--adaptive`` places the ``--theta-r`` angles where the
predicted curve bends (:mod:`goniolab.scan.adaptive`): as many readings, the same sweep.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Coroutine
from typing import TYPE_CHECKING, Any, TextIO, TypeVar

from goniolab import jsonout
from goniolab.commands._angles import allow_negative_angles
from goniolab.errors import UserError
from goniolab.model_registry import model_names

if TYPE_CHECKING:  # loaded when a scan runs, not at --help (tests/test_startup.py)
    import asyncio

    from goniolab.config import LabConfig
    from goniolab.scan.events import PointMeasured, Progress, RunState
    from goniolab.scan.plans import BrdfPlan
    from goniolab.scan.runner import RunResult
    from goniolab.store import RunMeta, RunStore

__all__ = [
    "format_eta",
    "format_summary",
    "point_detail",
    "read_stdin_line",
    "register",
    "run_lab",
]

_T = TypeVar("_T")


def _exit_code(state: RunState) -> int:
    """0 done, 1 failed, 130 aborted."""
    return {"done": 0, "failed": 1, "aborted": 130}[state.value]


def format_eta(seconds: float) -> str:
    """``1h02m03s`` / ``2m03s`` / ``7s`` for a non-negative duration."""
    if not math.isfinite(seconds):
        return "?"
    s = max(0, round(seconds))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    if h:
        return f"{h}h{m:02d}m{sec:02d}s"
    if m:
        return f"{m}m{sec:02d}s"
    return f"{sec}s"


def _fmt(v: Any, unit: str, spec: str = ".2f") -> str:
    return "-" if v is None else f"{v:{spec}}{unit}"


def format_summary(summary: dict[str, Any]) -> str:
    """Human-readable run summary (the same numbers as the JSON)."""
    lines = [
        f"  readings: {summary['readings']} of {summary['planned_readings']}"
        + ("" if summary["complete"] else " (incomplete)"),
    ]
    if summary.get("mirror_pct") is not None:
        lines.append(
            f"  mirror reference: {summary['mirror_pct']:.3f} % of the instrument's reference "
            "(divided out spectrally, times the mirror's certificate)"
        )
    lines.append(f"  RMSE measured - predicted: {_fmt(summary['rmse_pct'], ' %', '.3f')}")
    mp, pp = summary.get("measured_peak"), summary.get("predicted_peak")
    for label, pk in (("measured ", mp), ("predicted", pp)):
        if pk is not None:
            lines.append(
                f"  {label} peak: amplitude {_fmt(pk['amplitude_pct'], ' %', '.3f')}, "
                f"position {_fmt(pk['position_deg'], ' deg')}, FWHM {_fmt(pk['fwhm_deg'], ' deg')}"
            )
    if summary.get("peak_offset_deg") is not None:
        lines.append(f"  peak offset: {summary['peak_offset_deg']:+.2f} deg")
    if summary.get("hint"):
        lines.append(f"  hint: {summary['hint']}")
    check = summary.get("prediction_check")
    if check:
        verdict = "FLAGGED: " + "; ".join(check["reasons"]) if check["flagged"] else "consistent"
        lines.append(f"  prediction check: {verdict}")
    if summary.get("peak_note"):
        lines.append(f"  note: {summary['peak_note']}")
    return "\n".join(lines)


class ProgressBar:
    """Scan progress with the ETA of the motion model (on an instant sim clock, scale 0,
    from the measured wall time per reading instead: the motion model's lab time takes no
    wall time there, and "ETA 0s" stood through 15-20 s of computing; "?" until a reading
    has been timed).

    On a terminal a rich progress bar (redrawn in place; messages scroll above it); to a
    pipe or a file one plain line per 10 % (``[####......] 12/30 ETA 4s detail``), stable
    for scripts and logs.
    """

    def __init__(self, stream: TextIO, clock_scale: float, width: int = 30) -> None:
        self.stream = stream
        self.clock_scale = clock_scale
        self.width = width
        self.tty = stream.isatty()
        self._last_pct = -1
        self._rich: Any = None
        self._task: Any = None
        self._first: tuple[float, int] | None = None  # (monotonic s, done) of the first event

    def wall_s(self, lab_s: float) -> float:
        """Lab-clock seconds to wall seconds (a sim clock at scale 0 takes no wall time)."""
        if self.clock_scale <= 0:
            return 0.0
        return lab_s / self.clock_scale

    def _start_rich(self, total: int) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

        self._rich = Progress(
            BarColumn(bar_width=self.width),
            MofNCompleteColumn(),
            TextColumn("ETA {task.fields[eta]}"),
            TextColumn("{task.fields[detail]}"),
            console=Console(file=self.stream, highlight=False),
            # never wrap sys.stdout: the summary and --json go there (issue 22.3)
            redirect_stdout=False,
            redirect_stderr=False,
        )
        self._rich.start()
        self._task = self._rich.add_task("scan", total=total, eta="?", detail="")

    def eta_wall_s(self, ev: Progress, now_s: float) -> float:
        """Wall seconds left: the motion model's, or at clock scale 0 the measured rate's
        (NaN, shown as "?", until a reading has been timed)."""
        if self._first is None:
            self._first = (now_s, ev.done)
        if ev.total and ev.done >= ev.total:
            return 0.0
        if self.clock_scale > 0:
            return self.wall_s(ev.eta_s)
        t0, done0 = self._first
        if ev.done <= done0:
            return math.nan
        return (now_s - t0) / (ev.done - done0) * (ev.total - ev.done)

    def update(self, ev: Progress, detail: str) -> None:
        import time

        eta = format_eta(self.eta_wall_s(ev, time.monotonic()))
        if self.tty:
            if self._rich is None:
                self._start_rich(ev.total)
            self._rich.update(self._task, completed=ev.done, total=ev.total, eta=eta,
                              detail=detail)  # fmt: skip
            return
        frac = ev.done / ev.total if ev.total else 1.0
        n = round(frac * self.width)
        pct = int(frac * 100)
        if pct // 10 != self._last_pct // 10 or ev.done == ev.total:
            line = f"[{'#' * n}{'.' * (self.width - n)}] {ev.done}/{ev.total} ETA {eta} {detail}"
            self.stream.write(line + "\n")
            self.stream.flush()
        self._last_pct = pct

    def message(self, text: str) -> None:
        if self._rich is not None:
            self._rich.console.print(text, markup=False, highlight=False, soft_wrap=True)
            return
        self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self._rich is not None:
            self._rich.stop()
            self._rich = None


def point_detail(ev: PointMeasured, predicted_pct: float | None) -> str:
    """Progress-line detail of a reading: angle, luminance, prediction and residual."""
    text = f"theta_r={ev.theta_r_deg:g} L={ev.luminance_pct:.3f} %"
    if predicted_pct is not None:
        text += f" pred {predicted_pct:.3f} % res {ev.luminance_pct - predicted_pct:+.3f}"
    if ev.quality in ("saturated", "under_noise_floor"):
        text += f" [{ev.quality.replace('_', ' ').upper()}]"
    return text


async def _report(bus_q: asyncio.Queue[Any], bar: ProgressBar) -> None:
    from goniolab.scan.events import (
        InstrumentError,
        PointMeasured,
        PointPredicted,
        Progress,
        RunFinished,
    )

    detail = ""
    predicted: dict[int, float] = {}
    while (ev := await bus_q.get()) is not None:
        if isinstance(ev, PointPredicted):
            predicted[ev.index] = ev.predicted_pct
        elif isinstance(ev, PointMeasured):
            pred = ev.predicted_pct if ev.predicted_pct is not None else predicted.get(ev.index)
            detail = point_detail(ev, pred)
        elif isinstance(ev, Progress):
            bar.update(ev, detail)
        elif isinstance(ev, InstrumentError):
            bar.message(
                f"goniolab: {'fault' if ev.fatal else 'warning'}: {ev.device}: {ev.message}"
            )
        elif isinstance(ev, RunFinished):
            return


async def read_stdin_line() -> str:
    """One line from stdin without a blocking thread, so that Ctrl-C (an abort, then a
    cancellation) ends the wait at once; a regular file or a closed stdin falls back to
    a worker-thread read (it never blocks for long)."""
    import asyncio

    loop = asyncio.get_running_loop()
    try:
        fd = sys.stdin.fileno()
    except (AttributeError, OSError, ValueError):  # replaced or closed stdin
        return await asyncio.to_thread(sys.stdin.readline)
    ready: asyncio.Future[None] = loop.create_future()

    def on_readable() -> None:
        if not ready.done():
            ready.set_result(None)

    try:
        loop.add_reader(fd, on_readable)
    except (OSError, ValueError):  # epoll refuses regular files
        return await asyncio.to_thread(sys.stdin.readline)
    try:
        await ready
    finally:
        loop.remove_reader(fd)
    return sys.stdin.readline()


async def _specimen_prompt(which: str) -> None:
    """Ask the operator to place the mirror (or the sample back) and press Enter."""
    what = "the reference MIRROR" if which == "mirror" else "the SAMPLE"
    print(f"goniolab: place {what} under the instruments, then press Enter", file=sys.stderr)
    line = await read_stdin_line()
    if not line:
        raise UserError(f"no operator confirmation on stdin for placing {what}", exit_code=1)


async def _execute(
    *,
    config_path: str,
    time_scale: float | None,
    store: RunStore,
    plan: BrdfPlan | None,
    run_id: int | None,
    json_out: bool,
    model: str | None = None,
    adaptive: bool = False,
    config: LabConfig | None = None,
    meta: RunMeta | None = None,
) -> int:
    import asyncio

    from goniolab.commands._signals import describe, install_stop_signals
    from goniolab.config import load_lab_config
    from goniolab.scan.events import RunState
    from goniolab.scan.plans import BrdfPlan
    from goniolab.scan.runner import PlanRefused
    from goniolab.session import ScanSession
    from goniolab.store import RunBusy

    if plan is None:
        assert run_id is not None
        plan = BrdfPlan.from_dict(store.get_run(run_id).plan)
    cfg = config if config is not None else load_lab_config(config_path)
    if model is not None:  # --model overrides the config's [sample] model
        cfg = cfg.model_copy(update={"sample": cfg.sample.model_copy(update={"model": model})})
    async with ScanSession.open(
        cfg, store, sample=plan.sample, time_scale=time_scale, operator=_specimen_prompt
    ) as session:
        if adaptive and run_id is None:
            plan = await session.adaptive_plan(plan)
            steps = [b - a for a, b in zip(plan.theta_r_deg, plan.theta_r_deg[1:], strict=False)]
            print(
                f"goniolab: adaptive sampling: {plan.n_geometries} angles "
                f"{plan.theta_r_deg[0]:g}..{plan.theta_r_deg[-1]:g} deg, "
                f"{min(steps):.2f} to {max(steps):.2f} deg apart",
                file=sys.stderr,
            )
        # refuse an unsafe plan before any motion, and before a new run is even recorded
        # (the runner checks again); a resumed run checks only the readings still to take
        try:
            scan = await session.prepare(plan, run_id)
        except PlanRefused as exc:
            raise UserError(f"plan refused (no arm moved): {exc}") from exc
        clock_scale = session.clock_scale
        check = scan.check
        lab_time = "" if clock_scale == 1.0 else f" ({check.eta_s:.2f} s of lab clock)"
        # an instant sim clock takes no wall time for the lab's: the ETA comes from the
        # readings as they are timed (ProgressBar)
        eta = format_eta(check.eta_s / clock_scale) if clock_scale > 0 else "from the readings"
        homed = await session.homed()
        print(
            f"goniolab: {check.n_readings} readings, {check.n_moves} moves, "
            f"ETA {eta}{lab_time}"
            + ("" if homed else " after homing the arms (the home search is not estimated)"),
            file=sys.stderr,
        )
        runner = session.start(scan, meta=meta)
        run_id = runner.run_id
        announce_store(store, run_id)
        bar = ProgressBar(sys.stderr, clock_scale)
        report = asyncio.create_task(_report(session.bus.subscribe(), bar))
        loop = asyncio.get_running_loop()
        main_task = asyncio.current_task()

        def stop_first(name: str) -> None:
            bar.message(
                f"goniolab: {describe(name)}: stopping: the arms stop, then park "
                "(Ctrl-C again to quit at once: the arms still stop and the run is recorded)"
            )
            runner.abort(by=describe(name))

        def stop_again(name: str) -> None:
            bar.message(f"goniolab: {describe(name)} again: quitting, the arms stop and park")
            if main_task is not None:
                main_task.cancel()

        remove_signals = install_stop_signals(loop, stop_first, stop_again)
        try:
            result: RunResult = await session.run(runner)
        except PlanRefused as exc:
            raise UserError(f"plan refused (no arm moved): {exc}") from exc
        except RunBusy as exc:
            raise UserError(f"{exc} (no arm moved)") from exc
        except asyncio.CancelledError:
            bar.close()
            print(
                f"goniolab: run {run_id} aborted; continue it with: "
                f"{resume_command(run_id, store)}",
                file=sys.stderr,
            )
            return 130
        finally:
            remove_signals()
            session.bus.close()
            await report
            bar.close()
    payload = {
        "run_id": run_id,
        "state": result.state.value,
        "reason": result.reason,
        **result.summary,
    }
    if json_out:
        print(jsonout.dumps(payload, indent=2))
    else:
        print(
            f"run {run_id}: {result.state.value}" + (f" ({result.reason})" if result.reason else "")
        )
        print(format_summary(result.summary))
    if result.state is not RunState.DONE:
        print(
            f"goniolab: run {run_id} {result.state.value}; continue it with: "
            f"{resume_command(run_id, store)}",
            file=sys.stderr,
        )
    return _exit_code(result.state)


async def _align_prompt(which: str) -> None:
    """Ask the operator to place the black-glass standard (or the sample) and press Enter."""
    if which != "standard":
        await _specimen_prompt(which)
        return
    what = "the BLACK-GLASS STANDARD (ISO 2813, on the reference seat)"
    print(f"goniolab: place {what} under the instruments, then press Enter", file=sys.stderr)
    if not await read_stdin_line():
        raise UserError(f"no operator confirmation on stdin for placing {what}", exit_code=1)


async def _execute_align(
    *,
    config_path: str,
    time_scale: float | None,
    store: RunStore,
    plan: Any,
    json_out: bool,
    write_config: bool,
    config: LabConfig | None = None,
) -> int:
    import asyncio

    from goniolab.config import load_lab_config
    from goniolab.session import ScanSession

    cfg = config if config is not None else load_lab_config(config_path)
    async with ScanSession.open(
        cfg, store, sample=plan.sample, time_scale=time_scale, operator=_align_prompt
    ) as session:
        bar = ProgressBar(sys.stderr, session.clock_scale)
        report = asyncio.create_task(_report(session.bus.subscribe(), bar))
        try:
            run_id, result = await session.align(plan, save_state=write_config)
        finally:
            session.bus.close()
            await report
            bar.close()
    payload = {"run_id": run_id, "state": "done", "config_written": False}
    payload.update(result.as_dict())
    if json_out:
        print(jsonout.dumps(payload, indent=2))
        return 0
    c = result.corrections_deg()
    print(f"run {run_id}: alignment done ({result.readings} readings)")
    print(f"  lamp arm zero offset:     {result.lamp_zero_deg:+.3f} deg")
    print(f"  detector arm zero offset: {result.detector_zero_deg:+.3f} deg")
    print(f"  sample tilt:              {result.sample_tilt_deg:+.3f} deg")
    print(f"  corrections (lamp, detector): {c[0]:+.3f}, {c[1]:+.3f} deg")
    print(f"  black-glass fit: {100 * result.standard_rms_rel:.2f} % rms")
    fit = result.standard_fit
    if fit:
        print(
            f"  zeros' 1-sigma: lamp {fit['lamp_zero_sigma_deg']:.3f}, detector "
            f"{fit['detector_zero_sigma_deg']:.3f} deg; scale {fit['scale']:.3f} of certificate "
            f"{result.standard.get('certificate', '-')}"
        )
        print(
            f"  lamp - detector zero: fit {fit['fit_difference_deg']:+.3f} deg, peaks' "
            f"midpoints (no Fresnel shape) {fit['geometric_difference_deg']:+.3f} deg"
        )
    if result.state_file:
        print(
            f"  saved to {result.state_file} (the lab's alignment state; {config_path} untouched)"
        )
    else:
        print("  stored with the run only: later scans are not corrected")
    return 0


def run_lab(coro: Coroutine[Any, Any, _T]) -> _T:
    """``asyncio.run(coro)``; an instrument that cannot be reached (or fails outside a
    run, which records its own faults) becomes one line naming the device, exit code 1."""
    import asyncio

    from drivers.base import DeviceError
    from goniolab.store import StoreError

    try:
        return asyncio.run(coro)
    except DeviceError as exc:
        raise UserError(f"instrument error: {exc}", exit_code=1) from exc
    except StoreError as exc:  # the store refused a write outside a run (creating one)
        raise UserError(str(exc), exit_code=1) from exc


def _e2194_geometry(args: argparse.Namespace, cfg: Any) -> tuple[float, str]:
    """The ASTM E2194 / E2539 / DIN 6175-2 geometry: 45 deg incidence, detector at the
    aspecular angles -15, 15, 25, 45, 75, 110 deg (ascending theta_r). Angles the detector
    arm cannot reach (its limits, or beyond the lamp: it would pass through the lamp arm)
    are skipped, each named on stderr with the reason."""
    from goniolab.colour.multiangle import (
        E2194_ASPECULAR_DEG,
        E2194_INCIDENCE_DEG,
        theta_r_for_aspecular,
    )

    if args.theta_i != E2194_INCIDENCE_DEG:
        raise UserError(
            f"scan --plan e2194: the standard lights at 45 deg, not --theta-i {args.theta_i:g}"
        )
    if args.theta_r_given:
        raise UserError("scan --plan e2194 sets the detector angles itself; drop --theta-r")
    pairs = sorted((theta_r_for_aspecular(a), a) for a in E2194_ASPECULAR_DEG)
    lo, hi = cfg.goniometer.detector.limits_deg
    where = f"{cfg.source or 'config'}: goniometer.detector.limits_deg"
    keep: list[tuple[float, float]] = []
    for t, a in pairs:
        if t < -E2194_INCIDENCE_DEG:
            print(
                f"scan --plan e2194: aspecular {a:g} deg skipped: theta_r {t:g} lies beyond the "
                f"lamp (-{E2194_INCIDENCE_DEG:g} deg), the detector arm would pass through the "
                f"lamp arm (by reciprocity it is theta_i {-t:g}, theta_r -{E2194_INCIDENCE_DEG:g}; "
                "a plan holds one incidence)",
                file=sys.stderr,
            )
        elif not lo <= t <= hi:
            print(
                f"scan --plan e2194: aspecular {a:g} deg skipped: theta_r {t:g} outside the "
                f"detector arm's {lo:g}..{hi:g} deg ({where})",
                file=sys.stderr,
            )
        else:
            keep.append((t, a))
    if not keep:
        raise UserError(f"scan --plan e2194: no standard angle is within reach ({where})")
    pairs = keep
    return E2194_INCIDENCE_DEG, ",".join(f"{t:g}" for t, _ in pairs)


def _cmd_scan(args: argparse.Namespace) -> int:
    if not args.config:
        raise UserError("scan: --config FILE is required (e.g. configs/lab-sim.toml)")
    from goniolab.config import load_lab_config
    from goniolab.scan.plans import BrdfPlan, PlanError, parse_angles

    cfg = load_lab_config(args.config)
    args.theta_r_given = args.theta_r is not None
    if args.theta_r is None:
        args.theta_r = "0:70:1"
    sample = args.sample or cfg.sample.map
    if args.sample:
        from goniolab.session import check_sample

        check_sample(args.sample)
        sample = absolute_sample(args.sample)
    cfg = _with_step(cfg, args, sample)
    if args.plan == "align":
        from goniolab.scan.align import AlignPlan

        try:
            align_plan = AlignPlan(
                theta_i_deg=parse_angles(args.align_theta_i, name="--align-theta-i"),
                exposure_us=args.exposure_us or cfg.spectro.exposure_us,
                sample=sample,
            )
        except PlanError as exc:
            raise UserError(f"scan --plan align: {exc}") from exc
        with _open(args.store, cfg.lab.store) as align_store:
            return run_lab(
                _execute_align(
                    config_path=args.config,
                    time_scale=args.time_scale,
                    store=align_store,
                    plan=align_plan,
                    json_out=args.json,
                    write_config=not args.no_write_config,
                    config=cfg,
                )
            )
    theta_i, theta_r = args.theta_i, args.theta_r
    if args.plan == "e2194":
        if args.adaptive:
            raise UserError(
                "scan --plan e2194 measures the standard's fixed angles; drop --adaptive"
            )
        theta_i, theta_r = _e2194_geometry(args, cfg)
    try:
        plan = BrdfPlan(
            theta_i_deg=theta_i,
            theta_r_deg=parse_angles(theta_r, name="--theta-r"),
            repeats=args.repeats,
            dwell_s=args.dwell,
            exposure_us=args.exposure_us
            if args.exposure_us is not None
            else cfg.spectro.exposure_us,
            mirror_reference=args.mirror_reference,
            sample=sample,
            auto_exposure=args.auto_exposure,
        )
    except PlanError as exc:
        raise UserError(f"scan: {exc}") from exc
    store = _open(args.store, cfg.lab.store)
    with store:
        return run_lab(
            _execute(
                config_path=args.config,
                time_scale=args.time_scale,
                store=store,
                plan=plan,
                run_id=None,
                json_out=args.json,
                model=args.model,
                adaptive=args.adaptive,
                meta=run_meta_args(args),
                config=cfg,
            )
        )


def _with_step(cfg: LabConfig, args: argparse.Namespace, sample: str) -> LabConfig:
    """``cfg`` with ``--step-um`` as ``[sample] step_um``, after the map was read once here,
    so that a map without a lateral step (a ``.npy`` without sidecar) is one error naming
    the map and the option, not the config (issue 27, item 6)."""
    if args.step_um is not None:
        if not args.step_um > 0 or args.step_um != args.step_um:
            raise UserError(f"scan: --step-um must be > 0, got {args.step_um:g}")
        cfg = cfg.model_copy(
            update={"sample": cfg.sample.model_copy(update={"step_um": args.step_um})}
        )
    if sample.startswith("sample:"):
        return cfg
    from goniolab.surfaces.resolve import resolve_map

    try:
        resolve_map(sample if args.sample else _config_map(cfg), step_um=cfg.sample.step_um)
    except UserError as exc:  # its text starts with the map's file name
        if args.sample:
            raise UserError(f"--sample {exc}") from None
        raise UserError(f"{cfg.source}: sample.map: {exc} (or set [sample] step_um)") from None
    return cfg


def _config_map(cfg: LabConfig) -> str:
    return cfg.sample_map()


def _open(store_arg: str | None, config_store: str | None, *, create: bool = True) -> RunStore:
    from goniolab.store import RunStore, StoreError, resolve_store_path

    try:
        store = RunStore(resolve_store_path(store_arg, config_store), create=create)
    except StoreError as exc:
        raise UserError(str(exc)) from exc
    return store


def resume_command(run_id: int, store: RunStore) -> str:
    """The command that resumes run ``run_id`` of ``store``: ``--store`` named unless it is
    the default store (a store chosen by ``--store`` or a config's ``[lab] store`` would
    otherwise be lost: ``scan resume`` reads the run's config from the store itself). A
    PostgreSQL URL is shown without its password (libpq reads it from PGPASSWORD or
    ~/.pgpass)."""
    import shlex

    from goniolab.store import default_store_path

    cmd = f"goniolab scan resume {run_id}"
    if store.is_postgres:
        return f"{cmd} --store {shlex.quote(store.location)}"
    try:
        default = store.path.resolve() == default_store_path().resolve()
    except OSError:
        default = False
    if not default:
        cmd += f" --store {shlex.quote(str(store.path.resolve()))}"
    return cmd


def add_run_meta_args(p: argparse.ArgumentParser) -> None:
    """``--operator``, ``--sample-id``, ``--note`` and ``--tag`` (run identity, issue 22)."""
    p.add_argument("--operator", default=None, help="who measures (default: config [run])")
    p.add_argument(
        "--sample-id", default=None, help="the physical sample's id (label, LIMS number)"
    )
    p.add_argument("--note", default=None, help="free-text notes stored with the run")
    p.add_argument(
        "--tag", action="append", default=[], metavar="TAG", help="a tag (repeat for more)"
    )


def run_meta_args(args: argparse.Namespace) -> RunMeta:
    """The run metadata given on the command line (empty fields: not given)."""
    from goniolab.store import RunMeta

    return RunMeta.given(args.operator, args.sample_id, args.note, args.tag)


def absolute_sample(spec: str) -> str:
    """A height-map path made absolute (``sample:NAME`` as it is), so that the stored run
    names the same file from any directory (``scan resume`` elsewhere, a dask worker)."""
    if not spec or spec.startswith("sample:"):
        return spec
    from pathlib import Path

    return str(Path(spec).expanduser().resolve())


def announce_store(store: RunStore, run_id: int) -> None:
    """Say (stderr and the log) which run of which store the readings go to."""
    import logging

    where = store.location
    print(f"goniolab: run {run_id} in store {where}", file=sys.stderr)
    logging.getLogger("goniolab").info("run %d in store %s", run_id, where)


#: Config keys that do not change what a run measures (where the instruments are plugged,
#: how long to wait for them, the store, the run's own metadata): a live config that
#: differs from the run's snapshot only there resumes without a word.
_RESUME_IGNORED_SECTIONS = ("lab", "run", "glossmeter")
_RESUME_IGNORED_KEYS = frozenset(
    {"transport", "host", "port", "unit_id", "serial_port", "baudrate", "parity", "timeout_s",
     "move_timeout_s", "serial_number", "protocol"}
)  # fmt: skip


def _flat(doc: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(doc, dict):
        out: dict[str, Any] = {}
        for k, v in doc.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: doc}


def config_changes(snapshot: dict[str, Any], live: dict[str, Any]) -> list[str]:
    """The keys (dotted) whose value differs between a run's stored config and the live
    one, among those that change what is measured; ``"key: stored -> live"`` each."""
    a, b = _flat(snapshot), _flat(live)
    out = []
    for key in sorted(set(a) | set(b)):
        parts = key.split(".")
        if key.startswith("_") or parts[0] in _RESUME_IGNORED_SECTIONS:
            continue
        if parts[-1] in _RESUME_IGNORED_KEYS:
            continue
        if a.get(key) != b.get(key):
            out.append(f"{key}: {a.get(key, '(unset)')!r} -> {b.get(key, '(unset)')!r}")
    return out


def resume_config(rec: Any, config_arg: str | None, use_current: bool) -> LabConfig:
    """The config a stored run resumes with: its stored snapshot (issue 23.9), unless
    ``use_current``. The live file (``--config`` or the one the run started with) is
    compared with the snapshot: a change that alters the measurement is refused, naming
    each key, unless ``use_current`` (then the live file is used, and the changes are
    printed on stderr).

    Raises
    ------
    UserError
        A change refused, or a snapshot that cannot be used and no live file.
    """
    from pathlib import Path

    from pydantic import ValidationError

    from goniolab.config import LabConfig, load_lab_config
    from goniolab.session import with_sample

    snap = dict(rec.config)
    source = str(snap.pop("_source", "") or "")
    live_path = config_arg or (source if source and Path(source).exists() else "")
    live = load_lab_config(live_path) if live_path else None
    if live is not None:
        # what the run's own command line set (its sample, a --model) is no config change
        live = with_sample(live, rec.sample)
        started_with = rec.model.get("model_name")
        if started_with in model_names():
            s = live.sample.model_copy(update={"model": started_with})
            live = live.model_copy(update={"sample": s})
    stored: LabConfig | None = None
    why = ""
    try:
        stored = LabConfig.model_validate(snap).model_copy(update={"source": source})
    except ValidationError as exc:
        why = " ".join(str(exc).split())
    if use_current:
        if live is None:
            raise UserError(f"run {rec.id}: --use-current-config needs --config FILE")
        if stored is not None:
            for line in config_changes(
                stored.model_dump(mode="json"), live.model_dump(mode="json")
            ):
                print(f"goniolab: resuming with the current config: {line}", file=sys.stderr)
        return live
    if stored is None:
        if live is None:
            raise UserError(
                f"run {rec.id}: its stored config cannot be used ({why}); pass --config FILE"
            )
        print(
            f"goniolab: run {rec.id}: its stored config cannot be used ({why}); "
            f"resuming with {live_path}",
            file=sys.stderr,
        )
        return live
    if live is not None:
        changes = config_changes(stored.model_dump(mode="json"), live.model_dump(mode="json"))
        if changes:
            raise UserError(
                f"run {rec.id}: {live_path} changed since the run started ("
                + "; ".join(changes)
                + "): the rest of the run would not measure what its first readings did. "
                "Resume with the run's stored config by restoring the file, or pass "
                "--use-current-config to go on with the new one"
            )
        # the live file may hold what the snapshot could not keep (a store password)
        stored = stored.model_copy(update={"lab": live.lab, "source": live.source})
    return stored


def _cmd_resume(args: argparse.Namespace) -> int:
    from goniolab.config import load_lab_config
    from goniolab.store import StoreError

    config_store = None
    if args.config:
        config_store = load_lab_config(args.config).lab.store
    store = _open(args.store, config_store, create=False)
    with store:
        try:
            rec = store.get_run(args.run)
        except StoreError as exc:
            raise UserError(str(exc)) from exc
        if rec.kind in ("align", "calibration"):
            what = "an alignment" if rec.kind == "align" else "a calibration"
            raise UserError(
                f"run {rec.id} is {what}: it cannot be resumed, run it again "
                f"({'scan --plan align' if rec.kind == 'align' else 'calibrate'})"
            )
        from goniolab.session import resume_target

        resume_target(rec, None, store.count_points(rec.id), need_file=False)
        cfg = resume_config(rec, args.config, args.use_current_config)
        # the run goes on with the model it started with (a `scan --model` override included),
        # so the predictions still to compute are that model's, not the config's
        started_with = rec.model.get("model_name")
        print(
            f"goniolab: resuming run {rec.id}: {store.count_points(rec.id)} readings stored",
            file=sys.stderr,
        )
        return run_lab(
            _execute(
                config_path=cfg.source,
                time_scale=args.time_scale,
                store=store,
                plan=None,
                run_id=rec.id,
                json_out=args.json,
                model=started_with if started_with in model_names() else None,
                config=cfg,
            )
        )


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--store",
        help="run store: SQLite file or postgresql:// URL (default: the config's [lab] store, "
        "else goniolab.sqlite in the user data dir: goniolab --version)",
    )
    p.add_argument(
        "--time-scale",
        type=float,
        default=None,
        help="sim clock scale, 0 = instant, 1 = real time (default: the config's [lab] time_scale)",
    )
    p.add_argument("--json", action="store_true", help="print only the summary JSON on stdout")


def register(subparsers: Any) -> None:
    """Add ``scan`` (and ``scan resume RUN``)."""
    p = subparsers.add_parser(
        "scan",
        help="run an in-plane BRDF scan (or: scan resume RUN)",
        description="Measure the in-plane luminance curve at fixed incidence and compare it, "
        "point by point, with the model prediction (Wittmann et al. 2021, sec. 2.3).",
    )
    _add_common(p)
    p.add_argument("--config", help="lab config TOML (e.g. configs/lab-sim.toml)")
    p.add_argument(
        "--sample", help="sample:NAME or a height-map file (default: config [sample] map)"
    )
    p.add_argument(
        "--step-um",
        type=float,
        default=None,
        metavar="UM",
        help="lateral step of a map file that carries none (a .npy without sidecar), um "
        "(default: the config's [sample] step_um)",
    )
    p.add_argument("--theta-i", type=float, default=45.0, help="incidence (lamp) angle, deg")
    p.add_argument(
        "--theta-r",
        default=None,
        help='detector angles, deg: "start:stop:step" or "a,b,c" (default: 0:70:1)',
    )
    p.add_argument(
        "--plan",
        choices=("sweep", "e2194", "align"),
        default="sweep",
        help="sweep (--theta-r), e2194: the ASTM E2194/E2539, DIN 6175-2 multi-angle geometry, "
        "or align: find the arms' zero offsets and the sample's tilt (black-glass standard, "
        "then the sample) and save them to the lab's alignment state file",
    )
    from goniolab.scan.plans import DEFAULT_REPEATS  # light: stdlib and drivers.base

    p.add_argument(
        "--repeats",
        type=int,
        default=DEFAULT_REPEATS,
        help="readings per geometry (the TUI's default too)",
    )
    p.add_argument("--dwell", type=float, default=0.0, help="settling time after each move, s")
    p.add_argument("--exposure-us", type=int, default=None, help="exposure, us (default: config)")
    p.add_argument(
        "--mirror-reference",
        action="store_true",
        help="read a mirror at the specular geometry first; it sets the 100 %% level",
    )
    p.add_argument(
        "--model",
        choices=model_names(),
        default=None,
        help="prediction model (default: config [sample] model, itself default auto)",
    )
    p.add_argument(
        "--align-theta-i",
        default="20,40,60",
        help="incidence angles of --plan align, deg (two or more)",
    )
    p.add_argument(
        "--no-write-config",
        action="store_true",
        help="--plan align: store the result with the run only, not in the lab's alignment "
        "state file (the config file is never rewritten)",
    )
    p.add_argument(
        "--adaptive",
        action="store_true",
        help="place the --theta-r angles where the predicted curve bends (as many angles, "
        "same start and stop, same run time; dense at the specular peak, sparse on the flanks)",
    )
    p.add_argument(
        "--auto-exposure",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="adapt the spectro's exposure to each reading from its reported signal level "
        "(no saturation, no drowning; the default: at a fixed 10 ms a colour is noise); "
        "--no-auto-exposure keeps --exposure-us fixed",
    )
    add_run_meta_args(p)
    allow_negative_angles(p)  # "--theta-r -40:-30:5" is a lamp-side range, not an option
    p.set_defaults(func=_cmd_scan)
    sub = p.add_subparsers(dest="scan_command", metavar="resume")
    pr = sub.add_parser("resume", help="continue an interrupted run (also after a crash)")
    _add_common(pr)
    pr.add_argument(
        "run", type=int, metavar="RUN", help="the interrupted run's id (goniolab runs list)"
    )
    pr.add_argument(
        "--config",
        help="lab config TOML compared with the run's stored config (default: the file the "
        "run was started with); the run resumes with its stored config",
    )
    pr.add_argument(
        "--use-current-config",
        action="store_true",
        help="resume with the live config file even where it changed something that matters "
        "(each change is printed)",
    )
    pr.set_defaults(func=_cmd_resume)
