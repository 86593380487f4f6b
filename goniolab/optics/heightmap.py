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

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 3.1.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

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
    """

    z_um: FloatArray
    dx_um: float
    dy_um: float
    source: str = "<memory>"
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        src = self.source
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
            raise _fail(name, f"no lateral step in {what}: pass step_um")
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
    return HeightMap(
        z_um=np.asarray(z_um, dtype=np.float64), dx_um=dx_um, dy_um=dy_um, source=name, meta=meta
    )


# --------------------------------------------------------------------------------------
# .npy
# --------------------------------------------------------------------------------------


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".json")


def _read_npy(path: Path, step_um: StepArg) -> HeightMap:
    name = path.name
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise _fail(name, f"not a readable .npy file: {exc}") from None
    if not isinstance(arr, np.ndarray):
        raise _fail(name, "not a single .npy array")
    if arr.dtype.kind not in "iuf":
        raise _fail(name, f"heights must be a real numeric array, got dtype {arr.dtype}")
    if arr.ndim != 2:
        raise _fail(name, f"heights must be a 2-D array, got shape {arr.shape}")
    if arr.size == 0:
        raise _fail(name, f"height map has zero points (shape {arr.shape})")
    z = arr.astype(np.float64)
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
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
            raise _fail(side.name, f"bad step sidecar for {name}: {exc!r}") from None
    dx, dy = _resolve_steps(name, file_steps, step_um, what=f"{side.name}")
    return _make(name, z, dx, dy, meta)


def _write_npy(hm: HeightMap, path: Path) -> None:
    np.save(path, np.asarray(hm.z_um, dtype=np.float64), allow_pickle=False)
    info = {"dx_um": hm.dx_um, "dy_um": hm.dy_um, "meta": hm.meta}
    _sidecar(path).write_text(json.dumps(info, indent=1, sort_keys=True) + "\n", encoding="utf-8")


# --------------------------------------------------------------------------------------
# Dispatch
# --------------------------------------------------------------------------------------

Reader = Callable[[Path, StepArg], HeightMap]
Writer = Callable[[HeightMap, Path], None]

_READERS: dict[str, Reader] = {"npy": _read_npy}
_WRITERS: dict[str, Writer] = {"npy": _write_npy}
_EXTENSIONS: dict[str, str] = {".npy": "npy"}


def _format_for(path: Path, fmt: str | None, table: Mapping[str, object]) -> str:
    if fmt is not None:
        key = fmt.lower().lstrip(".")
        key = _EXTENSIONS.get("." + key, key)
        if key not in table:
            raise _fail(path.name, f"unknown height-map format {fmt!r} (known: {sorted(table)})")
        return key
    ext = path.suffix.lower()
    if ext not in _EXTENSIONS or _EXTENSIONS[ext] not in table:
        known = sorted(e for e, f in _EXTENSIONS.items() if f in table)
        raise _fail(path.name, f"unknown height-map extension {ext!r} (known: {known}); pass fmt")
    return _EXTENSIONS[ext]


def load_heightmap(
    path: str | Path, *, step_um: StepArg = None, fmt: str | None = None
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
        Format name overriding the extension (see the module docstring).

    Raises
    ------
    HeightMapError
        Missing file, directory, unknown format, malformed or truncated content; the message
        names the file and the problem.
    """
    p = Path(path)
    kind = _format_for(p, fmt, _READERS)
    _steps_from_arg(p.name, step_um)
    if not p.exists():
        raise _fail(p.name, f"no such file ({p})")
    if p.is_dir():
        raise _fail(p.name, f"is a directory, not a height-map file ({p})")
    try:
        return _READERS[kind](p, step_um)
    except HeightMapError:
        raise
    except OSError as exc:
        raise _fail(p.name, f"cannot read: {exc.strerror or exc}") from None


def save_heightmap(hm: HeightMap, path: str | Path, *, fmt: str | None = None) -> None:
    """Write a height map in the format given by ``fmt`` or the extension of ``path``.

    Every format :func:`load_heightmap` reads is written so that it reads back to the same
    map (exactly for float formats, within the stated z resolution for integer formats).

    Raises
    ------
    HeightMapError
        Unknown format or a map the format cannot hold.
    """
    p = Path(path)
    kind = _format_for(p, fmt, _WRITERS)
    try:
        _WRITERS[kind](hm, p)
    except OSError as exc:
        raise _fail(p.name, f"cannot write: {exc.strerror or exc}") from None
