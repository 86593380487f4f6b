"""``goniolab fit colour RUN``: fit a paint to a measured multi-angle run.

The run's measured L*a*b* per geometry (mean over repeats; geometries closer than
``--min-aspecular`` to the specular direction are left out: there the gloss of the coat
surface, not the paint, sets the colour) are fitted with the model the run was predicted
with -- its sample's coat surface model (``--model`` to choose another, ``--no-surface``
for the paint alone) over the sample's paint (``--paint FILE.toml`` for another start) --
through :func:`goniolab.colour.paint_fit.fit_paint`: K/S of the body, the flake populations'
area and spread (and a pearl's film), and the coat index, each with its 1-sigma
uncertainty, and the residual dE2000 per geometry. ``--save FILE.toml`` writes the fitted
paint in the format ``--paint`` reads (``goniolab predict colour MAP --paint FILE.toml``).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from typing import Any

from goniolab.commands._help import RUN_HELP
from goniolab.model_registry import model_names

__all__ = ["register"]


def _say(args: argparse.Namespace, text: str) -> None:
    """Progress on stderr while a terminal watches."""
    if sys.stderr.isatty() and not args.json:
        print(text, file=sys.stderr, flush=True)


def _cmd_fit_colour(args: argparse.Namespace) -> int:
    from goniolab.app.colour_fit import FitOptions, fit_colour

    opts = FitOptions(
        paint=args.paint,
        params=args.params,
        model=args.model,
        no_surface=args.no_surface,
        min_aspecular_deg=args.min_aspecular,
        metric=args.metric,
        step_nm=args.step_nm,
        save=args.save,
    )
    done = fit_colour(
        args.run, opts, store=args.store, config=args.config, say=lambda t: _say(args, t)
    )
    rec, doc, fit = done.record, done.doc, done.fit
    for w in done.warnings:
        print(f"goniolab: warning: {w}", file=sys.stderr)
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    metric = "dE2000" if args.metric == "de2000" else "dE*ab"
    print(
        f"run {rec.id} on {rec.sample or '-'}: paint fitted to {len(done.used)} geometries "
        f"({doc['illuminant']}, {doc['observer']}, {doc['scale']} scale; surface "
        f"{doc['surface'] or 'none'}; minimising {metric})"
    )
    for r in done.skipped:
        print(
            f"  aspecular {float(r['aspecular_deg']):g} deg left out "
            f"(closer than --min-aspecular {args.min_aspecular:g} to specular)"
        )
    print("  parameter                      start       fitted    +- 1 sigma")
    for p in fit.parameters:
        if p.at_bound:
            sig = "on a bound"
        elif not math.isfinite(p.sigma):
            sig = "not determined by the data"
        else:
            sig = f"{p.sigma:.4g}"
        unit = f" {p.unit}" if p.unit else ""
        print(f"  {p.name:<26} {p.start:>10.4g}   {p.value:>10.4g}    {sig}{unit}")
    print("  theta_r  aspec   measured L* a* b*       fitted L* a* b*     dE2000 (start)")
    for g in doc["geometries"]:
        m, f = g["measured"], g["fitted"]
        print(
            f"  {g['theta_r_deg']:7.2f} {g['aspecular_deg']:6.1f}  {m[0]:6.1f} {m[1]:6.1f} "
            f"{m[2]:6.1f}    {f[0]:6.1f} {f[1]:6.1f} {f[2]:6.1f}   {g['dE2000']:6.2f} "
            f"({g['start_dE2000']:.2f})"
        )
    print(
        f"  mean dE2000 {fit.mean_dE2000:.2f} (start {fit.start_mean_dE2000:.2f}); "
        f"rms residual {fit.residual_rms:.3f} ({metric} per component), {fit.dof} degrees "
        "of freedom"
    )
    if doc["saved"]:
        print(f"  fitted paint written to {doc['saved']}")
    return 0


def register(subparsers: Any) -> None:
    """Add ``goniolab fit`` and its sub-commands."""
    parser = subparsers.add_parser(
        "fit",
        help="fit a model to a measured run (colour: the paint's K/S, flakes, coat index)",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    sub = parser.add_subparsers(dest="fit_command", metavar="WHAT", required=True)
    p = sub.add_parser(
        "colour",
        help="fit K/S, flake area/spread and the coat index to a run's L*a*b* per angle",
        description=re.sub(r":\w+:`([^`]+)`", r"\1", (__doc__ or "").split("\n\n")[1]).replace(
            "``", "'"
        ),
    )
    p.add_argument("run", type=int, metavar="RUN", help=RUN_HELP)
    p.add_argument(
        "--store",
        help="run store: SQLite file or postgresql:// URL (default: the config's [lab] store, "
        "else goniolab.sqlite in the user data dir: goniolab --version)",
    )
    p.add_argument("--config", help="lab config TOML whose [lab] store to use")
    p.add_argument(
        "--paint", metavar="FILE.toml", help="starting paint (default: the run's sample's)"
    )
    p.add_argument(
        "--params",
        default=None,
        help="comma list of parameters to fit (default: body.ks_scale, the flakes' "
        "area_fraction and spread_deg, pearl.film_nm, coat.n; also body.s_scale)",
    )
    p.add_argument(
        "--model",
        choices=model_names(),
        default=None,
        help="coat-surface model (default: the one the run was predicted with)",
    )
    p.add_argument(
        "--no-surface", action="store_true", help="fit the paint alone (no coat-surface gloss)"
    )
    p.add_argument(
        "--min-aspecular",
        type=float,
        default=10.0,
        metavar="DEG",
        help="leave out geometries closer than this to specular, deg",
    )
    p.add_argument(
        "--metric",
        choices=("lab", "de2000"),
        default="lab",
        help="minimise dE*ab (lab: equal weights, calibrated uncertainties) or the "
        "local dE2000 metric of each measured colour",
    )
    p.add_argument("--step-nm", type=float, default=10.0, help="wavelength step, nm")
    p.add_argument("--save", metavar="FILE.toml", help="write the fitted paint (--paint format)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_fit_colour)
