"""Aperture sums over the direction-cosine cells of the physical-optics models (numba + numpy).

A physical-optics model (:mod:`goniolab.optics.physical`) predicts, for one nominal incident
direction, the fraction ``P[i, j]`` of the incident flux scattered into the cell of outgoing
directions ``wo = (wox[j], woy[i], sqrt(1 - wox^2 - woy^2))``. As in the facet model
(:mod:`goniolab.optics.facet`), a finite source is the mirror image of the source aperture
around ``wo`` (a cap of the source's size for a cone, the source rectangle translated for a
rectangle), so a detector collects ``sum P O`` with ``O`` the fraction of that image inside
it: the cap-overlap table for cones, the product of the in-plane and out-of-plane interval
overlaps for rectangles (Mihalik & Durikovic eqs. 15-17).

:func:`kirchhoff_band_numba` sums the Taylor terms of the Kirchhoff model's phase screen
(:mod:`goniolab.optics.kirchhoff`) per cell by Horner's scheme, the coherent part removed,
and adds ``|U|^2`` to the cell.

Each kernel exists as numpy code here (the default: no JIT start-up) and in numba
(``cache=True, nogil=True``) in :mod:`._cell_kernels_numba`, imported only when a model
asks for ``backend="numba"`` (``CK.cone_cells_numba`` and its siblings load it). Cells
outside each detector's reach are skipped by their sorted ``wox``/``woy`` coordinates.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.optics._kernels_numpy import interval_overlap_numpy, table_numpy

#: the numba kernels (``*_numba``) are loaded on first access (module ``__getattr__``)
__all__ = ["cone_cells_numpy", "kirchhoff_band_numpy", "rect_cells_numpy"]

FloatArray = NDArray[np.float64]


def _bounds(coord: FloatArray, centre: float, reach: float) -> tuple[int, int]:
    lo = int(np.searchsorted(coord, centre - reach, side="left"))
    hi = int(np.searchsorted(coord, centre + reach, side="right"))
    return lo, hi


def cone_cells_numpy(
    wox: FloatArray,
    woy: FloatArray,
    p: FloatArray,
    dirs: FloatArray,
    table: FloatArray,
    g0: float,
    g1: float,
    o_in: float,
) -> FloatArray:
    """Numpy twin of :func:`cone_cells_numba`."""
    reach = 2.0 * math.sin(0.5 * min(g1, math.pi)) + 1e-12
    out = np.zeros(dirs.shape[0])
    for k in range(dirs.shape[0]):
        d = dirs[k]
        j0, j1 = _bounds(wox, float(d[0]), reach)
        i0, i1 = _bounds(woy, float(d[1]), reach)
        if j1 <= j0 or i1 <= i0:
            continue
        xx = wox[None, j0:j1]
        yy = woy[i0:i1, None]
        z2 = 1.0 - xx * xx - yy * yy
        ok = z2 > 0.0
        zz = np.sqrt(np.where(ok, z2, 0.0))
        ch = 0.5 * np.sqrt((xx - d[0]) ** 2 + (yy - d[1]) ** 2 + (zz - d[2]) ** 2)
        g = 2.0 * np.arcsin(np.minimum(ch, 1.0))
        o_val = np.where(ok, table_numpy(g, table, g0, g1, o_in), 0.0)
        out[k] = float(np.sum(p[i0:i1, j0:j1] * o_val))
    return out


def rect_cells_numpy(
    wox: FloatArray,
    woy: FloatArray,
    p: FloatArray,
    alpha_r: FloatArray,
    s_in: float,
    r_in: float,
    s_perp: float,
    r_perp: float,
) -> FloatArray:
    """Numpy twin of :func:`rect_cells_numba` (all cells, no reach cut)."""
    z2 = 1.0 - wox[None, :] ** 2 - woy[:, None] ** 2
    ok = z2 > 0.0
    zz = np.sqrt(np.where(ok, z2, 0.0))
    al = np.arctan2(-wox[None, :], zz)
    ob = interval_overlap_numpy(np.arcsin(np.clip(woy, -1.0, 1.0)), s_perp, r_perp)[:, None]
    out = np.zeros(alpha_r.size)
    for k, ar in enumerate(alpha_r):
        ov = interval_overlap_numpy(al - ar, s_in, r_in) * ob
        out[k] = float(np.sum(np.where(ok, p * ov, 0.0)))
    return out


def kirchhoff_band_numpy(
    spec: NDArray[np.complex64],
    dc: NDArray[np.complex128],
    rows: NDArray[np.int64],
    cols: NDArray[np.int64],
    vz: FloatArray,
    ok: NDArray[np.bool_],
    lo: float,
    hi: float,
    hi_inclusive: bool,
    vc: float,
    h_max: float,
    w_rows: NDArray[np.complex128],
    w_cols: NDArray[np.complex128],
    acc: FloatArray,
) -> None:
    """Numpy twin of :func:`kirchhoff_band_numba`."""
    own = ok & (vz >= lo) & ((vz <= hi) if hi_inclusive else (vz < hi))
    ii, jj = np.nonzero(own)
    if ii.size == 0:
        return
    step = -1j * ((vz[ii, jj] - vc) * h_max)
    n_terms = spec.shape[0]
    r, c = rows[ii], cols[jj]
    f = spec[n_terms - 1, r, c].astype(np.complex128)
    e = np.full(ii.size, dc[n_terms - 1], dtype=np.complex128)
    for n in range(n_terms - 2, -1, -1):
        s = step / (n + 1)
        f = spec[n, r, c] + f * s
        e = dc[n] + e * s
    u = f - e * (w_rows[ii] * w_cols[jj])
    acc[ii, jj] += u.real * u.real + u.imag * u.imag


_NUMBA = ("cone_cells_numba", "kirchhoff_band_numba", "rect_cells_numba")


def __getattr__(name: str) -> Any:
    """The numba kernels, imported on first use (:mod:`._cell_kernels_numba`)."""
    if name in _NUMBA:
        from goniolab.optics import _cell_kernels_numba

        return getattr(_cell_kernels_numba, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
