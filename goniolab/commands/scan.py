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
import sys
from collections.abc import Coroutine
from typing import TYPE_CHECKING, Any, TypeVar

from goniolab import jsonout
from goniolab.commands._angles import allow_negative_angles
from goniolab.errors import UserError
from goniolab.model_registry import model_names

if TYPE_CHECKING:  # loaded when a scan runs, not at --help (tests/test_startup.py)
    from goniolab.app.lab_scan import ScanOutcome
    from goniolab.scan.events import PointMeasured, RunState
    from goniolab.scan.runner import ScanRunner
    from goniolab.store import RunMeta, RunStore

__all__ = [
    "add_run_meta_args",
    "format_summary",
    "point_detail",
    "read_stdin_line",
    "register",
    "resume_command",
    "run_lab",
    "run_meta_args",
    "specimen_prompt",
]

_T = TypeVar("_T")


def _exit_code(state: RunState) -> int:
    """0 done, 1 failed, 130 aborted."""
    return {"done": 0, "failed": 1, "aborted": 130}[state.value]


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


def point_detail(ev: PointMeasured, predicted_pct: float | None) -> str:
    """Progress-line detail of a reading (:func:`goniolab.app.lab_scan.point_detail`)."""
    from goniolab.app.lab_scan import point_detail as detail

    return detail(ev, predicted_pct)


def resume_command(run_id: int, store: RunStore) -> str:
    """The command that resumes run ``run_id`` (:func:`goniolab.app.lab_setup.resume_command`)."""
    from goniolab.app.lab_setup import resume_command as command

    return command(run_id, store)


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


async def specimen_prompt(which: str) -> None:
    """Ask the operator to place the mirror, the black-glass standard or the sample back
    and press Enter (a real lab; a simulated one swaps them itself)."""
    if which == "standard":
        what = "the BLACK-GLASS STANDARD (ISO 2813, on the reference seat)"
    else:
        what = "the reference MIRROR" if which == "mirror" else "the SAMPLE"
    print(f"goniolab: place {what} under the instruments, then press Enter", file=sys.stderr)
    if not await read_stdin_line():
        raise UserError(f"no operator confirmation on stdin for placing {what}", exit_code=1)


def run_lab(coro: Coroutine[Any, Any, _T]) -> _T:
    """``asyncio.run(coro)`` (the use cases turn the lab's errors into UserError)."""
    import asyncio

    return asyncio.run(coro)


async def _watch(state: dict[str, Any], run: Coroutine[Any, Any, ScanOutcome]) -> ScanOutcome | int:
    """Run a scan use case; once its run is stored (``state["runner"]``, set by
    :func:`_stop_on_signals`), Ctrl-C (SIGTERM, SIGHUP) aborts it (the arms stop and park)
    and a second one quits at once (the arms still park, the run is recorded as aborted):
    130."""
    import asyncio

    state["main"] = asyncio.current_task()
    try:
        return await run
    except asyncio.CancelledError:
        runner = state.get("runner")
        if runner is None:
            raise
        print(
            f"goniolab: run {runner.run_id} aborted; continue it with: "
            f"{resume_command(runner.run_id, runner.store)}",
            file=sys.stderr,
        )
        return 130
    finally:
        if "remove_signals" in state:
            state["remove_signals"]()


def _stop_on_signals(state: dict[str, Any], runner: ScanRunner) -> None:
    """The runner of the stored run, stopped by the stop signals from now on."""
    import asyncio

    from goniolab.commands._signals import describe, install_stop_signals

    state["runner"] = runner

    def stop_first(name: str) -> None:
        _say(state, f"goniolab: {describe(name)}: stopping: the arms stop, then park "
                    "(Ctrl-C again to quit at once: the arms still stop and the run is recorded)")  # fmt: skip
        runner.abort(by=describe(name))

    def stop_again(name: str) -> None:
        _say(state, f"goniolab: {describe(name)} again: quitting, the arms stop and park")
        if state.get("main") is not None:
            state["main"].cancel()

    loop = asyncio.get_running_loop()
    state["remove_signals"] = install_stop_signals(loop, stop_first, stop_again)


def _say(state: dict[str, Any], text: str) -> None:
    bar = state.get("bar")
    if bar is not None:
        bar.message(text)
    else:
        print(text, file=sys.stderr)


def _present(out: ScanOutcome, store: RunStore, json_out: bool) -> int:
    from goniolab.scan.events import RunState

    if json_out:
        print(jsonout.dumps(out.as_dict(), indent=2))
    else:
        print(f"run {out.run_id}: {out.state.value}" + (f" ({out.reason})" if out.reason else ""))
        print(format_summary(out.summary))
    if out.state is not RunState.DONE:
        print(
            f"goniolab: run {out.run_id} {out.state.value}; continue it with: "
            f"{resume_command(out.run_id, store)}",
            file=sys.stderr,
        )
    return _exit_code(out.state)


def _run_scan(store: RunStore, json_out: bool, start: Any) -> int:
    """Run the scan use case ``start(reporter, on_start)`` with the terminal's progress
    bar and the stop signals, then present its outcome."""
    from goniolab.progress import terminal_progress

    state: dict[str, Any] = {"bar": terminal_progress()}

    def on_start(runner: ScanRunner) -> None:
        _stop_on_signals(state, runner)

    result = run_lab(_watch(state, start(state["bar"], on_start)))
    if isinstance(result, int):
        return result
    return _present(result, store, json_out)


def _cmd_align(args: argparse.Namespace, cfg: Any, sample: str) -> int:
    from goniolab.app import lab_scan, lab_setup

    plan = lab_setup.align_plan(
        cfg, sample=sample, theta_i_deg=args.align_theta_i, exposure_us=args.exposure_us
    )
    with lab_setup.open_store(args.store, cfg.lab.store) as store:
        bar = _progress()
        out = run_lab(
            lab_scan.align(
                cfg, store, plan, time_scale=args.time_scale,
                save_state=not args.no_write_config, reporter=bar, operator=specimen_prompt,
            )
        )  # fmt: skip
    if args.json:
        print(jsonout.dumps(out.as_dict(), indent=2))
        return 0
    result = out.result
    c = result.corrections_deg()
    print(f"run {out.run_id}: alignment done ({result.readings} readings)")
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
            f"  saved to {result.state_file} (the lab's alignment state; {args.config} untouched)"
        )
    else:
        print("  stored with the run only: later scans are not corrected")
    return 0


def _progress() -> Any:
    from goniolab.progress import terminal_progress

    return terminal_progress()


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
    from goniolab.app.lab_setup import run_meta

    return run_meta(args.operator, args.sample_id, args.note, args.tag)


def _cmd_scan(args: argparse.Namespace) -> int:
    if not args.config:
        raise UserError("scan: --config FILE is required (e.g. configs/lab-sim.toml)")
    from goniolab.app import lab_scan, lab_setup

    cfg = lab_setup.load_config(args.config, args.store)
    theta_r_given = args.theta_r is not None
    sample = lab_setup.scan_sample(cfg, args.sample)
    cfg = lab_setup.check_map(cfg, sample, given=bool(args.sample), step_um=args.step_um)
    if args.plan == "align":
        return _cmd_align(args, cfg, sample)
    theta_i, theta_r = args.theta_i, args.theta_r or "0:70:1"
    if args.plan == "e2194":
        if args.adaptive:
            raise UserError(
                "scan --plan e2194 measures the standard's fixed angles; drop --adaptive"
            )
        theta_r, skipped = lab_setup.e2194_angles(cfg, theta_i, theta_r_given=theta_r_given)
        for line in skipped:
            print(line, file=sys.stderr)
    plan = lab_setup.brdf_plan(
        cfg, sample=sample, theta_i_deg=theta_i, theta_r_deg=theta_r, repeats=args.repeats,
        dwell_s=args.dwell, exposure_us=args.exposure_us,
        mirror_reference=args.mirror_reference, auto_exposure=args.auto_exposure,
    )  # fmt: skip
    with lab_setup.open_store(args.store, cfg.lab.store) as store:
        return _run_scan(
            store,
            args.json,
            lambda bar, on_start: lab_scan.scan(
                cfg, store, plan, time_scale=args.time_scale, model=args.model,
                adaptive=args.adaptive, meta=run_meta_args(args), reporter=bar,
                notify=lab_setup.stderr_notify, on_start=on_start, operator=specimen_prompt,
            ),
        )  # fmt: skip


def _cmd_resume(args: argparse.Namespace) -> int:
    from goniolab.app import lab_scan, lab_setup

    live = lab_setup.load_config(args.config, args.store) if args.config else None
    config_store = None if live is None else live.lab.store
    with lab_setup.open_store(args.store, config_store, create=False) as store:
        return _run_scan(
            store,
            args.json,
            lambda bar, on_start: lab_scan.resume(
                store, args.run, config=args.config, live=live,
                use_current_config=args.use_current_config, time_scale=args.time_scale,
                reporter=bar, notify=lab_setup.stderr_notify, on_start=on_start,
                operator=specimen_prompt,
            ),
        )  # fmt: skip


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
