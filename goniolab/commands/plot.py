"""``goniolab plot RUN --out run.png|svg|pdf [--log]``: a picture of a stored run.

The file is written only where ``--out`` says (issue 27: a plot without ``--out`` wrote
``run-RUN.png`` into the current directory unasked).

A scan: measured points with error bars, the predicted curve and a residual panel (plus
L*, a*, b* against the aspecular angle when the run has colour data); a gloss log: the
readings over time beside the predictions. See :mod:`goniolab.run_plots`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from goniolab.commands._help import RUN_HELP

__all__ = ["register"]


def _cmd_plot(args: argparse.Namespace) -> int:
    from goniolab.app.stored_runs import plot_run

    drawn = plot_run(args.run, args.out, log=args.log, store=args.store, config=args.config)
    rec, out = drawn.record, Path(args.out)
    if args.json:
        doc = {"run_id": rec.id, "kind": rec.kind, "output": str(out.resolve())}
        print(json.dumps(doc, indent=2))
    else:
        print(f"run {rec.id} ({rec.kind}) drawn to {out}", file=sys.stderr)
    return 0


def register(subparsers: Any) -> None:
    """Add ``goniolab plot``."""
    p = subparsers.add_parser(
        "plot",
        help="draw a stored run to PNG, SVG or PDF",
        description="Draw a stored run: a scan's measured points with error bars, the "
        "predicted curve and the residuals (and L*, a*, b* against the aspecular angle when "
        "it has colour data); a gloss log's readings over time.",
    )
    p.add_argument("run", type=int, metavar="RUN", help=RUN_HELP)
    p.add_argument(
        "--out",
        "-o",
        required=True,
        metavar="FILE",
        help="the file to write: .png, .svg or .pdf (the suffix picks the format)",
    )
    p.add_argument("--log", action="store_true", help="luminance on a log axis")
    p.add_argument(
        "--store",
        help="run store: SQLite file or postgresql:// URL (default: the config's [lab] store, "
        "else goniolab.sqlite in the user data dir: goniolab --version)",
    )
    p.add_argument("--config", help="lab config TOML whose [lab] store to use")
    p.add_argument("--json", action="store_true", help="print what was written as JSON")
    p.set_defaults(func=_cmd_plot)
