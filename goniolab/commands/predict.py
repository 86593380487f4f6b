"""``goniolab predict stats|gloss|brdf MAP``: roughness, gloss and BRDF predicted from a map.

MAP is a height-map file or ``sample:NAME`` (:func:`goniolab.surfaces.resolve_map`). The facet
model (Wittmann et al. 2021; docs/PHYSICS.md) gives

- ``stats``: Ra, Sq (nm), Sdq and the zero-slope histogram fraction h_r;
- ``gloss``: ISO 2813 G20/G60/G85, the ASTM D4039 haze index, ASTM E430 haze and DOI and the
  ASTM D523 recommended geometry (:func:`goniolab.optics.gloss_standards.gloss_report`);
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
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from goniolab.commands._angles import allow_negative_angles
from goniolab.errors import UserError

if TYPE_CHECKING:  # numpy and the optics load when a command runs, not at --help
    import numpy as np
    from numpy.typing import NDArray

    from goniolab.optics.apertures import Cone
    from goniolab.optics.metrics import PeakMetrics

__all__ = ["parse_index", "register"]

#: Default source and detector cones of the Wittmann goniometer (sec. 2.3), full angles.
DEFAULT_CONE_DEG = 6.0


def parse_index(text: str) -> complex:
    """Parse ``--n``: a real index (``1.55``) or ``n+kj`` for conductors (``0.27+3.41j``).

    ``i`` is accepted for ``j``. Requires n > 0 and k >= 0.
    """
    raw = text.strip().replace(" ", "")
    try:
        value = complex(raw.replace("i", "j"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--n {text!r}: not a number or complex index like 0.27+3.41j"
        ) from None
    if not (math.isfinite(value.real) and math.isfinite(value.imag)):
        raise argparse.ArgumentTypeError(f"--n {text!r}: must be finite")
    if value.real <= 0 or value.imag < 0:
        raise argparse.ArgumentTypeError(f"--n {text!r}: needs n > 0 and k >= 0")
    return value


def _index_json(n: complex) -> float | list[float]:
    return n.real if n.imag == 0 else [n.real, n.imag]


def _model(args: argparse.Namespace) -> Any:
    from goniolab.models import model_for

    return model_for(
        args.map,
        n=args.n,
        step_um=args.step_um,
        slope_method=args.slope_method,
        weighting=args.weighting,
        masking=args.masking,
    )


def _cmd_stats(args: argparse.Namespace) -> int:
    from goniolab.optics.surface import roughness_stats
    from goniolab.surfaces.resolve import resolve_map

    hm = resolve_map(args.map, step_um=args.step_um)
    try:
        st = roughness_stats(hm, slope_method=args.slope_method)
    except ValueError as exc:
        raise UserError(f"{args.map}: {exc}") from None
    out = {
        "map": str(args.map),
        "Ra_nm": st.Ra_nm,
        "Sq_nm": st.Sq_nm,
        "Sdq": st.Sdq,
        "h_r": st.h_r,
        "slope_rms_x": st.slope_rms_x,
        "slope_rms_y": st.slope_rms_y,
        "n_facets": st.n_facets,
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    ny, nx = hm.shape
    print(f"{args.map}: {nx} x {ny} points at {hm.dx_um:g} x {hm.dy_um:g} um")
    print(f"  Ra   {st.Ra_nm:10.1f} nm")
    print(f"  Sq   {st.Sq_nm:10.1f} nm")
    print(f"  Sdq  {st.Sdq:10.4f}")
    print(f"  h_r  {st.h_r:10.4f}   (facets in the zero-slope bin, 1e-3)")
    return 0


def _write_out(args: argparse.Namespace, make: Any) -> None:
    """``--out FILE.nc``: the prediction as a netCDF Dataset (units on every variable)."""
    if not args.out:
        return
    from goniolab.datasets import write_netcdf

    out = Path(args.out)
    if out.suffix.lower() not in (".nc", ".nc4"):
        raise UserError(f"--out {out}: a prediction is written as netCDF (.nc)")
    attrs = {"map": str(args.map), "n": _index_json(args.n), "weighting": args.weighting,
             "slope_method": args.slope_method, "masking": int(args.masking)}  # fmt: skip
    try:
        write_netcdf(make(attrs), out)
    except OSError as exc:
        raise UserError(f"cannot write {out}: {exc.strerror or exc}") from exc
    print(f"prediction written to {out}", file=sys.stderr)


def _cmd_gloss(args: argparse.Namespace) -> int:
    from goniolab.optics.gloss_standards import gloss_report

    rep = gloss_report(_model(args))
    from goniolab.datasets import gloss_dataset

    _write_out(args, lambda attrs: gloss_dataset(rep, attrs=attrs))
    e = rep.e430
    out: dict[str, Any] = {
        "map": str(args.map),
        "n": _index_json(args.n),
        "G20": rep.G20,
        "G60": rep.G60,
        "G85": rep.G85,
        "haze_index": rep.haze_index,
        "e430": rep.as_dict()["e430"],
        "d523_angle": rep.d523_recommended_angle,
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"{args.map} (n = {args.n.real:g}{f'+{args.n.imag:g}i' if args.n.imag else ''})")
    print(f"  gloss (ISO 2813)   G20 {rep.G20:6.1f}   G60 {rep.G60:6.1f}   G85 {rep.G85:6.1f} GU")
    print(f"  D523 geometry      {rep.d523_recommended_angle} deg")
    print(f"  haze index (D4039) {rep.haze_index:6.1f}")
    print(
        f"  E430 method B      gloss 20 {e.gloss_20:6.1f}   haze 18.1 {e.haze_18_1:6.2f}   "
        f"haze 21.9 {e.haze_21_9:6.2f}"
    )
    print(
        f"  E430 method A      Rs 30 {e.gloss_30:6.1f}   narrow haze {e.haze_narrow:6.2f}   "
        f"wide haze {e.haze_wide:6.2f}   DOI {e.doi:6.1f}"
    )
    return 0


def _projected_solid_angle_sr(detector: Cone, theta_r_deg: float) -> float:
    """int cos(theta) dOmega over the detector cone (above the horizon), in sr."""
    import numpy as np

    from goniolab.optics.apertures import inplane_centre, sample_aperture

    t, p = inplane_centre(theta_r_deg)
    dirs, w = sample_aperture(detector, t, p, n=32)
    return float(np.sum(np.clip(dirs[:, 2], 0.0, None) * w))


def _peak(tr: NDArray[np.float64], values: NDArray[np.float64]) -> PeakMetrics | None:
    """Peak metrics of the curve when the angles are >= 3 and strictly increasing."""
    import numpy as np

    from goniolab.optics.metrics import peak_metrics

    if tr.size < 3 or np.any(np.diff(tr) <= 0):
        return None
    return peak_metrics(tr, values)


def _cmd_brdf(args: argparse.Namespace) -> int:
    import numpy as np

    from goniolab.optics.apertures import Cone
    from goniolab.scan.plans import PlanError, parse_angles

    ti = float(args.theta_i)
    if not (math.isfinite(ti) and 0.0 <= ti < 90.0):
        raise UserError(f"--theta-i {args.theta_i}: must be in [0, 90) deg")
    try:
        tr = np.asarray(parse_angles(args.theta_r, name="--theta-r"), dtype=np.float64)
    except PlanError as exc:
        raise UserError(str(exc)) from None
    if np.any(np.abs(tr) >= 90.0):
        raise UserError(f"--theta-r {args.theta_r!r}: angles must be in (-90, 90) deg")
    if args.point and (args.detector_deg is not None or args.source_deg is not None):
        raise UserError("--point takes no --detector-deg/--source-deg (no aperture)")
    model = _model(args)
    out: dict[str, Any] = {"map": str(args.map), "n": _index_json(args.n), "theta_i_deg": ti}
    out["theta_r_deg"] = tr.tolist()
    if args.point:
        brdf = np.asarray(model.brdf_inplane(ti, tr), dtype=np.float64)
        out["brdf_sr"] = brdf.tolist()
        lum = None
    else:
        try:
            src = Cone(DEFAULT_CONE_DEG if args.source_deg is None else float(args.source_deg))
            det = Cone(DEFAULT_CONE_DEG if args.detector_deg is None else float(args.detector_deg))
        except ValueError as exc:
            raise UserError(f"--source-deg/--detector-deg: {exc}") from None
        if det.full_angle_deg == 0.0:
            raise UserError("--detector-deg 0 has no solid angle: use --point for the BRDF")
        try:
            lum = np.asarray(
                model.luminance_pct(ti, tr, source=src, detector=det), dtype=np.float64
            )
        except ValueError as exc:
            raise UserError(f"--theta-i {ti:g} / --source-deg: {exc}") from None
        omega = np.array([_projected_solid_angle_sr(det, float(t)) for t in tr])
        brdf = np.where(omega > 0, lum / 100.0 / np.where(omega > 0, omega, 1.0), 0.0)
        out["source_deg"] = src.full_angle_deg
        out["detector_deg"] = det.full_angle_deg
        out["brdf_sr"] = brdf.tolist()
        out["luminance_pct"] = lum.tolist()
    peak = _peak(tr, brdf if lum is None else lum)
    if peak is not None:
        out["peak"] = {
            "of": "brdf_sr" if lum is None else "luminance_pct",
            "amplitude": peak.amplitude,
            "position_deg": peak.position_deg,
            "fwhm_deg": None if math.isnan(peak.fwhm_deg) else peak.fwhm_deg,
        }
    from goniolab.datasets import brdf_dataset

    cones = {} if lum is None else {"source_cone_deg": out["source_deg"],
                                    "detector_cone_deg": out["detector_deg"]}  # fmt: skip
    _write_out(args, lambda attrs: brdf_dataset(ti, tr, brdf, lum, attrs={**attrs, **cones}))
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    head = f"{'theta_r':>8}  {'BRDF (1/sr)':>12}"
    print(head + (f"  {'luminance %':>12}" if lum is not None else ""))
    for k, t in enumerate(tr):
        line = f"{t:8.2f}  {brdf[k]:12.5g}"
        if lum is not None:
            line += f"  {lum[k]:12.5g}"
        print(line)
    if peak is not None:
        unit = "1/sr" if lum is None else "%"
        fwhm = (
            "outside the scanned range" if math.isnan(peak.fwhm_deg) else f"{peak.fwhm_deg:.3g} deg"
        )
        print(f"peak {peak.amplitude:.5g} {unit} at {peak.position_deg:.2f} deg, FWHM {fwhm}")
    return 0


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("map", metavar="MAP", help="height-map file or sample:NAME")
    p.add_argument(
        "--n",
        type=parse_index,
        default=complex(1.55),
        help="refractive index, or n+kj for metals, e.g. 0.27+3.41j (default 1.55)",
    )
    p.add_argument(
        "--step-um", type=float, default=None, help="lateral step for files that carry none"
    )
    p.add_argument("--slope-method", choices=("forward", "central", "plane8"), default="forward")
    p.add_argument(
        "--weighting",
        choices=("radiometric", "seed"),
        default="radiometric",
        help="facet weight: radiometric (docs/PHYSICS.md) or the seed's Fresnel-only",
    )
    p.add_argument("--masking", action="store_true", help="Smith masking from the slopes")
    p.add_argument("--json", action="store_true", help="machine-readable output")


def register(subparsers: Any) -> None:
    """Add ``goniolab predict`` and its sub-commands."""
    parser = subparsers.add_parser(
        "predict",
        help="roughness statistics, gloss and BRDF predicted from a height map",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    sub = parser.add_subparsers(dest="predict_command", metavar="WHAT", required=True)
    stats = sub.add_parser("stats", help="Ra, Sq, Sdq, h_r of the map")
    _add_common(stats)
    stats.set_defaults(func=_cmd_stats)
    gloss = sub.add_parser("gloss", help="ISO 2813 gloss, haze, DOI, D523 geometry")
    _add_common(gloss)
    gloss.add_argument("--out", metavar="FILE.nc", help="also write the prediction as netCDF")
    gloss.set_defaults(func=_cmd_gloss)
    brdf = sub.add_parser("brdf", help="in-plane BRDF and goniometer luminance")
    _add_common(brdf)
    brdf.add_argument("--theta-i", type=float, default=45.0, help="lamp angle, deg (default 45)")
    brdf.add_argument(
        "--theta-r",
        default="0:70:1",
        help="detector angles: start:stop:step (stop included) or a comma list, e.g. "
        "-20:20:1 (default 0:70:1)",
    )
    brdf.add_argument("--source-deg", type=float, default=None, help="lamp cone, full angle")
    brdf.add_argument("--detector-deg", type=float, default=None, help="detector cone, full angle")
    brdf.add_argument("--point", action="store_true", help="BRDF in the exact direction")
    brdf.add_argument("--out", metavar="FILE.nc", help="also write the curve as netCDF")
    allow_negative_angles(brdf)  # "--theta-r -20:20:1" is a range, not an option
    brdf.set_defaults(func=_cmd_brdf)
