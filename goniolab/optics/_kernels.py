"""Fused per-facet kernels of the facet model, each in numba and as a pure-numpy twin.

Every kernel walks the facet normals ``m = (mx, my, mz)`` once for one incident direction
``wi`` and does, per facet (Wittmann et al. 2021, eqs. 5-10, with the radiometric
weight of docs/PHYSICS.md, "The facet weight and the facet BRDF"):

- ``c = wi . m`` (cosine of the local incidence angle iota); facets with ``c <= 0`` face
  away from the lamp and get no light;
- ``wo = 2 c m - wi`` (the seed's ``M = 2 m m^T - I``, eqs. 5-8);
- facets whose ``wo_z <= 0`` would send the light into the surface: they are dropped
  (no multiple scattering is modelled, so that flux is lost, not redistributed);
- the weight ``w = c / (m_z cos ti) F(c)`` ("radiometric": flux reflected by the facet,
  whose projected area on x-y is one pixel, over the flux falling on that pixel) or
  ``w = F(c)`` ("seed": Wittmann weighs the slope histogram by Fresnel alone).

The fraction of the incident flux sent towards ``wo_k`` is ``w_k / N``. The kernels then
bin, deposit or integrate ``w`` in different ways; the cone kernels also use the
gradient of ``w`` across the mirror image of the source (:func:`_weight_grad`, with the
Fresnel derivative of :func:`_fresnel_d_scalar`) for the first-order aperture term
described in :mod:`goniolab.optics.facet`. The numba versions are compiled with
``nogil=True`` so the facet model can split the facets over threads; their numpy twins
(:mod:`goniolab.optics._kernels_numpy`, re-exported here) are the test reference and the
facet model's numba-free ``"lean"`` backend. All arithmetic is float64.

Facets are passed as three arrays ``(mx, my, mz)`` of unit normals, or, with an empty ``mz``,
as their slopes ``(p, q, empty)``: the normal ``(-p, -q, 1)/sqrt(1 + p^2 + q^2)`` is then
formed facet by facet (:func:`_normal`), bit for bit as :attr:`Surface.normals` forms it, so
the facet model never holds three normal arrays beside the slopes (24 bytes per facet less
memory and traffic).

Compiled kernels are cached on disk (``cache=True``): numba keeps them in ``__pycache__``
beside this file, or in the user cache directory (``NUMBA_CACHE_DIR`` to choose) when the
package directory is read-only; when no directory is writable the kernels are compiled
in each process instead (:func:`njit_cached`).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from goniolab.optics._kernels_numpy import (
    GRAD_COARSEN,
    cone_response_numpy,
    deposit_numpy,
    diamond_numpy,
    fresnel_d_numpy,
    hemisphere_bin_tables,
    hemisphere_numpy,
    interval_overlap_numpy,
    normals_numpy,
    rect_response_numpy,
    reflect_numpy,
    table_numpy,
    weight_grad_numpy,
)

__all__ = [
    "GRAD_COARSEN",
    "coarse_size",
    "cone_response_numba",
    "cone_response_numpy",
    "deposit_numba",
    "deposit_numpy",
    "diamond_numpy",
    "fresnel_d_numpy",
    "hemisphere_bin_tables",
    "hemisphere_numba",
    "hemisphere_numpy",
    "interval_overlap",
    "interval_overlap_numpy",
    "njit_cached",
    "normals_numpy",
    "rect_response_numba",
    "rect_response_numpy",
    "reflect_numpy",
    "table_numpy",
    "table_value",
    "weight_grad_numpy",
]

FloatArray = NDArray[np.float64]

#: Whether the kernels were compiled with an on-disk cache (False: no writable directory).
CACHED: bool = True


def njit_cached(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(cache=True, **options)``, without the cache when numba finds no
    writable cache directory (it raises at decoration then): slower start, same kernels."""

    def wrap(fn: Callable[..., Any]) -> Any:
        global CACHED
        try:
            return njit(cache=True, **options)(fn)
        except RuntimeError:  # "cannot cache function ...: no locator available"
            CACHED = False
            return njit(cache=False, **options)(fn)

    return wrap


@njit_cached(nogil=True, fastmath=False)
def _normal(
    mx: FloatArray, my: FloatArray, mz: FloatArray, k: int
) -> tuple[float, float, float]:  # pragma: no cover - numba
    """Unit normal of facet k: ``(mx[k], my[k], mz[k])``, or from the slopes ``p = mx[k]``,
    ``q = my[k]`` when ``mz`` is empty (docs/PHYSICS.md, "From a height map to facets")."""
    if mz.size == 0:
        p = mx[k]
        q = my[k]
        inv = 1.0 / math.sqrt(1.0 + p * p + q * q)
        return -p * inv, -q * inv, inv
    return mx[k], my[k], mz[k]


# ----------------------------------------------------------------------------- scalar helpers
@njit_cached(nogil=True, fastmath=False)
def _fresnel_scalar(c: float, n_re: float, n_im: float) -> float:  # pragma: no cover - numba
    """Unpolarised Fresnel reflectance (cosine form of Wittmann eq. 9; pbrt FrComplex)."""
    if c < 0.0:
        c = 0.0
    elif c > 1.0:
        c = 1.0
    if n_im == 0.0:
        s2 = (1.0 - c * c) / (n_re * n_re)
        if s2 >= 1.0:
            return 1.0
        ct = math.sqrt(1.0 - s2)
        rs = (c - n_re * ct) / (c + n_re * ct)
        rp = (n_re * c - ct) / (n_re * c + ct)
        return 0.5 * (rs * rs + rp * rp)
    eta = complex(n_re, n_im)
    cc = complex(c, 0.0)
    ctc = cmath.sqrt(1.0 - (1.0 - cc * cc) / (eta * eta))
    r_perp = (cc - eta * ctc) / (cc + eta * ctc)
    r_parl = (eta * cc - ctc) / (eta * cc + ctc)
    return 0.5 * (
        r_perp.real * r_perp.real
        + r_perp.imag * r_perp.imag
        + r_parl.real * r_parl.real
        + r_parl.imag * r_parl.imag
    )


@njit_cached(nogil=True, fastmath=False)
def _fresnel_d_scalar(
    c: float, n_re: float, n_im: float
) -> tuple[float, float]:  # pragma: no cover - numba
    """Unpolarised Fresnel reflectance F(c) and its derivative dF/dc (c = cos iota).

    With ``cos t = sqrt(1 - (1 - c^2)/eta^2)``, ``d cos t/dc = c/(eta^2 cos t)`` and both
    amplitude coefficients have ``dr/dc = 2 eta (cos t - c d cos t/dc) / D^2`` (D their
    denominator); ``dF/dc = Re(conj(r_s) dr_s + conj(r_p) dr_p)``. Zero slope under total
    internal reflection.
    """
    if c < 0.0:
        c = 0.0
    elif c > 1.0:
        c = 1.0
    if n_im == 0.0:
        s2 = (1.0 - c * c) / (n_re * n_re)
        if s2 >= 1.0:
            return 1.0, 0.0
        ct = math.sqrt(1.0 - s2)
        # ct - c dct = (ct^2 - c^2/n^2)/ct = (1 - 1/n^2)/ct
        num = 2.0 * n_re * (1.0 - 1.0 / (n_re * n_re)) / ct
        inv_s = 1.0 / (c + n_re * ct)
        inv_p = 1.0 / (n_re * c + ct)
        rs = (c - n_re * ct) * inv_s
        rp = (n_re * c - ct) * inv_p
        return 0.5 * (rs * rs + rp * rp), num * (rs * inv_s * inv_s + rp * inv_p * inv_p)
    eta = complex(n_re, n_im)
    cc = complex(c, 0.0)
    ctc = cmath.sqrt(1.0 - (1.0 - cc * cc) / (eta * eta))
    dct_c = cc / (eta * eta * ctc)
    den_sc = cc + eta * ctc
    den_pc = eta * cc + ctc
    r_perp = (cc - eta * ctc) / den_sc
    r_parl = (eta * cc - ctc) / den_pc
    num_c = 2.0 * eta * (ctc - cc * dct_c)
    d_perp = num_c / (den_sc * den_sc)
    d_parl = num_c / (den_pc * den_pc)
    f = 0.5 * (
        r_perp.real * r_perp.real
        + r_perp.imag * r_perp.imag
        + r_parl.real * r_parl.real
        + r_parl.imag * r_parl.imag
    )
    df = (
        r_perp.real * d_perp.real
        + r_perp.imag * d_perp.imag
        + r_parl.real * d_parl.real
        + r_parl.imag * d_parl.imag
    )
    return f, df


@njit_cached(nogil=True, fastmath=False)
def _weight_grad(
    c: float, mz: float, wz: float, n_re: float, n_im: float, seed: bool
) -> tuple[float, float, float]:  # pragma: no cover - numba
    """Facet weight w and its gradient over the mirror image of the source, ``dw = P (t.m) + Q t_z``.

    In the image space ``o = M s`` of the source directions s the weight is
    ``w = phi(c)/(m_z s_z)`` with ``c = o.m``, ``s_z = 2 c m_z - o_z`` and ``phi = c F`` (seed:
    ``w = F``); along a tangent t at the image centre (where s = wi)
    ``dc = t.m`` and ``ds_z = 2 (t.m) m_z - t_z``, so
    ``P = phi'(c)/(m_z wi_z) - 2 phi(c)/wi_z^2`` and ``Q = phi(c)/(m_z wi_z^2)`` (seed:
    ``P = F'(c)``, ``Q = 0``).
    """
    f, df = _fresnel_d_scalar(c, n_re, n_im)
    if seed:
        return f, df, 0.0
    phi = c * f
    return phi / (mz * wz), (f + c * df) / (mz * wz) - 2.0 * phi / (wz * wz), phi / (mz * wz * wz)


@njit_cached(nogil=True, fastmath=False)
def _reflect(
    mx: float,
    my: float,
    mz: float,
    wx: float,
    wy: float,
    wz: float,
    n_re: float,
    n_im: float,
    seed: bool,
) -> tuple[float, float, float, float]:  # pragma: no cover - numba
    """Mirror direction and weight of one facet; weight 0 for dropped facets."""
    ox, oy, oz, c = _mirror(mx, my, mz, wx, wy, wz)
    if c == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return ox, oy, oz, _weight(c, mz, wz, n_re, n_im, seed)


@njit_cached(nogil=True, fastmath=False)
def _mirror(
    mx: float, my: float, mz: float, wx: float, wy: float, wz: float
) -> tuple[float, float, float, float]:  # pragma: no cover - numba
    """Mirror direction and ``c = wi . m`` of one facet; c = 0 for facets that get no weight."""
    c = wx * mx + wy * my + wz * mz
    if c <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    oz = 2.0 * c * mz - wz
    if oz <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return 2.0 * c * mx - wx, 2.0 * c * my - wy, oz, c


@njit_cached(nogil=True, fastmath=False)
def _weight(
    c: float, mz: float, wz: float, n_re: float, n_im: float, seed: bool
) -> float:  # pragma: no cover - numba
    """Facet weight for ``c = wi . m > 0`` (same as :func:`_reflect`)."""
    f = _fresnel_scalar(c, n_re, n_im)
    return f if seed else c / (mz * wz) * f


@njit_cached(nogil=True, fastmath=False)
def interval_overlap(x: float, s: float, r: float) -> float:  # pragma: no cover - numba
    """Fraction of [x - s/2, x + s/2] inside [-r/2, r/2] (indicator when s == 0)."""
    if s <= 0.0:
        ax = abs(x)
        h = 0.5 * r
        if ax < h:
            return 1.0
        if ax == h:
            return 0.5
        return 0.0
    lo = max(x - 0.5 * s, -0.5 * r)
    hi = min(x + 0.5 * s, 0.5 * r)
    if hi <= lo:
        return 0.0
    return (hi - lo) / s


@njit_cached(nogil=True, fastmath=False)
def table_value(
    g: float, table: FloatArray, g0: float, g1: float, o_in: float
) -> float:  # pragma: no cover
    """Cap-overlap fraction O(gamma) from its table on [g0, g1] (linear interpolation)."""
    if g <= g0:
        return o_in
    if g >= g1:
        return 0.0
    t = (g - g0) / (g1 - g0) * (table.size - 1)
    i = int(t)
    if i >= table.size - 1:
        return table[table.size - 1]
    f = t - i
    return table[i] * (1.0 - f) + table[i + 1] * f


# ----------------------------------------------------------------------------- numba kernels
@njit_cached(nogil=True, fastmath=False)
def _diamond(x: float, y: float) -> float:  # pragma: no cover - numba
    """Pseudo-angle in [0, 4), strictly increasing with atan2(y, x) mod 2 pi; 0 at (0, 0)."""
    if x == 0.0 and y == 0.0:
        return 0.0
    if y >= 0.0:
        return y / (x + y) if x >= 0.0 else 1.0 - x / (y - x)
    return 2.0 - y / (-x - y) if x < 0.0 else 3.0 + x / (x - y)


@njit_cached(nogil=True, fastmath=False)
def hemisphere_numba(
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
) -> tuple[FloatArray, float]:  # pragma: no cover - numba
    """Sum of weights per (theta_o, phi_o) bin; also the total weight.

    Bins are found without inverse trigonometry: theta bin k holds
    ``cos_edges[k+1] < wo_z <= cos_edges[k]`` and phi bin k holds
    ``diamond_edges[k] <= D(wo_x, wo_y) < diamond_edges[k+1]`` (D the pseudo-angle), from a
    first guess tabulated on a uniform grid (``theta_guess`` over wo_z in [0, 1],
    ``phi_guess`` over D in [0, 4)) refined by comparisons.
    """
    n_theta = cos_edges.size - 1
    n_phi = diamond_edges.size - 1
    mt = theta_guess.size
    mp = phi_guess.size
    hist = np.zeros((n_theta, n_phi))
    wx, wy, wz = wi[0], wi[1], wi[2]
    total = 0.0
    for k in range(mx.size):
        mxk, myk, mzk = _normal(mx, my, mz, k)
        ox, oy, oz, w = _reflect(mxk, myk, mzk, wx, wy, wz, n_re, n_im, seed)
        if w == 0.0:
            continue
        total += w
        j = int(oz * mt)
        if j >= mt:
            j = mt - 1
        it = theta_guess[j]
        while it > 0 and oz > cos_edges[it]:
            it -= 1
        while it < n_theta - 1 and oz <= cos_edges[it + 1]:
            it += 1
        d = _diamond(ox, oy)
        j = int(d * 0.25 * mp)
        if j >= mp:
            j = mp - 1
        ip = phi_guess[j]
        while ip < n_phi - 1 and d >= diamond_edges[ip + 1]:
            ip += 1
        while ip > 0 and d < diamond_edges[ip]:
            ip -= 1
        hist[it, ip] += w
    return hist, total


@njit_cached(nogil=True)
def coarse_size(n_fine: int) -> int:  # pragma: no cover - numba (also callable from Python)
    """Nodes of the coarse gradient grid covering a fine grid of ``n_fine`` nodes."""
    return -(-(n_fine - 1) // GRAD_COARSEN) + 2


@njit_cached(nogil=True, fastmath=False)
def deposit_numba(
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
) -> tuple[FloatArray, FloatArray, float]:  # pragma: no cover - numba
    """Cloud-in-cell deposit of the weights on nodes ``(a0 + i ha, b0 + j hb)``.

    Coordinates: in-plane angle ``alpha = atan2(-wo_x, wo_z)`` (radians) and
    ``sin(beta) = wo_y`` (beta the out-of-plane angle). A facet is deposited on the four
    nodes of its cell only when the whole cell lies in the grid (callers keep a margin of
    empty nodes). Returns the weight grid ``(na, nb)``, the gradient grid
    ``(coarse_size(na), coarse_size(nb), 2)`` on nodes ``GRAD_COARSEN`` times further apart
    (zeros unless ``grad``): the weights' gradients over the source image
    (:func:`_weight_grad`) along the unit tangents ``t_alpha = (-wo_z, 0, wo_x)/rho`` and
    ``t_beta = (-wo_x wo_y, rho^2, -wo_z wo_y)/rho`` (``rho = cos beta``), and the total
    deposited weight (facets outside the grid are never weighed).
    """
    grid = np.zeros((na, nb))
    ggrid = np.zeros((coarse_size(na), coarse_size(nb), 2))
    wx, wy, wz = wi[0], wi[1], wi[2]
    total = 0.0
    x_hi = na - 1.0
    y_hi = nb - 1.0
    inv_c = 1.0 / GRAD_COARSEN
    for k in range(mx.size):
        mxk, myk, mzk = _normal(mx, my, mz, k)
        ox, oy, oz, c = _mirror(mxk, myk, mzk, wx, wy, wz)
        if c == 0.0:
            continue
        y = (oy - b0) / hb
        if y < 0.0 or y >= y_hi:
            continue
        x = (math.atan2(-ox, oz) - a0) / ha
        if x < 0.0 or x >= x_hi:
            continue
        if grad:
            w, pp, qq = _weight_grad(c, mzk, wz, n_re, n_im, seed)
            rho = math.sqrt(ox * ox + oz * oz)
            ga = (pp * (ox * mzk - oz * mxk) + qq * ox) / rho
            gb = (pp * (rho * rho * myk - oy * (ox * mxk + oz * mzk)) - qq * oz * oy) / rho
            xc = x * inv_c
            yc = y * inv_c
            ic = int(xc)
            jc = int(yc)
            gx = xc - ic
            gy = yc - jc
            c00 = (1.0 - gx) * (1.0 - gy)
            c01 = (1.0 - gx) * gy
            c10 = gx * (1.0 - gy)
            c11 = gx * gy
            ggrid[ic, jc, 0] += ga * c00
            ggrid[ic, jc, 1] += gb * c00
            ggrid[ic, jc + 1, 0] += ga * c01
            ggrid[ic, jc + 1, 1] += gb * c01
            ggrid[ic + 1, jc, 0] += ga * c10
            ggrid[ic + 1, jc, 1] += gb * c10
            ggrid[ic + 1, jc + 1, 0] += ga * c11
            ggrid[ic + 1, jc + 1, 1] += gb * c11
        else:
            w = _weight(c, mzk, wz, n_re, n_im, seed)
        total += w
        i = int(x)
        j = int(y)
        fx = x - i
        fy = y - j
        w0 = w * (1.0 - fx)
        w1 = w * fx
        grid[i, j] += w0 * (1.0 - fy)
        grid[i, j + 1] += w0 * fy
        grid[i + 1, j] += w1 * (1.0 - fy)
        grid[i + 1, j + 1] += w1 * fy
    return grid, ggrid, total


@njit_cached(nogil=True, fastmath=False)
def cone_response_numba(
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
) -> float:  # pragma: no cover - numba
    """``sum_k [w_k O(gamma_k) + (grad w_k . e_k) M1(gamma_k)]`` over the facets.

    gamma_k is the angle between wo_k and the detector axis d, e_k the unit tangent at wo_k
    towards d, O the cap-overlap fraction (``table`` on [g0, g1], ``o_in`` inside g0) and M1
    the first moment of the overlap along e_k (``m1`` on [0, g1]): the weight's variation
    across the source cone to first order (:func:`_weight_grad`).
    """
    wx, wy, wz = wi[0], wi[1], wi[2]
    dx, dy, dz = d[0], d[1], d[2]
    # beyond g1 the caps do not meet: reject on the cosine, before any asin
    cos_g1 = math.cos(min(g1, math.pi))
    acc = 0.0
    for k in range(mx.size):
        mxk, myk, mzk = _normal(mx, my, mz, k)
        ox, oy, oz, c = _mirror(mxk, myk, mzk, wx, wy, wz)
        if c == 0.0:
            continue
        cos_g = ox * dx + oy * dy + oz * dz
        if cos_g < cos_g1:
            continue
        w, pp, qq = _weight_grad(c, mzk, wz, n_re, n_im, seed)
        ex = ox - dx
        ey = oy - dy
        ez = oz - dz
        half_chord = 0.5 * math.sqrt(ex * ex + ey * ey + ez * ez)
        if half_chord >= 1.0:
            continue
        g = 2.0 * math.asin(half_chord)
        acc += w * table_value(g, table, g0, g1, o_in)
        # tangent at wo towards d: d - (d.wo) wo, of length sin(gamma)
        tx = dx - cos_g * ox
        ty = dy - cos_g * oy
        tz = dz - cos_g * oz
        tn = math.sqrt(tx * tx + ty * ty + tz * tz)
        if tn > 1e-300:
            grad = (pp * (tx * mxk + ty * myk + tz * mzk) + qq * tz) / tn
            acc += grad * table_value(g, m1, 0.0, g1, 0.0)
    return acc


@njit_cached(nogil=True, fastmath=False)
def rect_response_numba(
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
) -> float:  # pragma: no cover - numba
    """``sum_k w_k ov_in(alpha_k - alpha_r) ov_perp(beta_k)`` for rectangular apertures."""
    wx, wy, wz = wi[0], wi[1], wi[2]
    reach_b = 0.5 * (s_perp + r_perp)
    reach_a = 0.5 * (s_in + r_in)
    # Cheap rejection before any inverse trigonometric call: |wo_y| = sin|beta| and, in the
    # frame turned by alpha_r, tan|alpha - alpha_r| = |sd| / cd.
    sin_b = math.sin(min(reach_b, 0.5 * math.pi))
    tan_a = math.tan(min(reach_a, 0.49 * math.pi))
    ca = math.cos(alpha_r)
    sa = math.sin(alpha_r)
    acc = 0.0
    for k in range(mx.size):
        mxk, myk, mzk = _normal(mx, my, mz, k)
        ox, oy, oz, c = _mirror(mxk, myk, mzk, wx, wy, wz)
        if c == 0.0 or abs(oy) > sin_b:
            continue
        sd = -ox * ca - oz * sa
        cd = oz * ca - ox * sa
        if cd <= 0.0 or abs(sd) > tan_a * cd:
            continue
        be = math.asin(max(-1.0, min(1.0, oy)))
        ob = interval_overlap(be, s_perp, r_perp)
        if ob == 0.0:
            continue
        w = _weight(c, mzk, wz, n_re, n_im, seed)
        acc += w * ob * interval_overlap(math.atan2(sd, cd), s_in, r_in)
    return acc
