"""Height maps: the container, plane levelling and missing points.

A :class:`HeightMap` is a regular grid of surface heights ``z_um`` (micrometres; rows are y,
columns are x; NaN marks a missing or invalid point) with lateral steps ``dx_um`` and
``dy_um``. Wittmann et al. (2021, sec. 3.1) compute facet slopes from such a map after
subtracting the best-fitting plane; :func:`level_plane` does that, NaN-aware, and
:func:`fill_missing` fills missing points only when asked to. Reading and writing files is
:mod:`goniolab.surfaces`' job.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 3.1.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.facet_threads import run_tasks

__all__ = [
    "HeightMap",
    "HeightMapError",
    "fill_missing",
    "heightmap_error",
    "level_plane",
    "plane_fit",
    "plane_fit_and_completeness",
]

FloatArray = NDArray[np.float64]
#: Points per block of rows when a map is walked in blocks (8 MB of float64).
_BLOCK_POINTS = 1 << 20
StepArg = float | tuple[float, float] | None


class HeightMapError(ValueError):
    """A height map or height-map file is unusable; the message names the file and why."""


def heightmap_error(source: str | Path, problem: str) -> HeightMapError:
    """A :class:`HeightMapError` naming the file (its name, not its full path) and the problem."""
    return HeightMapError(f"{Path(source).name if isinstance(source, Path) else source}: {problem}")


@dataclass(frozen=True, eq=False)
class HeightMap:
    """A regular grid of surface heights.

    Parameters
    ----------
    z_um
        2-D heights in micrometres, rows = y, columns = x; NaN = missing point. Stored as a
        read-only float64 copy, except that a read-only, C-contiguous float64 or float32
        array owning its memory is taken as it is (a reader or :func:`level_plane` hands its
        fresh array over: no 32 MB copy of a 2048^2 map, and a float32 file stays float32,
        half the memory: an 8192^2 map is 256 MB, not 512). Every computation on the heights
        is float64: sums accumulate in float64 and slopes are taken from blocks of rows cast
        to float64 (:mod:`goniolab.optics.surface`), so a float32 map gives exactly what its
        float64 copy would. ``inf`` is rejected (readers turn invalid points into NaN).
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
    #: values derived from the (read-only) heights, kept: not a field
    _derived: dict[str, Any] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        src = self.source
        if np.iscomplexobj(self.z_um):
            raise heightmap_error(src, "heights must be real, got a complex array")
        given = self.z_um
        if (
            isinstance(given, np.ndarray)
            and given.dtype in (np.float64, np.float32)
            and not given.flags.writeable
            and given.flags.c_contiguous
            and (given.flags.owndata or _read_only_base(given))
        ):
            z = given  # handed over: nobody holds a writeable view of it
        else:
            try:
                z = np.array(given, dtype=np.float64, copy=True)
            except (TypeError, ValueError) as exc:
                raise heightmap_error(src, f"heights are not numeric: {exc}") from None
        if z.ndim != 2:
            raise heightmap_error(
                src, f"heights must be a 2-D array, got {z.ndim}-D shape {z.shape}"
            )
        if z.size == 0:
            raise heightmap_error(src, f"height map has zero points (shape {z.shape})")
        # one fast reduction (the column sums, which the plane fit reads too); only a
        # non-finite sum (NaN, inf or overflow) needs the scan
        col = z.sum(axis=0, dtype=np.float64) if z.ndim == 2 else np.sum(z, dtype=np.float64)
        complete = bool(np.isfinite(col).all())
        if not complete and np.isinf(z).any():
            raise heightmap_error(src, "heights contain inf (use NaN for missing points)")
        z.setflags(write=False)
        object.__setattr__(self, "z_um", z)
        # a finite sum: no NaN (n_valid needs no count); the heights are read-only, so what
        # is derived from them (the plane fit, the range) is kept (_derived)
        object.__setattr__(self, "_derived", {"complete": True, "col_sum": col} if complete else {})
        for name in ("dx_um", "dy_um"):
            value = getattr(self, name)
            try:
                step = float(value)
            except (TypeError, ValueError):
                raise heightmap_error(src, f"{name} must be a number, got {value!r}") from None
            if not (math.isfinite(step) and step > 0.0):
                raise heightmap_error(src, f"{name} must be finite and > 0, got {step!r}")
            object.__setattr__(self, name, step)
        if not isinstance(self.meta, Mapping):
            raise heightmap_error(
                src, f"meta must be a mapping of str to str, got {type(self.meta).__name__}"
            )
        meta = dict(self.meta)
        for key, value in meta.items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise heightmap_error(
                    src, f"meta entries must be str -> str, got {key!r}: {value!r}"
                )
        object.__setattr__(self, "meta", meta)

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``: number of rows (y) and columns (x)."""
        ny, nx = self.z_um.shape
        return int(ny), int(nx)

    def derived(self) -> dict[str, Any]:
        """What is derived from the heights (column sums, completeness, plane fit, range),
        kept while they are read-only. numpy lets the owner of a handed-over array make it
        writeable again: then nothing is kept (each value is computed from the heights as
        they are; review of 2026-11-26, a changed map kept its old plane fit)."""
        if self.z_um.flags.writeable:
            self._derived.clear()
        return self._derived

    @property
    def n_valid(self) -> int:
        """Number of valid (non-NaN) points (counted in blocks of rows: no map-sized mask)."""
        z = self.z_um
        if self.derived().get("complete"):
            return int(z.size)
        rows = max(1, _BLOCK_POINTS // max(1, z.shape[1]))
        nan = sum(int(np.count_nonzero(np.isnan(z[r : r + rows]))) for r in range(0, len(z), rows))
        return int(z.size - nan)

    @property
    def z_range(self) -> tuple[float, float]:
        """``(min, max)`` of the valid heights (NaN skipped; NaN, NaN when none), found
        once (``np.fmin`` / ``np.fmax`` reductions: no copy of the map)."""
        got = self.derived().get("z_range")
        if got is None:
            z = self.z_um
            # the two reductions at once when two threads may run (run_tasks); a map with
            # no NaN (its sums finite, "complete") takes min and max, a third faster than
            # fmin and fmax and the same values there
            complete = bool(self.derived().get("complete"))
            lo, hi = run_tasks(
                [
                    functools.partial((np.minimum if complete else np.fmin).reduce, z, axis=None),
                    functools.partial((np.maximum if complete else np.fmax).reduce, z, axis=None),
                ]
            )
            got = (float(lo), float(hi))
            self.derived()["z_range"] = got
        out: tuple[float, float] = got
        return out

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


def plane_fit(hm: HeightMap) -> tuple[float, float, float]:
    """Least-squares plane ``z = a + b x + c y`` through the valid points, in closed form.

    ``x = (j - (nx - 1)/2) dx_um`` and ``y = (i - (ny - 1)/2) dy_um`` are centred, so on a
    map without missing points the normal equations are diagonal:
    ``a = mean(z)``, ``b = sum_j x_j C_j / (ny sum x^2)``, ``c = sum_i y_i R_i / (nx sum y^2)``
    with ``C`` and ``R`` the column and row sums: two reductions over the map, no design
    matrix. With NaN points the 3 x 3 normal equations are built from sums over the valid
    points and solved by least squares (minimum norm when rank deficient: a single row or
    column keeps ``c = 0`` or ``b = 0``).

    Returns
    -------
    (a, b, c) : tuple of float
        Height at the map centre (um) and the plane's slopes dz/dx and dz/dy.

    Raises
    ------
    HeightMapError
        If the map has no valid point.
    """
    a, b, c, _ = plane_fit_and_completeness(hm)
    return a, b, c


def plane_fit_and_completeness(hm: HeightMap) -> tuple[float, float, float, bool]:
    """:func:`plane_fit` and whether the map has no missing point (computed once per map:
    the wave models' tiles and the facet slopes both level it)."""
    got = hm.derived().get("plane")
    if got is None:
        got = _plane_fit_and_completeness(hm)
        hm.derived()["plane"] = got
    out: tuple[float, float, float, bool] = got
    return out


def _plane_fit_and_completeness(hm: HeightMap) -> tuple[float, float, float, bool]:
    z = hm.z_um
    ny, nx = z.shape
    x = (np.arange(nx, dtype=np.float64) - (nx - 1) / 2.0) * hm.dx_um
    y = (np.arange(ny, dtype=np.float64) - (ny - 1) / 2.0) * hm.dy_um
    col = hm.derived().get("col_sum")
    if col is None:
        col = z.sum(axis=0, dtype=np.float64)  # a float32 map accumulates in float64
    if np.isfinite(col).all():
        row = z.sum(axis=1, dtype=np.float64)
        sxx = ny * float(x @ x)
        syy = nx * float(y @ y)
        a = float(col.sum()) / z.size
        b = float(col @ x) / sxx if sxx > 0 else 0.0
        c = float(row @ y) / syy if syy > 0 else 0.0
        return a, b, c, True
    valid = ~np.isnan(z)
    if not valid.any():
        raise heightmap_error(hm.source, "cannot level: no valid points")
    zz = np.where(valid, z.astype(np.float64, copy=False), 0.0)
    v = valid.astype(np.float64)
    vc, vr = v.sum(axis=0), v.sum(axis=1)
    sx, sy = float(vc @ x), float(vr @ y)
    sxy = float(y @ (v @ x))
    normal = np.array(
        [
            [float(vc.sum()), sx, sy],
            [sx, float(vc @ (x * x)), sxy],
            [sy, sxy, float(vr @ (y * y))],
        ]
    )
    rhs = np.array([float(zz.sum()), float(zz.sum(axis=0) @ x), float(zz.sum(axis=1) @ y)])
    coef = np.linalg.lstsq(normal, rhs, rcond=1e-12)[0]
    return float(coef[0]), float(coef[1]), float(coef[2]), False


def level_plane(hm: HeightMap) -> HeightMap:
    """Subtract the least-squares plane fitted to the valid points.

    Fits ``z = a + b x + c y`` (``x = j dx_um``, ``y = i dy_um``) to the non-NaN points by
    linear least squares (:func:`plane_fit`, closed form) and subtracts it everywhere; NaN
    points stay NaN (Wittmann et al. 2021, sec. 3.1: the map is levelled before slopes are
    taken). A map with a single row or column is rank deficient: the minimum-norm solution
    then removes the best line.

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
    a, b, c = plane_fit(hm)
    ny, nx = z.shape
    x_um = (np.arange(nx, dtype=np.float64) - (nx - 1) / 2.0) * hm.dx_um
    y_um = (np.arange(ny, dtype=np.float64) - (ny - 1) / 2.0) * hm.dy_um
    out = np.subtract(z, a + b * x_um)  # row vector broadcast: one pass, no plane array
    out -= (c * y_um)[:, None]
    out.setflags(write=False)
    return hm.replace(z_um=out)


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
        raise heightmap_error(hm.source, "cannot fill missing points: no valid points")
    if not missing.any():
        return hm
    if method == "mean":
        filled = np.where(missing, float(np.mean(z[~missing], dtype=np.float64)), z)
    elif method == "nearest":
        from scipy import ndimage

        _, (ii, jj) = ndimage.distance_transform_edt(missing, return_indices=True)
        filled = z[ii, jj]
    else:
        raise heightmap_error(
            hm.source, f"unknown fill method {method!r} (use 'nearest' or 'mean')"
        )
    return hm.replace(z_um=filled)


def owning_base(a: np.ndarray) -> np.ndarray | None:
    """The array owning the memory ``a`` views whole (``np.load`` returns a reshaped view
    of its 1-D read), else None."""
    base = a.base
    if isinstance(base, np.ndarray) and base.flags.owndata and base.nbytes == a.nbytes:
        return base
    return None


def _read_only_base(a: np.ndarray) -> bool:
    """``a`` views all of a read-only array that owns its memory (a reader made both
    read-only): nothing can write to it."""
    base = owning_base(a)
    return base is not None and not base.flags.writeable
