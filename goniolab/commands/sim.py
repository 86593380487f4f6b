"""``goniolab sim serve``: serve the simulated lab on the wire until interrupted.

Starts the Modbus TCP controllers and the pty serial devices of a lab config
(``configs/lab-sim-wire.toml``), prints where they are (one JSON object with ``--json``),
and runs until SIGINT or SIGTERM, then stops cleanly with exit code 0.

``goniolab sim cache``: where the twin's disk cache of response tables is and how much it
holds (this code version's files and the rest), ``--prune`` / ``--clear`` to shrink or
empty it (:mod:`sim.twin_cache`).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from goniolab.errors import UserError

__all__ = ["register"]


def register(subparsers: Any) -> None:
    """Add ``sim`` (with ``serve``) to the top-level parser."""
    p = subparsers.add_parser(
        "sim",
        help="the simulated lab",
        description="The simulated lab. 'goniolab sim serve --config configs/lab-sim-wire.toml' "
        "serves it on the wire (Modbus TCP or RTU-over-socket controllers, pty serial "
        "spectro-colorimeter and glossmeter) until Ctrl-C; see docs/WIRE_SIM.md.",
    )
    sub = p.add_subparsers(dest="sim_command", metavar="SUBCOMMAND")
    serve = sub.add_parser(
        "serve",
        help="serve the simulated lab over Modbus and ptys until Ctrl-C",
        description="Serve the simulated lab (Modbus TCP or RTU-over-socket stepper "
        "controllers, pty serial spectro-colorimeter and glossmeter) on the endpoints of a "
        "lab config; port 0 picks a free port (printed).",
    )
    serve.add_argument(
        "--config", required=True, help="lab config (e.g. configs/lab-sim-wire.toml)"
    )
    serve.add_argument("--json", action="store_true", help="print the endpoints as one JSON line")
    serve.add_argument(
        "--time-scale",
        type=float,
        default=None,
        help="sim clock scale, 0 = instant, 1 = real time (default: the config's [lab] time_scale)",
    )
    serve.set_defaults(func=_cmd_serve)
    cache = sub.add_parser(
        "cache",
        help="show the twin's response-table cache (location, size); --clear empties it",
        description="The realistic twin keeps its Kirchhoff response tables on disk, one file "
        "per sample, settings and version of the table code (docs/TWIN.md, 'Cost'). Shown: "
        "the directory, its files and bytes, this version's and the rest. Each write prunes "
        "it: other versions' files unused for a day, then the least recently used down to "
        "the size cap. [sim.twin] cache = false turns the cache off.",
    )
    cache.add_argument("--clear", action="store_true", help="remove every cached table file")
    cache.add_argument(
        "--prune",
        action="store_true",
        help="prune now, as after each write (with --max-mb, --other-versions-age-h)",
    )
    cache.add_argument("--max-mb", type=float, default=None, help="size cap of --prune, MB")
    cache.add_argument(
        "--other-versions-age-h",
        type=float,
        default=None,
        help="--prune removes other code versions' files unused this long, h (0: all of them)",
    )
    cache.add_argument("--json", action="store_true", help="print the state as JSON")
    cache.set_defaults(func=_cmd_cache)
    p.set_defaults(func=lambda args: _usage(p))


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def _cmd_serve(args: argparse.Namespace) -> int:
    if args.time_scale is not None and not args.time_scale >= 0:
        raise UserError(f"--time-scale must be >= 0, got {args.time_scale}")
    import asyncio

    return asyncio.run(_serve(args.config, args.time_scale, args.json))


async def _serve(config_path: str, time_scale: float | None, as_json: bool) -> int:
    import asyncio
    import signal

    from goniolab.app.lab_scan import serve_simulated_lab
    from goniolab.app.lab_setup import load_config

    cfg = load_config(config_path)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        async with serve_simulated_lab(cfg, time_scale=time_scale) as served:
            _show(served.endpoints, config_path, served.time_scale, as_json)
            await stop.wait()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    if not as_json:
        print("goniolab: simulated lab stopped", file=sys.stderr)
    return 0


def _show(endpoints: dict[str, Any], config_path: str, scale: float, as_json: bool) -> None:
    if as_json:
        print(
            json.dumps({"config": config_path, "time_scale": scale, "endpoints": endpoints}),
            flush=True,
        )
    else:
        print(f"goniolab: simulated lab from {config_path} (clock x{scale:g}):")
        for name, ep in endpoints.items():
            if "unit_id" not in ep:
                where = f"serial {ep['port']} -> {ep['pty']}"
            elif ep["transport"] == "tcp":
                where = f"modbus tcp {ep['host']}:{ep['port']} unit {ep['unit_id']}"
            else:
                where = f"modbus rtu {ep['serial_port']} unit {ep['unit_id']}"
            print(f"  {name:<10} {where}  (profile {ep['profile']})")
        print("Ctrl-C to stop.", flush=True)


def _mb(n_bytes: float) -> str:
    return f"{n_bytes / 1e9:.2f} GB" if n_bytes >= 1e9 else f"{n_bytes / 1e6:.1f} MB"


def _cmd_cache(args: argparse.Namespace) -> int:
    from sim.assembly import TWIN_CACHE_FOREIGN_MAX_AGE_S, TWIN_CACHE_MAX_BYTES, twin_cache

    if args.clear and args.prune:
        raise UserError("sim cache: --clear and --prune exclude each other")
    if not args.prune and (args.max_mb is not None or args.other_versions_age_h is not None):
        raise UserError("sim cache: --max-mb and --other-versions-age-h go with --prune")
    max_bytes = TWIN_CACHE_MAX_BYTES if args.max_mb is None else args.max_mb * 1e6
    age_s = (
        TWIN_CACHE_FOREIGN_MAX_AGE_S
        if args.other_versions_age_h is None
        else args.other_versions_age_h * 3600.0
    )
    if not (max_bytes >= 0 and age_s >= 0):
        raise UserError("sim cache: --max-mb and --other-versions-age-h must be >= 0")
    info, removed, code = twin_cache(
        clear_all=args.clear, prune=args.prune, max_bytes=int(max_bytes), foreign_max_age_s=age_s
    )
    mine, others = info.of_code(code), info.others(code)
    if args.json:
        print(json.dumps({
            "directory": str(info.directory),
            "files": len(info.entries),
            "bytes": info.total_bytes,
            "code_key": code[:12],
            "this_version": {"files": len(mine), "bytes": sum(e.size_bytes for e in mine)},
            "other_versions": {"files": len(others), "bytes": sum(e.size_bytes for e in others)},
            "removed": {"files": len(removed), "bytes": sum(e.size_bytes for e in removed)},
            "max_bytes": TWIN_CACHE_MAX_BYTES,
            "other_versions_max_age_s": TWIN_CACHE_FOREIGN_MAX_AGE_S,
        }, indent=2))  # fmt: skip
        return 0
    if removed:
        what = "cleared" if args.clear else "pruned"
        print(f"{what}: {len(removed)} files, {_mb(sum(e.size_bytes for e in removed))}")
    print(f"twin response-table cache: {info.directory}")
    print(f"  {len(info.entries)} files, {_mb(info.total_bytes)}: this version (code "
          f"{code[:12]}) {len(mine)} files, {_mb(sum(e.size_bytes for e in mine))}; other or "
          f"older versions and temporary files {len(others)}, "
          f"{_mb(sum(e.size_bytes for e in others))}")  # fmt: skip
    print(f"  pruned after each write: other versions' files unused for "
          f"{TWIN_CACHE_FOREIGN_MAX_AGE_S / 3600:g} h, then the least recently used down to "
          f"{_mb(TWIN_CACHE_MAX_BYTES)}; 'goniolab sim cache --clear' empties it")  # fmt: skip
    return 0
