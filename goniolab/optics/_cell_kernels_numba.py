"""The numba versions of the physical-optics aperture sums (:mod:`goniolab.optics._cell_kernels`).

Imported only when a model runs with ``backend="numba"`` (numba costs a process about 0.6 s
to import and more to load its cached kernels). Each kernel is the same sum, term for
term, as its numpy twin in :mod:`goniolab.optics._cell_kernels` (``tests/optics/test_kirchhoff.py``
holds the two backends together).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from goniolab.optics._kernels import interval_overlap, njit_cached, table_value

__all__ = ["cone_cells_numba", "kirchhoff_band_numba", "rect_cells_numba"]

FloatArray = NDArray[np.float64]


@njit_cached(nogil=True, fastmath=False)
def cone_cells_numba(
    wox: FloatArray,
    woy: FloatArray,
    p: FloatArray,
    dirs: FloatArray,
    table: FloatArray,
    g0: float,
    g1: float,
    o_in: float,
) -> FloatArray:  # pragma: no cover - numba
    """``out[k] = sum_cells P O(angle(wo, dirs[k]))`` (cap-overlap table on [g0, g1]).

    The cells' ``wo_z`` are formed once; per direction and row only the columns within the
    cap's chord are visited, and a cell whose chord to the direction is beyond the cap's
    (so ``angle >= g1``, ``O = 0``) is dropped before the square root and arcsine: the same
    sum, term for term, as :func:`cone_cells_numpy`.
    """
    s_half = math.sin(0.5 * min(g1, math.pi))
    reach = 2.0 * s_half + 1e-12
    cut2 = 4.0 * s_half * s_half * (1.0 + 1e-9) + 1e-15  # chord^2 beyond: angle >= g1
    ny, nx = p.shape
    zz = np.empty((ny, nx))
    for i in range(ny):
        yy = woy[i]
        for j in range(nx):
            xx = wox[j]
            z2 = 1.0 - xx * xx - yy * yy
            zz[i, j] = math.sqrt(z2) if z2 > 0.0 else -1.0
    out = np.zeros(dirs.shape[0])
    for k in range(dirs.shape[0]):
        dx, dy, dz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
        j0 = np.searchsorted(wox, dx - reach)
        j1 = np.searchsorted(wox, dx + reach, side="right")
        i0 = np.searchsorted(woy, dy - reach)
        i1 = np.searchsorted(woy, dy + reach, side="right")
        acc = 0.0
        for i in range(i0, i1):
            yy = woy[i]
            dyy = (yy - dy) ** 2
            if dyy >= cut2:
                continue
            half = math.sqrt(cut2 - dyy) + 1e-12
            ja = max(j0, np.searchsorted(wox, dx - half))
            jb = min(j1, np.searchsorted(wox, dx + half, side="right"))
            for j in range(ja, jb):
                v = p[i, j]
                if v == 0.0:
                    continue
                z = zz[i, j]
                if z < 0.0:
                    continue
                c2 = (wox[j] - dx) ** 2 + dyy + (z - dz) ** 2
                if c2 >= cut2:
                    continue
                ch = 0.5 * math.sqrt(c2)
                g = 2.0 * math.asin(min(ch, 1.0))
                if g >= g1:
                    continue
                acc += v * table_value(g, table, g0, g1, o_in)
        out[k] = acc
    return out


@njit_cached(nogil=True, fastmath=False)
def rect_cells_numba(
    wox: FloatArray,
    woy: FloatArray,
    p: FloatArray,
    alpha_r: FloatArray,
    s_in: float,
    r_in: float,
    s_perp: float,
    r_perp: float,
) -> FloatArray:  # pragma: no cover - numba
    """``out[k] = sum_cells P O_in(alpha - alpha_r[k]) O_perp(beta)`` (rectangles).

    ``alpha = atan2(-wo_x, wo_z)`` (in-plane angle), ``beta = asin(wo_y)``.
    """
    out = np.zeros(alpha_r.size)
    half_b = 0.5 * (s_perp + r_perp)
    half_a = 0.5 * (s_in + r_in)
    for k in range(alpha_r.size):
        ar = alpha_r[k]
        cb = math.cos(min(half_b, 1.5))
        s_hi = -math.sin(min(ar + half_a, 0.5 * math.pi))
        s_lo = -math.sin(max(ar - half_a, -0.5 * math.pi))
        lo = min(s_hi, s_hi * cb) - 1e-12
        hi = max(s_lo, s_lo * cb) + 1e-12
        j0 = np.searchsorted(wox, lo)
        j1 = np.searchsorted(wox, hi, side="right")
        yb = math.sin(min(half_b, 1.5)) + 1e-12
        i0 = np.searchsorted(woy, -yb)
        i1 = np.searchsorted(woy, yb, side="right")
        acc = 0.0
        for i in range(i0, i1):
            yy = woy[i]
            ob = interval_overlap(math.asin(max(-1.0, min(1.0, yy))), s_perp, r_perp)
            if ob == 0.0:
                continue
            for j in range(j0, j1):
                v = p[i, j]
                if v == 0.0:
                    continue
                xx = wox[j]
                z2 = 1.0 - xx * xx - yy * yy
                if z2 <= 0.0:
                    continue
                al = math.atan2(-xx, math.sqrt(z2))
                acc += v * ob * interval_overlap(al - ar, s_in, r_in)
        out[k] = acc
    return out


@njit_cached(nogil=True, fastmath=False)
def kirchhoff_band_numba(
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
) -> None:  # pragma: no cover - numba
    """Add ``|U_d|^2`` of one Taylor band to ``acc`` (in place) for the cells it owns.

    ``spec[n]`` is the transform of the n-th Taylor term ``W e^(-i v_c h) (h/h_max)^n``
    on a region of the FFT grid (the box's cell ``(i, j)`` at ``spec[:, rows[i], cols[j]]``),
    ``dc[n]`` its value at zero frequency. A cell with ``ok`` and ``lo <= vz < hi``
    (``<= hi`` when ``hi_inclusive``) gets, with ``d = (vz - v_c) h_max``,
    ``U = sum_n (spec[n] - dc[n] w_rows[i] w_cols[j]) (-i d)^n / n!`` (Horner's scheme;
    the ``dc`` part is the coherent beam times the window's normalised transform).
    """
    n_terms = spec.shape[0]
    for i in range(vz.shape[0]):
        r = rows[i]
        wr = w_rows[i]
        for j in range(vz.shape[1]):
            if not ok[i, j]:
                continue
            v = vz[i, j]
            if v < lo or v > hi or (v == hi and not hi_inclusive):
                continue
            step = -1j * ((v - vc) * h_max)
            c = cols[j]
            f = complex(spec[n_terms - 1, r, c])
            e = dc[n_terms - 1]
            for n in range(n_terms - 2, -1, -1):
                s = step / (n + 1)
                f = complex(spec[n, r, c]) + f * s
                e = dc[n] + e * s
            u = f - e * (wr * w_cols[j])
            acc[i, j] += u.real * u.real + u.imag * u.imag
