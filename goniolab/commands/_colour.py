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


# --------------------------------------------------------------------------- runs colour
def load_tolerance(arg: str) -> Any:
    """``--tolerance``: a built-in set's name or a TOML file (:mod:`goniolab.colour.tolerance`)."""
    from goniolab.colour.tolerance import BUILTIN_SETS, ToleranceError, load_tolerance_set

    try:
        if arg in BUILTIN_SETS:
            return load_tolerance_set(arg)
        p = Path(arg)
        if p.suffix.lower() != ".toml" and not p.exists():
            return load_tolerance_set(arg)  # names the built-in sets
        try:
            text = p.read_text(encoding="utf-8")
        except OSError as exc:
            raise UserError(f"--tolerance {p}: cannot read: {exc.strerror}") from None
        return load_tolerance_set(str(p), text)
    except ToleranceError as exc:
        raise UserError(f"--tolerance: {exc}") from None


def _mean_factors(measured: Any) -> Any:
    """Per geometry, the mean of the repeats' reflectance-factor spectra (NaN-aware)."""
    import warnings

    import numpy as np

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a geometry without readings: NaN
        return np.nanmean(measured, axis=1)


def run_spectra(store: Any, rec: Any) -> dict[str, Any]:
    """A run's spectra as reflectance factors: ``{"wavelengths_nm", "measured" (n, N) mean
    over repeats, "predicted_wavelengths_nm", "predicted" (n, M) or None}``."""
    from goniolab.datasets import predicted_grid_nm, run_reflectance_factors

    wl, measured, predicted = run_reflectance_factors(store, rec.id)
    return {
        "wavelengths_nm": wl,
        "measured": _mean_factors(measured) if wl.size else None,
        "predicted_wavelengths_nm": (
            None if predicted is None else predicted_grid_nm(predicted.shape[-1])
        ),
        "predicted": predicted,
    }


def _observer(rec: Any) -> str:
    cfg = rec.config if isinstance(rec.config, dict) else {}
    return str((cfg.get("colour") or {}).get("observer", "10"))


def _pairs_by_index(
    rows: list[dict[str, Any]], other_rows: list[dict[str, Any]] | None
) -> list[tuple[dict[str, Any], int, int | None]]:
    """(row, index in this run, index in the other run) of the geometries compared."""
    out: list[tuple[dict[str, Any], int, int | None]] = []
    for r in rows:
        if other_rows is None:
            out.append((r, int(r["index"]), None))
            continue
        match = next(
            (
                o
                for o in other_rows
                if abs(float(o["theta_r_deg"]) - float(r["theta_r_deg"])) < 0.01
            ),
            None,
        )
        if match is not None:
            out.append((r, int(r["index"]), int(match["index"])))
    return out


def colour_report(
    store: Any,
    rec: Any,
    other: Any | None,
    *,
    tolerance: Any,
    illuminants: list[str],
    metamerism: bool,
) -> dict[str, Any]:
    """Everything ``runs colour`` reports (its JSON document).

    The pair judged is (reference = the run's measured colour, sample = its prediction),
    or with ``other`` (``--vs``) (reference = the other run, the standard; sample = this
    run). Differences are sample - reference (:mod:`goniolab.colour.difference`); the
    tolerance set is applied per aspecular angle (:func:`goniolab.colour.tolerance.evaluate`).
    """
    import numpy as np

    from goniolab.colour.multiangle import flop_index_note, flop_of_rows
    from goniolab.colour.spectra import ColourError, range_note
    from goniolab.colour.tolerance import evaluate, lab_under, metamerism_table
    from goniolab.commands.runs import run_colour

    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    rows = run_colour(store, rec)
    if not any("L" in r for r in rows):
        raise UserError(f"run {rec.id} has no measured colour (no readings, or no usable spectra)")
    other_rows = run_colour(store, other) if other is not None else None
    pairs = _pairs_by_index(rows, other_rows)
    if other is not None and not pairs:
        raise UserError(f"runs {rec.id} and {other.id} share no detector angle with colour")

    def lab_of(r: dict[str, Any], prefix: str = "") -> list[float]:
        keys = [f"{prefix}L", f"{prefix}a", f"{prefix}b"]
        return [float(r[k]) if r.get(k) is not None else float("nan") for k in keys]

    ref_lab: list[list[float]] = []
    smp_lab: list[list[float]] = []
    aspec: list[float] = []
    for r, _, j in pairs:
        aspec.append(float(r["aspecular_deg"]))
        if other_rows is None:
            ref_lab.append(lab_of(r))
            smp_lab.append(lab_of(r, "predicted_"))
        else:
            o = next(x for x in other_rows if int(x["index"]) == j)
            ref_lab.append(lab_of(o))
            smp_lab.append(lab_of(r))
    verdicts, overall = evaluate(tolerance, aspec, np.array(ref_lab), np.array(smp_lab))
    for (r, _, _), v in zip(pairs, verdicts, strict=True):
        if other_rows is None and all(np.isfinite(lab_of(r, "predicted_"))):
            r.update({k: v.values[k] for k in ("dL", "dC", "dH", "dE_CMC")})
    settings = rec.config.get("colour", {}) if isinstance(rec.config, dict) else {}
    doc: dict[str, Any] = {
        "run": rec.id,
        "theta_i_deg": theta_i,
        "colour_settings": settings,
        "geometries": rows,
        "flop_index": flop_of_rows(rows, theta_i),
        "predicted_flop_index": flop_of_rows(rows, theta_i, "predicted_L"),
        "flop_index_note": flop_index_note(theta_i),
        "pair": (
            {"reference": f"run {rec.id} measured", "sample": f"run {rec.id} predicted"}
            if other is None
            else {"reference": f"run {other.id} measured", "sample": f"run {rec.id} measured"}
        ),
        "differences": "sample - reference; dE_CMC with the set's l:c",
        "tolerance": {
            **tolerance.describe(),
            "geometries": [v.as_dict() for v in verdicts],
            "overall": overall,
        },
    }
    if other is not None:
        cmp_ = [
            {"theta_r_deg": r["theta_r_deg"], **v.as_dict()}
            for (r, _, _), v in zip(pairs, verdicts, strict=True)
        ]
        de = [c["dE00"] for c in cmp_ if np.isfinite(c["dE00"])]
        doc["vs"] = {
            "run": other.id,
            "pairs": cmp_,
            "flop_index": flop_of_rows(other_rows or [], float(other.plan.get("theta_i_deg", 45))),
            "max_dE2000": max(de) if de else None,
            "mean_dE2000": sum(de) / len(de) if de else None,
        }
    if not (illuminants or metamerism):
        return doc
    # spectra of both sides, for colours under other illuminants
    mine = run_spectra(store, rec)
    observer = _observer(rec)
    if other is None:
        ref_wl, ref_r = mine["wavelengths_nm"], mine["measured"]
        smp_wl, smp_r = mine["predicted_wavelengths_nm"], mine["predicted"]
        missing = "predicted spectra" if smp_r is None else ""
    else:
        theirs = run_spectra(store, other)
        ref_wl, ref_r = theirs["wavelengths_nm"], theirs["measured"]
        smp_wl, smp_r = mine["wavelengths_nm"], mine["measured"]
        missing = ""
    if ref_r is None or smp_r is None:
        missing = missing or "measured spectra on one wavelength grid"
        raise UserError(
            f"--illuminant / --metamerism need the spectra of both sides: run {rec.id} has no "
            f"{missing}"
        )
    idx_ref = [i if other is None else j for _, i, j in pairs]
    idx_smp = [i for _, i, _ in pairs]
    ref_pair = (ref_wl, ref_r[idx_ref])
    smp_pair = (smp_wl, smp_r[idx_smp])
    notes = sorted({n for n in (range_note(ref_wl), range_note(smp_wl)) if n})
    doc["spectra_notes"] = notes
    try:
        per_ill: dict[str, Any] = {}
        for ill in illuminants:
            from goniolab.colour.spectra import ColourSettings

            name = ColourSettings(ill, observer).validated().illuminant
            lab_r = lab_under(ref_pair[0], ref_pair[1], name, observer)
            lab_s = lab_under(smp_pair[0], smp_pair[1], name, observer)
            v_ill, o_ill = evaluate(tolerance, aspec, lab_r, lab_s)
            per_ill[name] = {
                "geometries": [
                    {
                        "reference_lab": [float(x) for x in a],
                        "sample_lab": [float(x) for x in b],
                        **v.as_dict(),
                    }
                    for a, b, v in zip(lab_r, lab_s, v_ill, strict=True)
                ],
                "overall": o_ill,
            }
        if per_ill:
            doc["illuminants"] = per_ill
        if metamerism:
            doc["metamerism"] = metamerism_table(ref_pair, smp_pair, aspec, observer=observer)
    except ColourError as exc:
        raise UserError(str(exc)) from None
    return doc


def _fmt(v: Any, spec: str = "6.2f") -> str:
    import math

    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-".rjust(len(format(0.0, spec)))
    return format(float(v), spec)


def _verdict(passed: bool | None) -> str:
    return {True: "pass", False: "FAIL", None: "-"}[passed]


def _overall_text(overall: dict[str, Any]) -> str:
    if overall["passed"] is None:
        return "no angle of the set measured"
    parts = ["PASS" if overall["passed"] else "FAIL"]
    if overall["failed_angles"]:
        parts.append("failed at " + ", ".join(f"{a:g}" for a in overall["failed_angles"]))
    if overall["missing_angles"]:
        parts.append("not measured: " + ", ".join(f"{a:g}" for a in overall["missing_angles"]))
    return parts[0] + (f" ({'; '.join(parts[1:])})" if parts[1:] else "")


def colour_report_text(doc: dict[str, Any]) -> list[str]:
    """The text ``runs colour`` prints for :func:`colour_report`'s document."""
    from goniolab.commands.runs import colour_text

    out = colour_text(doc["geometries"], doc["theta_i_deg"])
    tol = doc["tolerance"]
    pair = doc["pair"]
    out.append(
        f"tolerance {tol['name']} ({tol['metric']}): {pair['sample']} vs {pair['reference']}"
    )
    out.append(f"  source: {tol['source']}")
    metric = tol["metric"]
    out.append(
        f"  aspec    dL*    dC*    dH*   dE*ab   dE94   dE00  {metric:>6}  limits"
        "                       verdict"
    )
    key = {"dE00": "dE00", "dE94": "dE94", "dE*ab": "dE76"}.get(metric, "dE_CMC")
    for g in tol["geometries"]:
        lim = g["limits"] or {}
        lim_text = " ".join(f"{k} {v:g}" for k, v in lim.items()) or "-"
        fails = f" ({', '.join(g['failed'])})" if g["failed"] else ""
        out.append(
            f"  {g['aspecular_deg']:5.0f} {_fmt(g['dL'])} {_fmt(g['dC'])} {_fmt(g['dH'])}"
            f"  {_fmt(g['dE76'])} {_fmt(g['dE94'])} {_fmt(g['dE00'])}  {_fmt(g[key])}  "
            f"{lim_text:<28} {_verdict(g['passed'])}{fails}"
        )
    out.append(f"  overall: {_overall_text(tol['overall'])}")
    for note in doc.get("spectra_notes", []):
        out.append(f"  note: {note}")
    for ill, block in doc.get("illuminants", {}).items():
        out.append(f"under {ill} (from the spectra):")
        out.append("  aspec    dL*    dC*    dH*   dE00  verdict")
        for g in block["geometries"]:
            out.append(
                f"  {g['aspecular_deg']:5.0f} {_fmt(g['dL'])} {_fmt(g['dC'])} {_fmt(g['dH'])}"
                f" {_fmt(g['dE00'])}  {_verdict(g['passed'])}"
                + (f" ({', '.join(g['failed'])})" if g["failed"] else "")
            )
        out.append(f"  overall: {_overall_text(block['overall'])}")
    if "metamerism" in doc:
        rows = doc["metamerism"]
        ills = list(dict.fromkeys(r["illuminant"] for r in rows))
        angles = list(dict.fromkeys(r["aspecular_deg"] for r in rows))
        out.append("metamerism: dE00 of the same pair under each illuminant (CIE 15:2004 9.2)")
        out.append("  aspec " + "".join(f"{i:>8}" for i in ills))
        table = {(r["illuminant"], r["aspecular_deg"]): r["dE00"] for r in rows}
        for a in angles:
            out.append(f"  {a:5.0f} " + "".join(f"{_fmt(table[(i, a)], '8.2f')}" for i in ills))
    return out


def add_runs_colour_options(p: argparse.ArgumentParser) -> None:
    """The tolerance, illuminant and metamerism options of ``runs colour``."""
    p.add_argument(
        "--tolerance",
        default="din6175-2",
        metavar="SET",
        help="tolerance set: din6175-2 (default; goniolab limits in the DIN 6175-2 frame), "
        "de00-1, or a FILE.toml with per-angle dE/dL/dC/dH limits",
    )
    p.add_argument(
        "--illuminant",
        action="append",
        default=[],
        metavar="ILL",
        help="also judge the pair under ILL (from the spectra; repeatable: D65, A, F11, LED...)",
    )
    p.add_argument(
        "--metamerism",
        action="store_true",
        help="dE00 of the pair under D65, A, F11 (FL11) and LED (LED-B3), per angle",
    )
