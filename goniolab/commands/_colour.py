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
import sys
import tomllib
from pathlib import Path
from typing import Any

from goniolab.commands._help import RUN_HELP
from goniolab.errors import UserError, a_run_of_kind

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
    from goniolab.model_cache import spectral_for

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
    if args.compare and args.theta_r:
        raise UserError("--compare takes the geometries from its file: leave out --theta-r")
    measured = _compare_file(args) if args.compare else None
    if measured is not None:
        file_ti = float(measured.theta_i_deg[0])
        if abs(file_ti - args.theta_i) > 1e-9:
            print(
                f"goniolab: note: --compare {args.compare} was measured at theta_i {file_ti:g}"
                f" deg: predicting there, not at --theta-i {args.theta_i:g}",
                file=sys.stderr,
            )
        args.theta_i = file_ti
        tr = np.asarray(measured.theta_r_deg, dtype=np.float64)
    elif args.theta_r:
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
    for t, c, s, f in zip(tr, colours, spectra, factors, strict=True):
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
                "reflectance_factor": [float(v) for v in f],
            }
        )
    fi = flop_of_rows(rows, args.theta_i)
    fi_note = flop_index_note(args.theta_i)
    from goniolab.colour.sparkle import sparkle_report

    try:
        sparkle = (
            sparkle_report(
                sp.paint,
                pixel_um=args.sparkle_pixel_um,
                lamp_radius_deg=0.5 * args.sparkle_lamp_deg,
            )
            if sp.paint.has_flakes
            else {}
        )
    except ValueError as exc:
        raise UserError(f"sparkle: {exc}") from None
    if args.spectra_out:
        from goniolab.colour.exchange import MultiAngleSpectra

        tables = [] if measured is None else [measured]
        tables.append(
            MultiAngleSpectra(
                np.asarray(sp.wavelengths_nm, dtype=np.float64),
                np.full(tr.size, float(args.theta_i)),
                tr,
                factors,
                tuple("predicted" for _ in tr),
                tuple(0 for _ in tr),
            )
        )
        write_spectra(
            tables,
            args.spectra_out,
            {"map": args.map, "scale": args.scale, "detector_cone_deg": args.detector_deg},
            mirror_scale=args.scale == "mirror",
        )
    compare = None
    if measured is not None:
        compare = _compare_doc(args, measured, np.array([[r["L"], r["a"], r["b"]] for r in rows]),
                               settings)  # fmt: skip
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
        if sparkle:
            doc["sparkle"] = sparkle
        if compare is not None:
            doc["compare"] = compare
        if args.spectra_out:
            doc["spectra_out"] = str(Path(args.spectra_out).resolve())
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
    for name, rep in sparkle.items():
        fl = rep["flakes"]
        print(
            f"  {name} sparkle (flakes {fl['size_um']:g} um, camera along the normal, "
            f"{rep['pixel_um']:g} um pixels; goniolab.colour.sparkle):"
        )
        for a in rep["angles"]:
            print(
                f"    lamp {a['illumination_deg']:4.0f} deg: S_a {a['S_a_pct']:.3g} % of pixels,"
                f" S_i {a['S_i']:.3g} x the surround"
            )
        print(f"    graininess G {rep['G']:.3g} % ({rep['grain_pixel_um']:g} um pixels)")
    if compare is not None:
        print(f"measured spectra {args.compare} ({compare['rows_read']} rows, repeats "
              "averaged as spectra) vs this prediction:")  # fmt: skip
        print("\n".join(colour_report_text({"tolerance": compare["tolerance"],
                                              "pair": compare["pair"],
                                              "spectra_notes": compare["spectra_notes"]},
                                             with_geometries=False)))  # fmt: skip
    if args.spectra_out:
        print(f"  spectra (reflectance factors) written to {args.spectra_out}")
    return 0


def _compare_file(args: argparse.Namespace) -> Any:
    """``--compare FILE.csv``: the measured multi-angle spectra (one incidence), repeats
    averaged as spectra."""
    import numpy as np

    from goniolab.colour.exchange import read_spectra_csv
    from goniolab.colour.spectra import ColourError

    p = Path(args.compare)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise UserError(f"--compare {p}: cannot read: {exc.strerror}") from None
    try:
        table = read_spectra_csv(text, where=str(p), unit=args.compare_unit,
                                 theta_i_deg=args.theta_i).select("measured")  # fmt: skip
    except ColourError as exc:
        raise UserError(str(exc)) from None
    incidences = sorted({round(float(t), 6) for t in table.theta_i_deg})
    if len(incidences) != 1:
        raise UserError(
            f"--compare {p}: one incidence per file, found theta_i "
            + ", ".join(f"{t:g}" for t in incidences)
        )
    avg = table.averaged()
    avg_rows = table.factors.shape[0]
    args._compare_rows = avg_rows
    order = np.argsort(-avg.theta_r_deg)
    from goniolab.colour.exchange import MultiAngleSpectra

    return MultiAngleSpectra(
        avg.wavelengths_nm,
        avg.theta_i_deg[order],
        avg.theta_r_deg[order],
        avg.factors[order],
        tuple(avg.source[k] for k in order),
        tuple(0 for _ in order),
    )


def _compare_doc(args: argparse.Namespace, measured: Any, predicted_lab: Any,
                 settings: Any) -> dict[str, Any]:  # fmt: skip
    """Differences and tolerance verdicts of the prediction against the measured file."""
    from goniolab.colour.spectra import range_note
    from goniolab.colour.tolerance import evaluate, lab_under

    tolerance = load_tolerance(args.tolerance)
    lab_m = lab_under(measured.wavelengths_nm, measured.factors, settings.illuminant,
                      settings.observer)  # fmt: skip
    verdicts, overall = evaluate(tolerance, measured.aspecular_deg, lab_m, predicted_lab)
    return {
        "file": str(args.compare),
        "rows_read": int(getattr(args, "_compare_rows", measured.factors.shape[0])),
        "wavelengths_nm": [float(w) for w in measured.wavelengths_nm],
        "measured_lab": [[float(v) for v in row] for row in lab_m],
        "pair": {"reference": f"measured {args.compare}", "sample": "this prediction"},
        "spectra_notes": [n for n in (range_note(measured.wavelengths_nm),) if n],
        "tolerance": {
            **tolerance.describe(),
            "geometries": [v.as_dict() for v in verdicts],
            "overall": overall,
        },
    }


def _add_colour_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--illuminant", default="D65", help="CIE illuminant")
    p.add_argument("--observer", default="10", help="10 (CIE 1964) or 2 (CIE 1931) degree observer")
    p.add_argument("--paint", metavar="FILE.toml", help="paint definition (else the sample's)")
    p.add_argument("--step-nm", type=float, default=10.0, help="wavelength step, nm")
    p.add_argument("--source-deg", type=float, default=6.0, help="lamp cone, full angle, deg")
    p.add_argument("--detector-deg", type=float, default=6.0, help="detector cone, full angle, deg")


def register_predict_colour(sub: Any, add_common: Any) -> None:
    """Add ``predict colour`` to the ``predict`` sub-parsers."""
    p = sub.add_parser(
        "colour", help="predicted L*a*b* per angle (ASTM E2194 geometry) and flop index"
    )
    add_common(p)
    _add_colour_options(p)
    p.add_argument("--theta-i", type=float, default=45.0, help="incidence (lamp) angle, deg")
    p.add_argument(
        "--theta-r",
        default=None,
        help="detector angles (default: the E2194 aspecular angles -15,15,25,45,75,110)",
    )
    p.add_argument(
        "--compare",
        metavar="FILE.csv",
        help="measured multi-angle spectra (R_400.. columns, aspecular_deg or theta_r_deg): "
        "predicted at the file's geometries and judged against it",
    )
    p.add_argument(
        "--compare-unit",
        choices=("factor", "percent"),
        default="factor",
        help="the --compare file's values: reflectance factors or percent",
    )
    p.add_argument(
        "--tolerance",
        default="din6175-2",
        metavar="SET",
        help="tolerance set for --compare (din6175-2, de00-1 or FILE.toml)",
    )
    p.add_argument(
        "--sparkle-pixel-um",
        type=float,
        default=15.0,
        help="camera pixel on the sample for the sparkle prediction, um",
    )
    p.add_argument(
        "--sparkle-lamp-deg",
        type=float,
        default=2.0,
        help="angular diameter of the sparkle lamp, deg",
    )
    p.add_argument(
        "--spectra-out",
        metavar="FILE",
        help="write the predicted (and --compare measured) spectra as reflectance factors: "
        "FILE.csv (R_380.. columns), .parquet or .nc",
    )
    p.add_argument(
        "--scale",
        choices=("diffuser", "mirror"),
        default="diffuser",
        help="mirror: %% of the mirror; diffuser: reflectance factor vs the perfect diffuser",
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
    if other is not None:
        ti_other = float(other.plan.get("theta_i_deg", 45.0))
        if abs(ti_other - theta_i) > 1e-6:
            raise UserError(
                f"runs {rec.id} and {other.id} were lit at theta_i {theta_i:g} and "
                f"{ti_other:g} deg: their colours are not comparable geometry by geometry"
            )
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
    note = ""
    if other is None and not any(r.get("predicted_L") is not None for r in rows):
        note = f"run {rec.id} has no predicted colours to judge against (compare runs: --vs RUN)"
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
            "note": note,
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
    # how the stored colours were integrated: a grid short of 380-780 nm is said
    grids = {
        tuple(p.raw.get("wavelengths_nm") or ())
        for p in store.points(rec.id)
        if p.index >= 0 and p.raw.get("wavelengths_nm")
    }
    doc["spectra_notes"] = sorted({n for g in grids if (n := range_note(np.asarray(g)))})
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
    doc["spectra_notes"] = sorted(set(doc["spectra_notes"]) | set(notes))
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


def colour_report_text(doc: dict[str, Any], *, with_geometries: bool = True) -> list[str]:
    """The text ``runs colour`` prints for :func:`colour_report`'s document."""
    from goniolab.commands.runs import colour_text

    out = colour_text(doc["geometries"], doc["theta_i_deg"]) if with_geometries else []
    tol = doc["tolerance"]
    pair = doc["pair"]
    out.append(
        f"tolerance {tol['name']} ({tol['metric']}): {pair['sample']} vs {pair['reference']}"
    )
    out.append(f"  source: {tol['source']}")
    if tol.get("note"):
        out.append(f"  {tol['note']}")
        return out
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
        help="tolerance set: din6175-2 (goniolab limits in the DIN 6175-2 frame), "
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


# --------------------------------------------------------------------------- spectra files
#: Spectra file formats by suffix.
SPECTRA_SUFFIXES = {".csv": "csv", ".parquet": "parquet", ".pq": "parquet", ".nc": "netcdf"}


def write_spectra(
    tables: list[Any], path: str, attrs: dict[str, Any], *, mirror_scale: bool = False
) -> str:
    """Write multi-angle reflectance-factor tables (:class:`MultiAngleSpectra`) to ``path``:
    CSV (``R_400..`` columns), Parquet (the same columns, ``attrs`` as JSON in the schema
    metadata under ``goniolab.spectra``) or netCDF (``reflectance_factor`` over
    ``(geometry, wavelength_nm)`` with units and long names). Returns the format."""
    import numpy as np

    from goniolab.colour.exchange import (
        CSV_HEADER_NOTE,
        MIRROR_NOTE,
        spectra_csv,
        spectral_column,
        union_table,
    )

    values_label = (
        "fraction of the mirror reference (scale = mirror): not a reflectance factor"
        if mirror_scale
        else "reflectance factor (1 = perfect reflecting diffuser)"
    )

    fmt = SPECTRA_SUFFIXES.get(Path(path).suffix.lower())
    if fmt is None:
        raise UserError(f"{path}: spectra files are .csv, .parquet or .nc")
    table = union_table(tables)
    try:
        if fmt == "csv":
            note = MIRROR_NOTE if mirror_scale else CSV_HEADER_NOTE
            Path(path).write_text(spectra_csv(tables, note=note), encoding="utf-8")
        elif fmt == "parquet":
            import pandas as pd
            import pyarrow as pa
            import pyarrow.parquet as pq

            df = pd.DataFrame(
                {
                    "source": list(table.source),
                    "theta_i_deg": table.theta_i_deg,
                    "theta_r_deg": table.theta_r_deg,
                    "aspecular_deg": table.aspecular_deg,
                    "repeat": np.asarray(table.repeat, dtype=np.int64),
                    **{
                        spectral_column(w): table.factors[:, k]
                        for k, w in enumerate(table.wavelengths_nm)
                    },
                }
            )
            t = pa.Table.from_pandas(df, preserve_index=False)
            meta = dict(t.schema.metadata or {})
            meta[b"goniolab.spectra"] = json.dumps(
                {**attrs, "values": values_label,
                 "aspecular": "theta_i_deg - theta_r_deg (ASTM E2194)"},
                sort_keys=True, default=str,
            ).encode()  # fmt: skip
            pq.write_table(t.replace_schema_metadata(meta), path)
        else:
            import xarray as xr

            from goniolab.datasets import LONG_NAMES as _LONG_NAMES
            from goniolab.datasets import UNITS, write_netcdf

            geom = np.arange(table.factors.shape[0])
            ds = xr.Dataset(
                {
                    "reflectance_factor": (
                        ("geometry", "wavelength_nm"),
                        table.factors,
                        {
                            "units": "1",
                            "long_name": f"spectral {values_label}, measured or "
                            "predicted per the source variable",
                        },
                    ),
                    "source": (
                        "geometry",
                        np.array(table.source, dtype=str),
                        {"long_name": "measured or predicted"},
                    ),
                    "repeat": (
                        "geometry",
                        np.asarray(table.repeat, dtype=np.int64),
                        {"long_name": "repeat number", "units": "1"},
                    ),
                },
                coords={
                    "geometry": ("geometry", geom, {"long_name": "row number"}),
                    "wavelength_nm": (
                        "wavelength_nm",
                        table.wavelengths_nm,
                        {"units": UNITS["wavelength_nm"], "long_name": "wavelength"},
                    ),
                    **{
                        name: (
                            "geometry",
                            values,
                            {"units": UNITS[name], "long_name": _LONG_NAMES.get(name, name)},
                        )
                        for name, values in (
                            ("theta_i_deg", table.theta_i_deg),
                            ("theta_r_deg", table.theta_r_deg),
                            ("aspecular_deg", table.aspecular_deg),
                        )
                    },
                },
                attrs={"title": "goniolab multi-angle spectra", **attrs},
            )
            write_netcdf(ds, path)
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None
    return fmt


def run_spectra_tables(store: Any, rec: Any, which: str) -> list[Any]:
    """A run's spectra as :class:`MultiAngleSpectra` tables (``measured`` per reading,
    ``predicted`` per geometry)."""
    import numpy as np

    from goniolab.colour.exchange import MultiAngleSpectra
    from goniolab.datasets import predicted_grid_nm, run_reflectance_factors

    wl, measured, predicted = run_reflectance_factors(store, rec.id)
    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    tr = np.asarray(rec.plan.get("theta_r_deg", []), dtype=np.float64)
    out: list[Any] = []
    if which in ("measured", "both") and wl.size:
        n, reps, _ = measured.shape
        keep = [
            (k, r) for k in range(n) for r in range(reps) if np.all(np.isfinite(measured[k, r]))
        ]
        if keep:
            out.append(
                MultiAngleSpectra(
                    wl,
                    np.full(len(keep), theta_i),
                    np.array([tr[k] for k, _ in keep]),
                    np.array([measured[k, r] for k, r in keep]),
                    tuple("measured" for _ in keep),
                    tuple(r for _, r in keep),
                )
            )
    if which in ("predicted", "both") and predicted is not None:
        keep_p = [k for k in range(predicted.shape[0]) if np.all(np.isfinite(predicted[k]))]
        if keep_p:
            out.append(
                MultiAngleSpectra(
                    predicted_grid_nm(predicted.shape[-1]),
                    np.full(len(keep_p), theta_i),
                    tr[keep_p],
                    predicted[keep_p],
                    tuple("predicted" for _ in keep_p),
                    tuple(0 for _ in keep_p),
                )
            )
    return out


def cmd_runs_spectra(args: argparse.Namespace) -> int:
    """``goniolab runs spectra RUN -o FILE``: the run's spectra as reflectance factors."""
    from goniolab.commands.runs import _get_run, open_store

    with open_store(args.store, args.config) as store:
        rec = _get_run(store, args.run)
        if rec.kind != "brdf":
            raise UserError(
                f"run {rec.id} is {a_run_of_kind(rec.kind)}: spectra need a scan (brdf) run"
            )
        tables = run_spectra_tables(store, rec, args.which)
    if not tables:
        raise UserError(f"run {rec.id} has no {args.which} spectra on one wavelength grid")
    cfg = rec.config if isinstance(rec.config, dict) else {}
    attrs = {
        "run_id": rec.id,
        "sample": rec.sample,
        "colour_scale": str((cfg.get("colour") or {}).get("scale", "diffuser")),
        "detector_cone_deg": float((cfg.get("spectro") or {}).get("detector_cone_deg", 6.0)),
    }
    fmt = write_spectra(tables, args.output, attrs, mirror_scale=attrs["colour_scale"] == "mirror")
    rows = sum(t.factors.shape[0] for t in tables)
    if args.json:
        print(json.dumps({"output": str(Path(args.output).resolve()), "format": fmt,
                          "rows": rows, "which": args.which}))  # fmt: skip
    else:
        print(f"run {rec.id}: {rows} {args.which} spectra (reflectance factors) -> {args.output}")
    return 0


def register_runs_spectra(sub: Any, common: argparse.ArgumentParser) -> None:
    """Add ``runs spectra`` to the ``runs`` sub-parsers."""
    p = sub.add_parser(
        "spectra",
        parents=[common],
        help="a scan's measured/predicted spectra as reflectance factors (CSV R_400.., "
        "Parquet, netCDF)",
    )
    p.add_argument("run", type=int, metavar="RUN", help=RUN_HELP)
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="FILE.csv, FILE.parquet or FILE.nc")  # fmt: skip
    p.add_argument(
        "--which",
        choices=("measured", "predicted", "both"),
        default="both",
        help="which spectra to write",
    )
    p.add_argument("--json", action="store_true", help="report what was written as JSON")
    p.set_defaults(func=cmd_runs_spectra)
