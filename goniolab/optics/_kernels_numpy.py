"""The numpy twins of the facet kernels of :mod:`goniolab.optics._kernels` (no numba).

Each function here does, for whole arrays of facets, what its numba namesake does facet by
facet (the per-facet step is described in :mod:`goniolab.optics._kernels`: Wittmann et al.
2021, eqs. 5-10, with the radiometric weight of docs/PHYSICS.md). They are the test
reference of the compiled kernels and the whole of the facet model's ``"lean"`` backend,
which runs without importing numba (about 1 s of import and set-up per process, more than
a command's work on a 2048^2 map). All arithmetic is float64.

``counts`` (optional, in the kernels that take it): the number of facets each entry stands
for, when the entries are the occupied cells of a slope histogram rather than single
facets (:class:`goniolab.optics.facet.FacetModel`, backend ``"lean"``).
"""

from __future__ import annotations

import functools
import itertools

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.facet_threads import run_tasks
from goniolab.optics.fresnel import fresnel

FloatArray = NDArray[np.float64]

#: The gradient channels of the deposit live on a grid this many times coarser per axis
#: (same origin): they carry a smooth first-order correction, and the fine grid's three
#: channels would not stay in cache.
GRAD_COARSEN: int = 4


def coarse_size(n_fine: int) -> int:
    """Nodes of the coarse gradient grid covering a fine grid of ``n_fine`` nodes."""
    return -(-(n_fine - 1) // GRAD_COARSEN) + 2


def normals_numpy(
    mx: FloatArray, my: FloatArray, mz: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Numpy twin of :func:`_normal` for whole arrays (normals, or slopes with an empty mz)."""
    if mz.size == 0:
        inv = 1.0 / np.sqrt(1.0 + mx * mx + my * my)
        return -mx * inv, -my * inv, inv
    return mx, my, mz


def reflect_numpy(
    mx: FloatArray,
    my: FloatArray,
    mz: FloatArray,
    wi: FloatArray,
    n_re: float,
    n_im: float,
    seed: bool,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Vectorised twin of the per-facet step: ``(wo_x, wo_y, wo_z, w)``, w = 0 when dropped."""
    mx, my, mz = normals_numpy(mx, my, mz)
    c = wi[0] * mx + wi[1] * my + wi[2] * mz
    ox = 2.0 * c * mx - wi[0]
    oy = 2.0 * c * my - wi[1]
    oz = 2.0 * c * mz - wi[2]
    keep = (c > 0.0) & (oz > 0.0)
    f = fresnel(np.clip(c, 0.0, 1.0), complex(n_re, n_im))
    w = f if seed else c / (mz * wi[2]) * f
    return ox, oy, oz, np.where(keep, w, 0.0)


def fresnel_d_numpy(c: FloatArray, n_re: float, n_im: float) -> tuple[FloatArray, FloatArray]:
    """Numpy twin of :func:`_fresnel_d_scalar`: ``(F, dF/dc)`` for ``c`` clipped to [0, 1].

    ``r_s = (c - n c_t)/(c + n c_t)``, ``r_p = (n c - c_t)/(n c + c_t)``, F their mean
    square modulus, total internal reflection F = 1 for a real n < 1. A real index is
    computed in real arithmetic (a quarter of the complex work).
    """
    c = np.clip(c, 0.0, 1.0)
    tir = (n_im == 0.0) & ((1.0 - c * c) / (n_re * n_re) >= 1.0)
    eta: complex | float = n_re
    cc: NDArray[np.float64] | NDArray[np.complex128] = c
    if n_im != 0.0:
        eta, cc = complex(n_re, n_im), c.astype(np.complex128)
    ct = np.sqrt(np.where(tir, 1.0, 1.0 - (1.0 - cc * cc) / (eta * eta)))
    dct = cc / (eta * eta * ct)
    den_s = cc + eta * ct
    den_p = eta * cc + ct
    r_s = (cc - eta * ct) / den_s
    r_p = (eta * cc - ct) / den_p
    num = 2.0 * eta * (ct - cc * dct)
    f = 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)
    df = (np.conj(r_s) * num / (den_s * den_s) + np.conj(r_p) * num / (den_p * den_p)).real
    return np.where(tir, 1.0, f), np.where(tir, 0.0, df)


def weight_grad_numpy(
    mx: FloatArray,
    my: FloatArray,
    mz: FloatArray,
    wi: FloatArray,
    n_re: float,
    n_im: float,
    seed: bool,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Numpy twin of the per-facet step with :func:`_weight_grad`: ``(ox, oy, oz, w, P, Q)``.

    All three coefficients are 0 for dropped facets (facing away or reflecting inwards).
    """
    mx, my, mz = normals_numpy(mx, my, mz)
    c = wi[0] * mx + wi[1] * my + wi[2] * mz
    ox = 2.0 * c * mx - wi[0]
    oy = 2.0 * c * my - wi[1]
    oz = 2.0 * c * mz - wi[2]
    keep = (c > 0.0) & (oz > 0.0)
    w, pp, qq = _weight_terms(c, mz, wi, n_re, n_im, seed)
    zero = np.zeros_like(c)
    return ox, oy, oz, np.where(keep, w, zero), np.where(keep, pp, zero), np.where(keep, qq, zero)


def _weight_terms(
    c: FloatArray, mz: FloatArray, wi: FloatArray, n_re: float, n_im: float, seed: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The weight and its gradient coefficients ``(w, P, Q)`` of facets with ``c = wi . m``
    (:func:`weight_grad_numpy`, before the facets facing away are zeroed)."""
    f, df = fresnel_d_numpy(c, n_re, n_im)
    wz = wi[2]
    if seed:
        return f, df, np.zeros_like(f)
    phi = c * f
    w = phi / (mz * wz)
    pp = (f + c * df) / (mz * wz) - 2.0 * phi / (wz * wz)
    qq = phi / (mz * wz * wz)
    return w, pp, qq


def diamond_numpy(x: FloatArray, y: FloatArray) -> FloatArray:
    """Numpy twin of the pseudo-angle ``D(x, y)`` in [0, 4)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(
            y >= 0.0,
            np.where(x >= 0.0, y / (x + y), 1.0 - x / (y - x)),
            np.where(x < 0.0, 2.0 - y / (-x - y), 3.0 + x / (x - y)),
        )
    out: FloatArray = np.where((x == 0.0) & (y == 0.0), 0.0, d)
    return out


def hemisphere_bin_tables(
    bin_rad: float, n_theta: int, n_phi: int, n_guess: int = 4096
) -> tuple[FloatArray, NDArray[np.int64], FloatArray, NDArray[np.int64]]:
    """Edge tables and first-guess tables for :func:`hemisphere_numba` / its twin."""
    cos_edges = np.cos(bin_rad * np.arange(n_theta + 1))
    phi_e = bin_rad * np.arange(n_phi + 1)
    diamond_edges = diamond_numpy(np.cos(phi_e), np.sin(phi_e))
    diamond_edges[0], diamond_edges[-1] = 0.0, 4.0
    theta_guess = _theta_bins(np.arange(n_guess) / n_guess, cos_edges)
    phi_guess = _phi_bins(4.0 * np.arange(n_guess) / n_guess, diamond_edges)
    return cos_edges, theta_guess, diamond_edges, phi_guess


def _theta_bins(oz: FloatArray, cos_edges: FloatArray) -> NDArray[np.int64]:
    """k with cos_edges[k+1] < oz <= cos_edges[k] (clipped to the valid bins)."""
    n_theta = cos_edges.size - 1
    asc = cos_edges[::-1]
    k = (asc.size - np.searchsorted(asc, oz, side="left")) - 1
    out: NDArray[np.int64] = np.clip(k, 0, n_theta - 1).astype(np.int64)
    return out


def _phi_bins(d: FloatArray, diamond_edges: FloatArray) -> NDArray[np.int64]:
    """k with diamond_edges[k] <= d < diamond_edges[k+1] (clipped to the valid bins)."""
    k = np.searchsorted(diamond_edges, d, side="right") - 1
    out: NDArray[np.int64] = np.clip(k, 0, diamond_edges.size - 2).astype(np.int64)
    return out


def hemisphere_numpy(
    mx: FloatArray,
    my: FloatArray,
    mz: FloatArray,
    wi: FloatArray,
    n_re: float,
    n_im: float,
    seed: bool,
    cos_edges: FloatArray,
    theta_guess: NDArray[np.int64],
    diamond_edges: FloatArray,
    phi_guess: NDArray[np.int64],
    *,
    counts: FloatArray | None = None,
) -> tuple[FloatArray, float]:
    """Numpy twin of :func:`hemisphere_numba` (same bin rule; the guess tables are unused)."""
    ox, oy, oz, w = reflect_numpy(mx, my, mz, wi, n_re, n_im, seed)
    if counts is not None:
        w = w * counts
    keep = w != 0.0
    ox, oy, oz, w = ox[keep], oy[keep], oz[keep], w[keep]
    n_theta, n_phi = cos_edges.size - 1, diamond_edges.size - 1
    it = _theta_bins(oz, cos_edges)
    ip = _phi_bins(diamond_numpy(ox, oy), diamond_edges)
    hist = np.bincount(it * n_phi + ip, weights=w, minlength=n_theta * n_phi).astype(np.float64)
    return hist.reshape(n_theta, n_phi), float(w.sum())


def deposit_numpy(
    mx: FloatArray,
    my: FloatArray,
    mz: FloatArray,
    wi: FloatArray,
    n_re: float,
    n_im: float,
    seed: bool,
    a0: float,
    ha: float,
    na: int,
    b0: float,
    hb: float,
    nb: int,
    grad: bool,
    *,
    counts: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, float]:
    """Numpy twin of :func:`deposit_numba`.

    The mirror directions come first: the weights (Fresnel and its derivative) are then
    formed only for the facets that face the lamp, reflect above the horizon and land on
    the grid (on a rough map about half of them), each by the same operations as
    :func:`weight_grad_numpy`, so the grid is the same.

    The facets' terms are formed in :data:`_DEPOSIT_PARTS` consecutive parts
    (:func:`~goniolab.optics.facet_threads.run_tasks`) joined in order, then each corner
    of each grid's cloud-in-cell weights is counted over all of them and the corners are
    added in order: the grids are the same bits however the parts are shared out."""
    n = mx.size
    parts = max(1, min(_DEPOSIT_PARTS, n // _DEPOSIT_PART_MIN))
    cuts = [n * k // parts for k in range(parts + 1)]
    geometry = (a0, ha, na, b0, hb, nb, grad)
    pieces = run_tasks(
        [
            functools.partial(
                _deposit_terms,
                mx[a:b],
                my[a:b],
                mz[a:b] if mz.size else mz,
                wi,
                n_re,
                n_im,
                seed,
                geometry,
                None if counts is None else counts[a:b],
            )
            for a, b in itertools.pairwise(cuts)
        ]
    )
    x, y, w, ga, gb = (
        pieces[0][k] if parts == 1 else np.concatenate([piece[k] for piece in pieces])
        for k in range(5)
    )
    nac, nbc = coarse_size(na), coarse_size(nb)
    # one thread: two threads summing corners at once were no faster (bincount, as the
    # corners were summed then, holds the GIL for a pass over its indices)
    grids = _cic_grids(x, y, (w,), na, nb)
    if grad:
        xc, yc = x / GRAD_COARSEN, y / GRAD_COARSEN
        grids += _cic_grids(xc, yc, (ga, gb), nac, nbc)
    ggrid = np.zeros((nac, nbc, 2))
    if grad:
        ggrid[..., 0] = grids[1]
        ggrid[..., 1] = grids[2]
    return grids[0], ggrid, float(w.sum())


#: The facets of a deposit are formed in this many parts (of at least _DEPOSIT_PART_MIN)
#: whatever the number of threads: one, as two threads forming parts at once were no
#: faster on a rough 2048^2 map (the deposit runs beside the Smith Lambda table instead).
_DEPOSIT_PARTS = 1
_DEPOSIT_PART_MIN = 1 << 15
#: The cloud-in-cell corners (di, dj), in the order their grids are added.
_CORNERS = ((0, 0), (0, 1), (1, 0), (1, 1))


def _deposit_terms(
    mx: FloatArray,
    my: FloatArray,
    mz: FloatArray,
    wi: FloatArray,
    n_re: float,
    n_im: float,
    seed: bool,
    geometry: tuple[float, float, int, float, float, int, bool],
    counts: FloatArray | None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`deposit_numpy`'s terms of the facets (or cells) given that land on the
    grid: grid coordinates ``(x, y)``, weight and its gradient components along the two
    grid axes (empty without ``grad``)."""
    a0, ha, na, b0, hb, nb, grad = geometry
    mx, my, mz = normals_numpy(mx, my, mz)
    c = wi[0] * mx + wi[1] * my + wi[2] * mz
    ox = 2.0 * c * mx - wi[0]
    oy = 2.0 * c * my - wi[1]
    oz = 2.0 * c * mz - wi[2]
    x = (np.arctan2(-ox, oz) - a0) / ha
    y = (oy - b0) / hb
    sel = (c > 0.0) & (oz > 0.0)
    sel &= x >= 0.0
    sel &= x < na - 1.0
    sel &= y >= 0.0
    sel &= y < nb - 1.0
    at = np.flatnonzero(sel)
    mx, my, mz, c = mx[at], my[at], mz[at], c[at]
    ox, oy, oz, x, y = ox[at], oy[at], oz[at], x[at], y[at]
    w, pp, qq = _weight_terms(c, mz, wi, n_re, n_im, seed)
    if counts is not None:
        cnt = counts[at]
        w, pp, qq = w * cnt, pp * cnt, qq * cnt
    keep = w != 0.0  # (none is dropped here unless its weight is 0)
    if not keep.all():
        mx, my, mz, ox, oy, oz = mx[keep], my[keep], mz[keep], ox[keep], oy[keep], oz[keep]
        w, pp, qq, x, y = w[keep], pp[keep], qq[keep], x[keep], y[keep]
    if not grad:
        return x, y, w, _EMPTY, _EMPTY
    rho = np.sqrt(ox * ox + oz * oz)
    ga = (pp * (ox * mz - oz * mx) + qq * ox) / rho
    gb = (pp * (rho * rho * my - oy * (ox * mx + oz * mz)) - qq * oz * oy) / rho
    return x, y, w, ga, gb


_EMPTY: FloatArray = np.empty(0)


def _cic_grids(
    xs: FloatArray, ys: FloatArray, vals: tuple[FloatArray, ...], n0: int, n1: int
) -> list[FloatArray]:
    """The cloud-in-cell deposits of each of ``vals`` at grid coordinates ``(xs, ys)`` on
    an ``n0 x n1`` grid: per corner ``(di, dj)`` of :data:`_CORNERS`, the nodes
    ``(i + di, j + dj)`` get ``val (1 - fx or fx) (1 - fy or fy)``, the corners' grids
    added in that order (the first is the sum's start). The nodes and fractions are
    formed once for all values and corners; each corner by ``np.add.at``, which adds the
    points in their order as ``np.bincount`` does (the same sums; 3x faster on a curve's
    0.4 M-node grid: no min/max pass over the nodes)."""
    i = xs.astype(np.int64)
    j = ys.astype(np.int64)
    fx, fy = xs - i, ys - j
    gx, gy = 1.0 - fx, 1.0 - fy
    node = i * n1
    node += j
    grids = []
    for val in vals:
        out: FloatArray | None = None
        for di, dj in _CORNERS:
            part = np.zeros(n0 * n1)
            np.add.at(part, node + (di * n1 + dj), val * (fx if di else gx) * (fy if dj else gy))
            if out is None:
                out = part
            else:
                out += part
        assert out is not None
        grids.append(out.reshape(n0, n1))
    return grids


def table_numpy(g: FloatArray, table: FloatArray, g0: float, g1: float, o_in: float) -> FloatArray:
    """Numpy twin of the O(gamma) table lookup."""
    if g1 > g0:
        t = (np.clip(g, g0, g1) - g0) / (g1 - g0) * (table.size - 1)
        inner = np.interp(t, np.arange(table.size, dtype=np.float64), table)
    else:
        inner = np.zeros_like(g)
    return np.where(g <= g0, o_in, np.where(g >= g1, 0.0, inner))


def cone_response_numpy(
    mx: FloatArray,
    my: FloatArray,
    mz: FloatArray,
    wi: FloatArray,
    n_re: float,
    n_im: float,
    seed: bool,
    d: FloatArray,
    table: FloatArray,
    g0: float,
    g1: float,
    o_in: float,
    m1: FloatArray,
    *,
    counts: FloatArray | None = None,
) -> float:
    """Numpy twin of :func:`cone_response_numba`."""
    mx, my, mz = normals_numpy(mx, my, mz)
    ox, oy, oz, w, pp, qq = weight_grad_numpy(mx, my, mz, wi, n_re, n_im, seed)
    if counts is not None:
        w, pp, qq = w * counts, pp * counts, qq * counts
    half_chord = 0.5 * np.sqrt((ox - d[0]) ** 2 + (oy - d[1]) ** 2 + (oz - d[2]) ** 2)
    g = 2.0 * np.arcsin(np.minimum(half_chord, 1.0))
    cos_g = ox * d[0] + oy * d[1] + oz * d[2]
    tx, ty, tz = d[0] - cos_g * ox, d[1] - cos_g * oy, d[2] - cos_g * oz
    tn = np.sqrt(tx * tx + ty * ty + tz * tz)
    ok = tn > 1e-300
    tn = np.where(ok, tn, 1.0)
    grad = np.where(ok, (pp * (tx * mx + ty * my + tz * mz) + qq * tz) / tn, 0.0)
    o_val = table_numpy(g, table, g0, g1, o_in)
    m1_val = table_numpy(g, m1, 0.0, g1, 0.0)
    return float(np.sum(w * o_val + grad * m1_val))


def interval_overlap_numpy(x: FloatArray, s: float, r: float) -> FloatArray:
    """Numpy twin of the 1-D interval overlap fraction."""
    if s <= 0.0:
        ax = np.abs(x)
        return np.where(ax < 0.5 * r, 1.0, np.where(ax == 0.5 * r, 0.5, 0.0))
    lo = np.maximum(x - 0.5 * s, -0.5 * r)
    hi = np.minimum(x + 0.5 * s, 0.5 * r)
    out: FloatArray = np.maximum(hi - lo, 0.0) / s
    return out


def rect_response_numpy(
    mx: FloatArray,
    my: FloatArray,
    mz: FloatArray,
    wi: FloatArray,
    n_re: float,
    n_im: float,
    seed: bool,
    alpha_r: float,
    s_in: float,
    r_in: float,
    s_perp: float,
    r_perp: float,
    *,
    counts: FloatArray | None = None,
) -> float:
    """Numpy twin of :func:`rect_response_numba`."""
    ox, oy, oz, w = reflect_numpy(mx, my, mz, wi, n_re, n_im, seed)
    if counts is not None:
        w = w * counts
    be = np.arcsin(np.clip(oy, -1.0, 1.0))
    al = np.arctan2(-ox, oz)
    ov = interval_overlap_numpy(be, s_perp, r_perp) * interval_overlap_numpy(
        al - alpha_r, s_in, r_in
    )
    return float(np.sum(w * ov))
