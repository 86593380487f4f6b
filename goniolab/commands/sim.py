"""``goniolab sim serve``: serve the simulated lab on the wire until interrupted.

Starts the Modbus TCP controllers and the pty serial devices of a lab config
(``configs/lab-sim-wire.toml``), prints where they are (one JSON object with ``--json``),
and runs until SIGINT or SIGTERM, then stops cleanly with exit code 0.
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
