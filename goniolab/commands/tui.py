"""``goniolab tui``: the Textual app (measured beside predicted, live).

Textual is imported only when the command runs (inside :mod:`goniolab.tui`), so the rest
of the CLI never loads it.
"""

from __future__ import annotations

import argparse
from typing import Any

from goniolab.errors import UserError

__all__ = ["DESCRIPTION", "KEYS", "register"]

#: Every key of the app (goniolab.tui.app.GonioApp.BINDINGS; tests/test_help.py checks
#: that none is left out), as ``tui --help`` lists them.
KEYS = (
    ("s", "start a scan with the form's sample, theta_i, theta_r range and repeats"),
    ("space", "pause after the current reading, or resume"),
    ("x", "abort the scan (arms parked, run stored as aborted)"),
    ("a", "align the arms and the sample (scan --plan align); press twice, it asks first"),
    ("g", "read the glossmeter (20/60/85 deg) beside the model's prediction"),
    ("h", "home the arms again (after an alarm or a failed homing)"),
    ("l", "side plot: residuals or log10 of both curves"),
    ("c", "main plot: luminance, L* or a*/b* against theta_r"),
    ("r", "browse stored runs (enter reopens one, esc back)"),
    ("f", "under 120 columns: the setup form or the plots"),
    ("i", "run identity: operator, sample id, notes, tags of the next runs"),
    ("q", "quit (a running scan is aborted, arms parked)"),
    ("ctrl+p", "command palette"),
    ("escape", "leave a form field"),
)

DESCRIPTION = (
    "Open the lab (simulated or real), home the goniometer and show scans live beside\n"
    "the model's prediction. The screen needs 80 x 24 at least.\n\nkeys:\n"
    + "\n".join(f"  {key:<7} {what}" for key, what in KEYS)
)


def register(sub: Any) -> None:
    """Add the ``tui`` sub-command to the ``goniolab`` parser."""
    p: argparse.ArgumentParser = sub.add_parser(
        "tui",
        help="interactive lab UI: scan setup, live measured-vs-predicted plots, gloss log",
        description=DESCRIPTION,
    )
    p.add_argument("--config", required=True, metavar="FILE", help="lab config TOML")
    p.add_argument(
        "--time-scale",
        type=float,
        default=None,
        metavar="S",
        help="sim clock scale, 0 = instant, 1 = real time (default: the config's [lab] time_scale)",
    )
    p.add_argument(
        "--sample",
        default=None,
        metavar="NAME",
        help="sample preselected for the prediction (built-in NAME, sample:NAME or a "
        "height-map file; default: the config's [sample] map)",
    )
    p.add_argument(
        "--store",
        default=None,
        metavar="STORE",
        help="run store: SQLite file or postgresql:// URL (default: the config's [lab] store, "
        "else goniolab.sqlite in the user data dir: goniolab --version)",
    )
    p.add_argument(
        "--autostart",
        action="store_true",
        help="once homed, take a gloss reading and start the form's scan",
    )
    p.add_argument(
        "--gloss-every",
        type=float,
        default=0.0,
        metavar="S",
        help="take a glossmeter reading every S seconds (0 = only on the g key)",
    )
    p.set_defaults(func=_cmd_tui)


def _cmd_tui(args: argparse.Namespace) -> int:
    if args.time_scale is not None and not args.time_scale >= 0:
        raise UserError(f"--time-scale must be >= 0, got {args.time_scale}")
    if not args.gloss_every >= 0:
        raise UserError(f"--gloss-every must be >= 0 s, got {args.gloss_every}")
    from goniolab.tui.app import GonioApp

    def backend() -> Any:
        # built by the app after its first frame: the lab's modules (pydantic, numpy, the
        # simulator) and the config's validation are most of a second
        from goniolab.tui.session_backend import SessionBackend

        return SessionBackend(
            args.config, time_scale=args.time_scale, sample=args.sample, store_path=args.store
        )

    app = GonioApp(backend, autostart=args.autostart, gloss_every_s=args.gloss_every)
    code = app.run()
    if app.boot_error is not None:  # a bad config, file, sample...: one clear error, exit 2
        raise app.boot_error
    return 0 if code is None else int(code)
