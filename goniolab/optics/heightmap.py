"""Height maps: the container, plane levelling and file I/O.

A :class:`HeightMap` is a regular grid of surface heights ``z_um`` (micrometres; rows are y,
columns are x; NaN marks a missing or invalid point) with lateral steps ``dx_um`` and
``dy_um``. Wittmann et al. (2021, sec. 3.1) compute facet slopes from such a map after
subtracting the best-fitting plane; :func:`level_plane` does that, NaN-aware, and
:func:`fill_missing` fills missing points only when asked to.

File formats (:func:`load_heightmap`, :func:`save_heightmap`):

``.npy``
    A 2-D numpy array of heights in micrometres, read with ``allow_pickle=False``. The steps
    live in a JSON sidecar ``<file>.npy.json`` (``{"dx_um": .., "dy_um": .., "meta": {..}}``)
    that :func:`save_heightmap` always writes; without a sidecar, ``step_um`` is required.
``.csv`` ``.txt`` ``.asc`` ``.dat``
    A text matrix, one row of the map per line. The delimiter is sniffed from the first data
    line (tab, then ``;`` -- which also allows a decimal comma --, then ``,``, else runs of
    whitespace). Comment lines (``#``, ``%``) before the data carry ``key = value``
    or ``Key: value`` settings: ``dx_um``, ``dy_um``, ``step_um`` (dy defaults to dx),
    ``z_unit`` (m, mm, um, nm, pm, A; default um), ``missing_value``, and Gwyddion's
    "ASCII data matrix" export header (``# Width: 5.000 µm``, ``# Height: ...`` are the
    x and y extents, ``# Value units: m``; Gwyddion modules/file/asciiexport.c). Missing
    points: empty cell, ``nan``, ``-``, ``BAD`` or the missing value. Ragged rows are an
    error.
``.sdf``
    ISO 25178-71 / Surfstand SDF, ASCII (``aISO-1.0``, ``aBCR-1.0``) or binary (``bISO-1.0``,
    ``bBCR-1.0``): header keys ManufacID, CreateDate, ModDate, NumPoints, NumProfiles,
    Xscale, Yscale, Zscale (metres per unit), Zresolution, Compression, DataType, CheckType.
    Binary header: 81 bytes, little-endian ``8s 10s 12s 12s uint16 uint16 4*float64
    3*uint8``, then NumProfiles rows of NumPoints values. DataType 0 uint8, 1 uint16,
    2 uint32, 3 float32, 4 int8, 5 int16, 6 int32, 7 float64 (Gwyddion
    modules/file/sdfile.c). ASCII: ``Key = value`` lines, ``*``, the values, ``*``, an
    optional trailer, ``*``. Invalid points: ``BAD`` in ASCII, NaN in floats, the type
    minimum in int16/int32 (the convention of SurfaceTopography's SDF reader).
    Compression and checksums are rejected with a clear error.
``.sur``
    Digital Surf (MountainsMap, STIL exports): a 512-byte little-endian header starting
    ``DIGITAL SURF`` (or ``DSCOMPRESSED``), the comment zone, the private zone, then
    int16/int32 points, row by row. Field offsets are those of Gwyddion
    modules/file/surffile.c (``surffile_load`` and its ``SurfWriter``), confirmed against
    RosettaSciIO rsciio/digitalsurf/_api.py, which also gives the DSCOMPRESSED layout
    (stream directory + zlib streams) and the non-measured value ``zmin - 2`` when the
    "special points" flag (offset 86) is 1. Heights are ``point * dz + z_offset`` in the
    z step unit, as Gwyddion computes them (RosettaSciIO subtracts ``zmin`` first; goniolab
    writes ``zmin = 0`` so its files read the same either way). Only the first object of
    a multi-object file is read.
``.gwy``
    Gwyddion native files: the first GwyDataField ``/N/data`` of the container, ``xreal``
    and ``yreal`` with ``si_unit_xy``, values with ``si_unit_z`` (metres by default); a
    mask ``/N/mask`` marks points that become NaN. Written with the ``gwyfile`` package;
    read with a bounded parser of the documented serialisation (``gwyfile``'s parser can
    loop forever on a malformed component).

Heights are returned in micrometres whatever the unit in the file; ``meta['format']`` names
the format read and integer formats report their z quantisation step as
``meta['z_step_um']``.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 3.1.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import struct
import time
import tokenize
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "HeightMap",
    "HeightMapError",
    "fill_missing",
    "level_plane",
    "load_heightmap",
    "save_heightmap",
]

FloatArray = NDArray[np.float64]
StepArg = float | tuple[float, float] | None


class HeightMapError(ValueError):
    """A height map or height-map file is unusable; the message names the file and why."""


def _fail(source: str | Path, problem: str) -> HeightMapError:
    return HeightMapError(f"{Path(source).name if isinstance(source, Path) else source}: {problem}")


@dataclass(frozen=True, eq=False)
class HeightMap:
    """A regular grid of surface heights.

    Parameters
    ----------
    z_um
        2-D heights in micrometres, rows = y, columns = x; NaN = missing point. Stored as a
        read-only float64 copy. ``inf`` is rejected (readers turn invalid points into NaN).
    dx_um, dy_um
        Lateral steps along x (columns) and y (rows) in micrometres, finite and > 0.
    source
        Where the map came from (a file name or ``sample:NAME``); used in error messages.
    meta
        Free-form string metadata (instrument, date, comment, original units ...).

    Notes
    -----
    Maps compare by identity (``eq=False``): element-wise array equality has no single
    truth value. Use :meth:`replace` to derive a changed copy.
    """

    z_um: FloatArray
    dx_um: float
    dy_um: float
    source: str = "<memory>"
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        src = self.source
        if np.iscomplexobj(self.z_um):
            raise _fail(src, "heights must be real, got a complex array")
        try:
            z = np.array(self.z_um, dtype=np.float64, copy=True)
        except (TypeError, ValueError) as exc:
            raise _fail(src, f"heights are not numeric: {exc}") from None
        if z.ndim != 2:
            raise _fail(src, f"heights must be a 2-D array, got {z.ndim}-D shape {z.shape}")
        if z.size == 0:
            raise _fail(src, f"height map has zero points (shape {z.shape})")
        if np.isinf(z).any():
            raise _fail(src, "heights contain inf (use NaN for missing points)")
        z.setflags(write=False)
        object.__setattr__(self, "z_um", z)
        for name in ("dx_um", "dy_um"):
            value = getattr(self, name)
            try:
                step = float(value)
            except (TypeError, ValueError):
                raise _fail(src, f"{name} must be a number, got {value!r}") from None
            if not (math.isfinite(step) and step > 0.0):
                raise _fail(src, f"{name} must be finite and > 0, got {step!r}")
            object.__setattr__(self, name, step)
        if not isinstance(self.meta, Mapping):
            raise _fail(
                src, f"meta must be a mapping of str to str, got {type(self.meta).__name__}"
            )
        meta = dict(self.meta)
        for key, value in meta.items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise _fail(src, f"meta entries must be str -> str, got {key!r}: {value!r}")
        object.__setattr__(self, "meta", meta)

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``: number of rows (y) and columns (x)."""
        ny, nx = self.z_um.shape
        return int(ny), int(nx)

    @property
    def n_valid(self) -> int:
        """Number of valid (non-NaN) points."""
        return int(np.count_nonzero(~np.isnan(self.z_um)))

    @property
    def valid_fraction(self) -> float:
        """Fraction of valid points, in [0, 1]."""
        return self.n_valid / self.z_um.size

    def replace(self, **changes: Any) -> HeightMap:
        """Return a copy with some fields changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)


# --------------------------------------------------------------------------------------
# Levelling and missing points
# --------------------------------------------------------------------------------------


def level_plane(hm: HeightMap) -> HeightMap:
    """Subtract the least-squares plane fitted to the valid points.

    Fits ``z = a + b x + c y`` (``x = j dx_um``, ``y = i dy_um``) to the non-NaN points by
    linear least squares and subtracts it everywhere; NaN points stay NaN (Wittmann et al.
    2021, sec. 3.1: the map is levelled before slopes are taken). A map with a single row or
    column is rank deficient: the minimum-norm solution then removes the best line.

    Parameters
    ----------
    hm
        The height map.

    Returns
    -------
    HeightMap
        Same grid and metadata, levelled heights.

    Raises
    ------
    HeightMapError
        If the map has no valid point.
    """
    z = hm.z_um
    valid = ~np.isnan(z)
    if not valid.any():
        raise _fail(hm.source, "cannot level: no valid points")
    ny, nx = z.shape
    # Centred coordinates keep the normal equations well conditioned.
    x_um = (np.arange(nx, dtype=np.float64) - (nx - 1) / 2.0) * hm.dx_um
    y_um = (np.arange(ny, dtype=np.float64) - (ny - 1) / 2.0) * hm.dy_um
    yy, xx = np.meshgrid(y_um, x_um, indexing="ij")
    design = np.column_stack([np.ones(int(valid.sum())), xx[valid], yy[valid]])
    coef, *_ = np.linalg.lstsq(design, z[valid], rcond=None)
    plane = coef[0] + coef[1] * xx + coef[2] * yy
    return hm.replace(z_um=z - plane)


def fill_missing(hm: HeightMap, method: Literal["nearest", "mean"] = "nearest") -> HeightMap:
    """Fill NaN points explicitly.

    Parameters
    ----------
    hm
        The height map.
    method
        ``"nearest"``: each missing point takes the height of the nearest valid point
        (Euclidean distance in grid units, ``scipy.ndimage.distance_transform_edt``);
        ``"mean"``: each missing point takes the mean of the valid points.

    Returns
    -------
    HeightMap
        A map without NaN.

    Raises
    ------
    HeightMapError
        If no point is valid or the method is unknown.
    """
    z = hm.z_um
    missing = np.isnan(z)
    if missing.all():
        raise _fail(hm.source, "cannot fill missing points: no valid points")
    if not missing.any():
        return hm
    if method == "mean":
        filled = np.where(missing, float(np.mean(z[~missing])), z)
    elif method == "nearest":
        from scipy import ndimage

        _, (ii, jj) = ndimage.distance_transform_edt(missing, return_indices=True)
        filled = z[ii, jj]
    else:
        raise _fail(hm.source, f"unknown fill method {method!r} (use 'nearest' or 'mean')")
    return hm.replace(z_um=filled)


# --------------------------------------------------------------------------------------
# Shared helpers for the readers
# --------------------------------------------------------------------------------------


def _steps_from_arg(name: str, step_um: StepArg) -> tuple[float, float] | None:
    if step_um is None:
        return None
    if isinstance(step_um, tuple):
        if len(step_um) != 2:
            raise _fail(name, f"step_um must be a number or (dx_um, dy_um), got {step_um!r}")
        dx, dy = step_um
    else:
        dx = dy = step_um
    try:
        dx_f, dy_f = float(dx), float(dy)
    except (TypeError, ValueError):
        raise _fail(name, f"step_um must be a number or (dx_um, dy_um), got {step_um!r}") from None
    for value in (dx_f, dy_f):
        if not (math.isfinite(value) and value > 0.0):
            raise _fail(name, f"step_um must be finite and > 0, got {step_um!r}")
    return dx_f, dy_f


def _resolve_steps(
    name: str,
    file_steps: tuple[float, float] | None,
    step_um: StepArg,
    *,
    what: str = "the file",
) -> tuple[float, float]:
    """Combine the steps a file carries with the ``step_um`` option.

    The file's steps win; ``step_um`` fills in when the file carries none. A ``step_um``
    that contradicts the file is an error rather than a silent choice.
    """
    arg = _steps_from_arg(name, step_um)
    if file_steps is None:
        if arg is None:
            raise _fail(
                name, f"no lateral step in {what}: pass step_um (--step-um on the command line)"
            )
        return arg
    for value in file_steps:
        if not (math.isfinite(value) and value > 0.0):
            raise _fail(name, f"lateral step in {what} must be finite and > 0, got {value!r}")
    if arg is not None and not np.allclose(arg, file_steps, rtol=1e-9, atol=0.0):
        raise _fail(
            name,
            f"step_um={step_um!r} contradicts the step in {what} "
            f"(dx_um={file_steps[0]!r}, dy_um={file_steps[1]!r})",
        )
    return file_steps


def _make(
    name: str, z_um: ArrayLike, dx_um: float, dy_um: float, meta: dict[str, str]
) -> HeightMap:
    z = np.asarray(z_um, dtype=np.float64)
    if np.isinf(z).any():
        raise _fail(name, "heights overflow to infinity after scaling: implausible z scale")
    return HeightMap(z_um=z, dx_um=dx_um, dy_um=dy_um, source=name, meta=meta)


# Length units accepted in headers, as micrometres per unit. The micro sign appears as
# U+00B5 (latin-1 0xB5, Digital Surf and Gwyddion) or U+03BC; both normalise to "u".
_UM_PER_UNIT: dict[str, float] = {
    "m": 1e6,
    "mm": 1e3,
    "um": 1.0,
    "nm": 1e-3,
    "pm": 1e-6,
    "a": 1e-4,
    "å": 1e-4,
}


def _um_per(name: str, unit: str, what: str) -> float:
    key = unit.strip().replace("\u00b5", "u").replace("\u03bc", "u").replace("&#181;", "u")
    key = key.lower()
    if key not in _UM_PER_UNIT:
        raise _fail(name, f"unknown {what} unit {unit!r} (known: m, mm, um, nm, pm, A)")
    return _UM_PER_UNIT[key]


def _snap(value: float) -> float:
    """Undo the last-digit noise of a unit conversion (e.g. 0.1e-6 m * 1e6 -> 0.1 um)."""
    return float(f"{value:.15g}")


def _mib(n_bytes: int) -> str:
    if n_bytes < 1024 * 1024:
        return f"{n_bytes} bytes"
    return f"{n_bytes / (1024 * 1024):.3g} MiB"


def _truncated(name: str, ny: int, nx: int, item: int, have: int) -> HeightMapError:
    need = ny * nx * item
    return _fail(
        name,
        f"truncated: header says {nx}x{ny} points of {item} bytes ({_mib(need)}) "
        f"but file has {_mib(max(have, 0))} of data",
    )


def _quantise(
    z_um: FloatArray, n_max: int, *, offset: bool
) -> tuple[NDArray[np.int64], float, float]:
    """Map heights to integers ``0..n_max`` (or ``-n_max..n_max`` without offset).

    Returns ``(raw, step_um, offset_um)`` with ``z ~= raw * step_um + offset_um`` and an error
    of at most ``step_um / 2`` (plus float rounding) on every valid point. Both numbers are
    representable in float32 so that the .sur header (float32 fields) stores them exactly.
    """
    valid = ~np.isnan(z_um)
    if valid.any():
        lo, hi = float(np.min(z_um[valid])), float(np.max(z_um[valid]))
    else:
        lo = hi = 0.0
    if offset:
        off = float(np.float32(lo))
        if off > lo:
            off = float(np.nextafter(np.float32(lo), np.float32(-np.inf)))
        span = hi - off
    else:
        off = 0.0
        span = max(abs(lo), abs(hi))
    step = span / n_max if span > 0 else 1e-6
    step32 = np.float32(step)
    if float(step32) < step:
        step32 = np.nextafter(step32, np.float32(np.inf))
    step = float(step32)
    raw = np.zeros(z_um.shape, dtype=np.int64)
    raw[valid] = np.rint((z_um[valid] - off) / step).astype(np.int64)
    return raw, step, off


# --------------------------------------------------------------------------------------
# .npy
# --------------------------------------------------------------------------------------


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".json")


def _read_npy(path: Path, opts: _ReadOptions) -> HeightMap:
    name = path.name
    size = path.stat().st_size
    try:
        with path.open("rb") as f:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(f)
            elif version in ((2, 0), (3, 0)):
                shape, _, dtype = np.lib.format.read_array_header_2_0(f)
            else:
                raise ValueError(f"unsupported .npy version {version}")
            if dtype.hasobject or dtype.kind not in "iuf":
                raise _fail(name, f"heights must be a real numeric array, got dtype {dtype}")
            if len(shape) != 2:
                raise _fail(name, f"heights must be a 2-D array, got shape {shape}")
            if shape[0] * shape[1] == 0:
                raise _fail(name, f"height map has zero points (shape {shape})")
            have = size - f.tell()
            if shape[0] * shape[1] * dtype.itemsize > have:
                raise _truncated(name, shape[0], shape[1], dtype.itemsize, have)
            f.seek(0)
            arr = np.load(f, allow_pickle=False)
    except HeightMapError:
        raise
    except (
        ValueError,
        EOFError,
        SyntaxError,
        TypeError,
        OverflowError,
        tokenize.TokenError,  # numpy tokenises the header dict to repair old files
    ) as exc:
        raise _fail(name, f"not a readable .npy file: {exc}") from None
    z = np.asarray(arr).astype(np.float64)
    z[np.isinf(z)] = np.nan
    meta: dict[str, str] = {"format": "npy"}
    file_steps: tuple[float, float] | None = None
    side = _sidecar(path)
    if side.exists():
        try:
            info = json.loads(side.read_text(encoding="utf-8"))
            file_steps = (float(info["dx_um"]), float(info["dy_um"]))
            extra = info.get("meta", {})
            if not isinstance(extra, dict):
                raise TypeError("meta is not an object")
            meta.update({str(k): str(v) for k, v in extra.items()})
        except (OSError, ValueError, KeyError, TypeError, RecursionError) as exc:
            raise _fail(side.name, f"bad step sidecar for {name}: {exc!r}") from None
    dx, dy = _resolve_steps(name, file_steps, opts.step_um, what=side.name)
    return _make(name, z, dx, dy, meta)


def _write_npy(hm: HeightMap, path: Path) -> None:
    np.save(path, np.asarray(hm.z_um, dtype=np.float64), allow_pickle=False)
    info = {"dx_um": hm.dx_um, "dy_um": hm.dy_um, "meta": hm.meta}
    _sidecar(path).write_text(json.dumps(info, indent=1, sort_keys=True) + "\n", encoding="utf-8")


# --------------------------------------------------------------------------------------
# Text matrices (.csv .txt .asc .dat), including Gwyddion's "ASCII data matrix" export
# --------------------------------------------------------------------------------------

_MISSING_TOKENS = frozenset({"", "nan", "-", "bad"})
_GWY_EXTENT = re.compile(r"^\s*([-+0-9.eE]+)\s*(\S+)\s*$")


def _decode_text(raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _parse_header_line(line: str) -> tuple[str, str] | None:
    """``# key = value`` or Gwyddion's ``# Key: value``; returns (lower-case key, value)."""
    body = line.lstrip("#% \t")
    for sep in ("=", ":"):
        if sep in body:
            key, value = body.split(sep, 1)
            return key.strip().lower(), value.strip()
    return None


def _sniff_delimiter(line: str) -> str | None:
    for delim in ("\t", ";", ","):
        if delim in line:
            return delim
    return None  # runs of whitespace


def _parse_row(
    name: str, lineno: int, line: str, delim: str | None, missing_value: float | None
) -> list[float]:
    cells = line.split(delim) if delim is not None else line.split()
    if delim == ";":
        cells = [c.replace(",", ".") for c in cells]  # decimal comma goes with ';'
    out: list[float] = []
    for col, cell in enumerate(cells, 1):
        token = cell.strip()
        if token.lower() in _MISSING_TOKENS:
            out.append(math.nan)
            continue
        try:
            value = float(token)
        except ValueError:
            raise _fail(
                name, f"line {lineno}, column {col}: non-numeric cell {token[:40]!r}"
            ) from None
        if not math.isfinite(value) or (missing_value is not None and value == missing_value):
            value = math.nan
        out.append(value)
    return out


def _read_text(path: Path, opts: _ReadOptions) -> HeightMap:
    name = path.name
    text = _decode_text(path.read_bytes())
    header: dict[str, str] = {}
    rows: list[list[float]] = []
    delim: str | None = None
    width = 0
    missing_value = opts.missing_value
    for lineno, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped[0] in "#%":
            if rows:
                continue  # trailing comments
            parsed = _parse_header_line(stripped)
            if parsed is not None:
                header[parsed[0]] = parsed[1]
                if parsed[0] == "missing_value" and missing_value is None:
                    try:
                        missing_value = float(parsed[1])
                    except ValueError:
                        raise _fail(name, f"bad missing_value {parsed[1]!r}") from None
            continue
        if not rows:
            delim = _sniff_delimiter(stripped)
        row = _parse_row(name, lineno, stripped if delim is None else line, delim, missing_value)
        if rows and len(row) != width:
            raise _fail(name, f"ragged rows: line {lineno} has {len(row)} values, expected {width}")
        width = len(row)
        rows.append(row)
    if not rows:
        raise _fail(name, "zero points: no data rows")
    z = np.array(rows, dtype=np.float64)
    ny, nx = z.shape

    z_unit = header.get("z_unit", header.get("value units", "um"))
    z = z * _um_per(name, z_unit, "z")
    file_steps = _text_steps(name, header, nx, ny)
    dx, dy = _resolve_steps(name, file_steps, opts.step_um, what="the file header")
    meta = {"format": "text", "z_unit_in_file": z_unit}
    for key, value in header.items():
        if key.startswith("meta."):
            try:
                meta[key[5:]] = str(json.loads(value))
            except (ValueError, RecursionError):
                meta[key[5:]] = value
        elif key == "channel":
            meta["channel"] = value
    return _make(name, z, dx, dy, meta)


def _float_key(name: str, header: Mapping[str, str], key: str) -> float | None:
    if key not in header:
        return None
    try:
        return float(header[key])
    except ValueError:
        raise _fail(name, f"header {key} = {header[key]!r} is not a number") from None


def _text_steps(
    name: str, header: Mapping[str, str], nx: int, ny: int
) -> tuple[float, float] | None:
    step = _float_key(name, header, "step_um")
    dx = _float_key(name, header, "dx_um")
    dy = _float_key(name, header, "dy_um")
    if dx is None and dy is None and step is None and "width" in header:
        # Gwyddion ASCII export: "# Width: 5.000 µm" / "# Height: 5.000 µm" (extents).
        extents = []
        for key, n in (("width", nx), ("height", ny)):
            match = _GWY_EXTENT.match(header.get(key, ""))
            if match is None:
                raise _fail(name, f"cannot read Gwyddion header {key}: {header.get(key)!r}")
            try:
                extent = float(match.group(1))
            except ValueError:
                raise _fail(name, f"cannot read Gwyddion header {key}: {header[key]!r}") from None
            extents.append(extent * _um_per(name, match.group(2), "lateral") / n)
        return extents[0], extents[1]
    dx = dx if dx is not None else step
    dy = dy if dy is not None else (step if step is not None else dx)
    if dx is None and dy is not None:
        dx = dy
    if dx is None or dy is None:
        return None
    return dx, dy


def _write_text(hm: HeightMap, path: Path, delimiter: str) -> None:
    lines = [
        "# goniolab height map (rows = y, columns = x; nan = missing point)",
        f"# dx_um = {hm.dx_um!r}",
        f"# dy_um = {hm.dy_um!r}",
        "# z_unit = um",
    ]
    lines += [f"# meta.{k} = {json.dumps(v)}" for k, v in hm.meta.items() if "\n" not in k]
    with path.open("w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(lines) + "\n")
        np.savetxt(f, hm.z_um, fmt="%.17g", delimiter=delimiter)


# --------------------------------------------------------------------------------------
# ISO 25178-71 SDF (ASCII and binary)
# --------------------------------------------------------------------------------------

# DataType codes, as in Gwyddion modules/file/sdfile.c (SDFDataType) and ISO 25178-71.
_SDF_DTYPES: dict[int, np.dtype[Any]] = {
    0: np.dtype("<u1"),
    1: np.dtype("<u2"),
    2: np.dtype("<u4"),
    3: np.dtype("<f4"),
    4: np.dtype("<i1"),
    5: np.dtype("<i2"),
    6: np.dtype("<i4"),
    7: np.dtype("<f8"),
}
# Invalid-point markers for signed integers (the type minimum), as SurfaceTopography does.
_SDF_INVALID: dict[int, int] = {5: -(2**15), 6: -(2**31)}
_SDF_BIN_HEADER = struct.Struct("<8s10s12s12sHHddddBBB")  # 81 bytes
_SDF_MAGICS = (b"aISO-1.0", b"aBCR-1.0", b"bISO-1.0", b"bBCR-1.0")
_SDF_REQUIRED = ("NumPoints", "NumProfiles", "Xscale", "Yscale", "Zscale", "DataType")


def _sdf_check(name: str, info: Mapping[str, Any]) -> tuple[int, int, float, float, float]:
    nx, ny = int(info["NumPoints"]), int(info["NumProfiles"])
    if nx <= 0 or ny <= 0:
        raise _fail(name, f"zero points: NumPoints={nx}, NumProfiles={ny}")
    for key in ("Xscale", "Yscale", "Zscale"):
        value = float(info[key])
        if not (math.isfinite(value) and value > 0.0):
            raise _fail(name, f"{key} must be finite and > 0 (metres), got {value!r}")
    if int(info.get("Compression", 0)) != 0:
        raise _fail(name, f"compressed SDF not supported (Compression={info['Compression']})")
    if int(info.get("CheckType", 0)) != 0:
        raise _fail(name, f"SDF checksums not supported (CheckType={info['CheckType']})")
    if int(info["DataType"]) not in _SDF_DTYPES:
        raise _fail(name, f"unknown SDF DataType {info['DataType']} (known: 0..7)")
    return (
        nx,
        ny,
        _snap(float(info["Xscale"]) * 1e6),
        _snap(float(info["Yscale"]) * 1e6),
        float(info["Zscale"]) * 1e6,
    )


def _read_sdf(path: Path, opts: _ReadOptions) -> HeightMap:
    name = path.name
    raw = path.read_bytes()
    magic = raw[:8]
    if magic not in _SDF_MAGICS:
        raise _fail(name, f"not an SDF file: first bytes {magic!r}, expected aISO-1.0/bISO-1.0")
    if magic[:1] == b"b":
        return _read_sdf_binary(name, raw, opts)
    return _read_sdf_ascii(name, raw, opts)


def _read_sdf_binary(name: str, raw: bytes, opts: _ReadOptions) -> HeightMap:
    if len(raw) < _SDF_BIN_HEADER.size:
        raise _fail(
            name,
            f"truncated: binary SDF header needs {_SDF_BIN_HEADER.size} bytes, file has {len(raw)}",
        )
    fields = _SDF_BIN_HEADER.unpack_from(raw)
    keys = [
        "Version",
        "ManufacID",
        "CreateDate",
        "ModDate",
        "NumPoints",
        "NumProfiles",
        "Xscale",
        "Yscale",
        "Zscale",
        "Zresolution",
        "Compression",
        "DataType",
        "CheckType",
    ]
    info = dict(zip(keys, fields, strict=True))
    nx, ny, dx_um, dy_um, zscale_um = _sdf_check(name, info)
    code = int(info["DataType"])
    dtype = _SDF_DTYPES[code]
    have = len(raw) - _SDF_BIN_HEADER.size
    if nx * ny * dtype.itemsize > have:
        raise _truncated(name, ny, nx, dtype.itemsize, have)
    data = np.frombuffer(raw, dtype=dtype, count=nx * ny, offset=_SDF_BIN_HEADER.size)
    z = data.astype(np.float64).reshape(ny, nx)
    if code in _SDF_INVALID:
        z[data.reshape(ny, nx) == _SDF_INVALID[code]] = np.nan
    z[np.isinf(z)] = np.nan  # invalid float points; overflow of the scale is caught later
    z = z * zscale_um
    meta = {
        "format": "sdf-binary",
        "manufacturer": _cstr(info["ManufacID"]),
        "create_date": _cstr(info["CreateDate"]),
        "sdf_data_type": str(code),
    }
    if dtype.kind in "iu":
        meta["z_step_um"] = repr(zscale_um)
    dx, dy = _resolve_steps(name, (dx_um, dy_um), opts.step_um)
    return _make(name, z, dx, dy, meta)


def _cstr(value: bytes) -> str:
    return value.split(b"\0", 1)[0].decode("latin-1").strip()


def _read_sdf_ascii(name: str, raw: bytes, opts: _ReadOptions) -> HeightMap:
    text = _decode_text(raw)
    lines = text.splitlines()
    info: dict[str, str] = {}
    i = 1
    while i < len(lines) and lines[i].strip() != "*":
        line = lines[i].strip()
        i += 1
        if not line or line.startswith(";"):
            continue
        if "=" not in line:
            raise _fail(name, f"SDF header line {i}: expected 'Key = value', got {line[:40]!r}")
        key, value = line.split("=", 1)
        info[key.strip()] = value.strip()
    if i >= len(lines):
        raise _fail(name, "truncated: no '*' line ends the SDF header")
    missing = [k for k in _SDF_REQUIRED if k not in info]
    if missing:
        raise _fail(name, f"SDF header lacks {', '.join(missing)}")
    try:
        nx, ny, dx_um, dy_um, zscale_um = _sdf_check(name, info)
    except ValueError as exc:
        if isinstance(exc, HeightMapError):
            raise
        raise _fail(name, f"bad SDF header value: {exc}") from None
    start = i + 1
    end = start
    while end < len(lines) and lines[end].strip() != "*":
        end += 1
    if end >= len(lines):
        raise _fail(name, "truncated: no '*' line ends the SDF data section")
    tokens = " ".join(lines[start:end]).split()
    if len(tokens) != nx * ny:
        raise _fail(
            name,
            f"header says {nx}x{ny} = {nx * ny} points but the data section has {len(tokens)}",
        )
    values = np.empty(nx * ny, dtype=np.float64)
    for k, token in enumerate(tokens):
        if token.upper() in ("BAD", "NAN"):
            values[k] = np.nan
            continue
        try:
            values[k] = float(token)
        except ValueError:
            raise _fail(name, f"SDF data value #{k + 1} is not a number: {token[:40]!r}") from None
    z = values.reshape(ny, nx)
    z[np.isinf(z)] = np.nan
    z = z * zscale_um
    meta = {
        "format": "sdf-ascii",
        "manufacturer": info.get("ManufacID", ""),
        "create_date": info.get("CreateDate", ""),
        "sdf_data_type": info["DataType"],
    }
    for line in lines[end + 1 :]:
        if "=" in line and line.strip() != "*":
            key, value = line.split("=", 1)
            meta[key.strip()] = value.strip()
    dx, dy = _resolve_steps(name, (dx_um, dy_um), opts.step_um)
    return _make(name, z, dx, dy, meta)


def _sdf_date() -> str:
    return time.strftime("%d%m%Y%H%M", time.gmtime())


def _write_sdf_ascii(hm: HeightMap, path: Path) -> None:
    ny, nx = hm.shape
    date = _sdf_date()
    head = [
        "aISO-1.0",
        "ManufacID   = goniolab",
        f"CreateDate  = {date}",
        f"ModDate     = {date}",
        f"NumPoints   = {nx}",
        f"NumProfiles = {ny}",
        f"Xscale      = {hm.dx_um * 1e-6!r}",
        f"Yscale      = {hm.dy_um * 1e-6!r}",
        "Zscale      = 1e-06",
        "Zresolution = -1",
        "Compression = 0",
        "DataType    = 7",
        "CheckType   = 0",
        "*",
    ]
    body = [" ".join("BAD" if math.isnan(v) else repr(float(v)) for v in row) for row in hm.z_um]
    trailer = [f"{k} = {v}" for k, v in hm.meta.items() if _trailer_safe(k, v)]
    path.write_text("\n".join([*head, *body, "*", *trailer, "*"]) + "\n", encoding="utf-8")


def _trailer_safe(key: str, value: str) -> bool:
    return not any(c in s for s in (key, value) for c in "\n\r*=") and bool(key.strip())


def _write_sdf_binary(hm: HeightMap, path: Path, code: int) -> None:
    ny, nx = hm.shape
    if nx > 0xFFFF or ny > 0xFFFF:
        raise _fail(path.name, f"binary SDF holds at most 65535x65535 points, map is {nx}x{ny}")
    z = np.asarray(hm.z_um)
    if code == 7:
        zscale_m = 1e-6  # data in micrometres: 1e-6 * 1e6 == 1.0 exactly, lossless
        zres_m = -1.0
        data = z.astype("<f8")
    else:
        n_max = 2**15 - 2 if code == 5 else 2**31 - 2
        ints, step_um, _ = _quantise(z, n_max, offset=False)
        zscale_m = step_um * 1e-6
        # the reader multiplies by Zscale * 1e6: quantise with exactly that factor
        scale_um = zscale_m * 1e6
        valid = ~np.isnan(z)
        ints[valid] = np.clip(np.rint(z[valid] / scale_um), -n_max - 1, n_max + 1)
        ints[~valid] = _SDF_INVALID[code]
        zres_m = zscale_m
        data = ints.astype(_SDF_DTYPES[code])
    date = _sdf_date().encode()
    header = _SDF_BIN_HEADER.pack(
        b"bISO-1.0",
        b"goniolab",
        date,
        date,
        nx,
        ny,
        hm.dx_um * 1e-6,
        hm.dy_um * 1e-6,
        zscale_m,
        zres_m,
        0,
        code,
        0,
    )
    path.write_bytes(header + data.tobytes())


# --------------------------------------------------------------------------------------
# Digital Surf .sur
# --------------------------------------------------------------------------------------

_SUR_HEADER_SIZE = 512
# (name, struct code, byte offset) of the fields goniolab reads and writes; offsets from
# Gwyddion modules/file/surffile.c (surffile_load / SurfWriter) and RosettaSciIO
# rsciio/digitalsurf/_api.py. All little-endian.
_SUR_FIELDS: tuple[tuple[str, str, int], ...] = (
    ("signature", "12s", 0),
    ("format", "h", 12),
    ("n_objects", "H", 14),
    ("version", "h", 16),
    ("object_type", "h", 18),
    ("object_name", "30s", 20),
    ("operator_name", "30s", 50),
    ("material_code", "h", 80),
    ("acquisition", "h", 82),
    ("range", "h", 84),
    ("special_points", "h", 86),
    ("absolute", "h", 88),
    ("gauge_resolution", "f", 90),
    ("w_size", "i", 94),
    ("point_size", "h", 98),
    ("zmin", "i", 100),
    ("zmax", "i", 104),
    ("xres", "i", 108),
    ("yres", "i", 112),
    ("n_points", "i", 116),
    ("dx", "f", 120),
    ("dy", "f", 124),
    ("dz", "f", 128),
    ("x_axis", "16s", 132),
    ("y_axis", "16s", 148),
    ("z_axis", "16s", 164),
    ("dx_unit", "16s", 180),
    ("dy_unit", "16s", 196),
    ("dz_unit", "16s", 212),
    ("x_length_unit", "16s", 228),
    ("y_length_unit", "16s", 244),
    ("z_length_unit", "16s", 260),
    ("x_unit_ratio", "f", 276),
    ("y_unit_ratio", "f", 280),
    ("z_unit_ratio", "f", 284),
    ("imprint", "h", 288),
    ("inversion", "h", 290),
    ("leveling", "h", 292),
    ("seconds", "h", 306),
    ("minutes", "h", 308),
    ("hours", "h", 310),
    ("day", "h", 312),
    ("month", "h", 314),
    ("year", "h", 316),
    ("day_of_week", "h", 318),
    ("duration", "f", 320),
    ("compressed_size", "I", 324),
    ("comment_size", "H", 334),
    ("private_size", "H", 336),
    ("client_zone", "128s", 338),
    ("x_offset", "f", 466),
    ("y_offset", "f", 470),
    ("z_offset", "f", 474),
)
_SUR_ACQUISITION = {
    0: "unknown",
    1: "contact stylus",
    2: "scanning optical gauge",
    3: "thermocouple",
    4: "unknown",
    5: "contact stylus with skid",
    6: "AFM",
    7: "STM",
    8: "video",
    9: "interferometer",
    10: "structured light projection",
}


def _sur_unpack(raw: bytes) -> dict[str, Any]:
    return {
        key: struct.unpack_from("<" + code, raw, offset)[0] for key, code, offset in _SUR_FIELDS
    }


def _read_sur(path: Path, opts: _ReadOptions) -> HeightMap:
    name = path.name
    raw = path.read_bytes()
    magic = raw[:12]
    if magic not in (b"DIGITAL SURF", b"DSCOMPRESSED"):
        raise _fail(name, f"not a Digital Surf file: first bytes {magic!r}")
    if len(raw) < _SUR_HEADER_SIZE:
        raise _fail(name, f"truncated: header needs {_SUR_HEADER_SIZE} bytes, file has {len(raw)}")
    h = _sur_unpack(raw)
    if h["format"] != 0:
        raise _fail(name, f"Digital Surf format {h['format']} (Macintosh byte order) not supported")
    if h["object_type"] not in (1, 2):
        raise _fail(
            name, f"object type {h['object_type']} is not a profile (1) or surface (2) height map"
        )
    nx, ny = int(h["xres"]), int(h["yres"])
    if nx <= 0 or ny <= 0:
        raise _fail(name, f"zero points: header says {nx}x{ny}")
    if h["n_points"] != nx * ny:
        raise _fail(name, f"header total points {h['n_points']} != {nx}x{ny}")
    if h["point_size"] not in (16, 32):
        raise _fail(name, f"unsupported point size {h['point_size']} bits (16 or 32)")
    item = h["point_size"] // 8
    for key in ("dx", "dy", "dz", "z_offset"):
        if not math.isfinite(h[key]):
            raise _fail(name, f"header {key} is not finite ({h[key]!r})")
    if h["dx"] == 0.0 or h["dy"] == 0.0 or h["dz"] == 0.0:
        raise _fail(name, f"zero spacing in header (dx={h['dx']}, dy={h['dy']}, dz={h['dz']})")
    dx_um = abs(h["dx"]) * _um_per(name, _cstr(h["dx_unit"]), "x step")
    dy_um = abs(h["dy"]) * _um_per(name, _cstr(h["dy_unit"]), "y step")
    z_um_per = _um_per(name, _cstr(h["dz_unit"]), "z step")
    start = _SUR_HEADER_SIZE + h["comment_size"] + h["private_size"]
    if start > len(raw):
        raise _fail(
            name,
            f"truncated: comment and private zones end at byte {start}, file has {len(raw)}",
        )
    comment = raw[_SUR_HEADER_SIZE : _SUR_HEADER_SIZE + h["comment_size"]].decode("latin-1")
    need = nx * ny * item
    if magic == b"DSCOMPRESSED":
        body = _sur_decompress(name, raw, start, need)
    else:
        body = raw[start : start + need]
        if len(body) < need:
            raise _truncated(name, ny, nx, item, len(raw) - start)
    ints = np.frombuffer(body, dtype="<i2" if item == 2 else "<i4", count=nx * ny)
    ints = ints.reshape(ny, nx)
    z = ints.astype(np.float64) * (float(h["dz"]) * z_um_per) + float(h["z_offset"]) * z_um_per
    if h["special_points"] == 1:
        z[ints == int(h["zmin"]) - 2] = np.nan
    # Inversion codes as in Gwyddion surffile.c: 1 = invert z, 2 = flip (mirror x) and
    # invert z, 3 = flop (mirror y) and invert z.
    if h["inversion"] in (1, 2, 3):
        z = -z
        if h["inversion"] == 2:
            z = z[:, ::-1]
        elif h["inversion"] == 3:
            z = z[::-1, :]
    meta = {
        "format": "sur",
        "object_name": _cstr(h["object_name"]),
        "operator_name": _cstr(h["operator_name"]),
        "acquisition": _SUR_ACQUISITION.get(h["acquisition"], str(h["acquisition"])),
        "z_step_um": repr(abs(float(h["dz"]) * z_um_per)),
    }
    if h["year"] > 0:
        meta["date"] = f"{h['year']:04d}-{h['month']:02d}-{h['day']:02d}"
    if h["n_objects"] > 1:
        meta["note"] = f"file holds {h['n_objects']} objects; the first was read"
    exact = _sur_parse_comment(comment, meta)
    if exact is not None and all(
        math.isclose(a, b, rel_tol=1e-6) for a, b in zip(exact, (dx_um, dy_um), strict=True)
    ):
        dx_um, dy_um = exact  # goniolab's own full-precision steps (header floats are float32)
    dx, dy = _resolve_steps(name, (dx_um, dy_um), opts.step_um)
    return _make(name, z, dx, dy, meta)


def _sur_decompress(name: str, raw: bytes, start: int, need: int) -> bytes:
    """DSCOMPRESSED data: uint32 stream count, (raw length, zipped length) uint32 pairs,
    then the zlib streams (RosettaSciIO rsciio/digitalsurf/_api.py, ``_unpack_data``)."""
    if start + 4 > len(raw):
        raise _fail(name, "truncated: compressed SUR stream directory missing")
    (count,) = struct.unpack_from("<I", raw, start)
    if not 1 <= count <= 1024:
        raise _fail(name, f"compressed SUR: implausible stream count {count}")
    pos = start + 4
    if pos + 8 * count > len(raw):
        raise _fail(name, "truncated: compressed SUR stream directory cut short")
    sizes = [struct.unpack_from("<II", raw, pos + 8 * k) for k in range(count)]
    pos += 8 * count
    out = bytearray()
    for raw_len, zip_len in sizes:
        chunk = raw[pos : pos + zip_len]
        if len(chunk) < zip_len:
            raise _fail(name, f"truncated: compressed SUR stream needs {zip_len} bytes")
        pos += zip_len
        try:
            part = zlib.decompressobj().decompress(chunk, need - len(out) + 1)
        except zlib.error as exc:
            raise _fail(name, f"compressed SUR data is corrupt: {exc}") from None
        if len(part) != raw_len:
            raise _fail(name, f"compressed SUR stream gave {len(part)} bytes, expected {raw_len}")
        out += part
        if len(out) > need:
            break
    if len(out) != need:
        raise _fail(name, f"compressed SUR data has {len(out)} bytes, header implies {need}")
    return bytes(out)


def _sur_parse_comment(comment: str, meta: dict[str, str]) -> tuple[float, float] | None:
    """goniolab writes ``$goniolab.dx_um = ...`` lines (MountainsMap's ``$key = value``
    comment style); other comments are kept whole in ``meta['comment']``."""
    steps: dict[str, float] = {}
    other: list[str] = []
    for line in comment.splitlines():
        if line.startswith("$goniolab.") and "=" in line:
            key, value = line[len("$goniolab.") :].split("=", 1)
            key = key.strip()
            try:
                if key in ("dx_um", "dy_um"):
                    steps[key] = float(value)
                elif key.startswith("meta."):
                    meta[key[5:]] = str(json.loads(value))
            except (ValueError, RecursionError):
                other.append(line)
        elif line.strip():
            other.append(line)
    if other:
        meta["comment"] = "\n".join(other)
    if "dx_um" in steps and "dy_um" in steps:
        return steps["dx_um"], steps["dy_um"]
    return None


def _write_sur(hm: HeightMap, path: Path, bits: int) -> None:
    ny, nx = hm.shape
    n_max = 2 ** (bits - 1) - 16
    ints, step_um, off_um = _quantise(np.asarray(hm.z_um), n_max, offset=True)
    for what, value in (("dx_um", hm.dx_um), ("dy_um", hm.dy_um), ("z", step_um), ("z", off_um)):
        if not np.isfinite(np.float32(value)) or (value != 0.0 and np.float32(value) == 0.0):
            raise _fail(path.name, f"{what} = {value!r} does not fit the float32 .sur header")
    missing = np.isnan(hm.z_um)
    ints[missing] = -2  # non-measured value: zmin - 2 with zmin = 0
    comment_lines = [f"$goniolab.dx_um = {hm.dx_um!r}", f"$goniolab.dy_um = {hm.dy_um!r}"]
    comment_lines += [
        f"$goniolab.meta.{k} = {json.dumps(v)}" for k, v in hm.meta.items() if "\n" not in k
    ]
    comment = ("\n".join(comment_lines) + "\n").encode("latin-1", errors="replace")
    if len(comment) > 0xFFFF:
        comment = ("\n".join(comment_lines[:2]) + "\n").encode("latin-1")
    values: dict[str, Any] = {
        "signature": b"DIGITAL SURF",
        "format": 0,
        "n_objects": 1,
        "version": 1,
        "object_type": 2 if ny > 1 else 1,
        "object_name": hm.source.encode("latin-1", errors="replace")[:30],
        "operator_name": b"goniolab",
        "material_code": 0,
        "acquisition": 0,
        "range": 0,
        "special_points": 1 if missing.any() else 0,
        "absolute": 1,
        "gauge_resolution": 0.0,
        "w_size": 0,
        "point_size": bits,
        "zmin": 0,
        "zmax": int(ints.max(initial=0)),
        "xres": nx,
        "yres": ny,
        "n_points": nx * ny,
        "dx": hm.dx_um,
        "dy": hm.dy_um,
        "dz": step_um,
        "x_axis": b"X",
        "y_axis": b"Y",
        "z_axis": b"Z",
        "dx_unit": b"\xb5m",
        "dy_unit": b"\xb5m",
        "dz_unit": b"\xb5m",
        "x_length_unit": b"\xb5m",
        "y_length_unit": b"\xb5m",
        "z_length_unit": b"\xb5m",
        "x_unit_ratio": 1.0,
        "y_unit_ratio": 1.0,
        "z_unit_ratio": 1.0,
        "imprint": 0,
        "inversion": 0,
        "leveling": 0,
        "seconds": 0,
        "minutes": 0,
        "hours": 0,
        "day": 0,
        "month": 0,
        "year": 0,
        "day_of_week": 0,
        "duration": 0.0,
        "compressed_size": 0,
        "comment_size": len(comment),
        "private_size": 0,
        "client_zone": b"",
        "x_offset": 0.0,
        "y_offset": 0.0,
        "z_offset": off_um,
    }
    header = bytearray(_SUR_HEADER_SIZE)
    for key, code, offset in _SUR_FIELDS:
        struct.pack_into("<" + code, header, offset, values[key])
    dtype = "<i2" if bits == 16 else "<i4"
    path.write_bytes(bytes(header) + comment + ints.astype(dtype).tobytes())


# --------------------------------------------------------------------------------------
# Gwyddion .gwy
# --------------------------------------------------------------------------------------


class _GwyParser:
    """Bounded reader of the Gwyddion native serialisation (GWYP).

    Layout from the Gwyddion user guide, "Gwyddion Native File Format" (gwyfile-format):
    an object is a NUL-terminated type name, a uint32 LE size, then components; a component
    is a NUL-terminated name, a one-byte type code (b c i q d s o; arrays C I Q D S O with a
    uint32 count) and the value. Every length is checked against the buffer, so malformed
    files end in :class:`HeightMapError` (``gwyfile``'s own parser can loop forever on a
    zero-length component).
    """

    _SCALAR: ClassVar[dict[str, str]] = {"b": "<?", "c": "<c", "i": "<i", "q": "<q", "d": "<d"}
    _ARRAY: ClassVar[dict[str, str]] = {"C": "<u1", "I": "<i4", "Q": "<i8", "D": "<f8"}

    def __init__(self, name: str, buf: bytes) -> None:
        self.name = name
        self.buf = buf

    def _err(self, pos: int, what: str) -> HeightMapError:
        return _fail(self.name, f"corrupt or truncated .gwy at byte {pos}: {what}")

    def cstring(self, pos: int, end: int) -> tuple[str, int]:
        stop = self.buf.find(b"\0", pos, end)
        if stop < 0:
            raise self._err(pos, "unterminated string")
        return self.buf[pos:stop].decode("utf-8", errors="replace"), stop + 1

    def uint32(self, pos: int, end: int) -> int:
        if pos + 4 > end:
            raise self._err(pos, "length field cut short")
        return int(struct.unpack_from("<I", self.buf, pos)[0])

    def obj(self, pos: int, end: int, depth: int = 0) -> tuple[dict[str, Any], int]:
        if depth > 32:
            raise self._err(pos, "objects nested too deeply")
        type_name, pos = self.cstring(pos, end)
        size = self.uint32(pos, end)
        pos += 4
        stop = pos + size
        if stop > end:
            raise self._err(pos, f"object {type_name!r} claims {size} bytes past the end")
        out: dict[str, Any] = {"__type__": type_name}
        while pos < stop:
            key, pos = self.cstring(pos, stop)
            if pos >= stop:
                raise self._err(pos, f"component {key!r} has no type code")
            code = chr(self.buf[pos])
            pos += 1
            out[key], pos = self.value(code, pos, stop, depth)
        return out, stop

    def value(self, code: str, pos: int, end: int, depth: int) -> tuple[Any, int]:
        if code in self._SCALAR:
            size = struct.calcsize(self._SCALAR[code])
            if pos + size > end:
                raise self._err(pos, "value cut short")
            return struct.unpack_from(self._SCALAR[code], self.buf, pos)[0], pos + size
        if code == "s":
            return self.cstring(pos, end)
        if code == "o":
            return self.obj(pos, end, depth + 1)
        if code in self._ARRAY:
            count = self.uint32(pos, end)
            pos += 4
            dtype = np.dtype(self._ARRAY[code])
            if pos + count * dtype.itemsize > end:
                raise self._err(pos, f"array of {count} items runs past the end")
            arr = np.frombuffer(self.buf, dtype=dtype, count=count, offset=pos)
            return arr, pos + count * dtype.itemsize
        if code in "SO":
            count = self.uint32(pos, end)
            pos += 4
            if count > end - pos:
                raise self._err(pos, f"list of {count} items runs past the end")
            items: list[Any] = []
            for _ in range(count):
                if code == "S":
                    text, pos = self.cstring(pos, end)
                    items.append(text)
                else:
                    child, pos = self.obj(pos, end, depth + 1)
                    items.append(child)
            return items, pos
        raise self._err(pos - 1, f"unknown type code {code!r}")


def _gwy_field(name: str, container: Mapping[str, Any], key: str) -> dict[str, Any] | None:
    field_obj = container.get(key)
    if not isinstance(field_obj, dict) or field_obj.get("__type__") != "GwyDataField":
        return None
    xres, yres = field_obj.get("xres"), field_obj.get("yres")
    data = field_obj.get("data")
    if not isinstance(xres, int) or not isinstance(yres, int) or not isinstance(data, np.ndarray):
        raise _fail(name, f"{key}: GwyDataField lacks xres/yres/data")
    if xres <= 0 or yres <= 0:
        raise _fail(name, f"{key}: zero points ({xres}x{yres})")
    if data.dtype != np.float64 or data.size != xres * yres:
        raise _fail(name, f"{key}: data has {data.size} values, expected {xres}x{yres}")
    return field_obj


def _gwy_unit(field_obj: Mapping[str, Any], key: str) -> str:
    unit = field_obj.get(key)
    if isinstance(unit, dict):
        return str(unit.get("unitstr", ""))
    return ""


def _read_gwy(path: Path, opts: _ReadOptions) -> HeightMap:
    name = path.name
    buf = path.read_bytes()
    if buf[:4] != b"GWYP":
        raise _fail(name, f"not a Gwyddion .gwy file: first bytes {buf[:4]!r}, expected b'GWYP'")
    parser = _GwyParser(name, buf)
    top, _ = parser.obj(4, len(buf))
    if top["__type__"] != "GwyContainer":
        raise _fail(name, f"top object is {top['__type__']!r}, expected GwyContainer")
    channels = sorted(int(k[1:-5]) for k in top if re.fullmatch(r"/\d{1,9}/data", k) is not None)
    field_obj = None
    channel = -1
    for channel in channels:
        field_obj = _gwy_field(name, top, f"/{channel}/data")
        if field_obj is not None:
            break
    if field_obj is None:
        raise _fail(name, "no GwyDataField (/N/data) in the container")
    xres, yres = field_obj["xres"], field_obj["yres"]
    z = np.array(field_obj["data"], dtype=np.float64).reshape(yres, xres)
    z_unit = _gwy_unit(field_obj, "si_unit_z") or "m"
    xy_unit = _gwy_unit(field_obj, "si_unit_xy") or "m"
    z[np.isinf(z)] = np.nan
    z = z * _um_per(name, z_unit, "z")
    xy_um = _um_per(name, xy_unit, "lateral")
    xreal, yreal = field_obj.get("xreal", 1.0), field_obj.get("yreal", 1.0)
    if not all(isinstance(v, float) and math.isfinite(v) and v > 0 for v in (xreal, yreal)):
        raise _fail(name, f"xreal/yreal must be finite and > 0, got {xreal!r}, {yreal!r}")
    mask_obj = _gwy_field(name, top, f"/{channel}/mask")
    if mask_obj is not None:
        if (mask_obj["xres"], mask_obj["yres"]) != (xres, yres):
            raise _fail(name, f"/{channel}/mask shape differs from the data")
        z[np.asarray(mask_obj["data"]).reshape(yres, xres) > 0.5] = np.nan
    meta = {"format": "gwy", "channel": str(channel)}
    title = top.get(f"/{channel}/data/title")
    if isinstance(title, str):
        meta["title"] = title
    gmeta = top.get(f"/{channel}/meta")
    if isinstance(gmeta, dict):
        for key, value in gmeta.items():
            if key != "__type__" and isinstance(value, (str, bytes)):
                meta[key] = value if isinstance(value, str) else value.decode("latin-1")
    dx = _snap(xreal * xy_um / xres)
    dy = _snap(yreal * xy_um / yres)
    dx, dy = _resolve_steps(name, (dx, dy), opts.step_um)
    return _make(name, z, dx, dy, meta)


def _write_gwy(hm: HeightMap, path: Path) -> None:
    from gwyfile.objects import GwyContainer, GwyDataField, GwySIUnit

    ny, nx = hm.shape
    missing = np.isnan(hm.z_um)
    z_m = np.where(missing, 0.0, hm.z_um) / 1e6
    field_obj = GwyDataField(
        np.ascontiguousarray(z_m, dtype=np.float64),
        xreal=nx * hm.dx_um / 1e6,
        yreal=ny * hm.dy_um / 1e6,
        si_unit_xy=GwySIUnit(unitstr="m"),
        si_unit_z=GwySIUnit(unitstr="m"),
    )
    container = GwyContainer()
    container["/0/data"] = field_obj
    container["/0/data/title"] = hm.meta.get("title", "Height")
    if missing.any():
        container["/0/mask"] = GwyDataField(
            missing.astype(np.float64),
            xreal=nx * hm.dx_um / 1e6,
            yreal=ny * hm.dy_um / 1e6,
            si_unit_xy=GwySIUnit(unitstr="m"),
            si_unit_z=GwySIUnit(unitstr=""),
        )
    meta = {k: v for k, v in hm.meta.items() if k not in ("format", "channel", "title")}
    if meta:
        container["/0/meta"] = GwyContainer(meta, typecodes=dict.fromkeys(meta, "s"))
    container.tofile(str(path))


# --------------------------------------------------------------------------------------
# Dispatch
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _ReadOptions:
    step_um: StepArg
    missing_value: float | None


Reader = Callable[[Path, _ReadOptions], HeightMap]
Writer = Callable[[HeightMap, Path], None]

_READERS: dict[str, Reader] = {
    "npy": _read_npy,
    "csv": _read_text,
    "txt": _read_text,
    "sdf": _read_sdf,
    "sur": _read_sur,
    "gwy": _read_gwy,
}
_WRITERS: dict[str, Writer] = {
    "npy": _write_npy,
    "csv": lambda hm, p: _write_text(hm, p, ","),
    "txt": lambda hm, p: _write_text(hm, p, "\t"),
    "sdf": lambda hm, p: _write_sdf_binary(hm, p, 7),
    "sdf-int16": lambda hm, p: _write_sdf_binary(hm, p, 5),
    "sdf-int32": lambda hm, p: _write_sdf_binary(hm, p, 6),
    "sdf-ascii": _write_sdf_ascii,
    "sur": lambda hm, p: _write_sur(hm, p, 32),
    "sur-int16": lambda hm, p: _write_sur(hm, p, 16),
    "gwy": _write_gwy,
}
_ALIASES: dict[str, str] = {
    "csv": "csv",
    "txt": "txt",
    "asc": "txt",
    "dat": "txt",
    "text": "txt",
    "npy": "npy",
    "sdf": "sdf",
    "sur": "sur",
    "gwy": "gwy",
}
_READ_ALIASES: dict[str, str] = {
    "sdf-int16": "sdf",
    "sdf-int32": "sdf",
    "sdf-ascii": "sdf",
    "sur-int16": "sur",
}


def _format_for(path: Path, fmt: str | None, table: Mapping[str, object]) -> str:
    if fmt is not None:
        key = fmt.lower().lstrip(".")
        key = _ALIASES.get(key, key)
        if table is _READERS:
            key = _READ_ALIASES.get(key, key)
        if key not in table:
            raise _fail(path.name, f"unknown height-map format {fmt!r} (known: {sorted(table)})")
        return key
    ext = path.suffix.lower().lstrip(".")
    if ext not in _ALIASES:
        known = sorted("." + e for e in _ALIASES if e != "text")
        raise _fail(path.name, f"unknown height-map extension {path.suffix!r} (known: {known})")
    return _ALIASES[ext]


def load_heightmap(
    path: str | Path,
    *,
    step_um: StepArg = None,
    fmt: str | None = None,
    missing_value: float | None = None,
) -> HeightMap:
    """Read a height map; heights are returned in micrometres whatever the file's unit.

    Parameters
    ----------
    path
        The file.
    step_um
        Lateral step in micrometres (one number, or ``(dx_um, dy_um)``), used when the file
        carries none (``.npy`` without sidecar, text matrices without a step header). If the
        file has a step and ``step_um`` contradicts it, :class:`HeightMapError` is raised.
    fmt
        Format name overriding the extension: ``npy``, ``csv``, ``txt`` (also ``asc``,
        ``dat``), ``sdf``, ``sur``, ``gwy``.
    missing_value
        Text matrices only: a number that marks a missing point (besides empty cells,
        ``nan``, ``-`` and ``BAD``); a ``# missing_value = ...`` header line does the same.

    Returns
    -------
    HeightMap
        ``source`` is the file name; ``meta['format']`` names the format read.

    Raises
    ------
    HeightMapError
        Missing file, directory, unknown format, malformed or truncated content; the message
        names the file and the problem.
    """
    p = Path(path)
    kind = _format_for(p, fmt, _READERS)
    _steps_from_arg(p.name, step_um)
    if missing_value is not None and not math.isfinite(missing_value):
        raise _fail(p.name, f"missing_value must be finite, got {missing_value!r}")
    if not p.exists():
        raise _fail(p.name, f"no such file ({p})")
    if p.is_dir():
        raise _fail(p.name, f"is a directory, not a height-map file ({p})")
    try:
        # an absurd scale in a header overflows to inf, which _make reports: no warnings
        with np.errstate(over="ignore", invalid="ignore"):
            return _READERS[kind](p, _ReadOptions(step_um, missing_value))
    except HeightMapError:
        raise
    except OSError as exc:
        raise _fail(p.name, f"cannot read: {exc.strerror or exc}") from None


def save_heightmap(hm: HeightMap, path: str | Path, *, fmt: str | None = None) -> None:
    """Write a height map in the format given by ``fmt`` or the extension of ``path``.

    Every format :func:`load_heightmap` reads is written so that it reads back to the same
    map: exactly for ``npy``, ``csv``/``txt``, ``sdf`` (binary double) and ``sdf-ascii``;
    to 1 ulp for ``gwy`` (metres on disk); within half the z step stored in the file for
    the integer formats ``sur`` (int32), ``sur-int16``, ``sdf-int32`` and ``sdf-int16``
    (that step is returned on reading as ``meta['z_step_um']``).

    Parameters
    ----------
    hm
        The map.
    path
        Destination; ``.npy`` also writes ``<path>.json`` with the steps and metadata.
    fmt
        ``npy``, ``csv``, ``txt``, ``sdf`` (binary, double), ``sdf-ascii``, ``sdf-int16``,
        ``sdf-int32``, ``sur`` (int32), ``sur-int16``, ``gwy``; default from the extension.

    Raises
    ------
    HeightMapError
        Unknown format, a map the format cannot hold, or an I/O error.
    """
    p = Path(path)
    kind = _format_for(p, fmt, _WRITERS)
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # float32 overflow is checked
            _WRITERS[kind](hm, p)
    except OSError as exc:
        raise _fail(p.name, f"cannot write: {exc.strerror or exc}") from None
