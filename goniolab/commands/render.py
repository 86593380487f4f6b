"""``goniolab render MAP|sample:NAME --out panel.png``: a picture of the predicted paint.

A curved panel (or a sphere) lit by one or two lamps, every pixel the predicted spectral BRDF
(coat gloss from the map's rms slope + the paint beneath) integrated with the illuminant and
observer, shown in sRGB (:mod:`goniolab.colour.paint_render`). A metallic darkens away from its
highlight (flop); a solid keeps its lightness apart from the lamp's cos(theta_i).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from typing import Any

__all__ = ["register"]


def _cmd_render(args: argparse.Namespace) -> int:
    from goniolab.app.panel_render import RenderOptions, render_paint

    opts = RenderOptions(
        size=args.size,
        lamps=args.lamps,
        shape=args.shape,
        paint=args.paint,
        n=args.n,
        step_um=args.step_um,
        illuminant=args.illuminant,
        observer=args.observer,
        step_nm=args.step_nm,
        lamp_deg=args.lamp_deg,
        exposure=args.exposure,
        sparkle=args.sparkle,
        seed=args.seed,
    )

    def started() -> None:
        if sys.stderr.isatty() and not args.json:  # the imports and the table take seconds
            print(f"rendering {args.map} ({args.size}x{args.size}) ...", file=sys.stderr,
                  flush=True)  # fmt: skip

    doc = render_paint(args.map, args.out, opts, started=started)
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print(
            f"{args.map}: {args.shape} {args.size}x{args.size}, {args.lamps} lamp"
            f"{'s' if args.lamps > 1 else ''}, drawn to {args.out} in {doc['seconds']:.1f} s; "
            f"exposure {doc['exposure']:.3g} ({'auto: ' if doc['exposure_auto'] else ''}"
            f"{100 * doc['clipped_fraction']:.2f} % of the pixels clip)"
            + (
                f"; sparkle: {100 * doc['sparkle_pixel_fraction']:.2f} % of the pixels "
                f"({doc['pixel_um']:.0f} um each) mirror the lamp"
                if doc["sparkle"]
                else ""
            ),
            file=sys.stderr,
        )
    return 0


def register(subparsers: Any) -> None:
    """Add ``goniolab render``."""
    p = subparsers.add_parser(
        "render",
        help="draw a curved panel or sphere of the predicted paint to PNG (sRGB)",
        description=re.sub(r":\w+:`([^`]+)`", r"\1", (__doc__ or "").split("\n\n")[1]),
    )
    p.add_argument("map", metavar="MAP", help="height-map file or sample:NAME")
    p.add_argument("--out", "-o", required=True, help="output PNG file")
    p.add_argument("--size", type=int, default=512, help="image width = height, pixels")
    p.add_argument(
        "--lamps", type=int, choices=(1, 2), default=1, help="1: the key lamp; 2: key and fill lamp"
    )
    p.add_argument("--shape", choices=("panel", "sphere"), default="panel", help="what is drawn")
    p.add_argument("--paint", metavar="FILE.toml", help="paint definition (else the sample's)")
    from goniolab.commands._surface_args import parse_index

    p.add_argument(
        "--n", type=parse_index, default=complex(1.55), help="coat index of a map without paint"
    )
    p.add_argument(
        "--step-um", type=float, default=None, help="lateral step, um, of a file that carries none"
    )
    p.add_argument("--illuminant", default="D65", help="CIE illuminant")
    p.add_argument("--observer", default="10", help="10 (CIE 1964) or 2 (CIE 1931) degree observer")
    p.add_argument("--step-nm", type=float, default=10.0, help="wavelength step, nm")
    p.add_argument("--lamp-deg", type=float, default=6.0, help="lamps' angular diameter, deg")
    p.add_argument(
        "--exposure",
        default="auto",
        help="auto: the largest exposure that lets at most 1%% of the pixels clip "
        "to white; a number: 1 = a white diffuser lit along its normal is display white",
    )
    p.add_argument(
        "--sparkle",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="draw each pixel's flakes (Poisson number mirroring the lamp): on for paints "
        "with flakes",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of the sparkle texture")
    p.add_argument("--json", action="store_true", help="print what was drawn as JSON")
    p.set_defaults(func=_cmd_render)
