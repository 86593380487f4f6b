"""The notebook face: surfaces, predictions and runs as xarray / pandas objects.

>>> import goniolab.api as gl
>>> z = gl.load_surface("sample:wittmann-3")              # DataArray (y_um, x_um)
>>> curve = gl.predict_brdf(z, theta_i_deg=45, theta_r_deg="0:70:1")   # Dataset on theta_r_deg
>>> gloss = gl.predict_gloss(z)                           # Dataset on geometry_deg
>>> run = gl.run_scan("configs/lab-sim.toml", sample="sample:wittmann-3",
...                   theta_r_deg="30:60:2", time_scale=0, store="runs.sqlite")
>>> ds = run.to_xarray()          # measured, predicted, residual (and colour) per point
>>> gl.open_runs("runs.sqlite")   # every run as a pandas DataFrame

Every array follows xarray's Dataset conventions: named dimensions (``theta_r_deg``,
``repeat``, ``wavelength_nm``, ``geometry_deg``), coordinates and variables with a
``units`` attribute, provenance as attributes (:mod:`goniolab.datasets`). Angles are in
degrees everywhere. Errors are :class:`goniolab.errors.UserError` with one clear line.

xarray, pandas and the lab are imported inside the functions that use them.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextvars
import functools
import math
import sys
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ParamSpec, TypeVar

import numpy as np

from goniolab.errors import UserError
from goniolab.scan.plans import DEFAULT_REPEATS
from goniolab.store import RunRecord, RunStore, StoreError, resolve_store_path

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd
    import xarray as xr

    from goniolab.optics.heightmap import HeightMap
    from goniolab.optics.models import ReflectanceModel

__all__ = [
    "Run",
    "load_surface",
    "open_dataset",
    "open_run",
    "open_runs",
    "predict_brdf",
    "predict_gloss",
    "run_scan",
    "run_scan_async",
]

_T = TypeVar("_T")
_P = ParamSpec("_P")

#: Default source and detector cones of the Wittmann goniometer (sec. 2.3), full angles.
DEFAULT_CONE_DEG = 6.0


# --------------------------------------------------------------------------- surfaces
def _heightmap(surface: Any, step_um: float | None = None) -> HeightMap:
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


#: Relative tolerance between a DataArray's coordinate steps and its dx_um/dy_um attributes
#: (and between its own steps: the grid must be regular).
_STEP_RTOL = 1e-6


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


def load_surface(path: str | Path, *, step_um: float | None = None) -> xr.DataArray:
    """A height map as a DataArray ``height_um`` with dims ``(y_um, x_um)``.

    Parameters
    ----------
    path
        A height-map file (``.npy``, CSV/text, ``.sdf``, ``.sur``, ``.gwy``) or
        ``sample:NAME`` (``goniolab samples`` lists them).
    step_um
        The lateral step for files that carry none.

    Returns
    -------
    xarray.DataArray
        Heights in micrometres; coords ``y_um``/``x_um`` in micrometres; attrs ``dx_um``,
        ``dy_um``, ``source`` and the file's metadata as ``meta_*``. The predictions take
        the steps from the coordinates (so ``isel``/``coarsen`` results work once
        ``dx_um``/``dy_um`` are set right or deleted; a disagreeing attribute is refused).
    """
    from goniolab.datasets import heightmap_dataarray

    return heightmap_dataarray(_heightmap(path, step_um))


def _model(
    surface: Any,
    *,
    n: complex | float,
    step_um: float | None,
    slope_method: str,
    weighting: str,
    masking: bool,
    model: str = "auto",
    wavelength_nm: float | None = None,
) -> ReflectanceModel:
    from goniolab.model_cache import model_for

    options: dict[str, Any] = {
        "slope_method": slope_method,
        "weighting": weighting,
        "masking": masking,
        "model": model,
        "wavelength_nm": wavelength_nm,
    }
    if isinstance(surface, str | Path):
        return model_for(surface, n=n, step_um=step_um, **options)
    return model_for(_heightmap(surface, step_um), n=n, **options)


def _angles(theta_r_deg: str | Sequence[float] | np.ndarray) -> np.ndarray:
    from goniolab.scan.plans import PlanError, parse_angles

    spec = theta_r_deg if isinstance(theta_r_deg, str) else [float(v) for v in theta_r_deg]
    try:
        return np.asarray(parse_angles(spec, name="theta_r_deg"), dtype=np.float64)
    except PlanError as exc:
        raise UserError(str(exc)) from None


def _source_label(surface: Any) -> str:
    if isinstance(surface, str | Path):
        return str(surface)
    return str(getattr(surface, "attrs", {}).get("source", getattr(surface, "source", "")))


def _index_attr(n: complex | float) -> float | list[float]:
    c = complex(n)
    return c.real if c.imag == 0 else [c.real, c.imag]


def predict_brdf(
    surface: Any,
    *,
    theta_i_deg: float = 45.0,
    theta_r_deg: str | Sequence[float] | np.ndarray = "0:70:1",
    n: complex | float = 1.55,
    source_deg: float = DEFAULT_CONE_DEG,
    detector_deg: float = DEFAULT_CONE_DEG,
    point: bool = False,
    step_um: float | None = None,
    slope_method: str = "forward",
    weighting: str = "radiometric",
    masking: bool = True,
    model: str = "auto",
    wavelength_nm: float | None = None,
) -> xr.Dataset:
    """The in-plane curve a scattering model predicts (facet: Wittmann et al. 2021; wave
    models and the regime rule: docs/PHYSICS.md).

    Parameters
    ----------
    surface
        A path, ``sample:NAME`` or a :func:`load_surface` DataArray.
    theta_i_deg
        Lamp angle, degrees in [0, 90).
    theta_r_deg
        Detector angles: ``"start:stop:step"``, ``"a,b,c"`` or a sequence, degrees.
    n
        Refractive index (complex ``n + ik`` for metals).
    source_deg, detector_deg
        Full angles of the lamp and detector cones (the goniometer's apertures).
    point
        The BRDF in the exact direction only (no apertures, no ``luminance_pct``).
    model, wavelength_nm
        ``auto`` (default: the regime rule per geometry), ``facet``, ``kirchhoff`` or
        ``rayleigh-rice``, and the wave models' wavelength (see
        :func:`goniolab.model_cache.model_for`).
    masking
        Smith masking-shadowing from the measured slopes (default on: it keeps the facet
        model's albedo at most 1 up to grazing incidence).

    Returns
    -------
    xarray.Dataset
        Dim ``theta_r_deg``; ``luminance_pct`` (% of a mirror, through the cones) and
        ``brdf_sr`` (1/sr: luminance / 100 / projected solid angle of the detector, or the
        point BRDF with ``point=True``); coords ``theta_i_deg`` and ``aspecular_deg``.
    """
    from goniolab.datasets import brdf_dataset
    from goniolab.optics.apertures import Cone, projected_solid_angle_sr
    from goniolab.scan.prediction import model_name

    ti = float(theta_i_deg)
    if not (math.isfinite(ti) and 0.0 <= ti < 90.0):
        raise UserError(f"theta_i_deg {theta_i_deg}: must be in [0, 90) deg")
    tr = _angles(theta_r_deg)
    if np.any(np.abs(tr) >= 90.0):
        raise UserError("theta_r_deg: angles must be in (-90, 90) deg")
    refl = _model(
        surface,
        n=n,
        step_um=step_um,
        slope_method=slope_method,
        weighting=weighting,
        masking=masking,
        model=model,
        wavelength_nm=wavelength_nm,
    )
    attrs: dict[str, Any] = {
        "sample": _source_label(surface),
        "n": _index_attr(n),
        "weighting": weighting,
        "slope_method": slope_method,
        "masking": int(masking),
        "model": type(refl).__name__,
        "model_name": model_name(refl),
    }
    if point:
        brdf = np.asarray(refl.brdf_inplane(ti, tr), dtype=np.float64)
        return brdf_dataset(ti, tr, brdf, None, attrs={**attrs, "aperture": "none (point)"})
    try:
        src, det = Cone(float(source_deg)), Cone(float(detector_deg))
    except ValueError as exc:
        raise UserError(f"source_deg/detector_deg: {exc}") from None
    if det.full_angle_deg == 0.0:
        raise UserError("detector_deg 0 has no solid angle: use point=True for the BRDF")
    try:
        lum = np.asarray(refl.luminance_pct(ti, tr, source=src, detector=det), dtype=np.float64)
    except ValueError as exc:
        raise UserError(f"theta_i_deg {ti:g} / source_deg: {exc}") from None
    om = np.array([projected_solid_angle_sr(det, float(t)) for t in tr])
    brdf = np.where(om > 0, lum / 100.0 / np.where(om > 0, om, 1.0), 0.0)
    attrs.update(source_cone_deg=src.full_angle_deg, detector_cone_deg=det.full_angle_deg)
    return brdf_dataset(ti, tr, brdf, lum, attrs=attrs)


def predict_gloss(
    surface: Any,
    *,
    n: complex | float = 1.55,
    step_um: float | None = None,
    slope_method: str = "forward",
    weighting: str = "radiometric",
    masking: bool = True,
    model: str = "auto",
    wavelength_nm: float | None = None,
) -> xr.Dataset:
    """ISO 2813 gloss at 20/60/85 deg and the ASTM D4039/E430 haze and DOI readings.

    ``model`` / ``wavelength_nm`` / ``masking`` as in :func:`predict_brdf` (default ``auto``,
    Smith masking on).

    Returns
    -------
    xarray.Dataset
        ``gloss_gu`` along ``geometry_deg`` (20, 60, 85), scalar ``haze_index``, ``doi``
        and the E430 readings; ``d523_recommended_angle_deg`` as an attribute.
    """
    from goniolab.datasets import gloss_dataset
    from goniolab.optics.gloss_standards import gloss_report

    refl = _model(
        surface,
        n=n,
        step_um=step_um,
        slope_method=slope_method,
        weighting=weighting,
        masking=masking,
        model=model,
        wavelength_nm=wavelength_nm,
    )
    return gloss_dataset(
        gloss_report(refl),
        attrs={"sample": _source_label(surface), "n": _index_attr(n), "weighting": weighting},
    )


# --------------------------------------------------------------------------- runs
def _store_location(store: str | Path | None, config: str | Path | None = None) -> str | Path:
    config_store = None
    if config is not None:
        from goniolab.config import load_lab_config

        config_store = load_lab_config(config).lab.store
    return resolve_store_path(None if store is None else str(store), config_store)


def _open_readonly(location: str | Path) -> RunStore:
    try:
        return RunStore(location, readonly=True)
    except StoreError as exc:
        raise UserError(str(exc)) from exc


@dataclass(frozen=True)
class Run:
    """A stored run: its record and its data as xarray / pandas.

    Each method reads the store afresh (a run still being measured shows its new points).
    """

    id: int
    store: str | Path

    def __repr__(self) -> str:
        # a notebook shows (and saves in the .ipynb) this: never the store's password
        from goniolab.redact import redact

        return f"Run(id={self.id}, store={redact(str(self.store))!r})"

    def annotate(
        self,
        *,
        operator: str | None = None,
        sample_id: str | None = None,
        notes: str | None = None,
        tags: Sequence[str] | None = None,
    ) -> RunRecord:
        """Set the run's operator, physical sample id, notes or tags (``None`` keeps one;
        the config's ``[run]`` table gives a new run its defaults); returns the record."""
        try:
            with RunStore(self.store, create=False) as s:
                return s.set_meta(
                    self.id, operator=operator, sample_id=sample_id, notes=notes, tags=tags
                )
        except StoreError as exc:
            raise UserError(str(exc)) from exc

    @property
    def record(self) -> RunRecord:
        """The run's row: kind, plan, config snapshot, sample, model, status, times."""
        with _open_readonly(self.store) as s:
            try:
                return s.get_run(self.id)
            except StoreError as exc:
                raise UserError(str(exc)) from exc

    @property
    def status(self) -> str:
        """``done``, ``running``, ``aborted``, ``failed`` ..."""
        return self.record.status

    def to_xarray(self) -> xr.Dataset:
        """Measured, predicted, residual (and colour) per point: see
        :func:`goniolab.datasets.run_dataset`."""
        from goniolab.datasets import run_dataset

        with _open_readonly(self.store) as s:
            try:
                return run_dataset(s, self.id)
            except StoreError as exc:
                raise UserError(str(exc)) from exc

    def to_dataframe(self) -> pd.DataFrame:
        """One row per reading (the CSV export's columns, ``timestamp`` as UTC datetimes)."""
        from goniolab.export import run_dataframe

        with _open_readonly(self.store) as s:
            try:
                s.get_run(self.id)
                return run_dataframe(s, self.id)
            except StoreError as exc:
                raise UserError(str(exc)) from exc

    def summary(self) -> dict[str, Any]:
        """The summary ``goniolab runs show`` prints (RMSE, peaks, counts)."""
        from goniolab.commands.runs import run_summary

        with _open_readonly(self.store) as s:
            return run_summary(s, self.record)

    def plot(self, out: str | Path | None = None, *, log: bool = False) -> Any:
        """The figure ``goniolab plot`` draws; saved to ``out`` when given.

        In a notebook the figure shows inline as the cell's value (no ``%matplotlib
        inline`` needed: :func:`_show_figures_inline`)."""
        from goniolab.run_plots import plot_run

        with _open_readonly(self.store) as s:
            fig = plot_run(s, self.id, out=out, log=log)
        _show_figures_inline()
        return fig


def _figure_png(fig: Any) -> bytes:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def _show_figures_inline() -> None:
    """In IPython / Jupyter: display a matplotlib ``Figure`` as a PNG.

    :mod:`goniolab.run_plots` builds figures without pyplot (no global state, Agg canvas), so
    the inline backend never registers its display formatter and a returned figure shows as
    ``<Figure size 800x600 with 2 Axes>`` (issue 22.2). This registers a PNG formatter for
    ``Figure`` with the running shell's display formatter (IPython's documented
    ``formatters['image/png'].for_type``), unless one is there already (``%matplotlib
    inline`` registers its own). Outside IPython it does nothing.
    """
    ipython_mod = sys.modules.get("IPython")
    if ipython_mod is None:
        return
    shell = ipython_mod.get_ipython()
    if shell is None:
        return
    from matplotlib.figure import Figure

    png = shell.display_formatter.formatters["image/png"]
    try:
        png.lookup_by_type(Figure)
    except KeyError:
        png.for_type(Figure, _figure_png)


def open_dataset(path: str | Path) -> xr.Dataset:
    """Read back a netCDF file goniolab wrote (``goniolab runs export RUN -o run.nc``, or
    a prediction saved with :func:`goniolab.datasets.write_netcdf`): the same variables,
    units and attributes as :meth:`Run.to_xarray`, times as UTC ``datetime64``."""
    from goniolab.datasets import open_dataset as read

    try:
        return read(path)
    except OSError as exc:
        raise UserError(str(exc)) from None


def open_run(run_id: int, store: str | Path | None = None) -> Run:
    """Run ``run_id`` of the store (``None``: the default store, as the CLI's)."""
    run = Run(int(run_id), _store_location(store))
    run.record  # noqa: B018 - fail here, with the store's message, when it does not exist
    return run


def open_runs(
    store: str | Path | None = None, *, config: str | Path | None = None, limit: int | None = None
) -> pd.DataFrame:
    """Every run of the store as a DataFrame indexed by run id, newest first.

    Columns: ``kind``, ``status``, ``interrupted``, ``sample``, ``readings``,
    ``created_at``/``finished_at`` (UTC datetimes), ``theta_i_deg``, ``reason``.
    """
    import pandas as pd

    from goniolab.commands.runs import interrupted

    location = _store_location(store, config)
    rows: list[dict[str, Any]] = []
    with _open_readonly(location) as s:
        for r in s.list_runs(limit=limit):
            rows.append(
                {
                    "id": r.id,
                    "kind": r.kind,
                    "status": r.status,
                    "interrupted": interrupted(s, r),
                    "sample": r.sample,
                    "readings": s.count_points(r.id)
                    if r.kind == "brdf"
                    else len(s.gloss_readings(r.id)),
                    "created_at": r.created_at,
                    "finished_at": r.finished_at,
                    "theta_i_deg": r.plan.get("theta_i_deg"),
                    "reason": r.reason,
                }
            )
    columns = ["id", "kind", "status", "interrupted", "sample", "readings", "created_at",
               "finished_at", "theta_i_deg", "reason"]  # fmt: skip
    df = pd.DataFrame.from_records(rows, columns=columns)
    for col in ("created_at", "finished_at"):
        df[col] = pd.to_datetime(df[col], unit="s", utc=True)
    df["theta_i_deg"] = pd.to_numeric(df["theta_i_deg"], errors="coerce")
    return df.set_index("id")


# --------------------------------------------------------------------------- scans
class _ScanControl:
    """The running scan's loop and runner, so that another thread can abort it."""

    def __init__(self) -> None:
        self.loop: asyncio.AbstractEventLoop | None = None
        self.runner: Any = None

    def abort(self) -> bool:
        """Ask the runner to stop (the arms stop, then park); False before it started."""
        if self.loop is None or self.runner is None:
            return False
        try:
            self.loop.call_soon_threadsafe(self.runner.abort)
        except RuntimeError:  # the scan's loop has closed: it ended meanwhile
            return False
        return True


#: The control of the blocking :func:`run_scan` call that runs this scan (None: awaited).
_CONTROL: contextvars.ContextVar[_ScanControl | None] = contextvars.ContextVar(
    "goniolab_scan_control", default=None
)


def _run_blocking(coro: Coroutine[Any, Any, _T], control: _ScanControl | None = None) -> _T:
    """Run ``coro`` to completion from plain code or from a notebook.

    A notebook (Jupyter, IPython) already runs an event loop in this thread, so the
    coroutine gets its own loop in a worker thread. Everything it uses must then be made in
    that thread too: the run store is opened *inside* the coroutine (an SQLite connection
    may only be used by the thread that made it; issue 22.2). ``await run_scan_async(...)``
    runs on the notebook's own loop instead.

    Interrupting the kernel (a KeyboardInterrupt here, while the scan runs in its thread)
    aborts the scan through ``control``: the arms stop and park and the run is stored as
    aborted, as Ctrl-C does in ``goniolab scan``; this call then returns the aborted run.
    """
    ctx = contextvars.copy_context()
    ctx.run(_CONTROL.set, control)
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return ctx.run(asyncio.run, coro)
    with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="goniolab-scan") as pool:
        future = pool.submit(ctx.run, asyncio.run, coro)
        try:
            return future.result()
        except KeyboardInterrupt:
            if future.done():
                return future.result()
            if control is None or not control.abort():
                raise
            print("goniolab: stopping: the arms stop, then park", file=sys.stderr, flush=True)
            return future.result()


def _blocking(scan: Callable[_P, Coroutine[Any, Any, Run]]) -> Callable[_P, Run]:
    """The blocking face of the coroutine ``scan`` (same parameters, same result)."""

    @functools.wraps(scan)
    def run(*args: _P.args, **kwargs: _P.kwargs) -> Run:
        control = _ScanControl()
        return _run_blocking(scan(*args, **kwargs), control)

    return run


async def run_scan_async(
    config: str | Path,
    *,
    sample: str | None = None,
    theta_i_deg: float = 45.0,
    theta_r_deg: str | Sequence[float] = "0:70:1",
    repeats: int = DEFAULT_REPEATS,
    dwell_s: float = 0.0,
    exposure_us: int | None = None,
    store: str | Path | None = None,
    time_scale: float | None = None,
    progress: bool = True,
    operator: str | None = None,
    sample_id: str | None = None,
    notes: str | None = None,
    tags: Sequence[str] = (),
    auto_exposure: bool = True,
) -> Run:
    """Run an in-plane scan and return the stored :class:`Run`: ``run = await
    gl.run_scan_async(...)`` on the caller's event loop (a notebook cell: the kernel stays
    responsive to other cells' ``await``s; the model work runs in threads).
    :func:`run_scan` is the same call, blocking.

    The use case is :func:`goniolab.app.lab_scan.scan` (the one ``goniolab scan`` runs):
    the config is read once, the plan built by :func:`goniolab.app.lab_setup.brdf_plan`.

    Parameters
    ----------
    config
        Lab config TOML (``configs/lab-sim.toml`` for the simulated lab).
    sample
        ``sample:NAME`` or a height-map path (default: the config's ``[sample] map``).
    theta_i_deg, theta_r_deg, repeats, dwell_s, exposure_us
        The plan, as ``goniolab scan`` takes it.
    store
        Run store file or ``postgresql://`` URL (default: config ``[lab] store``, else
        the user data dir).
    time_scale
        Simulated lab only: clock scale (0 = no waiting).
    progress
        Show a progress bar (:func:`goniolab.progress.auto_progress`: rich's bar as an
        output widget in a notebook, a text bar on stderr in a terminal; never on stdout).
    auto_exposure
        Choose each reading's exposure from the instrument's signal level (the default,
        as ``goniolab scan``); ``False`` keeps ``exposure_us``.
    operator, sample_id, notes, tags
        The run's identity (who measures, the physical sample's id, free text, tags),
        stored with the run beside its UUID; the config's ``[run]`` table fills what is
        left out. Change it later with :meth:`Run.annotate`.

    Returns
    -------
    Run
        Also when the run ends ``failed``: its ``status`` and ``record.reason`` say why and
        what was measured stays stored.
    """
    from goniolab.app.lab_scan import scan
    from goniolab.app.lab_setup import brdf_plan, load_config, open_store, run_meta
    from goniolab.app.lab_setup import store_location as location_of
    from goniolab.progress import auto_progress

    cfg = load_config(config)
    plan = brdf_plan(
        cfg, sample=sample or cfg.sample.map, theta_i_deg=theta_i_deg, theta_r_deg=theta_r_deg,
        repeats=repeats, dwell_s=dwell_s, exposure_us=exposure_us, auto_exposure=auto_exposure,
        what="run_scan", angles_option="theta_r_deg",
    )  # fmt: skip
    location = location_of(store, cfg.lab.store)
    control = _CONTROL.get()
    reporter = auto_progress() if progress else None

    def started(runner: Any) -> None:
        if reporter is not None:
            reporter.label = f"run {runner.run_id}"
        if control is not None:
            control.loop, control.runner = asyncio.get_running_loop(), runner

    # opened in the running thread (an SQLite connection stays in the thread that made it)
    with open_store(location) as rs:
        out = await scan(
            cfg, rs, plan, time_scale=time_scale, reporter=reporter, on_start=started,
            meta=run_meta(operator, sample_id, notes, tags),
        )  # fmt: skip
    return Run(out.run_id, location)


run_scan = _blocking(run_scan_async)
run_scan.__doc__ = (
    "Run an in-plane scan in one call (blocking) and return the stored :class:`Run`.\n\n"
    "Works from a script and from a notebook cell (whose event loop is already running: the\n"
    "scan then runs on its own loop in a worker thread, the store opened there). In a\n"
    "notebook, ``await run_scan_async(...)`` runs it on the notebook's loop instead.\n"
    "Interrupting the kernel aborts the scan (arms stopped and parked, the run stored\n"
    "``aborted``) and returns that run.\n\n"
    # the parameters and result of run_scan_async (python -OO strips both docstrings)
    + (run_scan_async.__doc__ or "\n\n").split("\n\n", 1)[1]
)
