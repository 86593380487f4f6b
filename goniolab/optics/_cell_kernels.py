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
and adds ``|U|^2`` to the cell; :func:`kirchhoff_bands_numpy` does so for the boxes of
several wavelengths a few at once (the same values, fewer numpy calls).

Each kernel exists as numpy code here (the default: no JIT start-up) and in numba
(``cache=True, nogil=True``) in :mod:`._cell_kernels_numba`, imported only when a model
asks for ``backend="numba"`` (``CK.cone_cells_numba`` and its siblings load it). Cells
outside each detector's reach are skipped by their sorted ``wox``/``woy`` coordinates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.optics._kernels_numpy import interval_overlap_numpy

#: the numba kernels (``*_numba``) are loaded on first access (module ``__getattr__``)
__all__ = ["cone_cells_numpy", "cone_window", "kirchhoff_band_numpy", "rect_cells_numpy"]

FloatArray = NDArray[np.float64]


def _bounds(coord: FloatArray, centre: float, reach: float) -> tuple[int, int]:
    lo = int(np.searchsorted(coord, centre - reach, side="left"))
    hi = int(np.searchsorted(coord, centre + reach, side="right"))
    return lo, hi


def _lookup(g: FloatArray, table: FloatArray, g0: float, g1: float, o_in: float) -> FloatArray:
    """The O(gamma) table at ``g`` (``g`` overwritten): ``o_in`` up to ``g0``, 0 from ``g1``,
    linear between the nodes as the numba kernels' ``_table`` (no search: the nodes are
    equally spaced, so the index is computed)."""
    n = table.size
    if not g1 > g0:
        out: FloatArray = np.where(g <= g0, o_in, 0.0)
        return out
    below, beyond = g <= g0, g >= g1
    t = np.clip(g, g0, g1, out=g)
    t -= g0
    t *= (n - 1) / (g1 - g0)
    i = t.astype(np.int64)
    np.minimum(i, n - 2, out=i)
    t -= i
    lo = table[i]
    inner = (table[i + 1] - lo) * t
    inner += lo
    inner[below] = o_in
    inner[beyond] = 0.0
    return inner


ConeWindow = tuple[FloatArray, FloatArray, tuple[int, int, int, int] | None]


def cone_window(wox: FloatArray, woy: FloatArray, p: FloatArray) -> ConeWindow:
    """What :func:`cone_cells_numpy` forms of the window before its directions: each
    cell's ``wo_z`` (0 below the horizon), the powers with the cells below the horizon
    set to 0, and the rows and columns ``(r0, r1, c0, c1)`` that carry power (None: no
    cell does). A source split into sub-cones (:mod:`goniolab.optics.cell_apertures`,
    up to 169 of them) sums the same window once per sub-cone: formed once for all (the
    same values; on a 2 mm field at 89 deg these passes over 4 M cells per sub-cone were
    1.5 of Rayleigh-Rice's 3.4 s)."""
    z2 = 1.0 - wox[None, :] ** 2 - woy[:, None] ** 2
    ok = z2 > 0.0
    zz = np.sqrt(np.where(ok, z2, 0.0))
    pv = np.where(ok, p, 0.0)
    # the cells that carry power: the rest add exactly 0 (a flat map's diffuse power is 0
    # everywhere: 129 sub-cone windows of 4 M cells at 89 deg summed zeros for 6 s)
    rows = np.flatnonzero(pv.any(axis=1))
    if rows.size == 0:
        return zz, pv, None
    cols = np.flatnonzero(pv.any(axis=0))
    return zz, pv, (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)


def cone_cells_numpy(
    wox: FloatArray,
    woy: FloatArray,
    p: FloatArray,
    dirs: FloatArray,
    table: FloatArray,
    g0: float,
    g1: float,
    o_in: float,
    window: ConeWindow | None = None,
) -> FloatArray:
    """Numpy twin of :func:`cone_cells_numba`: the cells' ``wo_z`` (and which cells are
    above the horizon) formed once (:func:`cone_window`, or ``window`` when the caller
    formed it for several calls), then per direction the chord to every cell of the
    window within reach, its angle and the table, summed with the cells' powers."""
    reach = 2.0 * math.sin(0.5 * min(g1, math.pi)) + 1e-12
    zz, pv, bounds = cone_window(wox, woy, p) if window is None else window
    out = np.zeros(dirs.shape[0])
    if bounds is None:
        return out
    r0, r1, c0, c1 = bounds
    for k in range(dirs.shape[0]):
        d = dirs[k]
        j0, j1 = _bounds(wox, float(d[0]), reach)
        i0, i1 = _bounds(woy, float(d[1]), reach)
        j0, j1, i0, i1 = max(j0, c0), min(j1, c1), max(i0, r0), min(i1, r1)
        if j1 <= j0 or i1 <= i0:
            continue
        g = zz[i0:i1, j0:j1] - d[2]
        g *= g
        g += ((woy[i0:i1] - d[1]) ** 2)[:, None]
        g += ((wox[j0:j1] - d[0]) ** 2)[None, :]
        np.sqrt(g, out=g)
        g *= 0.5
        np.minimum(g, 1.0, out=g)
        np.arcsin(g, out=g)
        g *= 2.0
        o_val = _lookup(g, table, g0, g1, o_in)
        out[k] = float(np.einsum("ij,ij->", pv[i0:i1, j0:j1], o_val))
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
    """Numpy twin of :func:`kirchhoff_band_numba`: the same
    Horner sums over the rectangle of cells holding those the band owns, in real and
    imaginary parts (the step ``-i d`` is imaginary: ``f (-i a) = a f_im - i a f_re``),
    added to ``acc`` where the band owns the cell."""
    owned = _owned_rect(vz, ok, lo, hi, hi_inclusive)
    if owned is None:
        return
    a0, a1, b0, b1, own = owned
    r, c = rows[a0:a1], cols[b0:b1]
    if r.size > 1 and np.all(np.diff(r) == 1) and c.size > 1 and np.all(np.diff(c) == 1):
        sub = spec[:, int(r[0]) : int(r[-1]) + 1, int(c[0]) : int(c[-1]) + 1]
    else:
        sub = spec[:, r][:, :, c]
    x = vz[a0:a1, b0:b1] - vc
    x *= h_max
    power = _horner_power(sub, dc, x, np.multiply.outer(w_rows[a0:a1], w_cols[b0:b1]))
    acc[a0:a1, b0:b1] += np.where(own, power, 0.0)


def _owned_rect(
    vz: FloatArray, ok: NDArray[np.bool_], lo: float, hi: float, hi_inclusive: bool
) -> tuple[int, int, int, int, NDArray[np.bool_]] | None:
    """The rectangle ``(a0, a1, b0, b1)`` of a box's cells holding those a Taylor band
    owns (real, ``lo <= v_z < hi``, or ``<= hi`` for the last band) and the owned cells in
    it; None: the band owns none."""
    own = ok & (vz >= lo) & ((vz <= hi) if hi_inclusive else (vz < hi))
    ri = np.flatnonzero(own.any(axis=1))
    if ri.size == 0:
        return None
    ci = np.flatnonzero(own.any(axis=0))
    a0, a1, b0, b1 = int(ri[0]), int(ri[-1]) + 1, int(ci[0]), int(ci[-1]) + 1
    return a0, a1, b0, b1, own[a0:a1, b0:b1]


def _horner_power(
    sub: NDArray[np.complex64],
    dc: NDArray[np.complex128],
    x: FloatArray,
    w: NDArray[np.complex128],
) -> FloatArray:
    """``|sum_n (F_n - dc_n w) (-i x)^n / n!|^2`` per cell by Horner's scheme in float64:
    ``sub[n]`` the term transforms at the cells (``x`` may carry a leading axis of boxes),
    ``w`` the window's shape there (the coherent field ``dc_n w`` taken out)."""
    n_terms = sub.shape[0]
    top = sub[n_terms - 1]
    fr, fi = top.real.astype(np.float64), top.imag.astype(np.float64)
    er = np.full(x.shape, dc[n_terms - 1].real)
    ei = np.full(x.shape, dc[n_terms - 1].imag)
    for n in range(n_terms - 2, -1, -1):
        a = x / (n + 1)
        term = sub[n]
        fr, fi = term.real + a * fi, term.imag - a * fr
        er, ei = dc[n].real + a * ei, dc[n].imag - a * er
    ur = fr - (er * w.real - ei * w.imag)
    ui = fi - (er * w.imag + ei * w.real)
    power: FloatArray = ur * ur
    power += ui * ui
    return power


#: Boxes per group of :func:`kirchhoff_bands_numpy` (consecutive wavelengths: their boxes
#: differ little, so the group's common rectangle adds few cells).
_BAND_GROUP: int = 4


def kirchhoff_bands_numpy(
    spec: NDArray[np.complex64],
    dc: NDArray[np.complex128],
    boxes: Sequence[tuple[NDArray[np.int64], NDArray[np.int64]]],
    vzs: Sequence[FloatArray],
    oks: Sequence[NDArray[np.bool_]],
    lo: float,
    hi: float,
    hi_inclusive: bool,
    vc: float,
    h_max: float,
    wy: NDArray[np.complex128],
    wx: NDArray[np.complex128],
    accs: Sequence[FloatArray],
) -> None:
    """:func:`kirchhoff_band_numpy` of several boxes (one per wavelength), a few at once:
    ``boxes[i] = (rows, cols)`` (consecutive indices into ``spec``'s region), ``wy`` and
    ``wx`` the window shapes over the whole region (a box's ``w_rows = wy[rows]``).

    A group of :data:`_BAND_GROUP` boxes is summed over the rectangle of the region
    holding all their owned cells, each box's ``x`` placed in its own layer (0 outside
    its cells, whose power is then not added): one set of numpy calls per group instead
    of per wavelength (a gloss's 16 wavelengths made some 5,000 calls on ten-thousand-cell
    arrays per gloss, each taking the GIL back from the other thread: issue 26, g16c).
    Every owned cell is formed by the same operations on the same values, the same
    bits."""
    for rows, cols in boxes:  # a box is placed by its first index: they must be runs
        for idx in (rows, cols):
            if idx.size and int(idx[-1]) - int(idx[0]) + 1 != idx.size:
                raise ValueError("kirchhoff_bands_numpy: a box's rows and columns are runs")
    items: list[tuple[int, int, int, int, int, NDArray[np.bool_]]] = []
    for i, (vz, ok) in enumerate(zip(vzs, oks, strict=True)):
        owned = _owned_rect(vz, ok, lo, hi, hi_inclusive)
        if owned is not None:
            items.append((i, *owned))
    for g in range(0, len(items), _BAND_GROUP):
        part = items[g : g + _BAND_GROUP]
        r_lo = min(int(boxes[i][0][a0]) for i, a0, _, _, _, _ in part)
        r_hi = max(int(boxes[i][0][a1 - 1]) for i, _, a1, _, _, _ in part) + 1
        c_lo = min(int(boxes[i][1][b0]) for i, _, _, b0, _, _ in part)
        c_hi = max(int(boxes[i][1][b1 - 1]) for i, _, _, _, b1, _ in part) + 1
        x = np.zeros((len(part), r_hi - r_lo, c_hi - c_lo))
        at = []
        for j, (i, a0, a1, b0, b1, _) in enumerate(part):
            r0, c0 = int(boxes[i][0][a0]) - r_lo, int(boxes[i][1][b0]) - c_lo
            place = (j, slice(r0, r0 + a1 - a0), slice(c0, c0 + b1 - b0))
            xs = vzs[i][a0:a1, b0:b1] - vc
            xs *= h_max
            x[place] = xs
            at.append(place)
        sub = spec[:, r_lo:r_hi, c_lo:c_hi]
        power = _horner_power(sub, dc, x, np.multiply.outer(wy[r_lo:r_hi], wx[c_lo:c_hi]))
        for (i, a0, a1, b0, b1, own), place in zip(part, at, strict=True):
            accs[i][a0:a1, b0:b1] += np.where(own, power[place], 0.0)


_NUMBA = ("cone_cells_numba", "kirchhoff_band_numba", "rect_cells_numba")


def __getattr__(name: str) -> Any:
    """The numba kernels, imported on first use (:mod:`._cell_kernels_numba`)."""
    if name in _NUMBA:
        from goniolab.optics import _cell_kernels_numba

        return getattr(_cell_kernels_numba, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
