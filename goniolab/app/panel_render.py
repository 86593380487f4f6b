"""The render use case (``goniolab render``): a panel or sphere of the paint predicted for a
map, drawn as an sRGB PNG (:mod:`goniolab.colour.paint_render`), with what was drawn.

Split from :mod:`goniolab.app.colours` (a module of the application layer stays under 800
lines, ``tests/test_layers.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from goniolab.app.colours import load_paint_file
from goniolab.errors import UserError

__all__ = ["RenderOptions", "render_paint", "write_png"]


def write_png(path: Path, rgb: Any) -> None:
    """Write an ``(h, w, 3)`` sRGB array in [0, 1] as an 8-bit RGB PNG (Pillow, which
    matplotlib depends on)."""
    import numpy as np
    from PIL import Image

    data = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    Image.fromarray(data, "RGB").save(path, format="PNG")


@dataclass(frozen=True)
class RenderOptions:
    """How to draw the predicted paint: picture ``size`` (pixels), ``lamps`` (1: key, 2:
    key and fill), ``shape`` (panel or sphere), a ``paint`` file (``None``: the sample's, or
    a coat of index ``n`` over black), the map's ``step_um``, CIE settings, wavelength step,
    the lamps' angular diameter, ``exposure`` (``"auto"``: at most 1 % of the pixels clip;
    a number: 1 = a white diffuser lit along its normal is display white), ``sparkle``
    (``None``: on for paints with flakes) and its random ``seed``."""

    size: int = 512
    lamps: int = 1
    shape: Literal["panel", "sphere"] = "panel"
    paint: str | None = None
    n: complex = complex(1.55)
    step_um: float | None = None
    illuminant: str = "D65"
    observer: str = "10"
    step_nm: float = 10.0
    lamp_deg: float = 6.0
    exposure: str | float = "auto"
    sparkle: bool | None = None
    seed: int = 0


def render_paint(
    surface: str, out: str | Path, opts: RenderOptions, *, started: Callable[[], None] | None = None
) -> dict[str, Any]:
    """Draw a curved panel (or a sphere) of the paint predicted for ``surface`` lit by one
    or two lamps, every pixel the predicted spectral BRDF (coat gloss from the map's rms
    slope + the paint beneath) integrated with the illuminant and observer, as an sRGB
    PNG at ``out`` (:mod:`goniolab.colour.paint_render`); returns what was drawn (the
    ``render --json`` document). ``started`` is called when the checks have passed and the
    work begins."""
    import time

    import numpy as np

    out = Path(out)
    if out.suffix.lower() != ".png":
        raise UserError(f"--out {out}: the picture is written as PNG (.png)")
    if out.parent and not out.parent.is_dir():
        raise UserError(f"--out {out}: no such directory {out.parent}")
    if not 8 <= opts.size <= 8192:
        raise UserError(f"--size {opts.size}: must be in [8, 8192] pixels")
    exposure: float | None = None
    if opts.exposure != "auto":
        try:
            exposure = float(opts.exposure)
        except ValueError:
            raise UserError(f"--exposure {opts.exposure}: a number or auto") from None
        if not (math.isfinite(exposure) and exposure > 0):
            raise UserError(f"--exposure {exposure:g}: must be > 0")
    if not (math.isfinite(opts.lamp_deg) and 0.0 <= opts.lamp_deg <= 60.0):
        raise UserError(f"--lamp-deg {opts.lamp_deg:g}: must be in [0, 60] deg")
    t0 = time.perf_counter()
    if started is not None:
        started()
    from goniolab.colour.dispersion import DispersionError
    from goniolab.colour.paint import PaintError
    from goniolab.colour.paint_render import render, tabulate_brdf
    from goniolab.colour.spectra import ColourError, ColourSettings, standard_grid_nm
    from goniolab.model_cache import paint_for
    from goniolab.optics.surface import roughness_stats
    from goniolab.surfaces.resolve import resolve_map

    try:
        settings = ColourSettings(opts.illuminant, opts.observer).validated()
    except ColourError as exc:
        raise UserError(str(exc)) from None
    paint = load_paint_file(opts.paint) if opts.paint else paint_for(surface, opts.n)
    hm = resolve_map(surface, step_um=opts.step_um)
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            alpha = float(roughness_stats(hm).Sdq)
    except ValueError as exc:
        raise UserError(f"{surface}: {exc}") from None
    if not (math.isfinite(alpha) and alpha > 0):
        raise UserError(f"{surface}: rms slope Sdq = {alpha:g}; the gloss lobe needs Sdq > 0")
    alpha = max(alpha, 1e-3)
    try:
        wl = standard_grid_nm(opts.step_nm)
        paint.coat.check_covers(wl)
        table = tabulate_brdf(
            paint, alpha, lamp_radius_deg=0.5 * opts.lamp_deg, wavelengths_nm=wl, settings=settings
        )
        sparkle = paint.has_flakes if opts.sparkle is None else opts.sparkle
        pic = render(
            table,
            shape=opts.shape,
            size=opts.size,
            lamps=opts.lamps,
            exposure=exposure,
            settings=settings,
            sparkle=sparkle,
            seed=opts.seed,
        )
    except (ColourError, DispersionError, PaintError, ValueError) as exc:
        raise UserError(f"{surface}: {' '.join(str(exc).split())}") from None
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
        "map": surface,
        "output": str(out.resolve()),
        "size": opts.size,
        "shape": opts.shape,
        "lamps": opts.lamps,
        "illuminant": settings.illuminant,
        "observer": settings.observer,
        "alpha_sdq": alpha,
        "lamp_deg": opts.lamp_deg,
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
    return doc
