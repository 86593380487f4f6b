"""``goniolab predict colour MAP``: the predicted colour of a surface angle by angle.

``predict colour`` predicts the spectrum of a goniometer reading (coat surface model with the
coat's n(lambda) + the paint beneath, :mod:`goniolab.colour.spectral`) at the ASTM E2194
aspecular angles (or ``--theta-r``), and reports CIE L*a*b*, L*C*h and the flop index.
The paint is the sample's ``[samples.NAME.paint]``, or ``--paint FILE.toml`` (a TOML file
with the same keys at its top level), or a clear coat of index ``--n`` over black.
"""

from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path
from typing import Any

from goniolab.errors import UserError

__all__ = ["load_paint_file", "register_predict_colour"]


def load_paint_file(path: str) -> Any:
    """A :class:`goniolab.colour.paint.Paint` from a TOML file (``n,k`` tables beside it)."""
    from goniolab.colour.paint import PaintError, paint_from_dict

    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UserError(f"{p}: cannot read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{p}: not valid TOML: {exc}") from None
    except RecursionError:  # tomllib recurses once per nested array / inline table
        raise UserError(f"{p}: arrays or tables nested too deeply to be a paint") from None
    tables: dict[str, str] = {}
    metallic = data.get("metallic")
    metal = metallic.get("metal") if isinstance(metallic, dict) else None
    for section in (data.get("coat"), metal):
        if isinstance(section, dict) and section.get("kind") == "table" and "file" in section:
            f = p.parent / str(section["file"])
            try:
                tables[str(section["file"])] = f.read_text(encoding="utf-8")
            except OSError as exc:
                raise UserError(f"{p}: n,k table {f}: cannot read: {exc.strerror}") from None
    try:
        return paint_from_dict(data, where=str(p), tables=tables)
    except PaintError as exc:
        raise UserError(" ".join(str(exc).split())) from None


def _settings(args: argparse.Namespace) -> Any:
    from goniolab.colour.spectra import ColourError, ColourSettings

    try:
        return ColourSettings(args.illuminant, args.observer).validated()
    except ColourError as exc:
        raise UserError(str(exc)) from None


def _spectral(args: argparse.Namespace) -> Any:
    from goniolab.colour.dispersion import DispersionError
    from goniolab.colour.spectra import ColourError
    from goniolab.commands.predict import _model
    from goniolab.models import spectral_for

    model = _model(args)
    paint = load_paint_file(args.paint) if args.paint else None
    try:
        return spectral_for(
            model,
            source_cone_deg=args.source_deg,
            detector_cone_deg=args.detector_deg,
            step_nm=args.step_nm,
            paint=paint,
        )
    except (ColourError, DispersionError) as exc:
        raise UserError(str(exc)) from None


def _cmd_predict_colour(args: argparse.Namespace) -> int:
    import numpy as np

    from goniolab.colour.multiangle import (
        E2194_ASPECULAR_DEG,
        aspecular_deg,
        flop_index_note,
        flop_of_rows,
        theta_r_for_aspecular,
    )
    from goniolab.colour.spectra import spectra_to_xyz, xyz_to_colour
    from goniolab.colour.spectral import reflectance_factor_scale
    from goniolab.scan.plans import PlanError, parse_angles

    settings = _settings(args)
    if args.theta_r:
        try:
            tr = np.asarray(parse_angles(args.theta_r, name="--theta-r"), dtype=np.float64)
        except PlanError as exc:
            raise UserError(str(exc)) from None
    else:
        tr = np.array([theta_r_for_aspecular(a, args.theta_i) for a in E2194_ASPECULAR_DEG])
    if np.any(np.abs(tr) + 0.5 * args.detector_deg >= 90.0):
        raise UserError("--theta-r: the detector cone must stay above the horizon (|theta_r| < 87)")
    sp = _spectral(args)
    try:
        spectra = sp.spectrum_pct(args.theta_i, tr)
        factors = (
            spectra / 100.0 * reflectance_factor_scale(tr, args.detector_deg, args.scale)[:, None]
        )
    except ValueError as exc:
        raise UserError(str(exc)) from None
    colours = xyz_to_colour(spectra_to_xyz(sp.wavelengths_nm, factors, settings), settings)
    rows: list[dict[str, Any]] = []
    for t, c, s in zip(tr, colours, spectra, strict=True):
        rows.append(
            {
                "theta_r_deg": float(t),
                "aspecular_deg": aspecular_deg(float(t), args.theta_i),
                "X": float(c[0]),
                "Y": float(c[1]),
                "Z": float(c[2]),
                "L": float(c[3]),
                "a": float(c[4]),
                "b": float(c[5]),
                "C": float(c[6]),
                "h_deg": float(c[7]),
                "spectrum_pct": [float(v) for v in s],
            }
        )
    fi = flop_of_rows(rows, args.theta_i)
    fi_note = flop_index_note(args.theta_i)
    if args.json:
        doc = {
            "map": args.map,
            "theta_i_deg": args.theta_i,
            "illuminant": settings.illuminant,
            "observer": settings.observer,
            "scale": args.scale,
            "wavelengths_nm": [float(w) for w in sp.wavelengths_nm],
            "model": sp.describe(),
            "geometries": rows,
            "flop_index": fi,
            "flop_index_note": fi_note,
        }
        print(json.dumps(doc, indent=2))
        return 0
    print(
        f"{args.map}: predicted colour at theta_i = {args.theta_i:g} deg "
        f"({settings.illuminant}, {settings.observer}, {args.scale} scale)"
    )
    print("  theta_r  aspec      L*      a*      b*      C*       h")
    for r in rows:
        print(
            f"  {r['theta_r_deg']:7.2f} {r['aspecular_deg']:6.1f} {r['L']:7.2f} {r['a']:7.2f}"
            f" {r['b']:7.2f} {r['C']:7.2f} {r['h_deg']:7.1f}"
        )
    if fi is not None:
        print(f"  flop index (2.69 (L*15 - L*110)^1.11 / L*45^0.86): {fi:.2f}")
    elif fi_note:
        print(f"  {fi_note}")
    return 0


def _add_colour_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--illuminant", default="D65", help="CIE illuminant (default D65)")
    p.add_argument(
        "--observer", default="10", help="10 (CIE 1964, default) or 2 (CIE 1931) degree observer"
    )
    p.add_argument("--paint", metavar="FILE.toml", help="paint definition (else the sample's)")
    p.add_argument("--step-nm", type=float, default=10.0, help="wavelength step (default 10)")
    p.add_argument("--source-deg", type=float, default=6.0, help="lamp cone, full angle")
    p.add_argument("--detector-deg", type=float, default=6.0, help="detector cone, full angle")


def register_predict_colour(sub: Any, add_common: Any) -> None:
    """Add ``predict colour`` to the ``predict`` sub-parsers."""
    p = sub.add_parser(
        "colour", help="predicted L*a*b* per angle (ASTM E2194 geometry) and flop index"
    )
    add_common(p)
    _add_colour_options(p)
    p.add_argument("--theta-i", type=float, default=45.0, help="incidence (default 45)")
    p.add_argument(
        "--theta-r",
        default=None,
        help="detector angles (default: the E2194 aspecular angles -15,15,25,45,75,110)",
    )
    p.add_argument(
        "--scale",
        choices=("diffuser", "mirror"),
        default="diffuser",
        help="reflectance factor vs the perfect diffuser (default) or %% of the mirror",
    )
    p.set_defaults(func=_cmd_predict_colour)
