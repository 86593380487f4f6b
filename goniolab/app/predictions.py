"""Predict the roughness, BRDF, gloss and albedo of a surface: the use cases of
``goniolab predict`` and of the notebook's :func:`goniolab.api.predict_brdf` /
:func:`~goniolab.api.predict_gloss` (issue 24: one use case under every face).

A surface is a height-map file, ``sample:NAME`` (:func:`goniolab.surfaces.resolve_map`), a
:class:`~goniolab.optics.heightmap.HeightMap` or a :func:`goniolab.api.load_surface`
DataArray (:func:`heightmap_of`). :func:`surface_model` chooses and builds its reflectance
model (the one way: :func:`goniolab.model_cache.model_for`); each prediction returns a typed
result that carries its provenance: the model that computed each number, the hand-overs to
the facet model and every note (validity limits, light the map cannot resolve, energy
scales; :mod:`goniolab.optics.provenance`). ``as_dict()`` of a result is the document
``goniolab predict ... --json`` prints. A face that runs an event loop calls the ``*_async``
variants, which compute in a worker thread.

Messages name the inputs as the face calls them (:class:`OptionNames`: ``--theta-i`` on the
command line, ``theta_i_deg`` in the notebook). The module is named ``predictions``: a
module name is used once in the tree, ``goniolab/commands/predict.py`` is the CLI's face.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ParamSpec, TypeVar

import numpy as np

from goniolab.errors import UserError
from goniolab.model_registry import DEFAULT_MODEL, model_names

if TYPE_CHECKING:  # the optics load when a prediction runs
    P = ParamSpec("P")
    R = TypeVar("R")
    from numpy.typing import NDArray

    from goniolab.optics.gloss_standards import GlossReport
    from goniolab.optics.heightmap import HeightMap
    from goniolab.optics.models import ReflectanceModel

__all__ = [
    "API_NAMES",
    "CLI_NAMES",
    "DEFAULT_CONE_DEG",
    "MODEL_OVERFLOW",
    "AlbedoPrediction",
    "BrdfPrediction",
    "GlossPrediction",
    "OptionNames",
    "SurfaceRequest",
    "SurfaceStats",
    "heightmap_of",
    "index_json",
    "parse_angle_list",
    "predict_albedo",
    "predict_brdf",
    "predict_brdf_async",
    "predict_gloss",
    "predict_gloss_async",
    "predict_gloss_batch",
    "require_finite",
    "surface_model",
    "surface_stats",
]

#: Default source and detector cones of the Wittmann goniometer (sec. 2.3), full angles.
DEFAULT_CONE_DEG = 6.0

#: The cause named when a prediction (not the map) is not finite.
MODEL_OVERFLOW = "the model overflowed double precision for this map; check its z unit and step"

#: Progress of long model work: ``(done, total, what)``.
Progress = Callable[[int, int, str], None]


@dataclass(frozen=True)
class OptionNames:
    """How a face names each input in its messages."""

    theta_i: str = "--theta-i"
    theta_r: str = "--theta-r"
    source: str = "--source-deg"
    detector: str = "--detector-deg"
    point: str = "--point"
    wavelength: str = "--wavelength-nm"


#: The command line's names (``goniolab predict``).
CLI_NAMES = OptionNames()
#: The notebook API's keyword arguments (:mod:`goniolab.api`).
API_NAMES = OptionNames(
    "theta_i_deg", "theta_r_deg", "source_deg", "detector_deg", "point=True", "wavelength_nm"
)


def index_json(n: complex) -> float | list[float]:
    """A refractive index as JSON: ``n`` when real, ``[n, k]`` for a conductor."""
    return n.real if n.imag == 0 else [n.real, n.imag]


# --------------------------------------------------------------------------- surfaces
#: Relative tolerance between a DataArray's coordinate steps and its dx_um/dy_um attributes
#: (and between its own steps: the grid must be regular).
_STEP_RTOL = 1e-6


def heightmap_of(surface: Any, step_um: float | None = None) -> HeightMap:
    """The height map of a path, ``sample:NAME``, a HeightMap or a ``(y_um, x_um)``
    DataArray of :func:`goniolab.api.load_surface`."""
    from goniolab.optics.heightmap import HeightMap
    from goniolab.surfaces.resolve import resolve_map

    if isinstance(surface, HeightMap):
        return surface
    if isinstance(surface, str | Path):
        return resolve_map(surface, step_um=step_um)
    attrs = getattr(surface, "attrs", None)
    if attrs is not None and getattr(surface, "ndim", 0) == 2:
        return _dataarray_heightmap(surface)
    raise UserError(
        f"surface: expected a file path, sample:NAME or a load_surface() DataArray, "
        f"got {type(surface).__name__}"
    )


def _coordinate_step(da: Any, dim: str, attr: str) -> float:
    """The lateral step along ``dim``: its coordinates' spacing, checked regular and
    against the ``attr`` attribute when both exist.

    After ``z.isel(x_um=slice(None, None, 2))`` or ``z.coarsen(x_um=2).mean()`` xarray keeps
    the attributes (``dx_um = 1``) while the coordinates step by 2: the step from the
    attribute silently gave the gloss of a map twice as steep (issue 22.10). The
    coordinates are what xarray keeps right, so they decide; a disagreeing attribute is
    refused rather than guessed over.
    """
    name = f"surface DataArray: {dim}"
    given = da.attrs.get(attr)
    coord = da.coords.get(dim)
    if coord is None or coord.size < 2:
        if given is None:
            raise UserError(f"{name}: no coordinates and no {attr} attribute (use load_surface)")
        step = float(given)
    else:
        diffs = np.diff(np.asarray(coord.values, dtype=np.float64))
        step = float(np.mean(diffs))
        if not (math.isfinite(step) and step > 0):
            raise UserError(f"{name}: coordinates must increase (mean step {step:g} um)")
        if float(np.max(np.abs(diffs - step))) > _STEP_RTOL * step:
            raise UserError(
                f"{name}: coordinates are not evenly spaced (steps {float(diffs.min()):g} to "
                f"{float(diffs.max()):g} um): a height map needs a regular grid"
            )
        if given is not None and abs(float(given) - step) > _STEP_RTOL * step:
            raise UserError(
                f"{name}: coordinates step by {step:g} um but attrs['{attr}'] = {float(given):g}"
                f" (after isel/coarsen/interp xarray keeps the old attribute): set "
                f"attrs['{attr}'] = {step:g} or delete it"
            )
    if not (math.isfinite(step) and step > 0):
        raise UserError(f"{name}: step {step:g} um must be positive")
    return step


def _dataarray_heightmap(da: Any) -> HeightMap:
    from goniolab.optics.heightmap import HeightMap

    dims = tuple(da.dims)
    if set(dims) == {"y_um", "x_um"} and dims != ("y_um", "x_um"):
        da = da.transpose("y_um", "x_um")  # rows are y, whatever order the user left
    elif dims != ("y_um", "x_um"):
        raise UserError(f"surface DataArray: dims {dims}, expected ('y_um', 'x_um')")
    try:
        return HeightMap(
            np.asarray(da.values, dtype=np.float64),
            _coordinate_step(da, "x_um", "dx_um"),
            _coordinate_step(da, "y_um", "dy_um"),
            source=str(da.attrs.get("source", "<DataArray>")),
        )
    except ValueError as exc:
        raise UserError(f"surface DataArray: {exc}") from None


@dataclass(frozen=True)
class SurfaceRequest:
    """A surface and how to model it: the options every prediction shares.

    ``model``: a name of :mod:`goniolab.model_registry` (``auto``: the regime rule per
    geometry); ``wavelength_nm``: the wave models' wavelength (``None``: gloss weighted
    over CIE C x V(lambda), BRDFs at 550 nm).
    """

    surface: Any
    n: complex = complex(1.55)
    step_um: float | None = None
    slope_method: str = "forward"
    weighting: str = "radiometric"
    masking: bool = True
    model: str = DEFAULT_MODEL
    wavelength_nm: float | None = None

    @property
    def label(self) -> str:
        """How results name the surface: the path or ``sample:NAME``, else the map's source."""
        s = self.surface
        if isinstance(s, str | Path):
            return str(s)
        return str(getattr(s, "attrs", {}).get("source", getattr(s, "source", "")))


def _is_a(obj: Any, module: str, name: str) -> bool:
    """``isinstance(obj, module.name)`` without importing ``module``: no instance of a class
    exists before its module is loaded (the physical-optics modules import numba)."""
    import sys

    mod = sys.modules.get(module)
    return mod is not None and isinstance(obj, getattr(mod, name))


def _is_physical(obj: Any) -> bool:
    return _is_a(obj, "goniolab.optics.physical", "PhysicalOpticsModel")


def _is_auto(obj: Any) -> bool:
    return _is_a(obj, "goniolab.optics.model_choice", "AutoModel")


def surface_model(
    req: SurfaceRequest,
    *,
    names: OptionNames = CLI_NAMES,
    progress: Progress | None = None,
) -> ReflectanceModel:
    """The reflectance model of ``req`` (:func:`goniolab.model_cache.model_for`).

    Every face gets the same model: the facet model on its slope cells (``backend="lean"``,
    the default of :func:`goniolab.model_cache.model_for`), so the CLI and the notebook print
    the same numbers (the notebook's per-pixel numba kernels differed by 0.3 %).
    ``progress`` is told of the physical-optics models' long work.
    """
    from goniolab.model_cache import model_for

    wl = req.wavelength_nm
    if wl is not None and not (math.isfinite(wl) and 100.0 <= wl <= 20000.0):
        raise UserError(f"{names.wavelength} {wl:g}: must be in [100, 20000] nm")
    options: dict[str, Any] = {
        "n": req.n,
        "slope_method": req.slope_method,
        "weighting": req.weighting,
        "masking": req.masking,
        "model": req.model,
        "wavelength_nm": wl,
    }
    if isinstance(req.surface, str | Path):
        model = model_for(req.surface, step_um=req.step_um, **options)
    else:
        model = model_for(heightmap_of(req.surface, req.step_um), **options)
    if progress is not None and (_is_physical(model) or _is_auto(model)):
        # auto passes it on to the wave models it builds (reading its .kirchhoff here built
        # both wave models, and imported their modules, for a map it sends to facets) and
        # to its facet model
        model.progress = progress  # type: ignore[attr-defined]
    elif progress is not None and _is_a(
        getattr(model, "surface", None), "goniolab.optics.surface", "MapSurface"
    ):
        # --model facet: the same display (a large map's walks over its slopes report)
        model.surface.progress = progress  # type: ignore[attr-defined]
    return model


def parse_angle_list(spec: str | Sequence[float] | NDArray[np.float64], name: str) -> NDArray[Any]:
    """Angles from ``start:stop:step`` (stop included), ``a,b,c`` or a sequence, degrees
    (:func:`goniolab.scan.angle_lists.parse_angles`); ``name`` names the input in the error."""
    from goniolab.scan.angle_lists import PlanError, parse_angles

    given = spec if isinstance(spec, str) else [float(v) for v in spec]
    try:
        return np.asarray(parse_angles(given, name=name), dtype=np.float64)
    except PlanError as exc:
        raise UserError(str(exc)) from None


def _non_finite_is_user_error(fn: Callable[P, R]) -> Callable[P, R]:
    """The energy check's ``NonFiniteEnergySums`` as the overflow error; others pass."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            return fn(*args, **kwargs)
        except FloatingPointError as exc:
            from goniolab.optics.energy_budget import NonFiniteEnergySums

            if not isinstance(exc, NonFiniteEnergySums):
                raise
            label = getattr(args[0] if args else kwargs.get("req"), "label", "the surface")
            raise UserError(f"{label}: {exc}: {MODEL_OVERFLOW}") from exc

    return wrapper


def require_finite(spec: str, doc: dict[str, Any], cause: str) -> None:
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

    walk(doc, "")


def _model_name(model: Any) -> str:
    kind = getattr(model, "kind", None)
    return kind if isinstance(kind, str) and kind in model_names() else "facet"


def _model_kind(model: Any) -> str:
    """:func:`goniolab.scan.prediction.model_name` of ``model`` (its :func:`model_for` name,
    else ``facet`` for a facet model, else its class name), without importing the scan
    layer (its config and store cost a ``predict`` process about 0.1 s)."""
    kind = getattr(model, "kind", None)
    if isinstance(kind, str) and kind in model_names():
        return kind
    return "facet" if _is_a(model, "goniolab.optics.facet", "FacetModel") else type(model).__name__


# --------------------------------------------------------------------------- stats
@dataclass(frozen=True)
class SurfaceStats:
    """``predict stats``: the roughness statistics and, per ISO geometry, the regime rule's
    model (``doc`` is the ``--json`` document); the map's shape and steps."""

    doc: dict[str, Any]
    shape: tuple[int, int]
    dx_um: float
    dy_um: float


def surface_stats(req: SurfaceRequest) -> SurfaceStats:
    """Ra, Sq, Sdq, the zero-slope fraction h_r (Wittmann sec. 3.1) and the model the
    regime rule (:mod:`goniolab.optics.model_choice`) picks at 20, 60 and 85 deg."""
    from goniolab.optics.surface import roughness_stats

    hm = heightmap_of(req.surface, req.step_um)
    label = req.label
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is checked below
            st = roughness_stats(hm, slope_method=req.slope_method)  # type: ignore[arg-type]
    except ValueError as exc:
        raise UserError(f"{label}: {exc}") from None
    with np.errstate(invalid="ignore"):
        z_max = float(np.nanmax(np.abs(hm.z_um))) if np.isfinite(hm.z_um).any() else math.nan
    overflow = (
        f"heights up to {z_max:.3g} um (steps {hm.dx_um:g} x {hm.dy_um:g} um) overflow double "
        "precision; check the map's z unit and step"
    )
    require_finite(label, {"Sq_nm": st.Sq_nm, "Sdq": st.Sdq, "Ra_nm": st.Ra_nm}, overflow)
    regime: dict[str, Any] = {}
    try:
        from goniolab.optics.model_choice import choose_model
        from goniolab.optics.shared_map import SharedMap

        ms = SharedMap(hm, 1024, 0.25).stats
        lam = 550.0 if req.wavelength_nm is None else float(req.wavelength_nm)
        for t in (20, 60, 85):
            regime[f"{t}"] = choose_model(ms, t, lam).as_dict()
    except ValueError as exc:
        regime = {"error": str(exc)}
    doc = {
        "map": label,
        "Ra_nm": st.Ra_nm,
        "Sq_nm": st.Sq_nm,
        "Sdq": st.Sdq,
        "h_r": st.h_r,
        "slope_rms_x": st.slope_rms_x,
        "slope_rms_y": st.slope_rms_y,
        "n_facets": st.n_facets,
        "regime": regime,
    }
    require_finite(label, doc, overflow)
    ny, nx = hm.shape
    return SurfaceStats(doc, (ny, nx), hm.dx_um, hm.dy_um)


# --------------------------------------------------------------------------- gloss
@dataclass(frozen=True)
class GlossPrediction:
    """ISO 2813 gloss, ASTM D4039 haze index, ASTM E430 haze and DOI and the ASTM D523
    geometry of a surface, with the model of each reading.

    ``model``: per reading G20/G60/G85 the model that computed it (with ``auto`` the
    rule's choice per geometry under ``"rule"``); ``e430_model``: the same for the E430
    readings; ``fallback``: readings handed over to the facet model and why;
    ``computed_by``: every reading's model (G and ``e430.<field>``).
    """

    surface: str
    n: complex
    wavelength_nm: float | None
    report: GlossReport
    model: dict[str, Any]
    e430_model: dict[str, str]
    computed_by: dict[str, str]
    fallback: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """``goniolab predict gloss --json``."""
        rep = self.report
        out: dict[str, Any] = {
            "map": self.surface,
            "n": index_json(self.n),
            "model": self.model,
            "wavelength_nm": (
                self.wavelength_nm if self.wavelength_nm is not None else "ISO 2813 C x V"
            ),
            "G20": rep.G20,
            "G60": rep.G60,
            "G85": rep.G85,
            "haze_index": rep.haze_index,
            "e430": rep.as_dict()["e430"],
            "e430_model": self.e430_model,
            "d523_angle": rep.d523_recommended_angle,
        }
        if self.fallback:
            out["fallback"] = self.fallback
        if self.warnings:
            out["warnings"] = self.warnings
        return out


def _gloss_models(model: Any, rep: Any) -> tuple[dict[str, Any], dict[str, Any], list[str]]:
    """Per reading, the model that computed it (``GlossReport.models``: G20/G60/G85 and
    ``e430.<field>``), the facet hand-overs and the notes; with ``auto`` the rule's choice
    per geometry under ``"rule"``."""
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


@_non_finite_is_user_error
def predict_gloss(
    req: SurfaceRequest,
    *,
    names: OptionNames = CLI_NAMES,
    progress: Progress | None = None,
) -> GlossPrediction:
    """ISO 2813 gloss at 20/60/85 deg and the ASTM D4039/E430 readings of ``req``
    (:func:`goniolab.optics.gloss_standards.gloss_report`)."""
    from goniolab.optics.gloss_standards import gloss_report

    model = surface_model(req, names=names, progress=progress)
    try:
        rep = gloss_report(model)
    except ValueError as exc:
        raise UserError(f"{req.label}: {exc}") from None
    require_finite(req.label, rep.as_dict(), MODEL_OVERFLOW)
    by, fallback, warnings = _gloss_models(model, rep)
    computed_by = {k: v for k, v in by.items() if isinstance(v, str)}
    e430 = {k.removeprefix("e430."): by.pop(k) for k in list(by) if k.startswith("e430.")}
    return GlossPrediction(
        req.label, complex(req.n), req.wavelength_nm, rep, by, e430, computed_by,
        fallback, warnings,
    )  # fmt: skip


async def predict_gloss_async(req: SurfaceRequest, **kwargs: Any) -> GlossPrediction:
    """:func:`predict_gloss` in a worker thread (the caller's event loop stays free)."""
    import asyncio  # here: a command's run (no event loop) need not import it

    return await asyncio.to_thread(predict_gloss, req, **kwargs)


def predict_gloss_batch(
    maps: Sequence[str],
    req: SurfaceRequest,
    *,
    jobs: int | None = None,
    scheduler: str | None = None,
) -> Iterator[dict[str, Any]]:
    """Gloss of many maps (``req`` gives the options; its surface is not used), one worker
    process per core or a dask cluster at ``scheduler``: one ``predict gloss --json`` row
    per map as it finishes, ``{"map", "error"}`` for a map that fails
    (:mod:`goniolab.batch`)."""
    from goniolab.batch import GlossOptions, run_dask, run_local

    if jobs is not None and jobs < 1:
        raise UserError(f"--jobs {jobs}: must be >= 1")
    opts = GlossOptions(
        n=req.n,
        step_um=req.step_um,
        slope_method=req.slope_method,
        weighting=req.weighting,
        masking=req.masking,
        model=req.model,
        wavelength_nm=req.wavelength_nm,
    )
    specs = [str(m) for m in maps]
    return (
        run_dask(specs, opts, address=scheduler) if scheduler else run_local(specs, opts, jobs=jobs)
    )


# --------------------------------------------------------------------------- brdf
@dataclass(frozen=True)
class BrdfPrediction:
    """The in-plane curve at ``theta_i_deg`` over ``theta_r_deg``.

    ``brdf_sr``: the aperture-averaged BRDF (luminance / 100 / projected solid angle of
    the detector), or with ``point`` the BRDF in the exact direction; ``luminance_pct``:
    the goniometer reading (% of a mirror through the cones; ``None`` with ``point``).
    Provenance: ``model`` (auto: the rule's choice, g and reason), ``models`` (the model
    that computed each angle), ``fallback`` (angles handed over to the facet model and
    why), ``warnings``; ``peak``: amplitude, position and FWHM of the curve (Wittmann sec.
    4.2, fig. 8) with three or more increasing angles.
    """

    surface: str
    n: complex
    theta_i_deg: float
    theta_r_deg: NDArray[np.float64]
    brdf_sr: NDArray[np.float64]
    luminance_pct: NDArray[np.float64] | None
    source_deg: float | None
    detector_deg: float | None
    wavelength_nm: float | None
    model: Any
    models: list[str]
    fallback: dict[str, str]
    warnings: list[str]
    peak: dict[str, Any] | None
    model_class: str  # the class of the reflectance model
    model_kind: str  # its model_for name (:func:`goniolab.scan.prediction.model_name`)

    @property
    def point(self) -> bool:
        """The BRDF in the exact direction (no apertures)."""
        return self.luminance_pct is None

    def as_dict(self) -> dict[str, Any]:
        """``goniolab predict brdf --json``."""
        out: dict[str, Any] = {
            "map": self.surface,
            "n": index_json(self.n),
            "theta_i_deg": self.theta_i_deg,
        }
        if self.wavelength_nm is not None:
            out["wavelength_nm"] = self.wavelength_nm
        out["theta_r_deg"] = self.theta_r_deg.tolist()
        out["model"] = self.model
        if self.luminance_pct is None:
            out["brdf_sr"] = self.brdf_sr.tolist()
        else:
            out["source_deg"] = self.source_deg
            out["detector_deg"] = self.detector_deg
            out["brdf_sr"] = self.brdf_sr.tolist()
            out["luminance_pct"] = self.luminance_pct.tolist()
        out["models"] = self.models
        if self.fallback:
            out["fallback"] = self.fallback
        if self.warnings:
            out["warnings"] = self.warnings
        if self.peak is not None:
            out["peak"] = dict(self.peak)
        return out


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


def _peak(tr: NDArray[np.float64], curve: NDArray[np.float64], of: str) -> dict[str, Any] | None:
    """Peak metrics of the curve when the angles are >= 3 and strictly increasing
    (:func:`goniolab.optics.metrics.peak_metrics`); a FWHM the grid cannot resolve is
    ``None`` with a ``fwhm_note`` saying why."""
    from goniolab.optics.metrics import peak_metrics

    if tr.size < 3 or np.any(np.diff(tr) <= 0):
        return None
    peak = peak_metrics(tr, curve)
    fwhm: float | None = None if math.isnan(peak.fwhm_deg) else peak.fwhm_deg
    note = ""
    if math.isnan(peak.fwhm_deg):
        note = "outside the scanned range"
    elif int(np.sum(curve >= peak.amplitude / 2.0)) < 2:
        # one sample above half maximum: the "width" is the grid's, not the curve's
        fwhm, note = None, "not resolved by this angle grid (use a finer --theta-r)"
    out: dict[str, Any] = {
        "of": of,
        "amplitude": peak.amplitude,
        "position_deg": peak.position_deg,
        "fwhm_deg": fwhm,
    }
    if note:
        out["fwhm_note"] = note
    return out


@_non_finite_is_user_error
def predict_brdf(
    req: SurfaceRequest,
    *,
    theta_i_deg: float = 45.0,
    theta_r_deg: str | Sequence[float] | NDArray[np.float64] = "0:70:1",
    source_deg: float | None = None,
    detector_deg: float | None = None,
    point: bool = False,
    names: OptionNames = CLI_NAMES,
    progress: Progress | None = None,
) -> BrdfPrediction:
    """The in-plane curve the scattering model of ``req`` predicts (facet: Wittmann et al.
    2021; wave models and the regime rule: docs/PHYSICS.md) through the goniometer's cones
    (default :data:`DEFAULT_CONE_DEG` each), or with ``point`` the BRDF in the exact
    direction (no cone may then be given)."""
    from goniolab.optics.apertures import Cone, Rect, projected_solid_angle_sr

    ti = float(theta_i_deg)
    if not (math.isfinite(ti) and 0.0 <= ti < 90.0):
        raise UserError(f"{names.theta_i} {theta_i_deg}: must be in [0, 90) deg")
    tr = parse_angle_list(theta_r_deg, names.theta_r)
    if np.any(np.abs(tr) >= 90.0):
        given = f" {theta_r_deg!r}" if isinstance(theta_r_deg, str) else ""
        raise UserError(f"{names.theta_r}{given}: angles must be in (-90, 90) deg")
    if point and (detector_deg is not None or source_deg is not None):
        raise UserError(f"{names.point} takes no {names.detector}/{names.source} (no aperture)")
    model = surface_model(req, names=names, progress=progress)
    lum: NDArray[np.float64] | None = None
    src_deg = det_deg = None
    if point:
        from goniolab.optics.physical import POINT_BRDF_BOX_DEG

        box = Rect(POINT_BRDF_BOX_DEG, POINT_BRDF_BOX_DEG)
        name, per, fb, warnings = _curve_models(model, ti, tr, Rect(0.0, 0.0), box)
        try:
            brdf = np.asarray(model.brdf_inplane(ti, tr), dtype=np.float64)
        except ValueError as exc:
            raise UserError(f"{names.theta_i} {ti:g}: {exc}") from None
    else:
        try:
            src = Cone(DEFAULT_CONE_DEG if source_deg is None else float(source_deg))
            det = Cone(DEFAULT_CONE_DEG if detector_deg is None else float(detector_deg))
        except ValueError as exc:
            raise UserError(f"{names.source}/{names.detector}: {exc}") from None
        if det.full_angle_deg == 0.0:
            raise UserError(
                f"{names.detector} 0 has no solid angle: use {names.point} for the BRDF"
            )
        name, per, fb, warnings = _curve_models(model, ti, tr, src, det)
        try:
            lum = np.asarray(
                model.luminance_pct(ti, tr, source=src, detector=det), dtype=np.float64
            )
        except ValueError as exc:
            raise UserError(f"{names.theta_i} {ti:g} / {names.source}: {exc}") from None
        omega = np.array([projected_solid_angle_sr(det, float(t)) for t in tr])
        brdf = np.where(omega > 0, lum / 100.0 / np.where(omega > 0, omega, 1.0), 0.0)
        src_deg, det_deg = src.full_angle_deg, det.full_angle_deg
    peak = _peak(tr, brdf if lum is None else lum, "brdf_sr" if lum is None else "luminance_pct")
    result = BrdfPrediction(
        req.label, complex(req.n), ti, tr, brdf, lum, src_deg, det_deg, req.wavelength_nm,
        name, per, fb, warnings, peak, type(model).__name__, _model_kind(model),
    )  # fmt: skip
    require_finite(req.label, result.as_dict(), MODEL_OVERFLOW)
    return result


async def predict_brdf_async(req: SurfaceRequest, **kwargs: Any) -> BrdfPrediction:
    """:func:`predict_brdf` in a worker thread (the caller's event loop stays free)."""
    import asyncio

    return await asyncio.to_thread(predict_brdf, req, **kwargs)


# --------------------------------------------------------------------------- albedo
@dataclass(frozen=True)
class AlbedoPrediction:
    """Per incidence of a collimated beam: the directional-hemispherical reflectance
    (coherent beam plus diffuse light), the total integrated scatter (ISO 13696: diffuse
    flux over incident flux), the Fresnel reflectance of the flat surface and the model
    that computed each row, with its notes."""

    surface: str
    n: complex
    wavelength_nm: float
    theta_i_deg: list[float]
    albedo: list[float]
    tis: list[float]
    fresnel: list[float]
    models: list[str]
    warnings: list[str]

    def as_dict(self) -> dict[str, Any]:
        """``goniolab predict albedo --json``."""
        out: dict[str, Any] = {
            "map": self.surface,
            "n": index_json(self.n),
            "wavelength_nm": self.wavelength_nm,
            "theta_i_deg": self.theta_i_deg,
            "albedo": self.albedo,
            "tis": self.tis,
            "fresnel": self.fresnel,
            "model": self.models,
        }
        if self.warnings:
            out["warnings"] = self.warnings
        return out


@_non_finite_is_user_error
def predict_albedo(
    req: SurfaceRequest,
    theta_i_deg: str | Sequence[float] = "0,30,60,85",
    *,
    names: OptionNames = CLI_NAMES,
    progress: Progress | None = None,
) -> AlbedoPrediction:
    """Directional-hemispherical reflectance and TIS of ``req`` per incidence (issue 20),
    each angle in [0, 89] deg."""
    from goniolab.optics.fresnel import fresnel
    from goniolab.optics.provenance import Provenance

    angles = [float(a) for a in parse_angle_list(theta_i_deg, names.theta_i)]
    bad = [a for a in angles if not (math.isfinite(a) and 0.0 <= a <= 89.0)]
    if bad or not angles:
        raise UserError(f"{names.theta_i} {theta_i_deg!r}: angles must be in [0, 89] deg")
    model = surface_model(req, names=names, progress=progress)
    lam = 550.0 if req.wavelength_nm is None else float(req.wavelength_nm)
    albedo: list[float] = []
    tis: list[float] = []
    models: list[str] = []
    warnings: list[str] = []
    for ti in angles:
        try:
            if hasattr(model, "albedo_tis"):
                a, t, prov = model.albedo_tis(ti)
            else:  # the facet model: all of its light is diffuse
                a = float(model.brdf_hemisphere(ti).albedo)  # type: ignore[attr-defined]
                t, prov = a, Provenance(_model_name(model))
        except ValueError as exc:
            raise UserError(f"{names.theta_i} {ti:g}: {exc}") from None
        albedo.append(float(a))
        tis.append(float(t))
        models.append(prov.model)
        warnings.extend(f"theta_i {ti:g} deg: {note}" for note in prov.notes)
    fres = [float(fresnel(math.cos(math.radians(t)), req.n)) for t in angles]
    result = AlbedoPrediction(
        req.label, complex(req.n), lam, angles, albedo, tis, fres, models, warnings
    )
    require_finite(req.label, result.as_dict(), MODEL_OVERFLOW)
    return result
