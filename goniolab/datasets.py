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

# the spectra of a stored run (its own module since issue 25; their names stay importable
# from here)
from goniolab.run_spectra import (
    RunSpectra,
    predicted_grid_nm,
    run_reflectance_factors,
    run_spectra,
)

if TYPE_CHECKING:  # pragma: no cover - typing only
    import xarray as xr

    from goniolab.optics.gloss_standards import GlossReport
    from goniolab.optics.heightmap import HeightMap
    from goniolab.store import RunRecord, RunStore

__all__ = [
    "LONG_NAMES",
    "UNITS",
    "aspecular_of",
    "brdf_dataset",
    "cf_dataset",
    "gloss_dataset",
    "heightmap_dataarray",
    "iso_utc",
    "netcdf_attrs",
    "open_dataset",
    "predicted_grid_nm",
    "run_dataset",
    "run_reflectance_factors",
    "run_spectra",
    "to_datetime64",
    "write_netcdf",
]

#: Gloss units (GU, ISO 2813: 100 = the polished black glass of n = 1.567) are a scale,
#: not a unit UDUNITS knows ("GU" parses as giga-U, pint reads enzyme units): gloss is
#: dimensionless ``"1"`` and its long_name and ``units_metadata`` say "gloss units".
GLOSS_UNITS = "1"
#: The ``units_metadata`` of every gloss variable (what the number is a multiple of).
GLOSS_UNITS_METADATA = "gloss units (GU), ISO 2813: 100 GU = polished black glass, n = 1.567"

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
    "reflectance_factor": "1",
    "predicted_reflectance_factor": "1",
    "brdf_sr": "sr-1",
    "wavelength_nm": "nm",
    "x_um": "um",
    "y_um": "um",
    "height_um": "um",
    "gloss_gu": GLOSS_UNITS,
    "predicted_gloss_gu": GLOSS_UNITS,
    "g20_gu": GLOSS_UNITS,
    "g60_gu": GLOSS_UNITS,
    "g85_gu": GLOSS_UNITS,
    "predicted_g20_gu": GLOSS_UNITS,
    "predicted_g60_gu": GLOSS_UNITS,
    "predicted_g85_gu": GLOSS_UNITS,
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

#: CF ``long_name`` of every variable goniolab writes, by variable name (shared with the
#: colour export of ``goniolab fit``/``render``).
LONG_NAMES: dict[str, str] = {
    "theta_i_deg": "lamp (incidence) angle from the sample normal",
    "theta_r_deg": "detector angle from the sample normal (> 0 on the specular side)",
    "aspecular_deg": (
        "aspecular angle theta_i - theta_r, ASTM E2194 / DIN 6175-2 (0 = specular, "
        "> 0 towards the lamp)"
    ),
    "measured_theta_i_deg": "lamp arm angle read back at the reading",
    "measured_theta_r_deg": "detector arm angle read back at the reading",
    "luminance_pct": "relative luminance, % of a mirror",
    "luminance_mean_pct": "mean of the repeats",
    "luminance_std_pct": "standard deviation of the repeats (ddof = 1)",
    "predicted_pct": "model prediction of the relative luminance",
    "residual_pct": "mean measured minus predicted",
    "reflectance_pct": (
        "spectral reading as the spectro reports it, % of its own reference, before the "
        "certified-mirror referencing and the detector-cone scale: not a reflectance factor"
    ),
    "reflectance_factor": (
        "measured spectral reflectance factor (1 = perfect reflecting diffuser, "
        "CIE 15:2004 sec. 3.3) at the geometry"
    ),
    "predicted_reflectance_factor": (
        "predicted spectral reflectance factor (1 = perfect reflecting diffuser)"
    ),
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
    "gloss_gu": "specular gloss, ISO 2813, in gloss units",
    "predicted_gloss_gu": "predicted specular gloss, ISO 2813, in gloss units",
    "temperature_c": "instrument temperature",
    "height_um": "surface height",
    "x_um": "lateral position along the map's rows",
    "y_um": "lateral position along the map's columns",
    "geometry_deg": "ISO 2813 gloss geometry (incidence = reception angle)",
    "wavelength_nm": "wavelength",
    "mirror_pct": "raw reading of the reference mirror (sets 100 %)",
    "n_readings": "readings stored at the geometry",
    "reading": "reading number of the gloss log",
    "repeat": "repeat number",
    "g20_gu": "measured 20 deg specular gloss, ISO 2813, in gloss units",
    "g60_gu": "measured 60 deg specular gloss, ISO 2813, in gloss units",
    "g85_gu": "measured 85 deg specular gloss, ISO 2813, in gloss units",
    "predicted_g20_gu": "predicted 20 deg specular gloss, ISO 2813, in gloss units",
    "predicted_g60_gu": "predicted 60 deg specular gloss, ISO 2813, in gloss units",
    "predicted_g85_gu": "predicted 85 deg specular gloss, ISO 2813, in gloss units",
}

#: Variables in gloss units (their ``units`` is "1", see :data:`GLOSS_UNITS`).
_GLOSS_VARS = frozenset(k for k, v in UNITS.items() if k.endswith("_gu") and v == GLOSS_UNITS)

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


def aspecular_of(theta_r_deg: Any, theta_i_deg: float) -> NDArray[np.float64]:
    """ASTM E2194 / DIN 6175-2 aspecular angles of signed detector angles: the core's
    ``theta_i - theta_r`` (:func:`goniolab.colour.multiangle.aspecular_deg`; 15 deg
    aspecular = theta_r 30 at theta_i 45, -15 = beyond the specular direction)."""
    out: NDArray[np.float64] = float(theta_i_deg) - np.asarray(theta_r_deg, dtype=np.float64)
    return out


def _attrs(name: str, **extra: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if name in UNITS:
        out["units"] = UNITS[name]
    if name in LONG_NAMES:
        out["long_name"] = LONG_NAMES[name]
    if name in _GLOSS_VARS:
        out["units_metadata"] = GLOSS_UNITS_METADATA
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


#: The CF version goniolab's netCDF files follow (checked by tests/test_cf_files.py).
CF_CONVENTIONS = "CF-1.8"
#: Time in netCDF files: seconds since the Unix epoch (UDUNITS: UTC midnight), float64 (microseconds exact until
#: 2255); ``nanoseconds since`` (xarray's default for datetime64[ns]) is refused by cftime
#: and by UDUNITS-based readers (issue 22.11).
TIME_UNITS = "seconds since 1970-01-01"


def cf_dataset(ds: xr.Dataset, *, history: str | None = None) -> xr.Dataset:
    """A copy of ``ds`` ready for a CF-conventions netCDF file (CF-1.8, UDUNITS units).

    - attributes made storable (:func:`netcdf_attrs`);
    - ``time`` variables encoded as float64 :data:`TIME_UNITS`, calendar ``standard``,
      ``standard_name = "time"``;
    - no ``_FillValue`` on coordinate variables (CF 2.5.1: coordinates have no missing
      values; xarray adds NaN fills to float coordinates by default), ``units = "1"`` on an
      integer coordinate that has none (an index or a count);
    - text variables as char arrays (CF 2.2 has no variable-length strings);
    - every variable with a ``long_name``, ``Conventions`` and a ``history`` line (CF 2.6.2)
      prepended to any the data already had.
    """
    from goniolab._version import __version__

    out = ds.copy()
    out.attrs = netcdf_attrs(out.attrs)
    out.attrs["Conventions"] = CF_CONVENTIONS
    now = dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    line = f"{now} goniolab {__version__}: {history or 'written by goniolab.datasets'}"
    previous = str(ds.attrs.get("history", "")).strip()
    out.attrs["history"] = line + ("\n" + previous if previous else "")
    for name in list(out.variables):
        var = out[name]
        attrs = netcdf_attrs(var.attrs)
        attrs.setdefault("long_name", LONG_NAMES.get(str(name), str(name).replace("_", " ")))
        encoding = dict(var.encoding)
        if np.issubdtype(var.dtype, np.datetime64):
            attrs.pop("units", None)
            attrs.pop("calendar", None)
            attrs["standard_name"] = "time"
            encoding.update(units=TIME_UNITS, calendar="standard", dtype="float64")
        if name in out.coords:
            encoding["_FillValue"] = None
            if var.dtype.kind in "iu" and "units" not in attrs:
                attrs["units"] = "1"  # an index or a count (row, repeat, reading number)
        if var.dtype.kind in "UO":
            # text as a char array (CF 2.2: netCDF-4 variable-length strings are not CF)
            encoding["dtype"] = "S1"
        var.attrs = attrs
        var.encoding = encoding
    return out


def write_netcdf(ds: xr.Dataset, path: str | Path, *, history: str | None = None) -> Path:
    """Write ``ds`` as a CF-conventions netCDF-4 file (h5netcdf engine, :func:`cf_dataset`).

    ``history`` says what made the file (``runs export 3``); it is prepended, dated, to the
    Dataset's own history.

    Raises
    ------
    OSError
        The file cannot be written.
    """
    out = cf_dataset(ds, history=history)
    # built in memory, then replaced whole: a full disk never meets HDF5 (which crashed
    # the process) and never destroys an existing file (goniolab._atomic)
    from goniolab._atomic import atomic_write_bytes

    data = out.to_netcdf(engine="h5netcdf", invalid_netcdf=False)
    return atomic_write_bytes(path, bytes(data))


def open_dataset(path: str | Path) -> xr.Dataset:
    """Read back a netCDF file goniolab wrote (a run export, a prediction).

    Times decode to ``datetime64`` (UTC), the JSON attributes (``plan_json``,
    ``model_json``, ``config_json``) stay text as written; the data are loaded and the
    file closed, so it may be overwritten afterwards.

    Raises
    ------
    OSError
        The file cannot be read or is not netCDF.
    """
    import xarray as xr

    target = Path(path)
    try:
        with xr.open_dataset(target, engine="h5netcdf") as ds:
            return ds.load()
    except (OSError, ValueError) as exc:
        raise OSError(f"{target}: not a netCDF file goniolab can read: {exc}") from exc


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
        "aspecular_deg": ("theta_r_deg", aspecular_of(tr, theta_i_deg), _attrs("aspecular_deg")),
    }
    ds = xr.Dataset(data, coords=coords)
    ds.attrs = {"title": "goniolab in-plane BRDF prediction", **dict(attrs or {})}
    return ds


def gloss_dataset(report: GlossReport, *, attrs: Mapping[str, Any] | None = None) -> xr.Dataset:
    """ISO 2813 gloss along ``geometry_deg`` (20, 60, 85) with the haze and DOI readings of
    ASTM D4039 / E430 as scalar variables (:func:`goniolab.optics.gloss_standards.gloss_report`)."""
    import xarray as xr

    e = report.e430
    # every reading but DOI is on the gloss-unit scale (E430 sec. 3: haze and Rs in GU as
    # read by the instrument); DOI is a 0-100 index, 100 (Rs - R0.3) / Rs
    gu = ", in gloss units"
    scalars: dict[str, tuple[float, str]] = {
        "haze_index": (report.haze_index, "ASTM D4039 haze index G60 - G20" + gu),
        "e430_gloss_20": (e.gloss_20, "ASTM E430 method B specular gloss at 20 deg" + gu),
        "e430_haze_18_1": (e.haze_18_1, "ASTM E430 method B haze at 18.1 deg" + gu),
        "e430_haze_21_9": (e.haze_21_9, "ASTM E430 method B haze at 21.9 deg" + gu),
        "e430_haze_b": (e.haze_b, "ASTM E430 method B haze (mean)" + gu),
        "e430_rs_30": (e.gloss_30, "ASTM E430 method A specular reading Rs at 30 deg" + gu),
        "e430_haze_narrow": (e.haze_narrow, "ASTM E430 method A narrow-angle haze" + gu),
        "e430_haze_wide": (e.haze_wide, "ASTM E430 method A wide-angle haze" + gu),
        "doi": (e.doi, "distinctness of image 100 (Rs - R0.3) / Rs, ASTM E430, of 100"),
    }
    data: dict[str, Any] = {
        "gloss_gu": (
            "geometry_deg",
            np.array([report.G20, report.G60, report.G85]),
            _attrs("gloss_gu", long_name="predicted specular gloss, ISO 2813, in gloss units"),
        )
    }
    for name, (value, long_name) in scalars.items():
        extra = {} if name == "doi" else {"units_metadata": GLOSS_UNITS_METADATA}
        data[name] = ((), float(value), {"units": "1", "long_name": long_name, **extra})
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
        "Conventions": CF_CONVENTIONS,
        "source": f"goniolab {rec.version}",
        "run_id": rec.id,
        "run_uuid": getattr(rec, "uuid", ""),
        "kind": rec.kind,
        "sample": rec.sample,
        "sample_id": getattr(rec, "sample_id", ""),
        "operator": getattr(rec, "operator", ""),
        "notes": getattr(rec, "notes", ""),
        "tags": ", ".join(getattr(rec, "tags", ())),
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
    if rec.kind in ("align", "calibration", "glosscal"):  # glosscal: no readings, its record
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
                 {"long_name": LONG_NAMES["time"]}),
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
            {"long_name": LONG_NAMES["time"]},
        ),
        "luminance_mean_pct": ("theta_r_deg", mean, _attrs("luminance_mean_pct")),
        "luminance_std_pct": ("theta_r_deg", std, _attrs("luminance_std_pct")),
        "n_readings": ("theta_r_deg", counts.astype(np.int64), _attrs("n_readings", units="1")),
        "predicted_pct": ("theta_r_deg", predicted, _attrs("predicted_pct")),
        "residual_pct": ("theta_r_deg", mean - predicted, _attrs("residual_pct")),
    }
    if spec is not None:
        data["reflectance_pct"] = ((*dims, "wavelength_nm"), spec, _attrs("reflectance_pct"))
    spectra = run_spectra(store, rec.id, points)
    factors, predicted_factors = spectra.measured, spectra.predicted
    labels = _spectrum_attrs(spectra)
    if spec is not None and factors.shape[-1] == spec.shape[-1]:
        data["reflectance_factor"] = (
            (*dims, "wavelength_nm"),
            factors,
            _attrs("reflectance_factor", **labels),
        )
    if predicted_factors is not None:
        data["predicted_reflectance_factor"] = (
            ("theta_r_deg", "predicted_wavelength_nm"),
            predicted_factors,
            _attrs("predicted_reflectance_factor", **labels),
        )
    if plan.mirror_reference:
        data["mirror_pct"] = (
            "repeat",
            mirror,
            _attrs("mirror_pct"),
        )
    for name, arr in colour.items():
        data[name] = (dims, arr, _attrs(name))
    for name, arr in _predicted_colour(store, rec.id, n).items():
        data[name] = ("theta_r_deg", arr, _attrs(name))
    coords: dict[str, Any] = {
        "theta_r_deg": ("theta_r_deg", tr, _attrs("theta_r_deg")),
        "repeat": ("repeat", np.arange(reps), _attrs("repeat", units="1")),
        "theta_i_deg": ((), float(plan.theta_i_deg), _attrs("theta_i_deg")),
        "aspecular_deg": (
            "theta_r_deg",
            aspecular_of(tr, plan.theta_i_deg),
            _attrs("aspecular_deg"),
        ),
    }
    if grid:
        coords["wavelength_nm"] = (
            "wavelength_nm",
            np.asarray(grid, dtype=np.float64),
            _attrs("wavelength_nm"),
        )
    if spectra.predicted_wavelengths_nm is not None:
        coords["predicted_wavelength_nm"] = (
            "predicted_wavelength_nm",
            spectra.predicted_wavelengths_nm,
            _attrs("wavelength_nm", long_name="wavelength of the predicted spectra"),
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


def _spectrum_attrs(spectra: RunSpectra) -> dict[str, Any]:
    """The attributes of a reflectance-factor variable: its scale, what it is relative
    to, what the readings were referenced to, the cone, the standards and the calibration
    the run cites (:meth:`goniolab.run_spectra.RunSpectra.provenance`)."""
    prov = spectra.provenance()
    out: dict[str, Any] = {
        "scale": spectra.scale,
        "relative_to": prov["relative_to"],
        "referenced_to": prov["referenced_to"],
        "detector_cone_deg": prov["detector_cone_deg"],
        "reference_standards_json": _dumps(prov["standards"]),
        "calibration_json": _dumps(prov["calibration"]),
    }
    if spectra.scale == "mirror":
        out["long_name"] = (
            "spectral reading as a fraction of the mirror reference ([colour] scale = mirror): "
            "not a reflectance factor"
        )
    return out


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
            {"long_name": LONG_NAMES["time"]},
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
            _attrs(f"g{angle}_gu"),
        )
        data[f"predicted_g{angle}_gu"] = (
            "reading",
            np.array([np.nan if v is None else float(v) for v in predicted]),
            _attrs(f"predicted_g{angle}_gu"),
        )
    ds = xr.Dataset(
        data,
        coords={
            "reading": (
                "reading",
                np.array([g.seq for g in rows], dtype=np.int64),
                _attrs("reading", units="1"),
            )
        },
    )
    ds.attrs = {**_run_attrs(store, rec), "stored_readings": m}
    return ds
