"""``goniolab calibrate --config LAB``: the reference mirror and a check standard read
against their certificates, stored as a calibration record that later runs cite
(:mod:`goniolab.scan.calibration`, docs/CALIBRATION.md)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from goniolab.errors import UserError

__all__ = ["register"]


async def _execute(args: argparse.Namespace) -> int:
    from drivers.base import DeviceError
    from goniolab import __version__
    from goniolab.commands.scan import _open, _specimen_prompt
    from goniolab.config import load_lab_config
    from goniolab.scan.calibration import CalibrationRefused, run_calibration
    from goniolab.scan.colour import PointColour
    from goniolab.scan.events import RunState
    from goniolab.session import ScanSession, config_snapshot, home_timeout_s

    cfg = load_lab_config(args.config)
    with _open(args.store, cfg.lab.store) as store:
        async with ScanSession.open(
            cfg, store, time_scale=args.time_scale, operator=_specimen_prompt
        ) as session:
            mirror, check = session.standard("mirror"), session.standard("black_glass")
            plan = {"kind": "calibration", "theta_deg": args.theta, "repeats": args.repeats,
                    "check": check.name}  # fmt: skip
            run_id = store.create_run(
                kind="calibration", plan=plan, config=config_snapshot(cfg), sample="",
                model={}, version=__version__,
            )  # fmt: skip
            hook = session.lab.place_specimen or session.operator
            if hook is None:
                raise UserError("a calibration needs an operator to place the standards")
            try:
                if not await session.homed():
                    await session.home()
                record = await run_calibration(
                    goniometer=session.lab.goniometer, spectro=session.lab.spectro,
                    place=hook, store=store, run_id=run_id, mirror=mirror, check=check,
                    settings=PointColour.from_config(cfg).settings, theta_deg=args.theta,
                    repeats=args.repeats, exposure_us=cfg.spectro.exposure_us,
                    move_timeout_s=cfg.goniometer.move_timeout_s,
                )  # fmt: skip
            except (CalibrationRefused, DeviceError) as exc:
                store.set_status(run_id, RunState.FAILED.value, str(exc))
                raise UserError(f"calibration run {run_id} failed: {exc}", exit_code=1) from exc
            finally:
                try:
                    await session.lab.goniometer.park(home_timeout_s(cfg))
                except DeviceError as exc:
                    print(f"goniolab: warning: parking failed: {exc}", file=sys.stderr)
            store.set_status(run_id, RunState.DONE.value)
    c = record["check"]
    if args.json:
        print(json.dumps({"run_id": run_id, **record}, indent=2))
    else:
        print(f"run {run_id}: calibration at {record['time_iso']} on {record['instrument']}")
        print(f"  mirror: certificate {record['mirror']['certificate']}, reads "
              f"{record['mirror_reading_y_pct']:.3f} % of the instrument's reference")  # fmt: skip
        print(f"  check {c['standard']} (certificate {c['certificate']}): {c['measured_y_pct']:.3f} %"
              f" against {c['certified_y_pct']:.3f} %, residual {c['residual_pct']:+.3f} %"
              f" (tolerance {c['tolerance_pct']:g} %): {'ok' if c['ok'] else 'MISSED'}")  # fmt: skip
    if not c["ok"]:
        print("goniolab: warning: the check standard missed its certificate", file=sys.stderr)
    return 0


def _cmd(args: argparse.Namespace) -> int:
    from goniolab.commands.scan import run_lab

    if not args.config:
        raise UserError("calibrate: --config is required")
    return run_lab(_execute(args))


def register(subparsers: Any) -> None:
    """Add ``calibrate``."""
    p = subparsers.add_parser(
        "calibrate",
        help="read the reference mirror and a check standard against their certificates",
        description="Calibration record (docs/CALIBRATION.md): the reference mirror and the "
        "black-glass check standard at the specular geometry, each referenced to its "
        "certificate (configs/standards.toml); later runs cite the newest record and warn "
        "when it is older than [spectro] calibration_max_age_h or its check missed.",
    )
    p.add_argument("--config", help="lab config TOML")
    p.add_argument(
        "--store",
        help="run store: SQLite file or postgresql:// URL (default: the config's [lab] store, "
        "else goniolab.sqlite in the user data dir: goniolab --version)",
    )
    p.add_argument("--theta", type=float, default=45.0, help="specular angle, deg")
    p.add_argument("--repeats", type=int, default=3, help="readings per standard")
    p.add_argument(
        "--time-scale",
        type=float,
        default=None,
        help="sim clock scale, 0 = instant, 1 = real time (default: the config's [lab] time_scale)",
    )
    p.add_argument("--json", action="store_true", help="print the record as JSON")
    p.set_defaults(func=_cmd)
