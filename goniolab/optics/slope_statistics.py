"""Slope statistics of a facet set: the slope density P22 and Smith's masking-shadowing.

:class:`SlopeStatistics` holds what :class:`goniolab.optics.facet.FacetModel` reads from the
distribution of the measured slopes: the slope density ``P22`` of the analytic facet BRDF
(a Gaussian kernel density with Scott's bandwidth, or the histogram of Wittmann et al.
2021, sec. 3.1) and the Smith ``Lambda`` of the empirical distribution, tabulated, with the
height-correlated ``G2 = 1/(1 + Lambda(wi) + Lambda(wo))`` (Heitz 2014).

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 3.1.
.. [2] E. Heitz, "Understanding the masking-shadowing function in microfacet-based BRDFs",
   JCGT 3(2) 2014 (Smith Lambda from a slope distribution, height-correlated G2).
.. [3] D. W. Scott, "Multivariate Density Estimation", Wiley 1992 (bandwidth rule).
"""

from __future__ import annotations

import functools
import itertools
import math
import threading
from collections.abc import Callable
from functools import cached_property
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics.facet_backends import check_slope_range
from goniolab.optics.facet_threads import run_tasks
from goniolab.optics.surface import Surface

__all__ = ["SlopeStatistics", "bilinear", "cell_bilinear"]

FloatArray = NDArray[np.float64]
T = TypeVar("T")

#: Histogram bin of P22 for maps without slope spread (Wittmann et al. 2021, sec. 3.1).
HIST_BIN = 1e-3
#: Most grid nodes per axis of the slope kernel density.
_KDE_MAX_NODES = 2048
#: Most facets used to tabulate the Smith Lambda function (deterministic subsample).
_LAMBDA_MAX_FACETS = 1 << 17
_LAMBDA_THETA_STEP_DEG = 0.5
_LAMBDA_PHI_STEP_DEG = 5.0
#: Bins of the projected slope per azimuth when the Lambda table is summed.
_LAMBDA_BINS = 1 << 12
#: Groups of azimuths the Lambda table is summed in (the same on any number of threads).
#: One: its small arrays' numpy calls hold the GIL most of the time, so two threads
#: summing groups at once were no faster (issue 26, bench/README.md, roughwall); the
#: table runs beside the slope cells instead (FacetModel._grid_fraction).
_LAMBDA_GROUPS = 1
#: Groups of in-plane angles the nodes' Lambda is computed in, of at least this many nodes:
#: a group's dozen temporaries are then about 0.5 MB each, reused by the next group, where
#: one group of a 71-point curve's 0.4 M nodes faulted in about 10 MB of fresh pages
#: (2,600 page faults; 31 against 36 ms on one thread, the same bits).
_NODE_GROUPS = 8
_NODE_GROUP_MIN = 1 << 15


def cell_bilinear(
    grid: FloatArray,
    i: NDArray[np.int64],
    j: NDArray[np.int64],
    fx: FloatArray,
    fy: FloatArray,
) -> FloatArray:
    """Bilinear interpolation in the cell ``[i, i + 1] x [j, j + 1]`` of ``grid`` at the
    fractions ``(fx, fy)`` of its sides (the corners gathered by flat index: the same
    values as ``grid[i, j]``, without numpy's slower 2-D fancy indexing)."""
    flat = i * grid.shape[1] + j
    g = grid.ravel()
    out: FloatArray = (
        g.take(flat) * (1 - fx) * (1 - fy)
        + g.take(flat + grid.shape[1]) * fx * (1 - fy)
        + g.take(flat + 1) * (1 - fx) * fy
        + g.take(flat + grid.shape[1] + 1) * fx * fy
    )
    return out


def bilinear(
    kde: tuple[FloatArray, float, float, float, float], p: FloatArray, q: FloatArray
) -> FloatArray:
    """Bilinear interpolation of a gridded density at (p, q); 0 outside or for NaN."""
    dens, p0, q0, gp, gq = kde
    n_p, n_q = dens.shape
    x = np.nan_to_num((p - p0) / gp, nan=-1.0, posinf=-1.0, neginf=-1.0)
    y = np.nan_to_num((q - q0) / gq, nan=-1.0, posinf=-1.0, neginf=-1.0)
    inside = (x >= 0) & (x <= n_p - 1) & (y >= 0) & (y <= n_q - 1)
    x, y = np.where(inside, x, 0.0), np.where(inside, y, 0.0)
    i = np.minimum(np.floor(x).astype(np.int64), n_p - 2)
    j = np.minimum(np.floor(y).astype(np.int64), n_q - 2)
    out: FloatArray = np.where(inside, cell_bilinear(dens, i, j, x - i, y - j), 0.0)
    return out


def _lambda_columns(
    p: FloatArray,
    q: FloatArray,
    th: FloatArray,
    ph: FloatArray,
    azimuths: range,
    table: FloatArray,
) -> None:
    """The columns ``j`` and ``j + half`` of :attr:`SlopeStatistics._lambda_table` for
    each ``j`` of ``azimuths`` (``half`` = the azimuths of a half turn), into ``table``.

    Per azimuth, the facets' projected slopes are binned (the walks over the facets);
    then every column of the group is formed at once from the bins (a few numpy calls on
    ``theta x azimuth`` arrays instead of a few dozen per azimuth: each element by the same
    operations, the same bits)."""
    ct, st = np.cos(th), np.sin(th)
    with np.errstate(divide="ignore"):
        cot = np.where(st > 0, ct / st, np.inf)
    m = p.size
    nb = _LAMBDA_BINS
    half = (ph.size - 1) // 2
    n_az = len(azimuths)
    x = np.empty(m)
    buf = np.empty(m)
    k = np.empty(m, dtype=np.int64)
    cnt = np.zeros((n_az, nb))
    tot = np.zeros((n_az, nb))
    lo = np.empty(n_az)
    width = np.empty(n_az)
    for a, j in enumerate(azimuths):  # the temporaries reused: x = p cos + q sin, k its bin
        np.multiply(p, math.cos(ph[j]), out=x)
        x += np.multiply(q, math.sin(ph[j]), out=buf)
        lo_a, hi_a = float(x.min()), float(x.max())
        width_a = max(hi_a - lo_a, 1e-300) / nb
        np.subtract(x, lo_a, out=buf)
        buf /= width_a
        k[...] = buf  # truncation, as astype(np.int64)
        np.minimum(k, nb - 1, out=k)
        # the counts and sums per bin by np.add.at: the facets added in their order, as
        # np.bincount adds them (the same sums), without bincount's min/max pass over k
        np.add.at(cnt[a], k, 1.0)
        np.add.at(tot[a], k, x)
        lo[a], width[a] = lo_a, width_a
    zero = np.zeros((n_az, 1))
    c_cnt = np.concatenate((zero, np.cumsum(cnt, axis=1)), axis=1).ravel()
    c_tot = np.concatenate((zero, np.cumsum(tot, axis=1)), axis=1).ravel()
    cnt_f = cnt.ravel()
    row = nb * np.arange(n_az)  # each azimuth's bins in the flat arrays
    row1 = row + np.arange(n_az)  # ... and its cumulative sums' (nb + 1 each)
    cols = np.asarray(azimuths)
    for sign in (1.0, -1.0):
        # facets with sign * x < cot: x below cot (sign +) or above -cot (sign -)
        u = np.clip((sign * cot[:, None] - lo) / width, 0.0, float(nb))
        b = np.minimum(u.astype(np.int64), nb - 1)
        f = np.clip(u - b, 0.0, 1.0)
        n_b = cnt_f.take(b + row)
        if sign > 0:  # bins below b, and the fraction f of bin b
            count = c_cnt.take(b + row1) + f * n_b
            total = c_tot.take(b + row1) + f * (n_b * (lo + width * (b + 0.5 * f)))
            at = cols
        else:  # bins above b, and the fraction 1 - f of bin b
            g = 1.0 - f
            count = (c_cnt.take(row1 + nb) - c_cnt.take(b + 1 + row1)) + g * n_b
            total = (c_tot.take(row1 + nb) - c_tot.take(b + 1 + row1)) + g * (
                n_b * (lo + width * (b + f + 0.5 * g))
            )
            at = cols + half
        table[:, at] = (count * ct[:, None] - sign * st[:, None] * total) / m


def _nodes_lambda_rows(table: FloatArray, al: FloatArray, be: FloatArray, out: FloatArray) -> None:
    """:meth:`SlopeStatistics._nodes_lambda` of the nodes ``al`` x ``be`` into ``out``."""
    n0, n1 = table.shape
    cb = np.cos(be)
    cz = np.multiply.outer(np.cos(al), cb)
    np.clip(cz, -1.0, 1.0, out=cz)
    x = np.arccos(cz)
    np.degrees(x, out=x)
    x /= _LAMBDA_THETA_STEP_DEG
    np.clip(x, 0.0, n0 - 1.0, out=x)
    y = np.arctan2(np.broadcast_to(np.sin(be), cz.shape), np.multiply.outer(-np.sin(al), cb))
    np.degrees(y, out=y)
    np.remainder(y, 360.0, out=y)
    y /= _LAMBDA_PHI_STEP_DEG
    np.clip(y, 0.0, n1 - 1.0, out=y)
    i = np.floor(x).astype(np.int64)
    np.minimum(i, n0 - 2, out=i)
    j = np.floor(y).astype(np.int64)
    np.minimum(j, n1 - 2, out=j)
    x -= i  # the fractions fx, fy
    y -= j
    flat = i
    flat *= n1
    flat += j
    del j
    tf = table.ravel()
    gx, gy = 1.0 - x, 1.0 - y
    # cell_bilinear's sum, term by term in its order
    t = tf.take(flat) * gx
    t *= gy
    u = tf.take(flat + n1) * x
    u *= gy
    t += u
    flat += 1
    u = tf.take(flat) * gx
    u *= y
    t += u
    flat += n1
    u = tf.take(flat) * x
    u *= y
    t += u
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(cz > 0, t / np.where(cz > 0, cz, 1.0) - 1.0, np.inf)
    np.maximum(lam, 0.0, out=out)


class SlopeStatistics:
    """P22 and Smith Lambda of a facet set (see :class:`goniolab.optics.facet.FacetModel`
    for ``slope_bin``: ``None`` is the kernel density, a float the histogram of that bin).
    """

    def __init__(self, surface: Surface, slope_bin: float | None = None) -> None:
        self.surface = surface
        self.slope_bin = HIST_BIN if slope_bin is None else float(slope_bin)
        self.use_kde = slope_bin is None
        self._node_lambda: dict[tuple[float, float, int, float, float, int], FloatArray] = {}
        self._lock = threading.Lock()  # of _node_lambda: the deposit's threads may fill it

    # ------------------------------------------------------------------ slope density P22
    @cached_property
    def _p22_index(self) -> tuple[NDArray[np.int64], NDArray[np.int64], int, int, int, int]:
        b = self.slope_bin
        check_slope_range(self.surface.p, self.surface.q, b, self.surface.source)
        ip = np.floor(self.surface.p / b + 0.5).astype(np.int64)
        iq = np.floor(self.surface.q / b + 0.5).astype(np.int64)
        p0, q0 = int(ip.min()), int(iq.min())
        n_q = int(iq.max()) - q0 + 1
        n_p = int(ip.max()) - p0 + 1
        keys, counts = np.unique((ip - p0) * n_q + (iq - q0), return_counts=True)
        return keys, counts, p0, q0, n_p, n_q

    def _bin_counts(self, ip: NDArray[np.int64], iq: NDArray[np.int64]) -> FloatArray:
        """Facet counts of the histogram bins centred on (ip, iq) x slope_bin (0 outside)."""
        keys, counts, p0, q0, n_p, n_q = self._p22_index
        a, b = ip - p0, iq - q0
        ok = (a >= 0) & (a < n_p) & (b >= 0) & (b < n_q)
        key = np.where(ok, a * n_q + b, 0)
        pos = np.clip(np.searchsorted(keys, key), 0, keys.size - 1)
        hit = ok & (keys[pos] == key)
        out: FloatArray = np.where(hit, counts[pos], 0).astype(np.float64)
        return out

    @cached_property
    def _kde_grid(self) -> tuple[FloatArray, float, float, float, float] | None:
        """Gaussian kernel density of the slopes on a grid: (density, p0, q0, gp, gq).

        Scott's rule bandwidth per axis, ``h = sigma N**(-1/6)`` (Scott 1992, d = 2). The
        slopes are linearly binned (bilinear weights) on a grid of step ``h/4`` (coarser
        only if the slope range needs more than 2048 nodes per axis) and convolved with the
        Gaussian kernel (``scipy.ndimage.gaussian_filter``, truncated at 5 h): the binned
        estimate differs from the exact kernel sum by ``O((step/h)^2)``, well under 1 %.
        ``None`` when the slopes have no spread (a flat map): the histogram is used.
        """
        from scipy.ndimage import gaussian_filter

        p, q = self.surface.p, self.surface.q
        ok = np.isfinite(p) & np.isfinite(q)
        p, q = p[ok], q[ok]
        n = p.size
        if n < 2:
            return None
        sp, sq = float(np.std(p)), float(np.std(q))
        if not (sp > 0 and sq > 0):
            return None
        shrink = n ** (-1.0 / 6.0)
        hp, hq = sp * shrink, sq * shrink
        axes = []
        for v, h in ((p, hp), (q, hq)):
            lo, hi = float(v.min()) - 5.0 * h, float(v.max()) + 5.0 * h
            step = max(h / 4.0, (hi - lo) / (_KDE_MAX_NODES - 1))
            axes.append((lo, step, math.ceil((hi - lo) / step) + 2))
        (p0, gp, n_p), (q0, gq, n_q) = axes
        x, y = (p - p0) / gp, (q - q0) / gq
        i, j = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
        fx, fy = x - i, y - j
        grid = np.zeros(n_p * n_q)
        for di, dj, w in (
            (0, 0, (1 - fx) * (1 - fy)),
            (1, 0, fx * (1 - fy)),
            (0, 1, (1 - fx) * fy),
            (1, 1, fx * fy),
        ):
            grid += np.bincount((i + di) * n_q + (j + dj), weights=w, minlength=n_p * n_q)
        dens = gaussian_filter(
            grid.reshape(n_p, n_q), sigma=(hp / gp, hq / gq), mode="constant", truncate=5.0
        )
        out: FloatArray = dens / (self.surface.n_facets * gp * gq)
        return out, p0, q0, gp, gq

    def density(self, p: ArrayLike, q: ArrayLike) -> FloatArray:
        """Slope density P22 (per unit p per unit q): the Gaussian kernel density of the
        slopes (default, see :attr:`_kde_grid`, interpolated bilinearly on its grid) or,
        with an explicit ``slope_bin``, the histogram of that bin.

        The histogram (bins centred on multiples of ``slope_bin``, Wittmann sec. 3.1) is
        interpolated bilinearly between bin centres, so P22 is continuous: its error is then
        second order in the bin (curvature x bin^2 / 8) instead of the first-order step of
        a piecewise-constant histogram. Non-finite slopes give 0.
        """
        b = self.slope_bin
        pa, qa = np.broadcast_arrays(
            np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
        )
        finite = np.isfinite(pa) & np.isfinite(qa)
        kde = self._kde_grid if self.use_kde else None
        if kde is not None:
            return bilinear(kde, np.where(finite, pa, np.nan), np.where(finite, qa, np.nan))
        # clipped far outside any histogram, so the integer bin indices cannot overflow
        x = np.clip(np.where(finite, pa, 0.0) / b, -1e15, 1e15)
        y = np.clip(np.where(finite, qa, 0.0) / b, -1e15, 1e15)
        i0, j0 = np.floor(x), np.floor(y)
        fx, fy = x - i0, y - j0
        i0i, j0i = i0.astype(np.int64), j0.astype(np.int64)
        acc = (
            self._bin_counts(i0i, j0i) * (1 - fx) * (1 - fy)
            + self._bin_counts(i0i + 1, j0i) * fx * (1 - fy)
            + self._bin_counts(i0i, j0i + 1) * (1 - fx) * fy
            + self._bin_counts(i0i + 1, j0i + 1) * fx * fy
        )
        out: FloatArray = np.where(finite, acc, 0.0) / (self.surface.n_facets * b * b)
        return out

    # ------------------------------------------------------------------ Smith masking
    @cached_property
    def _lambda_table(self) -> FloatArray:
        """``T(theta, phi) = mean(max(0, cos t - sin t (p cos ph + q sin ph)))`` on a grid.

        Per azimuth the projected slope ``x = p cos ph + q sin ph`` is counted in
        :data:`_LAMBDA_BINS` equal bins (counts and sums of x), and ``T`` summed over the
        bins below ``cot t``, the bin holding ``cot t`` taken in proportion (its facets
        spread evenly over it): one pass of ``bincount`` per azimuth instead of a sort,
        and the azimuth ``ph + 180`` (``x -> -x``) read from the same bins. The
        proportional bin is off by at most a bin's share of the facets times its width
        (1e-7 of ``cos t`` for 2**17 Gaussian facets), far below the subsample's own noise.
        """
        n = self.surface.n_facets
        if n > _LAMBDA_MAX_FACETS:
            idx = np.linspace(0, n - 1, _LAMBDA_MAX_FACETS).astype(np.int64)
            p, q = self.surface.take(idx)  # a map's surface reads these from the map
        elif self.surface.streamed:
            p, q = self.surface.take(np.arange(n))
        else:
            p, q = self.surface.p, self.surface.q
        th = np.radians(np.arange(0.0, 90.0 + 1e-9, _LAMBDA_THETA_STEP_DEG))
        n_ph = round(360.0 / _LAMBDA_PHI_STEP_DEG)
        ph = np.radians(_LAMBDA_PHI_STEP_DEG * np.arange(n_ph + 1))
        table = np.empty((th.size, ph.size))
        half = n_ph // 2
        # the azimuths in fixed groups, each on whichever thread is free: a column is
        # computed by the same operations whichever group or thread computes it
        groups = [range(half * k // _LAMBDA_GROUPS, half * (k + 1) // _LAMBDA_GROUPS)
                  for k in range(_LAMBDA_GROUPS)]  # fmt: skip
        run_tasks([functools.partial(_lambda_columns, p, q, th, ph, g, table) for g in groups])
        table[:, n_ph] = table[:, 0]
        return table

    def smith_lambda(self, w: ArrayLike) -> FloatArray:
        """Smith ``Lambda(w)`` of the measured slopes for unit directions ``w`` (..., 3).

        ``Lambda(w) = mean(max(0, cos t - sin t (p cos ph + q sin ph))) / cos t - 1``
        (docs/PHYSICS.md, "Masking and shadowing"; Heitz 2014, Smith Lambda of the empirical slope distribution), tabulated on a
        0.5 deg x 5 deg (theta, phi) grid from at most 2**17 facets and interpolated
        bilinearly. Infinite at grazing directions.
        """
        wa = np.asarray(w, dtype=np.float64)
        cz = np.clip(wa[..., 2], -1.0, 1.0)
        th_deg = np.degrees(np.arccos(cz))
        ph_deg = np.degrees(np.arctan2(wa[..., 1], wa[..., 0]))
        ph_deg += 360.0 * (ph_deg < 0.0)  # % 360.0 of atan2's range, without np.remainder
        table = self._lambda_table
        x = np.clip(th_deg / _LAMBDA_THETA_STEP_DEG, 0.0, table.shape[0] - 1.0)
        y = np.clip(ph_deg / _LAMBDA_PHI_STEP_DEG, 0.0, table.shape[1] - 1.0)
        i = np.minimum(np.floor(x).astype(np.int64), table.shape[0] - 2)
        j = np.minimum(np.floor(y).astype(np.int64), table.shape[1] - 2)
        t = cell_bilinear(table, i, j, x - i, y - j)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(cz > 0, t / np.where(cz > 0, cz, 1.0) - 1.0, np.inf)
        out: FloatArray = np.maximum(lam, 0.0)
        return out

    def _nodes_lambda(self, al: FloatArray, be: FloatArray) -> FloatArray:
        """:meth:`smith_lambda` of the grid nodes ``wo = (-sin al cos be, sin be, cos al
        cos be)`` (in-plane angle ``al`` x out-of-plane ``be``, rad), the same operations on
        the same values without the ``(..., 3)`` direction array: its strided components
        and a dozen temporaries of the grid's size cost a 71-point curve's two grids
        (0.9 M nodes) about 25 ms. In fixed groups of in-plane angles, each on whichever
        thread is free (:func:`~goniolab.optics.facet_threads.run_tasks`): every node by
        the same operations."""
        table = self._lambda_table
        out = np.empty((al.size, be.size))
        parts = max(1, min(_NODE_GROUPS, al.size * be.size // _NODE_GROUP_MIN))
        cuts = [al.size * k // parts for k in range(parts + 1)]
        run_tasks(
            [
                functools.partial(_nodes_lambda_rows, table, al[a:b], be, out[a:b])
                for a, b in itertools.pairwise(cuts)
            ]
        )
        return out

    def masking_g2(self, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
        """Height-correlated Smith masking-shadowing ``1/(1 + Lambda(wi) + Lambda(wo))``."""
        out: FloatArray = 1.0 / (1.0 + self.smith_lambda(wi) + self.smith_lambda(wo))
        return out

    def node_lambda(self, alpha_deg: FloatArray, beta_rad: FloatArray) -> FloatArray:
        """Smith ``Lambda`` of the grid nodes (in-plane angle alpha in degrees x out-of-plane
        beta), kept for the last few grids: it does not depend on the incidence, and the
        sub-cones of a split source share their grids (169 of them at grazing incidence)."""
        key = (
            float(alpha_deg[0]),
            float(alpha_deg[-1]),
            alpha_deg.size,
            float(beta_rad[0]),
            float(beta_rad[-1]),
            beta_rad.size,
        )
        with self._lock:
            lam = self._node_lambda.get(key)
        if lam is None:
            lam = self._nodes_lambda(np.radians(alpha_deg), np.asarray(beta_rad, np.float64))
            with self._lock:
                if len(self._node_lambda) >= 8:
                    self._node_lambda.pop(next(iter(self._node_lambda)))
                self._node_lambda[key] = lam
        return lam

    def beside(
        self,
        work: Callable[[], T],
        grids: list[tuple[FloatArray, FloatArray]],
        then: Callable[[], object] | None = None,
    ) -> T:
        """``work()``, while the :meth:`node_lambda` of each ``(alpha_deg, beta_rad)`` of
        ``grids`` (and the Lambda table they read), and then ``then()`` (work the caller
        needs next, e.g. a cached aperture table), are computed beside it: independent
        walks, on two threads when there are two (:func:`run_tasks`)."""

        def lambdas() -> None:
            for alpha_deg, beta_rad in grids:
                self.node_lambda(alpha_deg, beta_rad)
            if then is not None:
                then()

        tasks: list[Callable[[], Any]] = [work, lambdas]
        out: T = run_tasks(tasks)[0]
        return out

    def g2_nodes(self, wi: FloatArray, alpha_deg: FloatArray, beta_rad: FloatArray) -> FloatArray:
        """Smith G2 at grid nodes (in-plane angle alpha in degrees x out-of-plane beta), the
        nodes' Lambda from :meth:`node_lambda`."""
        lam = self.node_lambda(alpha_deg, beta_rad)
        out: FloatArray = 1.0 / (1.0 + self.smith_lambda(wi) + lam)
        return out
