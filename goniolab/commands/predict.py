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
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from goniolab.commands._angles import allow_negative_angles
from goniolab.errors import UserError
from goniolab.model_registry import DEFAULT_MODEL, model_help, model_names

if TYPE_CHECKING:  # numpy and the optics load when a command runs, not at --help
    import numpy as np
    from numpy.typing import NDArray

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


class _Progress:
    """Progress on stderr for model work that runs over ~2 s (only on a terminal)."""

    def __init__(self) -> None:
        self.start = time.monotonic()
        self.shown = False

    def __call__(self, done: int, total: int, what: str) -> None:
        if not sys.stderr.isatty() or time.monotonic() - self.start < 2.0:
            return
        self.shown = True
        end = "\n" if done >= total else ""
        print(
            f"\r{what}: {100 * done // max(total, 1):3d} % ({done}/{total})",
            end=end,
            file=sys.stderr,
            flush=True,
        )


def _is_a(obj: Any, module: str, name: str) -> bool:
    """``isinstance(obj, module.name)`` without importing ``module``: no instance of a class
    exists before its module is loaded (the physical-optics modules import numba)."""
    mod = sys.modules.get(module)
    return mod is not None and isinstance(obj, getattr(mod, name))


def _is_physical(obj: Any) -> bool:
    return _is_a(obj, "goniolab.optics.physical", "PhysicalOpticsModel")


def _is_auto(obj: Any) -> bool:
    return _is_a(obj, "goniolab.optics.model_choice", "AutoModel")


def _model(args: argparse.Namespace) -> Any:
    from goniolab.model_cache import model_for

    if args.wavelength_nm is not None and not (
        math.isfinite(args.wavelength_nm) and 100.0 <= args.wavelength_nm <= 20000.0
    ):
        raise UserError(f"--wavelength-nm {args.wavelength_nm:g}: must be in [100, 20000] nm")
    model = model_for(
        args.map,
        n=args.n,
        step_um=args.step_um,
        slope_method=args.slope_method,
        weighting=args.weighting,
        masking=args.masking,
        model=args.model,
        wavelength_nm=args.wavelength_nm,
        # one command, one process: the facet model without numba's ~1 s of import and
        # set-up (the physical-optics models compile theirs)
        backend="lean" if args.model == "facet" else "numba",
    )
    progress = _Progress()
    parts: tuple[Any, ...] = (
        model,
        getattr(model, "kirchhoff", None),
        getattr(model, "rayleigh_rice", None),
    )
    for m in parts:
        if _is_physical(m):
            m.progress = progress
    return model


#: The cause named when a prediction (not the map) is not finite.
_MODEL_OVERFLOW = "the model overflowed double precision for this map; check its z unit and step"


def _require_finite(spec: str, out: dict[str, Any], cause: str) -> None:
    """A non-finite number in a result is an error naming the key and the cause, not
    ``Infinity`` or ``NaN`` in the output (not valid JSON) with exit 0."""

    def walk(value: Any, key: str) -> None:
        if isinstance(value, float) and not math.isfinite(value):
            raise UserError(f"{spec}: {key} = {value} is not finite: {cause}")
        if isinstance(value, dict):
            for k, v in value.items():
                walk(v, f"{key}.{k}" if key else str(k))
        elif isinstance(value, list | tuple):
            for i, v in enumerate(value):
                walk(v, f"{key}[{i}]")

    walk(out, "")


def _model_name(model: Any) -> str:
    kind = getattr(model, "kind", None)
    return kind if isinstance(kind, str) and kind in model_names() else "facet"


def _gloss_models(model: Any, rep: Any) -> tuple[dict[str, Any], dict[str, Any], list[str]]:
    """Per reading, the model that computed it (``GlossReport.models``: G20/G60/G85 and
    ``e430.<field>``), the facet hand-overs and the notes, for --json, netCDF and stderr;
    with ``auto`` the rule's choice per geometry under ``"rule"``."""
    from goniolab.optics import gloss_standards as gs

    names: dict[str, Any] = dict(rep.models)
    fb: dict[str, Any] = {}
    if _is_auto(model):
        rule = {t: model.choice(t) for t in (20, 60, 85)}
        names["rule"] = {f"G{t}": {"model": c.model, "g": c.g, "reason": c.reason}
                         for t, c in rule.items()}  # fmt: skip
        chosen = {f"G{t}": c.model for t, c in rule.items()}
        method_b = ("e430.gloss_20", "e430.haze_18_1", "e430.haze_21_9", "e430.haze_b")
        for key in rep.models:
            if key.startswith("e430."):
                t_e = gs.E430_B_ANGLE_DEG if key in method_b else gs.E430_A_ANGLE_DEG
                chosen[key] = model.choice(t_e).model
    else:
        chosen = dict.fromkeys(rep.models, _model_name(model))
    for key, name in rep.models.items():
        if name == "facet" and chosen.get(key) != "facet":
            why = [w for w in rep.warnings if w.startswith(f"{key}: ")]
            fb[key] = why[-1].split(": ", 1)[1] if why else "facet model"
    return names, fb, list(rep.warnings)


def _warn(warnings: list[str]) -> None:
    """The notes of a prediction on stderr, one line each (the same text as --json's)."""
    for w in dict.fromkeys(warnings):
        print(f"goniolab: warning: {w}", file=sys.stderr)


def _curve_models(
    model: Any, ti: float, tr: NDArray[np.float64], src: Any, det: Any
) -> tuple[Any, list[str], dict[str, str], list[str]]:
    """For a curve at theta_i: ``"model"`` (auto: the rule's choice, g and reason), the
    model that computed each angle, the facet hand-overs and the notes (each note once,
    with the angles it concerns)."""
    from goniolab.optics.provenance import model_label, provenance_of

    name: Any = _model_name(model)
    if _is_auto(model):
        ch = model.choice(ti)
        name = {"auto": ch.model, "g": ch.g, "reason": ch.reason}
    chosen = name["auto"] if isinstance(name, dict) else name
    per: list[str] = []
    fb: dict[str, str] = {}
    by_note: dict[str, list[str]] = {}
    if not (_is_auto(model) or _is_physical(model)):
        return name, [model_label(model)] * tr.size, fb, []
    for t in tr:
        prov = provenance_of(model, ti, float(t), src, det)
        per.append(prov.model)
        for note in prov.notes:
            by_note.setdefault(note, []).append(f"{float(t):g}")
        if prov.model == "facet" and chosen != "facet":
            fb[f"{float(t):g}"] = prov.notes[-1] if prov.notes else "facet model"
    warnings = [f"theta_r {', '.join(a)} deg: {note}" for note, a in by_note.items()]
    return name, per, fb, warnings


def _cmd_stats(args: argparse.Namespace) -> int:
    import numpy as np

    from goniolab.optics.surface import roughness_stats
    from goniolab.surfaces.resolve import resolve_map

    hm = resolve_map(args.map, step_um=args.step_um)
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is checked below
            st = roughness_stats(hm, slope_method=args.slope_method)
    except ValueError as exc:
        raise UserError(f"{args.map}: {exc}") from None
    with np.errstate(invalid="ignore"):
        z_max = float(np.nanmax(np.abs(hm.z_um))) if np.isfinite(hm.z_um).any() else math.nan
    overflow = (
        f"heights up to {z_max:.3g} um (steps {hm.dx_um:g} x {hm.dy_um:g} um) overflow double "
        "precision; check the map's z unit and step"
    )
    _require_finite(args.map, {"Sq_nm": st.Sq_nm, "Sdq": st.Sdq, "Ra_nm": st.Ra_nm}, overflow)
    regime: dict[str, Any] = {}
    try:
        from goniolab.optics.model_choice import choose_model
        from goniolab.optics.shared_map import SharedMap

        ms = SharedMap(hm, 1024, 0.25).stats
        lam = 550.0 if args.wavelength_nm is None else float(args.wavelength_nm)
        for t in (20, 60, 85):
            regime[f"{t}"] = choose_model(ms, t, lam).as_dict()
    except ValueError as exc:
        regime = {"error": str(exc)}
    out = {
        "map": str(args.map),
        "Ra_nm": st.Ra_nm,
        "Sq_nm": st.Sq_nm,
        "Sdq": st.Sdq,
        "h_r": st.h_r,
        "slope_rms_x": st.slope_rms_x,
        "slope_rms_y": st.slope_rms_y,
        "n_facets": st.n_facets,
        "regime": regime,
    }
    _require_finite(args.map, out, overflow)
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=False))
        return 0
    ny, nx = hm.shape
    print(f"{args.map}: {nx} x {ny} points at {hm.dx_um:g} x {hm.dy_um:g} um")
    print(f"  Ra   {st.Ra_nm:10.1f} nm")
    print(f"  Sq   {st.Sq_nm:10.1f} nm")
    print(f"  Sdq  {st.Sdq:10.4f}")
    print(
        f"  h_r  {st.h_r:10.4f}   (fraction of facets in the slope histogram's zero bin, "
        "|p|, |q| < 5e-4; Wittmann sec. 3.1: the higher, the glossier)"
    )
    for t_key, ch in regime.items():
        if isinstance(ch, dict):
            print(f"  {t_key:>2} deg: {ch['model']:<13} ({ch['reason']})")
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
             "slope_method": args.slope_method, "masking": int(args.masking),
             "model": args.model}  # fmt: skip
    if args.wavelength_nm is not None:
        attrs["wavelength_nm"] = float(args.wavelength_nm)
    try:
        write_netcdf(make(attrs), out)
    except OSError as exc:
        raise UserError(f"cannot write {out}: {exc.strerror or exc}") from exc
    print(f"prediction written to {out}", file=sys.stderr)


def _cmd_gloss(args: argparse.Namespace) -> int:
    if len(args.map) > 1 or args.scheduler:
        return _cmd_gloss_batch(args)
    args.map = args.map[0]
    from goniolab.optics.gloss_standards import gloss_report

    model = _model(args)
    try:
        rep = gloss_report(model)
    except ValueError as exc:
        raise UserError(f"{args.map}: {exc}") from None
    _require_finite(args.map, rep.as_dict(), _MODEL_OVERFLOW)
    from goniolab.datasets import gloss_dataset

    names, fallback, warnings = _gloss_models(model, rep)
    computed_by = {k: v for k, v in names.items() if isinstance(v, str)}
    e430_names = {
        k.removeprefix("e430."): names.pop(k) for k in list(names) if k.startswith("e430.")
    }
    prov_attrs = {"computed_by": json.dumps(computed_by), "warnings": json.dumps(warnings)}
    _write_out(args, lambda attrs: gloss_dataset(rep, attrs={**attrs, **prov_attrs}))
    _warn(warnings)
    e = rep.e430
    out: dict[str, Any] = {
        "map": str(args.map),
        "n": _index_json(args.n),
        "model": names,
        "wavelength_nm": (
            args.wavelength_nm if args.wavelength_nm is not None else "ISO 2813 C x V"
        ),
        "G20": rep.G20,
        "G60": rep.G60,
        "G85": rep.G85,
        "haze_index": rep.haze_index,
        "e430": rep.as_dict()["e430"],
        "e430_model": e430_names,
        "d523_angle": rep.d523_recommended_angle,
    }
    if fallback:
        out["fallback"] = fallback
    if warnings:
        out["warnings"] = warnings
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=False))
        return 0
    print(f"{args.map} (n = {args.n.real:g}{f'+{args.n.imag:g}i' if args.n.imag else ''})")
    print(_gloss_table(rep, names, e430_names))
    if e.doi < 0:
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
    from goniolab.batch import GlossOptions, run_dask, run_local

    if args.out:
        raise UserError("--out writes one map's prediction: give a single MAP")
    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs {args.jobs}: must be >= 1")
    opts = GlossOptions(
        n=args.n,
        step_um=args.step_um,
        slope_method=args.slope_method,
        weighting=args.weighting,
        masking=args.masking,
        model=args.model,
        wavelength_nm=args.wavelength_nm,
    )
    maps = [str(m) for m in args.map]
    rows = (
        run_dask(maps, opts, address=args.scheduler)
        if args.scheduler
        else run_local(maps, opts, jobs=args.jobs)
    )
    failed = 0
    with _progress(len(maps)) as bar:
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
        print(f"goniolab: {failed} of {len(maps)} maps failed", file=sys.stderr)
        return 2
    return 0


class _BatchBar:
    """The batch's progress: a rich bar drawn on stderr, messages scrolled above it.

    The bar never touches stdout: rich's ``Progress`` redirects ``sys.stdout`` into its own
    console by default (``redirect_stdout=True``), so with the console on stderr every row
    printed while the bar was live went to the terminal and ``--json > file`` stayed empty
    (issue 22.3). Here both redirections are off and messages go through the bar's console.
    """

    def __init__(self, progress: Any = None, task: Any = None) -> None:
        self._progress = progress
        self._task = task

    def advance(self) -> None:
        if self._progress is not None:
            self._progress.advance(self._task)

    def message(self, text: str) -> None:
        if self._progress is not None:
            self._progress.console.print(text, markup=False, highlight=False, soft_wrap=True)
        else:
            print(text, file=sys.stderr, flush=True)


def _progress(total: int) -> Any:
    """A rich progress bar on stderr while a terminal watches (nothing otherwise)."""
    from contextlib import contextmanager

    @contextmanager
    def bar() -> Any:
        if not sys.stderr.isatty():
            yield _BatchBar()
            return
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

        with Progress(
            "[progress.description]{task.description}",
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
            console=Console(stderr=True),
            transient=True,
            redirect_stdout=False,
            redirect_stderr=False,
        ) as progress:
            task = progress.add_task("gloss", total=total)
            yield _BatchBar(progress, task)

    return bar()


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
    if args.wavelength_nm is not None:
        out["wavelength_nm"] = args.wavelength_nm
    out["theta_r_deg"] = tr.tolist()
    if args.point:
        from goniolab.optics.apertures import Rect
        from goniolab.optics.physical import POINT_BRDF_BOX_DEG

        box = Rect(POINT_BRDF_BOX_DEG, POINT_BRDF_BOX_DEG)
        out["model"], per, fb, warnings = _curve_models(model, ti, tr, Rect(0.0, 0.0), box)
        try:
            brdf = np.asarray(model.brdf_inplane(ti, tr), dtype=np.float64)
        except ValueError as exc:
            raise UserError(f"--theta-i {ti:g}: {exc}") from None
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
        out["model"], per, fb, warnings = _curve_models(model, ti, tr, src, det)
        try:
            lum = np.asarray(
                model.luminance_pct(ti, tr, source=src, detector=det), dtype=np.float64
            )
        except ValueError as exc:
            raise UserError(f"--theta-i {ti:g} / --source-deg: {exc}") from None
        from goniolab.optics.apertures import projected_solid_angle_sr

        omega = np.array([projected_solid_angle_sr(det, float(t)) for t in tr])
        brdf = np.where(omega > 0, lum / 100.0 / np.where(omega > 0, omega, 1.0), 0.0)
        out["source_deg"] = src.full_angle_deg
        out["detector_deg"] = det.full_angle_deg
        out["brdf_sr"] = brdf.tolist()
        out["luminance_pct"] = lum.tolist()
    out["models"] = per  # the model that computed each angle
    if fb:
        out["fallback"] = fb
    if warnings:
        out["warnings"] = warnings
    _warn(warnings)
    curve = brdf if lum is None else lum
    peak = _peak(tr, curve)
    fwhm_note = ""
    if peak is not None:
        fwhm: float | None = None if math.isnan(peak.fwhm_deg) else peak.fwhm_deg
        if math.isnan(peak.fwhm_deg):
            fwhm_note = "outside the scanned range"
        elif int(np.sum(curve >= peak.amplitude / 2.0)) < 2:
            # one sample above half maximum: the "width" is the grid's, not the curve's
            fwhm, fwhm_note = None, "not resolved by this angle grid (use a finer --theta-r)"
        out["peak"] = {
            "of": "brdf_sr" if lum is None else "luminance_pct",
            "amplitude": peak.amplitude,
            "position_deg": peak.position_deg,
            "fwhm_deg": fwhm,
        }
        if fwhm_note:
            out["peak"]["fwhm_note"] = fwhm_note
    _require_finite(args.map, out, _MODEL_OVERFLOW)
    from goniolab.datasets import brdf_dataset

    cones: dict[str, Any] = {} if lum is None else {"source_cone_deg": out["source_deg"],
                                    "detector_cone_deg": out["detector_deg"]}  # fmt: skip
    cones["computed_by"] = json.dumps(per)
    cones["warnings"] = json.dumps(warnings)
    _write_out(args, lambda attrs: brdf_dataset(ti, tr, brdf, lum, attrs={**attrs, **cones}))
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=False))
        return 0
    head = f"{'theta_r':>8}  {'BRDF (1/sr)':>12}"
    print(head + (f"  {'luminance %':>12}" if lum is not None else "") + "  model")
    for k, t in enumerate(tr):
        line = f"{t:8.2f}  {brdf[k]:12.5g}"
        if lum is not None:
            line += f"  {lum[k]:12.5g}"
        print(f"{line}  {per[k]}")
    if peak is not None:
        unit = "1/sr" if lum is None else "%"
        width = fwhm_note or f"{peak.fwhm_deg:.3g} deg"
        print(f"peak {peak.amplitude:.5g} {unit} at {peak.position_deg:.2f} deg, FWHM {width}")
    return 0


def _cmd_albedo(args: argparse.Namespace) -> int:
    """Directional-hemispherical reflectance and TIS per incidence (issue 20)."""
    from goniolab.optics.fresnel import fresnel
    from goniolab.optics.provenance import Provenance
    from goniolab.scan.plans import PlanError, parse_angles

    try:
        angles = [float(a) for a in parse_angles(args.theta_i, name="--theta-i")]
    except PlanError as exc:
        raise UserError(str(exc)) from None
    bad = [a for a in angles if not (math.isfinite(a) and 0.0 <= a <= 89.0)]
    if bad or not angles:
        raise UserError(f"--theta-i {args.theta_i!r}: angles must be in [0, 89] deg")
    model = _model(args)
    lam = 550.0 if args.wavelength_nm is None else float(args.wavelength_nm)
    albedo: list[float] = []
    tis: list[float] = []
    names: list[str] = []
    warnings: list[str] = []
    for ti in angles:
        try:
            if hasattr(model, "albedo_tis"):
                a, t, prov = model.albedo_tis(ti)
            else:  # the facet model: all of its light is diffuse
                a = float(model.brdf_hemisphere(ti).albedo)
                t, prov = a, Provenance(_model_name(model))
        except ValueError as exc:
            raise UserError(f"--theta-i {ti:g}: {exc}") from None
        albedo.append(float(a))
        tis.append(float(t))
        names.append(prov.model)
        warnings.extend(f"theta_i {ti:g} deg: {note}" for note in prov.notes)
    fres = [float(fresnel(math.cos(math.radians(t)), args.n)) for t in angles]
    out: dict[str, Any] = {
        "map": str(args.map),
        "n": _index_json(args.n),
        "wavelength_nm": lam,
        "theta_i_deg": angles,
        "albedo": albedo,
        "tis": tis,
        "fresnel": fres,
        "model": names,
    }
    if warnings:
        out["warnings"] = warnings
    _require_finite(args.map, out, _MODEL_OVERFLOW)
    _warn(warnings)
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=False))
        return 0
    print(f"{args.map} (n = {args.n.real:g}{f'+{args.n.imag:g}i' if args.n.imag else ''}, "
          f"{lam:g} nm, collimated beam)")  # fmt: skip
    print(f"{'theta_i':>8}  {'albedo':>9}  {'TIS':>9}  {'Fresnel R':>9}  model")
    for ti, a, t, f, name in zip(angles, albedo, tis, fres, names, strict=True):
        print(f"{ti:8.2f}  {a:9.5f}  {t:9.5f}  {f:9.5f}  {name}")
    print(
        "albedo: directional-hemispherical reflectance (coherent beam + diffuse light the map "
        "resolves); TIS: the diffuse part over the incident flux (ISO 13696)"
    )
    return 0


def _add_common(p: argparse.ArgumentParser, *, many: bool = False) -> None:
    if many:
        p.add_argument("map", metavar="MAP", nargs="+", help="height-map files or sample:NAME")
    else:
        p.add_argument("map", metavar="MAP", help="height-map file or sample:NAME")
    p.add_argument(
        "--n",
        type=parse_index,
        default=complex(1.55),
        help="refractive index, or n+kj for metals, e.g. 0.27+3.41j",
    )
    p.add_argument(
        "--step-um", type=float, default=None, help="lateral step, um, of a file that carries none"
    )
    p.add_argument(
        "--slope-method",
        choices=("forward", "central", "plane8"),
        default="forward",
        help="facet slopes from the map: forward differences (the seed's), central "
        "differences, or the least-squares plane through 3 x 3 points (smooths pixel noise)",
    )
    p.add_argument(
        "--weighting",
        choices=("radiometric", "seed"),
        default="radiometric",
        help="facet weight: radiometric (docs/PHYSICS.md) or the seed's Fresnel-only",
    )
    p.add_argument(
        "--masking",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="Smith masking-shadowing from the measured slopes (default: on)",
    )
    p.add_argument(
        "--model",
        choices=model_names(),
        default=DEFAULT_MODEL,
        help=model_help(),
    )
    p.add_argument(
        "--wavelength-nm",
        type=float,
        default=None,
        help="wavelength of every response (default: gloss weighted over CIE C x V(lambda), "
        "BRDFs at 550 nm)",
    )
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
    gloss = sub.add_parser(
        "gloss",
        help="ISO 2813 gloss, haze, DOI, D523 geometry (several maps: in parallel, JSON Lines)",
    )
    _add_common(gloss, many=True)
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
    _add_common(brdf)
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
    _add_common(albedo)
    albedo.add_argument(
        "--theta-i",
        default="0,30,60,85",
        help="incidence (lamp) angles, deg, each <= 89: a comma list or start:stop:step",
    )
    albedo.set_defaults(func=_cmd_albedo)
    from goniolab.commands._colour import register_predict_colour

    register_predict_colour(sub, _add_common)
