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
from typing import TYPE_CHECKING, Any

from goniolab.commands._help import RUN_HELP
from goniolab.commands._surface_args import add_surface_options, surface_request
from goniolab.progress import model_progress

if TYPE_CHECKING:
    from goniolab.app.colours import ColourOptions

__all__ = [
    "add_runs_colour_options",
    "colour_report_text",
    "register_predict_colour",
    "register_runs_spectra",
]


def _colour_options(args: argparse.Namespace) -> ColourOptions:
    from goniolab.app.colours import ColourOptions

    return ColourOptions(
        illuminant=args.illuminant,
        observer=args.observer,
        paint=args.paint,
        step_nm=args.step_nm,
        source_deg=args.source_deg,
        detector_deg=args.detector_deg,
        theta_i_deg=args.theta_i,
        theta_r_deg=args.theta_r,
        compare=args.compare,
        compare_unit=args.compare_unit,
        tolerance=args.tolerance,
        sparkle_pixel_um=args.sparkle_pixel_um,
        sparkle_lamp_deg=args.sparkle_lamp_deg,
        spectra_out=args.spectra_out,
        scale=args.scale,
    )


def _cmd_predict_colour(args: argparse.Namespace) -> int:
    from goniolab.app.colours import predict_colour

    pred = predict_colour(surface_request(args), _colour_options(args), progress=model_progress())
    for note in pred.notes:
        print(f"goniolab: note: {note}", file=sys.stderr)
    doc = pred.doc
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(
        f"{args.map}: predicted colour at theta_i = {doc['theta_i_deg']:g} deg "
        f"({doc['illuminant']}, {doc['observer']}, {args.scale} scale)"
    )
    print("  theta_r  aspec      L*      a*      b*      C*       h")
    for r in doc["geometries"]:
        print(
            f"  {r['theta_r_deg']:7.2f} {r['aspecular_deg']:6.1f} {r['L']:7.2f} {r['a']:7.2f}"
            f" {r['b']:7.2f} {r['C']:7.2f} {r['h_deg']:7.1f}"
        )
    fi, fi_note = doc["flop_index"], doc["flop_index_note"]
    if fi is not None:
        print(f"  flop index (2.69 (L*15 - L*110)^1.11 / L*45^0.86): {fi:.2f}")
    elif fi_note:
        print(f"  {fi_note}")
    for name, rep in doc.get("sparkle", {}).items():
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
    compare = doc.get("compare")
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


def _add_colour_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--illuminant", default="D65", help="CIE illuminant")
    p.add_argument("--observer", default="10", help="10 (CIE 1964) or 2 (CIE 1931) degree observer")
    p.add_argument("--paint", metavar="FILE.toml", help="paint definition (else the sample's)")
    p.add_argument("--step-nm", type=float, default=10.0, help="wavelength step, nm")
    p.add_argument("--source-deg", type=float, default=6.0, help="lamp cone, full angle, deg")
    p.add_argument("--detector-deg", type=float, default=6.0, help="detector cone, full angle, deg")


def register_predict_colour(sub: Any) -> None:
    """Add ``predict colour`` to the ``predict`` sub-parsers."""
    p = sub.add_parser(
        "colour", help="predicted L*a*b* per angle (ASTM E2194 geometry) and flop index"
    )
    add_surface_options(p)
    _add_colour_options(p)
    p.add_argument("--theta-i", type=float, default=45.0, help="incidence (lamp) angle, deg")
    p.add_argument(
        "--theta-r",
        default=None,
        help="detector angles (default: the E2194 aspecular angles -15,15,25,45,75,110)",
    )
    p.add_argument(
        "--compare",
        metavar="FILE",
        help="measured multi-angle spectra, a CSV (R_400.. columns, aspecular_deg or "
        "theta_r_deg) or a CxF3 file (.cxf, needs goniolab[cxf]): predicted at the file's "
        "geometries and judged against it",
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
    out.extend(f"note: {n}" for n in doc.get("predicted_colour_notes", []))
    if doc.get("calibration_note"):
        out.append(doc["calibration_note"])
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


def cmd_runs_spectra(args: argparse.Namespace) -> int:
    """``goniolab runs spectra RUN -o FILE``: the run's spectra as reflectance factors."""
    from goniolab.app.stored_runs import write_run_spectra

    done = write_run_spectra(
        args.run, args.output, args.which, store=args.store, config=args.config
    )
    if args.json:
        print(json.dumps({"output": str(done.output.resolve()), "format": done.format,
                          "rows": done.rows, "which": done.which}))  # fmt: skip
    else:
        print(f"run {done.run_id}: {done.rows} {done.which} spectra (reflectance factors) -> "
              f"{args.output}")  # fmt: skip
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
