"""``goniolab lab``: the instruments outside a run.

``goniolab lab reset-alarm`` clears a latched controller alarm on the goniometer arms
(:mod:`goniolab.scan.alarm`): a scan that failed on an alarm, and its ``scan resume``, fail
the same way until the alarm is reset. Nothing moves; the next scan homes the arms when
they lost their reference.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from goniolab.errors import UserError

__all__ = ["register"]


def _cmd_reset_alarm(args: argparse.Namespace) -> int:
    from goniolab.app.lab_scan import reset_alarms
    from goniolab.app.lab_setup import load_config
    from goniolab.commands.scan import run_lab

    if not args.config:
        raise UserError("lab reset-alarm: --config FILE is required (the scan's lab config)")
    alarms = run_lab(reset_alarms(load_config(args.config)))
    if args.json:
        print(json.dumps([{"arm": a.arm, "before": a.before, "after": a.after} for a in alarms]))
    else:
        for a in alarms:
            print(a.describe())
    remaining = [a for a in alarms if a.after is not None]
    if remaining:
        print(
            f"goniolab: {len(remaining)} alarm(s) remain: remove the cause, then reset again",
            file=sys.stderr,
        )
        return 1
    if any(a.cleared for a in alarms):
        print("goniolab: alarms cleared; continue with: goniolab scan resume RUN", file=sys.stderr)
    return 0


def register(subparsers: Any) -> None:
    """Add ``lab`` with its ``reset-alarm`` subcommand."""
    p = subparsers.add_parser("lab", help="the instruments outside a run (reset-alarm)")
    sub = p.add_subparsers(dest="lab_command", metavar="reset-alarm")
    pr = sub.add_parser(
        "reset-alarm",
        help="clear a latched controller alarm on the goniometer arms (nothing moves)",
        description="Read both arms' controller alarms, reset the alarmed ones (ALM-RST) and "
        "read them again. Check the arm first: an alarm whose cause is still there stays "
        "(exit 1).",
    )
    pr.add_argument("--config", help="lab config TOML (the one the scan used)")
    pr.add_argument("--json", action="store_true", help="each arm's alarm before/after as JSON")
    pr.set_defaults(func=_cmd_reset_alarm)

    def _usage(args: argparse.Namespace) -> int:
        raise UserError("goniolab lab: give a subcommand (reset-alarm)", exit_code=2)

    p.set_defaults(func=_usage)
