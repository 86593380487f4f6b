"""``goniolab render MAP|sample:NAME --out panel.png``: a picture of the predicted paint.

A curved panel (or a sphere) lit by one or two lamps, every pixel the predicted spectral BRDF
(coat gloss from the map's rms slope + the paint beneath) integrated with the illuminant and
observer, shown in sRGB (:mod:`goniolab.colour.paint_render`). A metallic darkens away from its
highlight (flop); a solid keeps its lightness apart from the lamp's cos(theta_i).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path
from typing import Any

from goniolab.errors import UserError

__all__ = ["register", "write_png"]


def write_png(path: Path, rgb: Any) -> None:
    """Write an ``(h, w, 3)`` sRGB array in [0, 1] as an 8-bit RGB PNG (Pillow, which
    matplotlib depends on)."""
    import numpy as np
    from PIL import Image

    data = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    Image.fromarray(data, "RGB").save(path, format="PNG")


def _cmd_render(args: argparse.Namespace) -> int:
    import numpy as np

    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise UserError(f"--out {out}: the picture is written as PNG (.png)")
    if out.parent and not out.parent.is_dir():
        raise UserError(f"--out {out}: no such directory {out.parent}")
    if not 8 <= args.size <= 8192:
        raise UserError(f"--size {args.size}: must be in [8, 8192] pixels")
    exposure: float | None = None
    if args.exposure != "auto":
        try:
            exposure = float(args.exposure)
        except ValueError:
            raise UserError(f"--exposure {args.exposure}: a number or auto") from None
        if not (math.isfinite(exposure) and exposure > 0):
            raise UserError(f"--exposure {exposure:g}: must be > 0")
    if not (math.isfinite(args.lamp_deg) and 0.0 <= args.lamp_deg <= 60.0):
        raise UserError(f"--lamp-deg {args.lamp_deg:g}: must be in [0, 60] deg")
    t0 = time.perf_counter()
    if sys.stderr.isatty() and not args.json:  # the imports and the table take seconds
        print(f"rendering {args.map} ({args.size}x{args.size}) ...", file=sys.stderr, flush=True)
    from goniolab.colour.dispersion import DispersionError
    from goniolab.colour.paint import PaintError
    from goniolab.colour.paint_render import render, tabulate_brdf
    from goniolab.colour.spectra import ColourError, ColourSettings, standard_grid_nm
    from goniolab.model_cache import paint_for
    from goniolab.optics.surface import roughness_stats
    from goniolab.surfaces.resolve import resolve_map

    try:
        settings = ColourSettings(args.illuminant, args.observer).validated()
    except ColourError as exc:
        raise UserError(str(exc)) from None
    if args.paint:
        from goniolab.commands._colour import load_paint_file

        paint = load_paint_file(args.paint)
    else:
        paint = paint_for(args.map, args.n)
    hm = resolve_map(args.map, step_um=args.step_um)
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            alpha = float(roughness_stats(hm).Sdq)
    except ValueError as exc:
        raise UserError(f"{args.map}: {exc}") from None
    if not (math.isfinite(alpha) and alpha > 0):
        raise UserError(f"{args.map}: rms slope Sdq = {alpha:g}; the gloss lobe needs Sdq > 0")
    alpha = max(alpha, 1e-3)
    try:
        wl = standard_grid_nm(args.step_nm)
        paint.coat.check_covers(wl)
        table = tabulate_brdf(
            paint, alpha, lamp_radius_deg=0.5 * args.lamp_deg, wavelengths_nm=wl, settings=settings
        )
        sparkle = paint.has_flakes if args.sparkle is None else args.sparkle
        pic = render(
            table,
            shape=args.shape,
            size=args.size,
            lamps=args.lamps,
            exposure=exposure,
            settings=settings,
            sparkle=sparkle,
            seed=args.seed,
        )
    except (ColourError, DispersionError, PaintError, ValueError) as exc:
        raise UserError(f"{args.map}: {' '.join(str(exc).split())}") from None
    try:
        write_png(out, pic.srgb)
    except OSError as exc:
        raise UserError(f"cannot write {out}: {exc.strerror or exc}") from None
    seconds = time.perf_counter() - t0
    # the lightness range over the shape, as reflectance factors (the lamp's cos taken out)
    y = pic.xyz[..., 1]
    lit = pic.mask & (pic.cos_i > 0.05)
    factor_l = 116.0 * np.cbrt(np.maximum(y[lit] / pic.cos_i[lit] / 100.0, 216 / 24389)) - 16.0
    doc = {
        "map": args.map,
        "output": str(out.resolve()),
        "size": args.size,
        "shape": args.shape,
        "lamps": args.lamps,
        "illuminant": settings.illuminant,
        "observer": settings.observer,
        "alpha_sdq": alpha,
        "lamp_deg": args.lamp_deg,
        "paint": paint.describe(),
        "exposure": pic.exposure,
        "exposure_auto": pic.exposure_auto,
        "clipped_fraction": pic.clipped_fraction,
        "sparkle": sparkle,
        "sparkle_pixel_fraction": (
            float(np.mean(pic.sparkle_pixels[pic.mask])) if pic.sparkle_pixels is not None else 0.0
        ),
        "pixel_um": pic.pixel_um,
        "lightness_factor_range": [float(np.min(factor_l)), float(np.max(factor_l))]
        if factor_l.size
        else None,
        "seconds": seconds,
    }
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print(
            f"{args.map}: {args.shape} {args.size}x{args.size}, {args.lamps} lamp"
            f"{'s' if args.lamps > 1 else ''}, drawn to {out} in {seconds:.1f} s; exposure "
            f"{pic.exposure:.3g} ({'auto: ' if pic.exposure_auto else ''}"
            f"{100 * pic.clipped_fraction:.2f} % of the pixels clip)"
            + (
                f"; sparkle: {100 * doc['sparkle_pixel_fraction']:.2f} % of the pixels "
                f"({pic.pixel_um:.0f} um each) mirror the lamp"
                if sparkle
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
    from goniolab.commands.predict import parse_index

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
