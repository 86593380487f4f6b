"""xarray views of height maps, predictions and stored runs (the notebook face's data).

Every object follows xarray's own Dataset conventions: named dimensions (``theta_r_deg``,
``repeat``, ``wavelength_nm``, ``y_um``/``x_um``), coordinates and variables carrying a
CF-style ``units`` attribute and a ``long_name``, and the provenance (sample, model, plan,
run status, goniolab version) as attributes, so that ``ds.to_netcdf`` writes a file any
netCDF reader understands.

xarray, pandas and numpy-datetime handling are imported inside the functions: importing this
module costs nothing at ``goniolab --help``.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:  # pragma: no cover - typing only
    import xarray as xr

    from goniolab.optics.gloss_standards import GlossReport
    from goniolab.optics.heightmap import HeightMap
    from goniolab.store import RunRecord, RunStore

__all__ = [
    "UNITS",
    "brdf_dataset",
    "gloss_dataset",
    "heightmap_dataarray",
    "iso_utc",
    "netcdf_attrs",
    "run_dataset",
    "to_datetime64",
    "write_netcdf",
]

#: Units (CF / UDUNITS spelling) of every variable goniolab writes, by variable name.
UNITS: dict[str, str] = {
    "theta_i_deg": "degree",
    "theta_r_deg": "degree",
    "aspecular_deg": "degree",
    "measured_theta_i_deg": "degree",
    "measured_theta_r_deg": "degree",
    "geometry_deg": "degree",
    "luminance_pct": "percent",
    "luminance_mean_pct": "percent",
    "luminance_std_pct": "percent",
    "predicted_pct": "percent",
    "residual_pct": "percent",
    "mirror_pct": "percent",
    "reflectance_pct": "percent",
    "brdf_sr": "sr-1",
    "wavelength_nm": "nm",
    "x_um": "um",
    "y_um": "um",
    "height_um": "um",
    "gloss_gu": "GU",
    "predicted_gloss_gu": "GU",
    "g20_gu": "GU",
    "g60_gu": "GU",
    "g85_gu": "GU",
    "predicted_g20_gu": "GU",
    "predicted_g60_gu": "GU",
    "predicted_g85_gu": "GU",
    "temperature_c": "degC",
    "X": "1",
    "Y": "1",
    "Z": "1",
    "L_star": "1",
    "a_star": "1",
    "b_star": "1",
    "C_star": "1",
    "h_deg": "degree",
    "predicted_L_star": "1",
    "predicted_a_star": "1",
    "predicted_b_star": "1",
}

_LONG_NAMES: dict[str, str] = {
    "theta_i_deg": "lamp (incidence) angle from the sample normal",
    "theta_r_deg": "detector angle from the sample normal (> 0 on the specular side)",
    "aspecular_deg": "aspecular angle theta_r - theta_i (0 = specular direction)",
    "measured_theta_i_deg": "lamp arm angle read back at the reading",
    "measured_theta_r_deg": "detector arm angle read back at the reading",
    "luminance_pct": "relative luminance, % of a mirror",
    "luminance_mean_pct": "mean of the repeats",
    "luminance_std_pct": "standard deviation of the repeats (ddof = 1)",
    "predicted_pct": "model prediction of the relative luminance",
    "residual_pct": "mean measured minus predicted",
    "reflectance_pct": "spectral reflectance factor, % of the reference",
    "brdf_sr": "in-plane BRDF",
    "time": "time of the reading (UTC)",
    "L_star": "CIE 1976 L*",
    "a_star": "CIE 1976 a*",
    "b_star": "CIE 1976 b*",
    "C_star": "CIE 1976 chroma C*ab",
    "h_deg": "CIE 1976 hue angle h_ab",
    "X": "CIE XYZ tristimulus X",
    "Y": "CIE XYZ tristimulus Y",
    "Z": "CIE XYZ tristimulus Z",
    "predicted_L_star": "predicted CIE 1976 L*",
    "predicted_a_star": "predicted CIE 1976 a*",
    "predicted_b_star": "predicted CIE 1976 b*",
    "gloss_gu": "specular gloss, ISO 2813 (gloss units)",
    "predicted_gloss_gu": "predicted specular gloss, ISO 2813",
    "temperature_c": "instrument temperature",
    "height_um": "surface height",
}

#: Measured colour of a point as the store keeps it (issue 11) -> the variable name.
_COLOUR_VARS: tuple[tuple[str, str], ...] = (
    ("X", "X"),
    ("Y", "Y"),
    ("Z", "Z"),
    ("L", "L_star"),
    ("a", "a_star"),
    ("b", "b_star"),
    ("C", "C_star"),
    ("h_deg", "h_deg"),
)


def _attrs(name: str, **extra: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if name in UNITS:
        out["units"] = UNITS[name]
    if name in _LONG_NAMES:
        out["long_name"] = _LONG_NAMES[name]
    out.update(extra)
    return out


def iso_utc(ts: float | None) -> str:
    """ISO 8601 UTC time of a Unix timestamp (``2026-01-31T12:00:00.250000+00:00``);
    ``""`` for ``None``."""
    if ts is None:
        return ""
    return dt.datetime.fromtimestamp(ts, tz=dt.UTC).isoformat(timespec="microseconds")


def to_datetime64(ts: Sequence[float | None]) -> NDArray[np.datetime64]:
    """Unix timestamps (s) to ``datetime64[ns]`` in UTC, ``NaT`` for missing ones."""
    out = np.full(len(ts), np.datetime64("NaT"), dtype="datetime64[ns]")
    for k, t in enumerate(ts):
        if t is not None and math.isfinite(t):
            out[k] = np.datetime64(round(t * 1e9), "ns")
    return out


def _dumps(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)


def netcdf_attrs(attrs: Mapping[str, Any]) -> dict[str, Any]:
    """Attributes a netCDF file can hold: ``None`` dropped, booleans as 0/1, mappings and
    lists of non-numbers as JSON text."""
    out: dict[str, Any] = {}
    for k, v in attrs.items():
        if v is None:
            continue
        if isinstance(v, bool | np.bool_):
            out[k] = int(v)
        elif isinstance(v, str | int | float | np.integer | np.floating):
            out[k] = v
        elif isinstance(v, list | tuple) and v and all(isinstance(x, int | float) for x in v):
            out[k] = np.asarray(v)
        else:
            out[k] = _dumps(v)
    return out


def write_netcdf(ds: xr.Dataset, path: str | Path) -> Path:
    """Write ``ds`` as netCDF-4 (h5netcdf engine), attributes made storable.

    Raises
    ------
    OSError
        The file cannot be written.
    """
    out = ds.copy()
    out.attrs = netcdf_attrs(out.attrs)
    for name in list(out.variables):
        out[name].attrs = netcdf_attrs(out[name].attrs)
    target = Path(path)
    out.to_netcdf(target, engine="h5netcdf", invalid_netcdf=False)
    return target


# --------------------------------------------------------------------------- height maps
def heightmap_dataarray(hm: HeightMap) -> xr.DataArray:
    """A height map as a DataArray ``height_um`` with dims ``(y_um, x_um)``.

    Coordinates are the lateral positions in micrometres from the first point; attributes
    hold the steps, the source and the file's own metadata (``meta_*``).
    """
    import xarray as xr

    ny, nx = hm.z_um.shape
    attrs = _attrs(
        "height_um",
        source=hm.source,
        dx_um=float(hm.dx_um),
        dy_um=float(hm.dy_um),
    )
    attrs.update({f"meta_{k}": str(v) for k, v in hm.meta.items()})
    return xr.DataArray(
        np.array(hm.z_um, dtype=np.float64),
        dims=("y_um", "x_um"),
        coords={
            "y_um": ("y_um", np.arange(ny) * float(hm.dy_um), _attrs("y_um")),
            "x_um": ("x_um", np.arange(nx) * float(hm.dx_um), _attrs("x_um")),
        },
        name="height_um",
        attrs=attrs,
    )


# --------------------------------------------------------------------------- predictions
def brdf_dataset(
    theta_i_deg: float,
    theta_r_deg: Sequence[float] | NDArray[np.float64],
    brdf_sr: Sequence[float] | NDArray[np.float64],
    luminance_pct: Sequence[float] | NDArray[np.float64] | None = None,
    *,
    attrs: Mapping[str, Any] | None = None,
) -> xr.Dataset:
    """The predicted in-plane curve as a Dataset along ``theta_r_deg``.

    Variables ``brdf_sr`` (1/sr) and, for a goniometer prediction through apertures,
    ``luminance_pct`` (% of a mirror); ``theta_i_deg`` and ``aspecular_deg`` are
    coordinates. ``attrs`` (sample, index, cones, model) are stored on the Dataset.
    """
    import xarray as xr

    tr = np.asarray(theta_r_deg, dtype=np.float64)
    data: dict[str, Any] = {"brdf_sr": ("theta_r_deg", np.asarray(brdf_sr), _attrs("brdf_sr"))}
    if luminance_pct is not None:
        data["luminance_pct"] = (
            "theta_r_deg",
            np.asarray(luminance_pct, dtype=np.float64),
            _attrs("luminance_pct", long_name="predicted relative luminance, % of a mirror"),
        )
    coords = {
        "theta_r_deg": ("theta_r_deg", tr, _attrs("theta_r_deg")),
        "theta_i_deg": ((), float(theta_i_deg), _attrs("theta_i_deg")),
        "aspecular_deg": ("theta_r_deg", tr - float(theta_i_deg), _attrs("aspecular_deg")),
    }
    ds = xr.Dataset(data, coords=coords)
    ds.attrs = {"title": "goniolab in-plane BRDF prediction", **dict(attrs or {})}
    return ds


def gloss_dataset(report: GlossReport, *, attrs: Mapping[str, Any] | None = None) -> xr.Dataset:
    """ISO 2813 gloss along ``geometry_deg`` (20, 60, 85) with the haze and DOI readings of
    ASTM D4039 / E430 as scalar variables (:func:`goniolab.optics.gloss_standards.gloss_report`)."""
    import xarray as xr

    e = report.e430
    scalars: dict[str, tuple[float, str]] = {
        "haze_index": (report.haze_index, "ASTM D4039 haze index G60 - G85"),
        "e430_gloss_20": (e.gloss_20, "ASTM E430 method B specular gloss at 20 deg"),
        "e430_haze_18_1": (e.haze_18_1, "ASTM E430 method B haze at 18.1 deg"),
        "e430_haze_21_9": (e.haze_21_9, "ASTM E430 method B haze at 21.9 deg"),
        "e430_haze_b": (e.haze_b, "ASTM E430 method B haze (mean)"),
        "e430_rs_30": (e.gloss_30, "ASTM E430 method A specular reading Rs at 30 deg"),
        "e430_haze_narrow": (e.haze_narrow, "ASTM E430 method A narrow-angle haze"),
        "e430_haze_wide": (e.haze_wide, "ASTM E430 method A wide-angle haze"),
        "doi": (e.doi, "distinctness of image 100 (Rs - R0.3) / Rs, ASTM E430"),
    }
    data: dict[str, Any] = {
        "gloss_gu": (
            "geometry_deg",
            np.array([report.G20, report.G60, report.G85]),
            _attrs("gloss_gu", long_name="predicted specular gloss, ISO 2813"),
        )
    }
    for name, (value, long_name) in scalars.items():
        data[name] = ((), float(value), {"units": "1", "long_name": long_name})
    ds = xr.Dataset(
        data,
        coords={"geometry_deg": ("geometry_deg", np.array([20, 60, 85]), _attrs("geometry_deg"))},
    )
    ds.attrs = {
        "title": "goniolab gloss prediction (ISO 2813, ASTM D523/D4039/E430)",
        "d523_recommended_angle_deg": int(report.d523_recommended_angle),
        **dict(attrs or {}),
    }
    return ds


# --------------------------------------------------------------------------- stored runs
def _run_attrs(store: RunStore, rec: RunRecord) -> dict[str, Any]:
    return {
        "title": f"goniolab run {rec.id} ({rec.kind}) on {rec.sample or '-'}",
        "Conventions": "CF-1.10",
        "source": f"goniolab {rec.version}",
        "run_id": rec.id,
        "kind": rec.kind,
        "sample": rec.sample,
        "status": rec.status,
        "reason": rec.reason,
        "goniolab_version": rec.version,
        "created_at": iso_utc(rec.created_at),
        "updated_at": iso_utc(rec.updated_at),
        "finished_at": iso_utc(rec.finished_at),
        "store": store_label(store),
        "plan_json": _dumps(rec.plan),
        "model_json": _dumps(rec.model),
        "config_json": _dumps(rec.config),
    }


def store_label(store: RunStore) -> str:
    """How a store names itself in files and messages (a URL without its password)."""
    label = getattr(store, "location", None)
    return str(label if label is not None else store.path)


def run_dataset(store: RunStore, run_id: int) -> xr.Dataset:
    """Stored run ``run_id`` as a Dataset.

    A scan (``kind = brdf``) has dims ``(theta_r_deg, repeat)`` (and ``wavelength_nm`` for
    the spectra): ``luminance_pct`` per reading (NaN where none is stored yet), its
    ``time`` and read-back arm angles, per geometry ``luminance_mean_pct``,
    ``luminance_std_pct``, ``predicted_pct`` and ``residual_pct``; with colour data (a
    spectro that reports spectra) also ``L_star``, ``a_star``, ``b_star`` ... per reading.
    A gloss log has dim ``reading`` with ``g20_gu``, ``g60_gu``, ``g85_gu`` and their
    predictions. The run's plan, model, config snapshot and status are attributes.
    """
    rec = store.get_run(run_id)
    if rec.kind == "gloss":
        return _gloss_run_dataset(store, rec)
    if rec.kind in ("align", "calibration"):
        return _align_run_dataset(store, rec)
    return _brdf_run_dataset(store, rec)


def _align_run_dataset(store: RunStore, rec: RunRecord) -> xr.Dataset:
    """An alignment run (``kind = align``, :mod:`goniolab.scan.align`): one row per reading
    (dim ``reading``) with its geometry, luminance, specimen (standard or sample), sweep
    phase (coarse or fine), exposure and quality flag; the result in ``alignment_json``."""
    import xarray as xr

    pts = store.points(rec.id)
    text = {"specimen": "specimen under the instruments", "phase": "sweep (coarse or fine)",
            "quality": "reading quality flag (ok, saturated, under_noise_floor, unknown)"}  # fmt: skip
    data: dict[str, Any] = {
        "time": ("reading", to_datetime64([p.timestamp for p in pts]),
                 {"long_name": _LONG_NAMES["time"]}),
        "theta_i_deg": ("reading", np.array([p.theta_i_deg for p in pts], dtype=np.float64),
                        _attrs("theta_i_deg")),
        "theta_r_deg": ("reading", np.array([p.theta_r_deg for p in pts], dtype=np.float64),
                        _attrs("theta_r_deg")),
        "luminance_pct": ("reading", np.array([p.luminance_pct for p in pts], dtype=np.float64),
                          _attrs("luminance_pct")),
        "exposure_us": ("reading", np.array([float(p.raw.get("exposure_us") or np.nan)
                                             for p in pts]), {"long_name": "exposure", "units": "us"}),
    }  # fmt: skip
    for key, long_name in text.items():
        data[key] = ("reading", np.array([str(p.raw.get(key, "")) for p in pts], dtype=str),
                     {"long_name": long_name})  # fmt: skip
    ds = xr.Dataset(
        data, coords={"reading": ("reading", np.array([p.index for p in pts], dtype=np.int64))}
    )
    ds.attrs = {
        **_run_attrs(store, rec),
        "stored_readings": len(pts),
        "alignment_json": _dumps(rec.model.get("alignment", {})),
        "calibration_json": _dumps(rec.model.get("calibration", {})),
    }
    return ds


def _brdf_run_dataset(store: RunStore, rec: RunRecord) -> xr.Dataset:
    import xarray as xr

    from goniolab.scan.plans import MIRROR_INDEX, BrdfPlan

    plan = BrdfPlan.from_dict(rec.plan)
    tr = np.asarray(plan.theta_r_deg, dtype=np.float64)
    n, reps = tr.size, plan.repeats
    shape = (n, reps)
    lum = np.full(shape, np.nan)
    mti = np.full(shape, np.nan)
    mtr = np.full(shape, np.nan)
    times: list[list[float | None]] = [[None] * reps for _ in range(n)]
    mirror = np.full(reps, np.nan)
    points = store.points(rec.id)
    # spectra: kept when every reading shares one wavelength grid
    grids = {tuple(p.raw.get("wavelengths_nm") or ()) for p in points if p.index >= 0}
    grid = next(iter(grids)) if len(grids) == 1 else ()
    spec = np.full((n, reps, len(grid)), np.nan) if grid else None
    colour: dict[str, NDArray[np.float64]] = {}
    for p in points:
        if p.index == MIRROR_INDEX:
            if 0 <= p.repeat < reps:
                mirror[p.repeat] = p.luminance_pct
            continue
        if not (0 <= p.index < n and 0 <= p.repeat < reps):
            continue
        k, r = p.index, p.repeat
        lum[k, r] = p.luminance_pct
        mti[k, r] = p.measured_theta_i_deg
        mtr[k, r] = p.measured_theta_r_deg
        times[k][r] = p.timestamp
        values = p.raw.get("values")
        if spec is not None and values is not None and len(values) == len(grid):
            spec[k, r, :] = np.asarray(values, dtype=np.float64)
        measured = getattr(p, "colour", None)  # issue 11's colour columns, when present
        if measured:
            for key, name in _COLOUR_VARS:
                if key in measured and measured[key] is not None:
                    colour.setdefault(name, np.full(shape, np.nan))[k, r] = float(measured[key])
    preds = store.predictions(rec.id)
    predicted = np.array([preds.get(k, np.nan) for k in range(n)], dtype=np.float64)
    counts = np.sum(np.isfinite(lum), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        sums = np.nansum(lum, axis=1)
        mean = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
        dev = np.where(np.isfinite(lum), lum - mean[:, None], 0.0)
        var = np.sum(dev**2, axis=1) / np.maximum(counts - 1, 1)
    std = np.where(counts > 1, np.sqrt(var), np.nan)
    dims = ("theta_r_deg", "repeat")
    data: dict[str, Any] = {
        "luminance_pct": (dims, lum, _attrs("luminance_pct")),
        "measured_theta_i_deg": (dims, mti, _attrs("measured_theta_i_deg")),
        "measured_theta_r_deg": (dims, mtr, _attrs("measured_theta_r_deg")),
        "time": (
            dims,
            to_datetime64([t for row in times for t in row]).reshape(shape),
            {"long_name": _LONG_NAMES["time"]},
        ),
        "luminance_mean_pct": ("theta_r_deg", mean, _attrs("luminance_mean_pct")),
        "luminance_std_pct": ("theta_r_deg", std, _attrs("luminance_std_pct")),
        "n_readings": ("theta_r_deg", counts.astype(np.int64), {"units": "1"}),
        "predicted_pct": ("theta_r_deg", predicted, _attrs("predicted_pct")),
        "residual_pct": ("theta_r_deg", mean - predicted, _attrs("residual_pct")),
    }
    if spec is not None:
        data["reflectance_pct"] = ((*dims, "wavelength_nm"), spec, _attrs("reflectance_pct"))
    if plan.mirror_reference:
        data["mirror_pct"] = (
            "repeat",
            mirror,
            _attrs("mirror_pct", long_name="raw reading of the reference mirror (sets 100 %)"),
        )
    for name, arr in colour.items():
        data[name] = (dims, arr, _attrs(name))
    for name, arr in _predicted_colour(store, rec.id, n).items():
        data[name] = ("theta_r_deg", arr, _attrs(name))
    coords: dict[str, Any] = {
        "theta_r_deg": ("theta_r_deg", tr, _attrs("theta_r_deg")),
        "repeat": ("repeat", np.arange(reps), {"long_name": "repeat number"}),
        "theta_i_deg": ((), float(plan.theta_i_deg), _attrs("theta_i_deg")),
        "aspecular_deg": ("theta_r_deg", tr - float(plan.theta_i_deg), _attrs("aspecular_deg")),
    }
    if grid:
        coords["wavelength_nm"] = (
            "wavelength_nm",
            np.asarray(grid, dtype=np.float64),
            _attrs("wavelength_nm"),
        )
    ds = xr.Dataset(data, coords=coords)
    ds.attrs = {
        **_run_attrs(store, rec),
        "theta_i_deg": float(plan.theta_i_deg),
        "repeats": int(reps),
        "planned_readings": int(n * reps),
        "stored_readings": int(np.sum(counts)),
    }
    return ds


def _predicted_colour(store: RunStore, run_id: int, n: int) -> dict[str, NDArray[np.float64]]:
    """Predicted L*a*b* per geometry when the store keeps it (issue 11), else nothing."""
    getter = getattr(store, "predicted_colours", None)
    if getter is None:
        return {}
    rows = getter(run_id)
    if not rows:
        return {}
    out = {name: np.full(n, np.nan) for name in _PREDICTED_COLOUR_NAMES.values()}
    for idx, pc in rows.items():
        if 0 <= int(idx) < n:
            for attr, name in _PREDICTED_COLOUR_NAMES.items():
                value = getattr(pc, attr, None)
                if value is not None:
                    out[name][int(idx)] = float(value)
    return out


_PREDICTED_COLOUR_NAMES = {
    "L": "predicted_L_star",
    "a": "predicted_a_star",
    "b": "predicted_b_star",
}


def _gloss_run_dataset(store: RunStore, rec: RunRecord) -> xr.Dataset:
    import xarray as xr

    rows = store.gloss_readings(rec.id)
    m = len(rows)
    data: dict[str, Any] = {
        "time": (
            "reading",
            to_datetime64([g.timestamp for g in rows]),
            {"long_name": _LONG_NAMES["time"]},
        ),
        "temperature_c": (
            "reading",
            np.array([np.nan if g.temperature_c is None else g.temperature_c for g in rows]),
            _attrs("temperature_c"),
        ),
    }
    for angle in (20, 60, 85):
        measured = [g.values_gu.get(angle) for g in rows]
        predicted = [None if g.predicted_gu is None else g.predicted_gu.get(angle) for g in rows]
        data[f"g{angle}_gu"] = (
            "reading",
            np.array([np.nan if v is None else float(v) for v in measured]),
            _attrs(f"g{angle}_gu", long_name=f"measured {angle} deg gloss, ISO 2813"),
        )
        data[f"predicted_g{angle}_gu"] = (
            "reading",
            np.array([np.nan if v is None else float(v) for v in predicted]),
            _attrs(f"predicted_g{angle}_gu", long_name=f"predicted {angle} deg gloss"),
        )
    ds = xr.Dataset(
        data,
        coords={"reading": ("reading", np.array([g.seq for g in rows], dtype=np.int64))}
        if m
        else {"reading": ("reading", np.zeros(0, dtype=np.int64))},
    )
    ds.attrs = {**_run_attrs(store, rec), "stored_readings": m}
    return ds
