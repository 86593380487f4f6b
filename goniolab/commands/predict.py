"""``goniolab predict stats|gloss|brdf|albedo|colour MAP``: roughness, gloss, BRDF, albedo and colour
predicted from a height map.

MAP is a height-map file or ``sample:NAME`` (:func:`goniolab.surfaces.resolve_map`). The facet
model (Wittmann et al. 2021; docs/PHYSICS.md) gives

- ``stats``: Ra, Sq (nm), Sdq and the zero-slope histogram fraction h_r;
- ``gloss``: ISO 2813 G20/G60/G85, the ASTM D4039 haze index, ASTM E430 haze and DOI and the
  ASTM D523 recommended geometry (:func:`goniolab.optics.gloss_standards.gloss_report`);
- every command takes ``--model`` (a name of :mod:`goniolab.model_registry`: ``auto``,
  ``facet``, ``kirchhoff``, ``rayleigh-rice``; default ``auto``: per geometry, the regime rule of :mod:`goniolab.optics.model_choice`) and ``--wavelength-nm``
  (default: gloss weighted over wavelength by CIE C x V(lambda) as ISO 2813 does, BRDFs at
  550 nm); ``--json`` names the model that computed each reading under ``"model"`` (gloss)
  or ``"models"`` (one per angle of a curve), any hand-over to the facet model under
  ``"fallback"`` and every note (validity limits, light the map cannot resolve, energy
  scales) under ``"warnings"``, also printed on stderr (``goniolab: warning: ...``);
- ``albedo``: the directional-hemispherical reflectance (coherent beam plus diffuse light)
  and the total integrated scatter (ISO 13696: diffuse flux over incident flux) at each
  ``--theta-i`` for a collimated beam, with the Fresnel reflectance of the flat surface
  beside them and the model that computed each row;
- ``brdf``: the in-plane curve at ``--theta-i`` over ``--theta-r``: the goniometer reading
  (``luminance_pct``, % of a mirror, source and detector cones) and the aperture-averaged
  BRDF ``luminance / 100 / (projected solid angle of the detector)``, or with ``--point`` the
  BRDF in the exact direction (no aperture, no luminance). With three or more increasing
  angles it also reports the seed's two comparison numbers (Wittmann sec. 4.2, fig. 8):
  peak amplitude and FWHM of the luminance curve (of the BRDF with ``--point``),
  :func:`goniolab.optics.metrics.peak_metrics`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from goniolab.commands._angles import allow_negative_angles
from goniolab.commands._surface_args import add_surface_options, surface_request
from goniolab.errors import UserError
from goniolab.progress import model_progress, terminal_progress

__all__ = ["register"]


def _warn(warnings: list[str]) -> None:
    """The notes of a prediction on stderr, one line each (the same text as --json's)."""
    for w in dict.fromkeys(warnings):
        print(f"goniolab: warning: {w}", file=sys.stderr)


def _n_text(n: complex) -> str:
    return f"n = {n.real:g}{f'+{n.imag:g}i' if n.imag else ''}"


def _cmd_stats(args: argparse.Namespace) -> int:
    from goniolab.app.predictions import surface_stats

    st = surface_stats(surface_request(args))
    out = st.doc
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=False))
        return 0
    ny, nx = st.shape
    print(f"{args.map}: {nx} x {ny} points at {st.dx_um:g} x {st.dy_um:g} um")
    print(f"  Ra   {out['Ra_nm']:10.1f} nm")
    print(f"  Sq   {out['Sq_nm']:10.1f} nm")
    print(f"  Sdq  {out['Sdq']:10.4f}")
    print(
        f"  h_r  {out['h_r']:10.4f}   (fraction of facets in the slope histogram's zero bin, "
        "|p|, |q| < 5e-4; Wittmann sec. 3.1: the higher, the glossier)"
    )
    for t_key, ch in out["regime"].items():
        if isinstance(ch, dict):
            print(f"  {t_key:>2} deg: {ch['model']:<13} ({ch['reason']})")
    return 0


def _datasets() -> Any:
    """:mod:`goniolab.datasets`, imported only when ``--out`` writes a file."""
    from goniolab import datasets

    return datasets


def _write_out(args: argparse.Namespace, make: Any) -> None:
    """``--out FILE.nc``: the prediction as a netCDF Dataset (units on every variable)."""
    if not args.out:
        return
    from goniolab.app.netcdf_files import save_dataset
    from goniolab.app.predictions import index_json

    out = Path(args.out)
    if out.suffix.lower() not in (".nc", ".nc4"):
        raise UserError(f"--out {out}: a prediction is written as netCDF (.nc)")
    attrs = {"map": str(args.map), "n": index_json(args.n), "weighting": args.weighting,
             "slope_method": args.slope_method, "masking": int(args.masking),
             "model": args.model}  # fmt: skip
    if args.wavelength_nm is not None:
        attrs["wavelength_nm"] = float(args.wavelength_nm)
    save_dataset(make(attrs), out)
    print(f"prediction written to {out}", file=sys.stderr)


def _cmd_gloss(args: argparse.Namespace) -> int:
    if len(args.map) > 1 or args.scheduler:
        return _cmd_gloss_batch(args)
    args.map = args.map[0]
    from goniolab.app.predictions import predict_gloss

    pred = predict_gloss(surface_request(args), progress=model_progress())
    rep = pred.report
    prov_attrs = {"computed_by": json.dumps(pred.computed_by),
                  "warnings": json.dumps(pred.warnings)}  # fmt: skip
    _write_out(args, lambda attrs: _datasets().gloss_dataset(rep, attrs={**attrs, **prov_attrs}))
    _warn(pred.warnings)
    if args.json:
        print(json.dumps(pred.as_dict(), indent=2, allow_nan=False))
        return 0
    print(f"{args.map} ({_n_text(args.n)})")
    print(_gloss_table(rep, pred.model, pred.e430_model))
    if rep.e430.doi < 0:
        print(
            "  note: DOI < 0: the 0.3 deg off-specular reading exceeds the specular one "
            "(no distinct reflected image; DOI = 100 (Rs - R0.3) / Rs, ASTM E430)"
        )
    if rep.haze_index < 0:
        print("  note: haze index < 0: G20 above G60 (a mirror-like coat: no measurable haze)")
    return 0


def _gloss_table(rep: Any, names: dict[str, Any], e430: dict[str, str] | None = None) -> str:
    """``predict gloss`` as a table: what each number is, its value and its unit (and the
    model that computed it)."""
    e = rep.e430
    e430 = e430 or {}

    def by(*keys: str) -> str:
        found = sorted({e430[k] for k in keys if k in e430})
        return f" ({' + '.join(found)} model)" if found else ""

    head_b = f"ASTM E430 method B, 20 deg{by('gloss_20', 'haze_18_1', 'haze_21_9')}:"
    head_a = f"ASTM E430 method A, 30 deg{by('gloss_30', 'haze_narrow', 'haze_wide', 'doi')}:"
    gu = "GU (ISO 2813 black glass = 100)"
    rows: list[tuple[str, str, str]] = [
        (f"G{t}  specular gloss at {t} deg", f"{g:.1f}", f"{gu if t == 20 else 'GU'}, "
         f"{names.get(f'G{t}', '')} model")
        for t, g in ((20, rep.G20), (60, rep.G60), (85, rep.G85))
    ]  # fmt: skip
    rows += [
        ("geometry to report (ASTM D523)", f"{rep.d523_recommended_angle}",
         "deg (20 if G60 > 70, 85 if G60 < 10)"),
        ("haze index HI (ASTM D4039)", f"{rep.haze_index:.1f}", "GU, G60 - G20"),
        (head_b, "", ""),
        ("  specular gloss", f"{e.gloss_20:.1f}", "GU"),
        ("  haze at 18.1 deg / 21.9 deg", f"{e.haze_18_1:.2f} / {e.haze_21_9:.2f}", "GU"),
        (head_a, "", ""),
        ("  specular reading Rs", f"{e.gloss_30:.1f}", "GU"),
        ("  narrow-angle haze (28, 32 deg)", f"{e.haze_narrow:.2f}", "GU"),
        ("  wide-angle haze (25, 35 deg)", f"{e.haze_wide:.2f}", "GU"),
        ("  distinctness of image DOI", f"{e.doi:.1f}",
         "of 100, 100 (Rs - R0.3) / Rs (100: a perfect image)"),
    ]  # fmt: skip
    wl = max(len(r[0]) for r in rows)
    wv = max(len(r[1]) for r in rows)
    return "\n".join(
        f"  {label:<{wl}}  {value:>{wv}}  {unit}".rstrip() for label, value, unit in rows
    )


def _batch_line(row: dict[str, Any]) -> str:
    e = row["e430"]
    return (
        f"{row['map']}: G20 {row['G20']:6.1f}  G60 {row['G60']:6.1f}  G85 {row['G85']:6.1f} GU"
        f"  haze {row['haze_index']:6.1f}  DOI {e['doi']:5.1f}  D523 {row['d523_angle']} deg"
    )


def _cmd_gloss_batch(args: argparse.Namespace) -> int:
    """Many maps: one worker process per core (or a dask cluster), rows as maps finish."""
    from goniolab.app.predictions import predict_gloss_batch

    if args.out:
        raise UserError("--out writes one map's prediction: give a single MAP")
    rows = predict_gloss_batch(
        args.map, surface_request(args), jobs=args.jobs, scheduler=args.scheduler
    )
    failed = 0
    # a bar on a terminal (never on stdout: the rows go there, issue 22.3); to a pipe or
    # a file only the messages
    with terminal_progress(len(args.map), "gloss", piped_lines=False) as bar:
        for row in rows:
            if "error" in row:
                failed += 1
                bar.message(f"goniolab: error: {row['error']}")
            if args.json:
                print(json.dumps(row), flush=True)  # JSON Lines: one object per map
            elif "error" not in row:
                print(_batch_line(row), flush=True)
            bar.advance()
    if failed:
        print(f"goniolab: {failed} of {len(args.map)} maps failed", file=sys.stderr)
        return 2
    return 0


def _cmd_brdf(args: argparse.Namespace) -> int:
    from goniolab.app.predictions import predict_brdf

    pred = predict_brdf(
        surface_request(args),
        theta_i_deg=args.theta_i,
        theta_r_deg=args.theta_r,
        source_deg=args.source_deg,
        detector_deg=args.detector_deg,
        point=args.point,
        progress=model_progress(),
    )
    _warn(pred.warnings)
    tr, brdf, lum = pred.theta_r_deg, pred.brdf_sr, pred.luminance_pct
    cones: dict[str, Any] = {} if lum is None else {"source_cone_deg": pred.source_deg,
                                    "detector_cone_deg": pred.detector_deg}  # fmt: skip
    cones["computed_by"] = json.dumps(pred.models)
    cones["warnings"] = json.dumps(pred.warnings)
    _write_out(
        args,
        lambda attrs: _datasets().brdf_dataset(
            pred.theta_i_deg, tr, brdf, lum, attrs={**attrs, **cones}
        ),
    )
    if args.json:
        print(json.dumps(pred.as_dict(), indent=2, allow_nan=False))
        return 0
    head = f"{'theta_r':>8}  {'BRDF (1/sr)':>12}"
    print(head + (f"  {'luminance %':>12}" if lum is not None else "") + "  model")
    for k, t in enumerate(tr):
        line = f"{t:8.2f}  {brdf[k]:12.5g}"
        if lum is not None:
            line += f"  {lum[k]:12.5g}"
        print(f"{line}  {pred.models[k]}")
    peak = pred.peak
    if peak is not None:
        unit = "1/sr" if lum is None else "%"
        width = peak.get("fwhm_note") or f"{peak['fwhm_deg']:.3g} deg"
        print(
            f"peak {peak['amplitude']:.5g} {unit} at {peak['position_deg']:.2f} deg, FWHM {width}"
        )
    return 0


def _cmd_albedo(args: argparse.Namespace) -> int:
    """Directional-hemispherical reflectance and TIS per incidence (issue 20)."""
    from goniolab.app.predictions import predict_albedo

    pred = predict_albedo(surface_request(args), args.theta_i, progress=model_progress())
    _warn(pred.warnings)
    if args.json:
        print(json.dumps(pred.as_dict(), indent=2, allow_nan=False))
        return 0
    print(f"{args.map} ({_n_text(args.n)}, {pred.wavelength_nm:g} nm, collimated beam)")
    print(f"{'theta_i':>8}  {'albedo':>9}  {'TIS':>9}  {'Fresnel R':>9}  model")
    rows = zip(pred.theta_i_deg, pred.albedo, pred.tis, pred.fresnel, pred.models, strict=True)
    for ti, a, t, f, name in rows:
        print(f"{ti:8.2f}  {a:9.5f}  {t:9.5f}  {f:9.5f}  {name}")
    print(
        "albedo: directional-hemispherical reflectance (coherent beam + diffuse light the map "
        "resolves); TIS: the diffuse part over the incident flux (ISO 13696)"
    )
    return 0


def register(subparsers: Any) -> None:
    """Add ``goniolab predict`` and its sub-commands."""
    parser = subparsers.add_parser(
        "predict",
        help="roughness statistics, gloss and BRDF predicted from a height map",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    sub = parser.add_subparsers(dest="predict_command", metavar="WHAT", required=True)
    stats = sub.add_parser("stats", help="Ra, Sq, Sdq, h_r of the map")
    add_surface_options(stats)
    stats.set_defaults(func=_cmd_stats)
    gloss = sub.add_parser(
        "gloss",
        help="ISO 2813 gloss, haze, DOI, D523 geometry (several maps: in parallel, JSON Lines)",
    )
    add_surface_options(gloss, many=True)
    gloss.add_argument(
        "--jobs",
        type=int,
        default=None,
        metavar="N",
        help="several maps: worker processes (default: one per core)",
    )
    gloss.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the maps on a dask.distributed cluster (tcp://host:8786; extra goniolab[dask])",
    )
    gloss.add_argument("--out", metavar="FILE.nc", help="also write the prediction as netCDF")
    gloss.set_defaults(func=_cmd_gloss)
    brdf = sub.add_parser("brdf", help="in-plane BRDF and goniometer luminance")
    add_surface_options(brdf)
    brdf.add_argument("--theta-i", type=float, default=45.0, help="incidence (lamp) angle, deg")
    brdf.add_argument(
        "--theta-r",
        default="0:70:1",
        help="detector angles: start:stop:step (stop included) or a comma list, e.g. -20:20:1",
    )
    brdf.add_argument(
        "--source-deg", type=float, default=None, help="lamp cone, full angle, deg (default: 6)"
    )
    brdf.add_argument(
        "--detector-deg",
        type=float,
        default=None,
        help="detector cone, full angle, deg (default: 6)",
    )
    brdf.add_argument("--point", action="store_true", help="BRDF in the exact direction")
    brdf.add_argument("--out", metavar="FILE.nc", help="also write the curve as netCDF")
    allow_negative_angles(brdf)  # "--theta-r -20:20:1" is a range, not an option
    brdf.set_defaults(func=_cmd_brdf)
    albedo = sub.add_parser(
        "albedo",
        help="directional-hemispherical reflectance and total integrated scatter per theta_i",
    )
    add_surface_options(albedo)
    albedo.add_argument(
        "--theta-i",
        default="0,30,60,85",
        help="incidence (lamp) angles, deg, each <= 89: a comma list or start:stop:step",
    )
    albedo.set_defaults(func=_cmd_albedo)
    from goniolab.commands._colour import register_predict_colour

    register_predict_colour(sub)
