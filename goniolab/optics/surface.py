"""From a height map to the facet set: slopes, slope histogram and roughness statistics.

Wittmann et al. (sec. 3.1) take the slopes of a levelled profilometer map by forward
differences, one facet per pixel, and describe the surface by the 2-D slope histogram
(bin 1e-3). The height of that histogram at zero slope, ``h_r``, is their best single
predictor of gloss. The facet normal is ``m = (-p, -q, 1)/sqrt(1 + p^2 + q^2)`` with
``p = dz/dx``, ``q = dz/dy`` (seed eq. 3; its eq. 4 prints ``+dz/dy`` in the y component,
a slip that only hides on isotropic samples).

Axis convention: ``z_um[i, j]`` has row ``i`` along y (step ``dy_um``) and column ``j``
along x (step ``dx_um``).

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 3.1, eqs. 3-4.
.. [2] NIST SCATMECH / ray method: surface normal from the least-squares plane through a
   point and its 8 neighbours.
.. [3] ISO 25178-2: Sq, Sdq (root mean square gradient).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics.heightmap import HeightMap, level_plane, plane_fit_and_completeness

__all__ = [
    "SLOPE_BLOCK_FACETS",
    "STREAM_MIN_FACETS",
    "MapSurface",
    "RoughnessStats",
    "SlopeHistogram",
    "SlopeMethod",
    "Surface",
    "roughness_stats",
    "slope_histogram",
    "slopes",
]

FloatArray = NDArray[np.float64]
SlopeMethod = Literal["forward", "central", "plane8"]
_METHODS: tuple[str, ...] = ("forward", "central", "plane8")

#: Largest dense slope histogram :func:`slope_histogram` will allocate (cells).
MAX_HISTOGRAM_CELLS = 50_000_000
#: Rows per block of the one-pass forward-difference walk (a few hundred kB per array).
_BLOCK_ROWS = 16
#: Facets per block when a surface's slopes are walked block by block
#: (:meth:`Surface.slope_blocks`: 32 MB of float64 p and q).
SLOPE_BLOCK_FACETS = 1 << 21
#: ``progress(done, total, what)`` (as :data:`goniolab.optics.physical.Progress`).
Progress = Callable[[int, int, str], None]


def _forward_blocks(
    hm: HeightMap, level: bool
) -> tuple[float, float, float, list[tuple[int, int]]] | None:
    """Plane and row blocks for the one-pass walk, or None when the map needs the general
    path (missing points, or a single row or column)."""
    z = hm.z_um
    ny, nx = z.shape
    if ny < 2 or nx < 2:
        return None
    if level:
        a, b, c, complete = plane_fit_and_completeness(hm)
    else:
        a = b = c = 0.0
        complete = math.isfinite(float(np.sum(z)))
    if not complete:
        return None  # missing points: the general path
    blocks = [(r, min(r + _BLOCK_ROWS, ny - 1)) for r in range(0, ny - 1, _BLOCK_ROWS)]
    return a, b, c, blocks


def _forward_facets(hm: HeightMap, level: bool) -> tuple[FloatArray, FloatArray] | None:
    """Forward-difference slopes of the (levelled) map without a levelled copy.

    Levelling subtracts a plane, so it shifts every forward slope by the plane's own slope:
    ``p = (z[i, j+1] - z[i, j]) / dx - b`` and ``q = (z[i+1, j] - z[i, j]) / dy - c``
    (:func:`~goniolab.optics.heightmap.plane_fit`). Walked in blocks of rows, each written once into the facet arrays
    (facets ``[:-1, :-1]``, row-major, as :meth:`Surface.from_heightmap` orders them).
    None when the map has missing points (the general path handles them).
    """
    plan = _forward_blocks(hm, level)
    if plan is None:
        return None
    _, b, c, blocks = plan
    ny, nx = hm.z_um.shape
    p = np.empty((ny - 1, nx - 1))
    q = np.empty((ny - 1, nx - 1))
    for r0, r1 in blocks:
        _forward_rows(hm, b, c, level, r0, r1, p[r0:r1], q[r0:r1])
    return p.reshape(-1), q.reshape(-1)


def _forward_rows(
    hm: HeightMap,
    b: float,
    c: float,
    level: bool,
    r0: int,
    r1: int,
    pb: FloatArray | None = None,
    qb: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Forward slopes of the facet rows ``r0 .. r1 - 1`` (2-D, into ``pb``, ``qb`` when
    given), levelled by the plane slopes ``b``, ``c``; a float32 map's rows are cast to
    float64 first, so they equal the slopes of its float64 copy."""
    z = hm.z_um[r0 : r1 + 1]
    if z.dtype != np.float64:
        z = z.astype(np.float64)
    rows = r1 - r0
    dx, dy = float(hm.dx_um), float(hm.dy_um)
    pb = np.subtract(z[:rows, 1:], z[:rows, :-1], out=pb)
    if dx != 1.0:  # x / 1.0 is x: a walk's pass saved on the common 1 um step
        np.divide(pb, dx, out=pb)
    qb = np.subtract(z[1 : rows + 1, :-1], z[:rows, :-1], out=qb)
    if dy != 1.0:
        np.divide(qb, dy, out=qb)
    if level:
        pb -= b
        qb -= c
    return pb, qb


def slopes(hm: HeightMap, method: SlopeMethod = "forward") -> tuple[FloatArray, FloatArray]:
    """Slopes ``p = dz/dx`` and ``q = dz/dy`` of a height map, per pixel.

    Parameters
    ----------
    hm : HeightMap
        The height map (``z_um[i, j]``, i along y, j along x; NaN = missing).
    method : {"forward", "central", "plane8"}
        ``"forward"``: ``p[i, j] = (z[i, j+1] - z[i, j]) / dx`` and
        ``q[i, j] = (z[i+1, j] - z[i, j]) / dy`` (Wittmann sec. 3.1); the last column of p
        and the last row of q are undefined.
        ``"central"``: ``(z[.., j+1] - z[.., j-1]) / (2 dx)`` and likewise in y.
        ``"plane8"``: slopes of the least-squares plane through the pixel and its 8
        neighbours (NIST ray method); for a full 3 x 3 stencil this is
        ``p = (sum of the right column - sum of the left column) / (6 dx)``.

    Returns
    -------
    (p, q) : tuple of ndarray
        2-D arrays of the map's shape, NaN where the stencil leaves the map or touches a
        NaN height. Both are dimensionless (um / um).
    """
    if method not in _METHODS:
        raise ValueError(f"unknown slope method {method!r} for {hm.source}; use one of {_METHODS}")
    z = np.asarray(hm.z_um, dtype=np.float64)
    ny, nx = z.shape
    p = np.full((ny, nx), np.nan)
    q = np.full((ny, nx), np.nan)
    dx, dy = float(hm.dx_um), float(hm.dy_um)
    if method == "forward":
        if nx >= 2:
            p[:, :-1] = (z[:, 1:] - z[:, :-1]) / dx
        if ny >= 2:
            q[:-1, :] = (z[1:, :] - z[:-1, :]) / dy
    elif method == "central":
        if nx >= 3:
            p[:, 1:-1] = (z[:, 2:] - z[:, :-2]) / (2.0 * dx)
        if ny >= 3:
            q[1:-1, :] = (z[2:, :] - z[:-2, :]) / (2.0 * dy)
    else:
        if nx >= 3 and ny >= 3:
            # Sums over the 3 x 3 stencil; any NaN in it propagates (undefined facet).
            right = z[:-2, 2:] + z[1:-1, 2:] + z[2:, 2:]
            left = z[:-2, :-2] + z[1:-1, :-2] + z[2:, :-2]
            lower = z[2:, :-2] + z[2:, 1:-1] + z[2:, 2:]
            upper = z[:-2, :-2] + z[:-2, 1:-1] + z[:-2, 2:]
            # The plane is fitted to all nine points: any missing one undefines the facet.
            bad = np.isnan(z).astype(np.int64)
            bad9 = sum(bad[a : ny - 2 + a, b : nx - 2 + b] for a in range(3) for b in range(3))
            ok9 = bad9 == 0
            p[1:-1, 1:-1] = np.where(ok9, (right - left) / (6.0 * dx), np.nan)
            q[1:-1, 1:-1] = np.where(ok9, (lower - upper) / (6.0 * dy), np.nan)
    return p, q


@dataclass(frozen=True, eq=False)
class Surface:
    """The facet set of a surface: one facet per valid pixel.

    Attributes
    ----------
    p, q : ndarray
        1-D float64 slopes ``dz/dx`` and ``dz/dy`` of the valid facets.
    dx_um, dy_um : float
        Lateral steps of the map the facets come from.
    source : str
        Where the map came from (file name or ``sample:NAME``).
    slope_method : str
        How the slopes were taken (see :func:`slopes`).
    """

    p: FloatArray
    q: FloatArray
    dx_um: float = 1.0
    dy_um: float = 1.0
    source: str = "<memory>"
    slope_method: str = "forward"

    def __post_init__(self) -> None:
        p = np.ascontiguousarray(self.p, dtype=np.float64)
        q = np.ascontiguousarray(self.q, dtype=np.float64)
        if p.ndim != 1 or q.shape != p.shape:
            raise ValueError(
                f"Surface from {self.source}: p and q must be 1-D of equal length, "
                f"got {p.shape} and {q.shape}"
            )
        if p.size == 0:
            raise ValueError(f"Surface from {self.source}: no valid facets")
        # one reduction each; only a non-finite sum needs the element-wise scan
        finite = math.isfinite(float(np.sum(p))) and math.isfinite(float(np.sum(q)))
        if not finite and not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
            raise ValueError(f"Surface from {self.source}: slopes must be finite")
        object.__setattr__(self, "p", p)
        object.__setattr__(self, "q", q)

    @classmethod
    def from_heightmap(
        cls, hm: HeightMap, *, slope_method: SlopeMethod = "forward", level: bool = True
    ) -> Surface:
        """Facets of a height map (levelled first with :func:`level_plane` when ``level``).

        Forward differences on a map without missing points take one pass and no levelled
        copy (:func:`_forward_facets`); the other methods and maps with NaN level first.
        """
        if slope_method == "forward" and cls is Surface:
            plan = _forward_blocks(hm, level)
            if plan is not None and _slopes_finite(hm, plan[1], plan[2]):
                return MapSurface(hm, plan[1], plan[2], level)
        if slope_method == "forward":
            fast = _forward_facets(hm, level)
            if fast is not None:
                return cls(
                    p=fast[0],
                    q=fast[1],
                    dx_um=float(hm.dx_um),
                    dy_um=float(hm.dy_um),
                    source=hm.source,
                    slope_method=slope_method,
                )
        if level:
            hm = level_plane(hm)
        p2, q2 = slopes(hm, slope_method)
        ok = np.isfinite(p2) & np.isfinite(q2)
        if not ok.any():
            raise ValueError(
                f"{hm.source}: no valid facets with slope method {slope_method!r} "
                f"(map {hm.z_um.shape}, too small or all missing)"
            )
        return cls(
            p=p2[ok],
            q=q2[ok],
            dx_um=float(hm.dx_um),
            dy_um=float(hm.dy_um),
            source=hm.source,
            slope_method=slope_method,
        )

    @property
    def n_facets(self) -> int:
        """Number of facets."""
        return int(self.p.size)

    def slope_blocks(
        self,
        facets: int | None = None,
        *,
        reuse: bool = False,
        span: tuple[int, int] | None = None,
    ) -> Iterator[tuple[FloatArray, FloatArray]]:
        """The slopes ``(p, q)`` in consecutive blocks of about ``facets`` facets
        (default :data:`SLOPE_BLOCK_FACETS`), in facet order (a map's surface forms each block from the map when asked, so a walk
        over its facets holds one block, not the map's facets: :class:`MapSurface`).
        ``reuse``: a map's surface may form each block in the previous block's arrays (the
        caller keeps none of them): small blocks then stay in cache, and no new memory is
        touched per block. ``span``: only the facets ``lo .. hi - 1``, one of
        :meth:`spans` (a map's surface walks whole rows)."""
        step = max(1, int(SLOPE_BLOCK_FACETS if facets is None else facets))
        lo, hi = (0, self.n_facets) if span is None else span
        for at in range(lo, hi, step):
            end = min(at + step, hi)
            yield self.p[at:end], self.q[at:end]

    def spans(self, parts: int) -> list[tuple[int, int]]:
        """The facets cut into at most ``parts`` consecutive spans ``(lo, hi)`` of about
        equal size, for walks that :func:`~goniolab.optics.facet_threads.run_tasks` shares
        out (:meth:`slope_blocks` ``span=``); a map's surface cuts between rows."""
        n = self.n_facets
        parts = max(1, min(parts, n))
        return [(n * k // parts, n * (k + 1) // parts) for k in range(parts)]

    def take(self, idx: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
        """The slopes of the facets ``idx`` (indices in facet order)."""
        return self.p[idx], self.q[idx]

    @cached_property
    def slope_range(self) -> tuple[float, float, float, float]:
        """``(p_min, p_max, q_min, q_max)`` of the facets (one walk over the blocks)."""
        lo_p = lo_q = math.inf
        hi_p = hi_q = -math.inf
        for p, q in self.slope_blocks():
            lo_p, hi_p = min(lo_p, float(p.min())), max(hi_p, float(p.max()))
            lo_q, hi_q = min(lo_q, float(q.min())), max(hi_q, float(q.max()))
        return lo_p, hi_p, lo_q, hi_q

    @property
    def streamed(self) -> bool:
        """True when the slopes are formed block by block from the map, not held
        (:class:`MapSurface` before anything asked for :attr:`p` or :attr:`q`)."""
        return False

    @cached_property
    def normals(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Unit facet normals ``m = (-p, -q, 1)/sqrt(1 + p^2 + q^2)`` (Wittmann eq. 4 corrected)."""
        inv = 1.0 / np.sqrt(1.0 + self.p * self.p + self.q * self.q)
        return (
            np.ascontiguousarray(-self.p * inv),
            np.ascontiguousarray(-self.q * inv),
            np.ascontiguousarray(inv),
        )


def _slopes_finite(hm: HeightMap, b: float, c: float) -> bool:
    """Whether every forward slope of a complete map is finite (no difference overflows):
    bounded by the height range over the smaller step plus the plane's slopes."""
    lo, hi = hm.z_range  # a complete map's: its min and max
    span = (hi - lo) / min(float(hm.dx_um), float(hm.dy_um))
    return math.isfinite(span + abs(b) + abs(c))


class MapSurface(Surface):
    """The facets of a complete height map by forward differences (Wittmann sec. 3.1),
    formed from the map block by block (:meth:`slope_blocks`) instead of held: the map's
    own array (float32 or float64) is all that stays, so an 8192^2 float32 map costs its
    256 MB, not 1 GB of float64 slopes beside it.

    :attr:`p` and :attr:`q` are formed whole (and kept) only when something asks for them
    (the per-facet numba and numpy kernels on a map of at most
    :data:`STREAM_MIN_FACETS` facets, the kernel density of :meth:`brdf_point`): they equal
    the blocks, which equal the slopes of the levelled map
    (:func:`~goniolab.optics.heightmap.level_plane`) bit for bit. ``progress`` (settable,
    ``progress(done, total, what)``) hears of every block of a walk over a map of more
    than :data:`STREAM_MIN_FACETS` facets, as ``"facet slopes, pass N"`` (a gloss report
    walks the map about a dozen times, a curve once or twice).
    """

    _hm: HeightMap
    _plane: tuple[float, float, bool]

    def __init__(self, hm: HeightMap, b: float, c: float, level: bool) -> None:
        object.__setattr__(self, "dx_um", float(hm.dx_um))
        object.__setattr__(self, "dy_um", float(hm.dy_um))
        object.__setattr__(self, "source", hm.source)
        object.__setattr__(self, "slope_method", "forward")
        object.__setattr__(self, "_hm", hm)
        object.__setattr__(self, "_plane", (float(b), float(c), bool(level)))
        #: ``progress(done, total, what)`` or None (settable: not a dataclass field)
        self.progress: Progress | None = None

    def __repr__(self) -> str:
        ny, nx = self._hm.shape
        return f"MapSurface({self.source!r}, {nx} x {ny} map, {self.n_facets} facets)"

    @property
    def n_facets(self) -> int:
        ny, nx = self._hm.shape
        return (ny - 1) * (nx - 1)

    @cached_property
    def _whole(self) -> tuple[FloatArray, FloatArray]:
        b, c, level = self._plane
        hm = self._hm
        ny, nx = hm.shape
        p = np.empty((ny - 1, nx - 1))
        q = np.empty((ny - 1, nx - 1))
        for r0 in range(0, ny - 1, _BLOCK_ROWS):
            r1 = min(r0 + _BLOCK_ROWS, ny - 1)
            _forward_rows(hm, b, c, level, r0, r1, p[r0:r1], q[r0:r1])
        return p.reshape(-1), q.reshape(-1)

    @property
    def p(self) -> FloatArray:
        return self._whole[0]

    @property
    def q(self) -> FloatArray:
        return self._whole[1]

    @property
    def streamed(self) -> bool:
        return "_whole" not in self.__dict__

    def slope_blocks(
        self,
        facets: int | None = None,
        *,
        reuse: bool = False,
        span: tuple[int, int] | None = None,
    ) -> Iterator[tuple[FloatArray, FloatArray]]:
        if not self.streamed:
            yield from super().slope_blocks(facets, span=span)
            return
        b, c, level = self._plane
        ny, nx = self._hm.shape
        rows = max(1, int(SLOPE_BLOCK_FACETS if facets is None else facets) // (nx - 1))
        total = ny - 1
        first, last = 0, total
        if span is not None:
            first, last = span[0] // (nx - 1), span[1] // (nx - 1)
            if (first * (nx - 1), last * (nx - 1)) != span:
                raise ValueError(f"{self!r}: span {span} does not fall between rows")
        report = self.progress if self.n_facets > STREAM_MIN_FACETS and span is None else None
        what = ""
        if report is not None:
            self.__dict__["_passes"] = self.__dict__.get("_passes", 0) + 1
            what = f"facet slopes, pass {self.__dict__['_passes']}"
        rows = min(rows, max(1, last - first))
        bufs = (np.empty((rows, nx - 1)), np.empty((rows, nx - 1))) if reuse else None
        for r0 in range(first, last, rows):
            r1 = min(r0 + rows, last)
            if bufs is None:
                pb, qb = _forward_rows(self._hm, b, c, level, r0, r1)
            else:
                pb, qb = _forward_rows(
                    self._hm, b, c, level, r0, r1, bufs[0][: r1 - r0], bufs[1][: r1 - r0]
                )
            yield pb.reshape(-1), qb.reshape(-1)
            if report is not None:
                report(r1, total, what)

    def spans(self, parts: int) -> list[tuple[int, int]]:
        if not self.streamed:
            return super().spans(parts)
        ny, nx = self._hm.shape
        rows = ny - 1
        parts = max(1, min(parts, rows))
        return [
            (rows * k // parts * (nx - 1), rows * (k + 1) // parts * (nx - 1)) for k in range(parts)
        ]

    def take(self, idx: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
        if not self.streamed:
            return super().take(idx)
        b, c, level = self._plane
        hm = self._hm
        nx = hm.shape[1]
        i, j = np.divmod(np.asarray(idx, dtype=np.int64), nx - 1)
        k = i * nx  # flat index of each facet's corner: 1-D gathers of the map
        k += j
        z = hm.z_um.reshape(-1)
        z0 = z.take(k).astype(np.float64, copy=False)
        p = (z.take(k + 1).astype(np.float64, copy=False) - z0) / float(hm.dx_um)
        q = (z.take(k + nx).astype(np.float64, copy=False) - z0) / float(hm.dy_um)
        if level:
            p -= b
            q -= c
        return p, q


#: A map's surface with more facets than this (4096^2) runs the per-facet numba and numpy
#: kernels block by block instead of over its whole slope arrays, and reports progress.
STREAM_MIN_FACETS = 1 << 24


@dataclass(frozen=True, eq=False)
class SlopeHistogram:
    """2-D slope histogram as a probability density.

    Attributes
    ----------
    density : ndarray
        ``density[a, b]`` is the fraction of facets with p in ``p_edges[a:a+2]`` and q in
        ``q_edges[b:b+2]``, divided by the bin area (per unit p per unit q): the slope
        density P22 of the facet model. Bins are centred on multiples of the bin size.
    p_edges, q_edges : ndarray
        Bin edges.
    h_r : float
        Fraction of facets in the bin centred on (0, 0) (Wittmann's "height of the slope
        distribution function").
    """

    density: FloatArray
    p_edges: FloatArray
    q_edges: FloatArray
    h_r: float


def _zero_bin_fraction(p: FloatArray, q: FloatArray, bin_size: float) -> float:
    half = 0.5 * bin_size
    inside = (p >= -half) & (p < half) & (q >= -half) & (q < half)
    return float(np.count_nonzero(inside)) / float(p.size)


def slope_histogram(p: ArrayLike, q: ArrayLike, *, bin_size: float = 1e-3) -> SlopeHistogram:
    """Slope density P22 of a facet set (Wittmann sec. 3.1, bin 1e-3).

    Parameters
    ----------
    p, q : array_like
        Slopes dz/dx and dz/dy of the facets (finite).
    bin_size : float
        Bin width in slope units, the same along p and q; bins are centred on multiples of
        it, so the bin ``[-bin/2, bin/2)^2`` gives ``h_r``.

    Returns
    -------
    SlopeHistogram
    """
    pa = np.asarray(p, dtype=np.float64).ravel()
    qa = np.asarray(q, dtype=np.float64).ravel()
    if pa.shape != qa.shape or pa.size == 0:
        raise ValueError("p and q must be non-empty and of equal length")
    if not (np.all(np.isfinite(pa)) and np.all(np.isfinite(qa))):
        raise ValueError("slopes must be finite")
    if not (math.isfinite(bin_size) and bin_size > 0):
        raise ValueError(f"bin_size must be positive, got {bin_size}")
    ip = np.floor(pa / bin_size + 0.5).astype(np.int64)
    iq = np.floor(qa / bin_size + 0.5).astype(np.int64)
    p0, p1 = int(ip.min()), int(ip.max())
    q0, q1 = int(iq.min()), int(iq.max())
    n_p, n_q = p1 - p0 + 1, q1 - q0 + 1
    if n_p * n_q > MAX_HISTOGRAM_CELLS:
        raise ValueError(
            f"slope histogram would need {n_p} x {n_q} bins at bin_size {bin_size}; "
            "use a larger bin_size"
        )
    counts = np.bincount((ip - p0) * n_q + (iq - q0), minlength=n_p * n_q).reshape(n_p, n_q)
    density = counts.astype(np.float64) / (pa.size * bin_size * bin_size)
    p_edges = (np.arange(p0, p1 + 2, dtype=np.float64) - 0.5) * bin_size
    q_edges = (np.arange(q0, q1 + 2, dtype=np.float64) - 0.5) * bin_size
    return SlopeHistogram(
        density=density,
        p_edges=p_edges,
        q_edges=q_edges,
        h_r=_zero_bin_fraction(pa, qa, bin_size),
    )


@dataclass(frozen=True, slots=True)
class RoughnessStats:
    """Roughness statistics of a levelled height map.

    ``Ra_nm``: mean absolute deviation from the mean height; ``Sq_nm``: rms height;
    ``Sdq``: rms gradient ``sqrt(mean(p^2 + q^2))``; ``h_r``: fraction of facets in the
    zero-slope bin; ``slope_rms_x``/``slope_rms_y``: ``sqrt(mean(p^2))``, ``sqrt(mean(q^2))``.
    """

    Ra_nm: float
    Sq_nm: float
    Sdq: float
    h_r: float
    n_facets: int
    slope_rms_x: float
    slope_rms_y: float


def _forward_stats(hm: HeightMap, bin_size: float) -> RoughnessStats | None:
    """:func:`roughness_stats` in one blocked pass (forward slopes, no missing points)."""
    plan = _forward_blocks(hm, level=True)
    if plan is None:
        return None
    a, b, c, blocks = plan
    z = hm.z_um
    ny, nx = z.shape
    dx, dy = float(hm.dx_um), float(hm.dy_um)
    x_um = (np.arange(nx, dtype=np.float64) - (nx - 1) / 2.0) * dx
    y_um = (np.arange(ny, dtype=np.float64) - (ny - 1) / 2.0) * dy
    row_plane = a + b * x_um
    half = 0.5 * bin_size
    s_abs = s_sq = s_pp = s_qq = 0.0
    n_zero = 0
    width = nx - 1
    pb_all = np.empty((_BLOCK_ROWS, width))
    qb_all = np.empty((_BLOCK_ROWS, width))
    dev_all = np.empty((_BLOCK_ROWS + 1, nx))
    for r0, r1 in blocks:
        # heights of rows r0 .. r1 (a float32 map's rows cast to float64 first)
        zb = z[r0 : r1 + 1] if z.dtype == np.float64 else z[r0 : r1 + 1].astype(np.float64)
        rows = r1 - r0
        # heights of rows r0 .. r1 - 1 (the last row is added after the loop)
        dev = dev_all[:rows]
        np.subtract(zb[:rows], row_plane, out=dev)
        dev -= (c * y_um[r0:r1])[:, None]
        s_abs += float(np.abs(dev).sum())
        s_sq += float(np.vdot(dev, dev))
        pb, qb = pb_all[:rows], qb_all[:rows]
        np.subtract(zb[:rows, 1:], zb[:rows, :-1], out=pb)
        np.divide(pb, dx, out=pb)
        pb -= b
        np.subtract(zb[1 : rows + 1, :-1], zb[:rows, :-1], out=qb)
        np.divide(qb, dy, out=qb)
        qb -= c
        s_pp += float(np.vdot(pb, pb))
        s_qq += float(np.vdot(qb, qb))
        n_zero += int(np.count_nonzero((pb >= -half) & (pb < half) & (qb >= -half) & (qb < half)))
    last = z[ny - 1] - row_plane - c * y_um[ny - 1]
    s_abs += float(np.abs(last).sum())
    s_sq += float(last @ last)
    n_pts = z.size
    n_fac = (ny - 1) * width
    return RoughnessStats(
        Ra_nm=s_abs / n_pts * 1e3,
        Sq_nm=math.sqrt(s_sq / n_pts) * 1e3,
        Sdq=math.sqrt((s_pp + s_qq) / n_fac),
        h_r=n_zero / n_fac,
        n_facets=n_fac,
        slope_rms_x=math.sqrt(s_pp / n_fac),
        slope_rms_y=math.sqrt(s_qq / n_fac),
    )


def roughness_stats(
    hm: HeightMap, *, slope_method: SlopeMethod = "forward", bin_size: float = 1e-3
) -> RoughnessStats:
    """Ra, Sq, Sdq and the slope-histogram height h_r of a map (levelled first).

    Parameters
    ----------
    hm : HeightMap
        The height map; NaN points are ignored.
    slope_method : {"forward", "central", "plane8"}
        See :func:`slopes`.
    bin_size : float
        Slope bin width for ``h_r`` (Wittmann: 1e-3).

    Returns
    -------
    RoughnessStats

    Notes
    -----
    With forward slopes on a map without missing points everything comes from one walk over
    the map in row blocks: the levelled heights ``z - plane`` (their mean is 0, the plane
    having an intercept) and the slopes of :func:`_forward_facets`, summed block by block
    without a levelled copy or facet arrays.
    """
    if not (math.isfinite(bin_size) and bin_size > 0):
        raise ValueError(f"bin_size must be positive, got {bin_size}")
    if slope_method == "forward":
        one_pass = _forward_stats(hm, bin_size)
        if one_pass is not None:
            return one_pass
    lev = level_plane(hm)
    z = lev.z_um[np.isfinite(lev.z_um)]
    dev = z - z.mean()
    surf = Surface.from_heightmap(lev, slope_method=slope_method, level=False)
    p, q = surf.p, surf.q
    return RoughnessStats(
        Ra_nm=float(np.mean(np.abs(dev))) * 1e3,
        Sq_nm=float(np.sqrt(np.mean(dev * dev))) * 1e3,
        Sdq=float(np.sqrt(np.mean(p * p + q * q))),
        h_r=_zero_bin_fraction(p, q, bin_size),
        n_facets=int(p.size),
        slope_rms_x=float(np.sqrt(np.mean(p * p))),
        slope_rms_y=float(np.sqrt(np.mean(q * q))),
    )
