"""``goniolab gloss log``: log glossmeter readings into the run store.

Either from a lab config (``--config FILE``: the configured glossmeter, real or simulated)
or straight from a port (``--port PORT --protocol NAME``, no config; the protocols are
those of :data:`drivers.protocols.GLOSSMETERS`). Each reading
is committed to the store with its timestamp, printed beside the model's ISO 2813 gloss
when the sample has a height map, or printed as one JSON object per line with ``--json``
(readings carry ``seq``; the last line holds the session's ``statistics``: n, mean and
sample standard deviation per geometry).
Garbled lines and disconnects are reported on stderr; the logger reconnects with backoff
and loses nothing already read. Ctrl-C ends the session after the current reading.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import sys
from typing import TYPE_CHECKING, Any

from goniolab.commands.scan import add_run_meta_args, run_lab, run_meta_args
from goniolab.errors import UserError

if TYPE_CHECKING:  # loaded when a session runs, not at --help (tests/test_startup.py)
    import asyncio

    from goniolab.scan.events import GlossRead
    from goniolab.scan.gloss_logger import GlossLogger, GlossResult

__all__ = ["format_reading", "register"]


def _iso(ts: float) -> str:
    return dt.datetime.fromtimestamp(ts, tz=dt.UTC).isoformat(timespec="milliseconds")


def format_reading(ev: GlossRead, seq: int) -> str:
    """One text line: sequence number, UTC time, measured GU per geometry with the
    predicted GU beside it, instrument temperature."""
    parts = [f"{seq:>4}  {_iso(ev.timestamp)}"]
    for angle, v in sorted(ev.values_gu.items()):
        txt = f"G{angle}     - GU" if v is None else f"G{angle} {v:6.1f} GU"
        if ev.predicted_gu is not None and angle in ev.predicted_gu:
            by = ev.predicted_models.get(angle)
            txt += f" (pred {ev.predicted_gu[angle]:6.1f}{', ' + by if by else ''})"
        parts.append(txt)
    if ev.temperature_c is not None:
        parts.append(f"{ev.temperature_c:.1f} degC")
    return "  ".join(parts)


def reading_json(ev: GlossRead, seq: int) -> str:
    """One JSON object (one line) per reading."""
    return json.dumps(
        {
            "run_id": ev.run_id,
            "seq": seq,
            "timestamp": ev.timestamp,
            "time_utc": _iso(ev.timestamp),
            "values_gu": {str(k): v for k, v in sorted(ev.values_gu.items())},
            "predicted_gu": None
            if ev.predicted_gu is None
            else {str(k): v for k, v in sorted(ev.predicted_gu.items())},
            "predicted_models": {str(k): v for k, v in sorted(ev.predicted_models.items())},
            "temperature_c": ev.temperature_c,
        }
    )


async def _print_events(q: asyncio.Queue[Any], json_out: bool) -> None:
    from goniolab.scan.events import GlossRead, InstrumentError

    seq = 0
    while (ev := await q.get()) is not None:
        if isinstance(ev, GlossRead):
            print(reading_json(ev, seq) if json_out else format_reading(ev, seq), flush=True)
            seq += 1
        elif isinstance(ev, InstrumentError):
            kind = "fault" if ev.fatal else "warning"
            print(f"goniolab: {kind}: {ev.device}: {ev.message}", file=sys.stderr, flush=True)


def _cmd_log(args: argparse.Namespace) -> int:
    if not args.config and not args.port:
        from drivers.protocols import GLOSSMETERS

        raise UserError(
            "gloss log: give --config FILE, or --port PORT --protocol "
            + "|".join(GLOSSMETERS.names())
        )
    from goniolab.app.lab_gloss import MeterPort, gloss_log, gloss_plan, stored_gloss_prediction
    from goniolab.app.lab_setup import check_sample, load_config, open_store, stderr_notify
    from goniolab.scan.events import RunState

    if args.config and args.port:
        raise UserError("gloss log: --config and --port exclude each other")
    if args.port and "://" not in args.port and not os.path.exists(args.port):
        raise UserError(f"gloss log: --port {args.port}: no such device")
    if not args.interval >= 0:
        raise UserError(f"gloss log: --interval must be >= 0 s, got {args.interval}")
    if not args.timeout > 0:
        raise UserError(f"gloss log: --timeout must be > 0 s, got {args.timeout}")
    if args.calibration_max_age_h is not None and not args.calibration_max_age_h > 0:
        raise UserError(  # inf is the lab's "never", as in the config
            f"gloss log: --calibration-max-age-h must be > 0 (inf: never warn), "
            f"got {args.calibration_max_age_h}"
        )
    sample = args.sample or ""
    if args.sample:  # checked, as the user typed it (the stored run names it so)
        check_sample(args.sample)
    cfg = load_config(args.config) if args.config else None
    if cfg is not None:
        sample = args.sample or cfg.sample.map
    plan = gloss_plan(args.count, args.angles, sample)
    port = None
    if args.port:
        port = MeterPort(
            args.port, protocol=args.protocol, profile=args.profile,
            serial_number=args.serial_number, baudrate=args.baudrate, timeout_s=args.timeout,
            n=args.n,
        )  # fmt: skip
    stops: dict[str, Any] = {}

    def on_start(logger: GlossLogger) -> None:
        import asyncio

        from goniolab.commands._signals import describe, install_stop_signals

        def stop_first(name: str) -> None:
            # Ctrl-C ends a log as the operator's stop; SIGTERM / SIGHUP as an abort
            logger.stop(by="" if name == "SIGINT" else describe(name))

        def stop_again(name: str) -> None:
            # the stop already ends every wait; a reading in progress ends within its
            # timeout and is stored, and so is the run's end: nothing to cancel
            logger.stop(by=describe(name))

        loop = asyncio.get_running_loop()
        stops["remove"] = install_stop_signals(loop, stop_first, stop_again)

    async def log() -> GlossResult:
        try:
            return await gloss_log(
                store, plan, config=cfg, port=port, time_scale=args.time_scale,
                mode=args.mode, interval_s=args.interval, meta=run_meta_args(args),
                watch=lambda q: _print_events(q, args.json), on_start=on_start,
                notify=stderr_notify, max_age_h=args.calibration_max_age_h,
            )  # fmt: skip
        finally:
            if "remove" in stops:
                stops["remove"]()

    with open_store(args.store, config=cfg) as store:
        result = run_lab(log())
        if args.json:
            # the last JSON line: the session's statistics (reading lines carry "seq")
            print(
                json.dumps(
                    {
                        "run_id": result.run_id,
                        "state": result.state.value,
                        "reason": result.reason,
                        "readings": result.readings,
                        "reconnects": result.reconnects,
                        "statistics": result.stats.as_dict(),
                        # the stored run's predicted gloss: its model per geometry and
                        # the warnings of those numbers
                        "prediction": stored_gloss_prediction(store, result.run_id),
                        # the calibration the readings rest on (gloss calibrate)
                        "calibration": store.get_run(result.run_id).model.get(
                            "glossmeter_calibration"
                        ),
                    }
                )
            )
        else:
            for angle in plan.angles_deg:
                if angle in result.stats.n:
                    print(
                        f"G{angle}: mean {result.stats.mean_gu[angle]:.2f} GU, "
                        f"std {result.stats.std_gu[angle]:.2f} GU (n = {result.stats.n[angle]})"
                    )
        print(
            f"goniolab: gloss run {result.run_id}: {result.readings} readings, "
            f"{result.state.value}" + (f" ({result.reason})" if result.reason else ""),
            file=sys.stderr,
        )
    return 0 if result.state in (RunState.DONE, RunState.ABORTED) else 1


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from goniolab.app.lab_gloss import MeterPort, gloss_calibrate
    from goniolab.app.lab_setup import load_config, open_store, stderr_notify

    if bool(args.config) == bool(args.port):
        raise UserError("gloss calibrate: give --config FILE or --port PORT (one of them)")
    if args.port and "://" not in args.port and not os.path.exists(args.port):
        raise UserError(f"gloss calibrate: --port {args.port}: no such device")
    cfg = load_config(args.config) if args.config else None
    port = None
    if args.port:
        port = MeterPort(
            args.port, protocol=args.protocol, profile=args.profile,
            serial_number=args.serial_number, baudrate=args.baudrate, timeout_s=args.timeout,
        )  # fmt: skip
    with open_store(args.store, config=cfg) as store:
        calibration = gloss_calibrate(
            store, config=cfg, port=port, angles_deg=args.angles, standard=args.standard,
            time_scale=args.time_scale, notify=stderr_notify,
        )  # fmt: skip
        run_id, record = run_lab(calibration)
        if args.json:
            print(json.dumps({"run_id": run_id, "store": str(store.location), **record}))
        else:
            std = record["standard"]
            gu = ", ".join(f"G{a} {v:.1f} GU" for a, v in std["gu"].items())
            print(
                f"glossmeter {record['instrument']['identity']} calibrated "
                f"{record['time_iso']} on {std['name']}" + (f" ({gu})" if gu else "")
            )
            for a, r in record["angles"].items():
                print(
                    f"  G{a}: deviation from the factory calibration {r['deviation_ppm']} ppm "
                    f"({r['deviation_pct']:+.4f} %)"
                )
            print(f"stored as run {run_id} in {store.location}")
    return 0


def _meter_args(p: Any) -> None:
    from drivers.protocols import GLOSSMETERS  # the standard library only: cheap at --help

    p.add_argument("--config", help="lab config TOML (uses its [glossmeter])")
    p.add_argument("--port", help="serial port of the meter (without --config)")
    p.add_argument(
        "--protocol",
        choices=GLOSSMETERS.names(),
        default="zgm1120",
        help=f"meter protocol (without --config): {GLOSSMETERS.help_text()}",
    )
    p.add_argument("--profile", default=None, help="protocol profile (default: the protocol's)")
    p.add_argument("--serial-number", default="401120999", help="ZGM1120 serial number")
    p.add_argument(
        "--baudrate", type=int, default=None, help="serial baud rate (default: the profile's)"
    )
    p.add_argument("--timeout", type=float, default=2.0, help="reply timeout, s")


def register(subparsers: Any) -> None:
    """Add ``gloss log`` and ``gloss calibrate``."""

    p = subparsers.add_parser("gloss", help="glossmeter sessions (gloss log, gloss calibrate)")
    sub = p.add_subparsers(dest="gloss_command", metavar="ACTION", required=True)
    pl = sub.add_parser("log", help="log glossmeter readings into the store")
    _meter_args(pl)
    pl.add_argument("--sample", help="sample:NAME or height map: print the predicted gloss beside")
    pl.add_argument(
        "--n", type=float, default=1.55, help="refractive index for --sample (no config)"
    )
    pl.add_argument("--count", type=int, default=0, help="readings to take (0 = until Ctrl-C)")
    add_run_meta_args(pl)  # --operator, --sample-id, --note, --tag (run identity)
    pl.add_argument("--angles", type=int, nargs="+", default=[20, 60, 85], help="geometries, deg")
    pl.add_argument("--mode", choices=("measure", "push"), default=None,
                    help="ask for each reading, or take readings the meter pushes")  # fmt: skip
    pl.add_argument("--interval", type=float, default=0.0, help="pause between readings, s")
    pl.add_argument("--time-scale", type=float, default=None,
                    help="sim clock scale, 0 = instant (default: the config's [lab] time_scale)")  # fmt: skip
    pl.add_argument(
        "--store",
        help="run store: SQLite file or postgresql:// URL (default: the config's [lab] store, "
        "else goniolab.sqlite in the user data dir: goniolab --version)",
    )
    pl.add_argument(
        "--calibration-max-age-h", type=float, default=None,
        help="warn when the meter's newest stored calibration is older (h; the lab's rule; "
        "default: the config's [glossmeter] calibration_max_age_h, else 24)",
    )  # fmt: skip
    pl.add_argument("--json", action="store_true", help="one JSON object per reading on stdout")
    pl.set_defaults(func=_cmd_log)

    pc = sub.add_parser(
        "calibrate", help="calibrate the glossmeter on its standard and store the record"
    )
    _meter_args(pc)
    pc.add_argument("--angles", type=int, nargs="+", default=[20, 60, 85], help="geometries, deg")
    pc.add_argument(
        "--standard", default=None,
        help="a fresnel standard of the config's standards.toml (its GU from n; ISO 2813 "
        "black glass n = 1.567 is 100 GU); default: the meter's own working standard",
    )  # fmt: skip
    pc.add_argument("--time-scale", type=float, default=None,
                    help="sim clock scale, 0 = instant (default: the config's [lab] time_scale)")  # fmt: skip
    pc.add_argument("--store", help="run store: SQLite file or postgresql:// URL (as gloss log)")
    pc.add_argument("--json", action="store_true", help="the stored record as one JSON object")
    pc.set_defaults(func=_cmd_calibrate)
