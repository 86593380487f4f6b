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


def _cmd(args: argparse.Namespace) -> int:
    if not args.config:
        raise UserError("calibrate: --config is required")
    from goniolab.app.lab_scan import calibrate
    from goniolab.app.lab_setup import load_config, open_store, stderr_notify
    from goniolab.commands.scan import run_lab, specimen_prompt

    cfg = load_config(args.config, args.store)
    with open_store(args.store, config=cfg) as store:
        out = run_lab(
            calibrate(
                cfg, store, theta_deg=args.theta, repeats=args.repeats,
                time_scale=args.time_scale, operator=specimen_prompt, notify=stderr_notify,
            )
        )  # fmt: skip
    run_id, record = out.run_id, out.record
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
        print(f"    certified value read as: {c['weighting']} (unpolarised "
              f"{c['certified_unpolarised_y_pct']:.3f} %)")  # fmt: skip
    if not c["ok"]:
        print("goniolab: warning: the check standard missed its certificate", file=sys.stderr)
    return 0


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
