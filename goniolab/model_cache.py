"""The reflectance model of a surface spec, built once and cached.

Every command, the lab and the TUI name a surface the same way (a height-map file or
``sample:NAME``, :func:`goniolab.surfaces.resolve_map`); :func:`model_for` turns it into the
model that predicts it, cached per spec, file version and options. Errors become
:class:`goniolab.errors.UserError` (exit code 2) naming the file or sample and the reason.

Models (``model=``, the CLI's ``--model``) are the names of :mod:`goniolab.model_registry`:
``facet`` (geometric optics, Wittmann et al.), ``kirchhoff`` (scalar Kirchhoff by FFT of the
map's phase screen), ``rayleigh-rice`` (first-order perturbation from the map's PSD) and
``auto`` (the default: per geometry, the regime rule of :mod:`goniolab.optics.model_choice`);
the factories that build them from a map are here (:func:`build_facet` and its siblings).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from goniolab import model_registry
from goniolab.errors import UserError
from goniolab.model_registry import DEFAULT_MODEL, ModelOptions
from goniolab.optics.facet import Backend, FacetModel, Weighting
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.models import ReflectanceModel
from goniolab.optics.surface import SlopeMethod, Surface
from goniolab.surfaces.resolve import SAMPLE_PREFIX, one_line, resolve_map

if TYPE_CHECKING:
    from goniolab.colour.paint import Paint
    from goniolab.colour.spectral import SpectralPredictor, SurfaceFactory

__all__ = [
    "build_auto",
    "build_facet",
    "build_kirchhoff",
    "build_model",
    "build_rayleigh_rice",
    "model_for",
    "paint_for",
    "spectral_for",
    "surface_factory",
]


def _spec_key(spec: str | Path) -> tuple[str, int, int]:
    """Cache key: the sample spec, or the resolved path with its mtime and size."""
    text = str(spec)
    if text.startswith(SAMPLE_PREFIX):
        return text, 0, 0
    path = Path(text).expanduser()
    try:
        st = path.stat()
    except OSError:
        return text, -1, -1  # resolve_map reports the missing file
    return str(path.resolve()), st.st_mtime_ns, st.st_size


# ------------------------------------------------------- factories of goniolab.model_registry
def _need_map(hm: HeightMap | None, name: str) -> HeightMap:
    if hm is None:
        raise ValueError(f"the {name} model needs a height map")
    return hm


def _wave_options(options: ModelOptions) -> dict[str, Any]:
    """Wavelength, gloss weighting and masking of the wave-optics models: ``None`` is
    550 nm for curves and ISO 2813's C x V(lambda) weighting for gloss."""
    wl = options.wavelength_nm
    return {
        "wavelength_nm": 550.0 if wl is None else wl,
        "gloss_weighting": "iso2813" if wl is None else "single",
        "masking": options.masking,
    }


def build_facet(hm: HeightMap | None, options: ModelOptions) -> ReflectanceModel:
    """The ``facet`` model: :class:`FacetModel` of the map's slopes."""
    surface = Surface.from_heightmap(
        _need_map(hm, "facet"),
        slope_method=options.slope_method,  # type: ignore[arg-type]
    )
    return FacetModel(
        surface,
        n=options.n,
        weighting=options.weighting,  # type: ignore[arg-type]
        masking=options.masking,
        backend=options.backend,  # type: ignore[arg-type]
    )


def build_auto(hm: HeightMap | None, options: ModelOptions) -> ReflectanceModel:
    """The ``auto`` model (:class:`goniolab.optics.model_choice.AutoModel`) on the facet
    model ``options.facet`` (a model or a factory; when not given, one on the slope cells,
    ``backend="lean"``, built the first time a geometry needs it).

    The rule reads the map's statistics only, so a map the rule sends to the facet model
    imports no wave-optics code and one it sends to the wave models forms no facet slopes;
    ``options.backend`` is not used: the facet model of ``auto`` always runs on the slope
    cells and the wave models on numpy, the faster whole-process (``bench/bench_lean.py``;
    the per-pixel numba kernels cost a process about 1 s of numba start-up)."""
    from goniolab.optics.model_choice import AutoModel

    hm = _need_map(hm, "auto")
    facet = options.facet
    if facet is None:
        lean = dataclasses.replace(options, backend="lean")
        the_map = hm

        def facet() -> FacetModel:
            try:
                built = build_facet(the_map, lean)
            except ValueError as exc:  # built late: the error still names the map
                raise UserError(one_line(f"{the_map.source}: {exc}")) from None
            assert isinstance(built, FacetModel)
            return built

    out: ReflectanceModel = AutoModel(hm, facet, n=options.n, **_wave_options(options))
    return out


def build_kirchhoff(hm: HeightMap | None, options: ModelOptions) -> ReflectanceModel:
    """The ``kirchhoff`` model (:class:`goniolab.optics.kirchhoff.KirchhoffModel`)."""
    from goniolab.optics.kirchhoff import KirchhoffModel

    return KirchhoffModel(_need_map(hm, "kirchhoff"), n=options.n, **_wave_options(options))


def build_rayleigh_rice(hm: HeightMap | None, options: ModelOptions) -> ReflectanceModel:
    """The ``rayleigh-rice`` model (:class:`goniolab.optics.rayleigh_rice.RayleighRiceModel`)."""
    from goniolab.optics.rayleigh_rice import RayleighRiceModel

    hm = _need_map(hm, "rayleigh-rice")
    return RayleighRiceModel(hm, n=options.n, **_wave_options(options))


def build_model(
    hm: HeightMap | None,
    *,
    n: complex | float = 1.55,
    slope_method: SlopeMethod = "forward",
    weighting: Weighting = "radiometric",
    masking: bool = True,
    model: str = DEFAULT_MODEL,
    wavelength_nm: float | None = None,
    facet: FacetModel | None = None,
    backend: Backend = "lean",
) -> ReflectanceModel:
    """The registered ``model`` (:mod:`goniolab.model_registry`) of a loaded height map,
    not cached (:func:`model_for` caches by spec). ``facet``: the facet model of the map a
    model that uses one (``auto``) shares, if already built; ``backend``: that of the facet
    model (:class:`FacetModel`). Raises ``ValueError`` for an unknown model or a map with
    no usable facets."""
    entry = model_registry.get(model)
    options = ModelOptions(
        n=complex(n),
        slope_method=slope_method,
        weighting=weighting,
        masking=bool(masking),
        wavelength_nm=wavelength_nm,
        backend=backend,
        facet=facet if entry.uses_facet else None,
    )
    return entry.load()(hm if entry.needs_heightmap else None, options)


#: Largest height or slope the models can square without overflowing double precision.
_MAX_SQUARABLE = 1e150


def _check_numeric_range(spec: str, hm: Any) -> None:
    """Refuse a map whose heights or facet slopes overflow double precision when squared
    (1e300 um heights made every prediction 0 GU, or Infinity, without a word).

    Cheap: the largest height bounds every slope by ``2 max|z| / min(dx, dy)``; the slopes
    themselves are computed only when that bound is beyond :data:`_MAX_SQUARABLE`.

    Raises
    ------
    UserError
        Naming the largest height (or slope), the steps and what to check.
    """
    import numpy as np

    z = np.asarray(hm.z_um)
    # fmax/fmin skip NaN and make no copy of the map (np.abs(z[finite]) made two)
    bottom, top = hm.z_range
    if math.isfinite(top) and math.isfinite(bottom):
        z_max = max(abs(top), abs(bottom))
    else:  # all NaN, or an infinity: the finite points only (copies; a rare map)
        with np.errstate(invalid="ignore"):
            finite = np.isfinite(z)
            z_max = float(np.max(np.abs(z[finite]))) if finite.any() else 0.0
    what = f"heights up to {z_max:.3g} um"
    bad = z_max > _MAX_SQUARABLE
    if not bad and 2.0 * z_max / min(hm.dx_um, hm.dy_um) > _MAX_SQUARABLE:
        with np.errstate(over="ignore", invalid="ignore"):
            sx = np.abs(np.diff(z, axis=1)) / hm.dx_um
            sy = np.abs(np.diff(z, axis=0)) / hm.dy_um
            slope = max(float(np.nanmax(sx, initial=0.0)), float(np.nanmax(sy, initial=0.0)))
        bad = not slope <= _MAX_SQUARABLE
        what = f"facet slopes up to {slope:.3g} ({what} at {hm.dx_um:g} x {hm.dy_um:g} um steps)"
    if bad:
        raise UserError(
            one_line(
                f"{spec}: {what} overflow double precision: the heights or the lateral step "
                "are implausible; check the map's z unit and step"
            )
        )


@functools.lru_cache(maxsize=16)
def _model(
    key: tuple[str, int, int],
    spec: str,
    n: complex,
    step_um: float | None,
    slope_method: SlopeMethod,
    weighting: Weighting,
    masking: bool,
    model: str,
    wavelength_nm: float | None,
    backend: Backend,
) -> Any:
    entry = model_registry.get(model)
    hm = None
    if entry.needs_heightmap:
        hm = resolve_map(spec, step_um=step_um)
        _check_numeric_range(spec, hm)
    try:
        return build_model(
            hm,
            n=n,
            slope_method=slope_method,
            weighting=weighting,
            masking=masking,
            model=model,
            wavelength_nm=wavelength_nm,
            backend=backend,
        )
    except ValueError as exc:
        raise UserError(one_line(f"{spec}: {exc}")) from None


def model_for(
    spec: str | Path | HeightMap,
    *,
    n: complex | float = 1.55,
    step_um: float | None = None,
    slope_method: SlopeMethod = "forward",
    weighting: Weighting = "radiometric",
    masking: bool = True,
    model: str = DEFAULT_MODEL,
    wavelength_nm: float | None = None,
    backend: Backend = "lean",
) -> ReflectanceModel:
    """The reflectance model of a surface: the one way every face gets a sample's model.

    A file or ``sample:NAME`` is cached per spec, file version and options; a
    :class:`HeightMap` already in memory (the notebook API's arrays) is modelled each call.

    Parameters
    ----------
    spec, step_um
        As in :func:`resolve_map`, or a loaded :class:`HeightMap` (``step_um`` unused).
    n
        Refractive index; complex ``n + ik`` for conductors.
    slope_method, weighting, masking
        Passed to :meth:`Surface.from_heightmap` and :class:`FacetModel` (masking also to
        the physical-optics models).
    model
        A name of :mod:`goniolab.model_registry` (``auto``, ``facet``, ``kirchhoff``,
        ``rayleigh-rice`` and any registered since).
    wavelength_nm
        For the wave-optics models: the wavelength of every response, gloss included.
        ``None``: BRDF and goniometer responses at 550 nm, gloss weighted over wavelength by
        CIE illuminant C x V(lambda) as ISO 2813 does.
    backend
        Of the facet model: ``"numba"`` (compiled kernels, for a process that predicts
        often: the lab, the TUI) or ``"lean"`` (no numba, for a one-shot command), see
        :class:`FacetModel`.

    Raises
    ------
    UserError
        Bad spec or file (see :func:`resolve_map`), unknown model, or a map with no usable
        facets.
    """
    try:
        model_registry.get(model)
    except model_registry.UnknownModel as exc:
        raise UserError(str(exc)) from None
    if wavelength_nm is not None and not (100.0 <= float(wavelength_nm) <= 20000.0):
        raise UserError(f"wavelength {wavelength_nm} nm: must be in [100, 20000] nm")
    wl = None if wavelength_nm is None else float(wavelength_nm)
    options: dict[str, Any] = {
        "slope_method": slope_method,
        "weighting": weighting,
        "masking": bool(masking),
        "model": model,
        "wavelength_nm": wl,
        "backend": backend,
    }
    if isinstance(spec, HeightMap):
        name = spec.source or "<height map>"
        _check_numeric_range(name, spec)
        try:
            return build_model(spec, n=complex(n), **options)
        except ValueError as exc:
            raise UserError(one_line(f"{name}: {exc}")) from None
    out: ReflectanceModel = _model(
        _spec_key(spec),
        str(spec),
        complex(n),
        step_um,
        slope_method,
        weighting,
        bool(masking),
        model,
        wl,
        backend,
    )
    return out


# ------------------------------------------------------------------------- colour (issue 11)
def paint_for(spec: str | Path | None, n: complex | float = 1.55) -> Paint:
    """The paint of a surface spec: a built-in sample's ``[samples.NAME.paint]`` table, else
    a coat of constant index ``n`` over a black body (the grey luminance model).

    Raises
    ------
    UserError
        The sample's paint table is malformed (names the key).
    """
    from goniolab.colour.dispersion import Constant
    from goniolab.colour.paint import Paint, PaintError, paint_from_dict

    text = "" if spec is None else str(spec)
    if text.startswith(SAMPLE_PREFIX):
        from goniolab.surfaces.synthetic import SampleError, sample_info

        try:
            info = sample_info(text[len(SAMPLE_PREFIX) :])
        except SampleError as exc:
            raise UserError(one_line(str(exc))) from None
        table = info.params.get("paint")
        if table is not None:
            try:
                return paint_from_dict(table, where=f"samples.{info.name}.paint")
            except PaintError as exc:
                raise UserError(one_line(str(exc))) from None
    return Paint(coat=Constant(complex(n)))


def surface_factory(model: ReflectanceModel) -> SurfaceFactory:
    """The coat-surface model of ``model``'s surface for any index and wavelength.

    A facet model is rebuilt on the same facets (weighting, masking kept), an analytic one
    with the same kind and roughness, a physical-optics one (Kirchhoff, Rayleigh-Rice) by its
    ``with_optics(n=, wavelength_nm=)`` (then evaluated at wavelength nodes); any other model
    (``auto``) is used as it is (its own n and wavelength: the factory says so in its name).
    """
    from goniolab.colour.spectral import SurfaceFactory
    from goniolab.optics.analytic import AnalyticModel

    if isinstance(model, FacetModel):
        m = model

        def build_facet(n: complex, wavelength_nm: float) -> ReflectanceModel:
            if complex(n) == m.n:
                return m
            return FacetModel(m.surface, n=n, weighting=m.weighting, masking=m.masking)

        return SurfaceFactory(build_facet, name="facet")
    if isinstance(model, AnalyticModel):
        a = model

        def build_analytic(n: complex, wavelength_nm: float) -> ReflectanceModel:
            return AnalyticModel(a.kind, alpha=a.alpha, n=n)

        return SurfaceFactory(build_analytic, name=f"analytic-{a.kind}")
    with_optics = getattr(model, "with_optics", None)
    if with_optics is not None:  # physical optics (Kirchhoff, Rayleigh-Rice): n and lambda

        def build_physical(n: complex, wavelength_nm: float) -> ReflectanceModel:
            out: ReflectanceModel = with_optics(n=n, wavelength_nm=wavelength_nm)
            return out

        kind = getattr(model, "kind", type(model).__name__)
        return SurfaceFactory(build_physical, wavelength_dependent=True, name=str(kind))
    return SurfaceFactory(lambda n, wl: model, name=f"{type(model).__name__} (fixed n)")


def spectral_for(
    model: ReflectanceModel,
    *,
    source_cone_deg: float = 6.0,
    detector_cone_deg: float = 6.0,
    step_nm: float = 10.0,
    paint: Paint | None = None,
) -> SpectralPredictor:
    """The spectral predictor of a model's surface with its sample's paint (380-780 nm)."""
    from goniolab.colour.spectra import standard_grid_nm
    from goniolab.colour.spectral import SpectralPredictor
    from goniolab.optics.apertures import Cone

    surface = getattr(model, "surface", None)
    spec = getattr(surface, "source", None)
    n = complex(getattr(model, "n", 1.55))
    return SpectralPredictor(
        surface_factory(model),
        paint if paint is not None else paint_for(spec, n),
        source=Cone(source_cone_deg),
        detector=Cone(detector_cone_deg),
        wavelengths_nm=standard_grid_nm(step_nm),
    )
