"""Where the facet model's kernels run: numba threads, numpy, or the lean slope histogram.

:class:`goniolab.optics.facet.FacetModel` sums its facets with the fused numba kernels of
:mod:`goniolab.optics._kernels` (imported on first use by :func:`numba_kernels`: numba costs
a process about 1 s), threaded over chunks of at least :data:`MIN_CHUNK` facets on
:func:`kernel_pool` (at most :func:`limit_threads` threads), or with their numpy twins
(:mod:`goniolab.optics._kernels_numpy`). The ``"lean"`` backend runs the twins over the
occupied cells of the slope histogram of bin :data:`LEAN_SLOPE_BIN`
(:func:`slope_cells`), and reads narrow slits exactly over the facets that can reach them
(:func:`facets_near`).
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.facet_threads import limit_threads, run_tasks, thread_limit
from goniolab.optics.surface import Surface

if TYPE_CHECKING:  # the pool is made (and concurrent.futures imported) for numba's threads
    from concurrent.futures import ThreadPoolExecutor

__all__ = [
    "LEAN_EXACT_BELOW_DEG",
    "LEAN_SLOPE_BIN",
    "MIN_CHUNK",
    "SLOPES",
    "cell_index_of",
    "check_slope_range",
    "facets_near",
    "kernel_pool",
    "limit_threads",
    "numba_kernels",
    "run_blocks",
    "slope_cells",
    "slope_cells_indexed",
    "thread_limit",
]

FloatArray = NDArray[np.float64]
#: Every facet's lean cell indices ``(ip, iq)``, in facet order.
CellIndex = tuple[NDArray[np.int16], NDArray[np.int16]]

#: Facets per thread below which the numba kernels run on one thread.
MIN_CHUNK = 1 << 16
#: Rectangles narrower than this (deg, in plane) are read facet by facet in the ``"lean"``
#: backend: the slope cells' 0.06 deg steps of mirror direction are too coarse for the
#: ASTM E430 slits (0.05-0.4 deg; 1-50 % off), while the ISO 2813 readings stay within
#: 0.2 % of the facets' (Gaussian maps of rms slope 0.001-0.3).
LEAN_EXACT_BELOW_DEG = 0.5
#: Slope bin of the histogram whose occupied cells stand for the facets in the ``"lean"``
#: backend's deposits and cone responses (a facet moves by up to half a bin in each slope,
#: its mirror direction by about 0.06 deg, against cones of degrees).
LEAN_SLOPE_BIN = 1e-3
#: Facets per block when the slope cells are counted.
_CELL_BLOCK = 1 << 18
#: The lean histogram keeps its counts dense while the slope range has at most this many
#: cells per facet (8 bytes each): beyond, only the occupied cells are counted.
_DENSE_CELLS_PER_FACET = 4
#: ... and always up to this many cells (8 MiB).
_DENSE_MIN_CELLS = 1 << 20
#: Largest |slope| / bin the lean histogram indexes: (2 * 2**30)**2 cells fit an int64 key.
_MAX_SLOPE_CELLS = 1 << 30
#: Maps of at most this many facets count their slope cells in one walk
#: (:func:`_dense_cells_one_pass`: 4 bytes per facet kept meanwhile).
_ONE_PASS_MAX_FACETS = 1 << 24
#: ... forming the slopes this many at a time (a few rows of a map: in cache) ...
_ONE_PASS_CHUNK = 1 << 16
#: ... and count the kept indices in tasks of this many facets (each task a grid of counts
#: of its own; one task for a 2048^2 map: a second grid of counts, and its fresh pages,
#: cost more than a second thread gains).
_ONE_PASS_COUNT = 1 << 24
#: Spans of rows the one walk is cut into (the same on any number of threads).
_WALK_PARTS = 8
_I16_MIN, _I16_MAX = float(np.iinfo(np.int16).min), float(np.iinfo(np.int16).max)
#: Empty third facet array: the kernels read ``(p, q)`` slopes instead of unit normals.
SLOPES: FloatArray = np.empty(0)


def check_slope_range(
    p: FloatArray, q: FloatArray, bin_: float, source: str, *, worst: float | None = None
) -> None:
    """Refuse slopes the lean histogram cannot index, naming the map and the range.

    A slope of ``2**30 * 1e-3`` (about 1e6, a facet 6e-5 deg from vertical) means a map
    in the wrong units or with the wrong step, not a surface. ``worst``: the largest
    ``|slope|`` when already known (``p`` and ``q`` are then not read).
    """
    if worst is None:
        worst = max(float(np.max(np.abs(p))), float(np.max(np.abs(q))))
    if not (math.isfinite(worst) and worst / bin_ < _MAX_SLOPE_CELLS):
        raise ValueError(
            f"{source}: slopes up to {worst:.3g} (a facet {math.degrees(math.atan(worst)):.6g} "
            f"deg from horizontal): beyond the {_MAX_SLOPE_CELLS * bin_:.3g} the slope "
            "histogram indexes; check the map's height unit and lateral step"
        )


_executor: ThreadPoolExecutor | None = None


def numba_kernels() -> Any:
    """The compiled kernels (:mod:`goniolab.optics._kernels`), imported on first use: numba
    costs a process about 1 s to import and set up, which the ``"lean"`` backend avoids."""
    from goniolab.optics import _kernels

    return _kernels


def kernel_pool() -> ThreadPoolExecutor:
    global _executor
    if _executor is None:
        from concurrent.futures import ThreadPoolExecutor

        _executor = ThreadPoolExecutor(
            max_workers=max(1, os.cpu_count() or 1), thread_name_prefix="facet"
        )
    return _executor


def run_blocks(surface: Surface, kernel: Any, common: tuple[Any, ...]) -> list[Any]:
    """:meth:`goniolab.optics.facet.FacetModel._run`'s per-facet kernels over a large
    map's ``surface``, block by block as it forms them
    (:meth:`~goniolab.optics.surface.Surface.slope_blocks`): numba's on up to as many
    blocks at once as threads, the numpy twin (``kernel`` a function) one by one. The map's facets are never all held, nor the blocks' results: they are
    summed as they come (every kernel's result is a sum over facets)."""

    def add(a: Any, b: Any) -> Any:
        return b if a is None else tuple(map(add, a, b)) if isinstance(a, tuple) else a + b

    total: Any = None
    if callable(kernel):
        for p, q in surface.slope_blocks():
            total = add(total, kernel(p, q, SLOPES, *common))
        return [total]
    numba_fn = getattr(numba_kernels(), kernel + "_numba")
    width = max(1, thread_limit() or os.cpu_count() or 1)
    wave: list[Any] = []
    for p, q in surface.slope_blocks():
        wave.append(kernel_pool().submit(numba_fn, p, q, SLOPES, *common))
        if len(wave) >= width:
            for f in wave:
                total = add(total, f.result())
            wave = []
    for f in wave:
        total = add(total, f.result())
    return [total]


def slope_cells(
    p: FloatArray | Surface, q: FloatArray | None = None, source: str = ""
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The occupied cells of the slope histogram of bin :data:`LEAN_SLOPE_BIN`:
    ``(p, q, count)`` of each cell's centre, for the ``"lean"`` backend (the slopes
    ``p``, ``q`` of the map ``source``).

    Every facet is moved to its cell's centre, at most half a bin in each slope: its
    mirror direction by up to about 0.06 deg, and the readings, which average
    over many facets spread over apertures of degrees, by a fraction of that (the
    tests hold the lean readings to the per-facet kernels).

    Memory is bounded by the map, never by its slope range (issue 23.5: one 20 um spike
    on a 512^2 map asked a dense 1e-3 histogram for 48 GiB): the counts are kept dense
    only while the slope range's cells number at most :data:`_DENSE_CELLS_PER_FACET`
    per facet (or :data:`_DENSE_MIN_CELLS`), otherwise only the occupied cells are counted (a sort of each
    block's cell keys, merged), at most one per facet. A slope range whose cell index
    does not fit 64-bit integers is refused (:func:`_check_slope_range`).

    ``slope_cells(surface)`` takes the slopes of a
    :class:`~goniolab.optics.surface.Surface` block by block
    (:meth:`~goniolab.optics.surface.Surface.slope_blocks`): a map's surface then forms
    them from the map as it goes, and the count never holds the map's facets.
    """
    surface = p if isinstance(p, Surface) else Surface(p=p, q=p if q is None else q, source=source)
    return slope_cells_indexed(surface)[0]


def slope_cells_indexed(
    surface: Surface,
) -> tuple[tuple[FloatArray, FloatArray, FloatArray], CellIndex | None]:
    """:func:`slope_cells` of ``surface`` and, when they were counted in one walk
    (:func:`_dense_cells_one_pass`), every facet's cell indices ``(ip, iq)`` (int16, in
    facet order), which :func:`facets_near` reads instead of walking the slopes again."""
    if surface.n_facets <= _ONE_PASS_MAX_FACETS:
        got = _dense_cells_one_pass(surface)
        if got is not None:
            return got
    return _cells_two_walks(surface), None


def _cells_two_walks(surface: Surface) -> tuple[FloatArray, FloatArray, FloatArray]:
    b = LEAN_SLOPE_BIN
    p_lo, p_hi, q_lo, q_hi = surface.slope_range
    worst = max(abs(p_lo), abs(p_hi), abs(q_lo), abs(q_hi))
    check_slope_range(SLOPES, SLOPES, b, surface.source, worst=worst)
    p0 = math.floor(p_lo / b + 0.5)
    q0 = math.floor(q_lo / b + 0.5)
    n_q = math.floor(q_hi / b + 0.5) - q0 + 1
    n_p = math.floor(p_hi / b + 0.5) - p0 + 1
    size = surface.n_facets
    dense = n_p * n_q <= max(_DENSE_CELLS_PER_FACET * size, _DENSE_MIN_CELLS)
    counts = np.zeros(n_p * n_q if dense else 0, dtype=np.int64)
    keys: list[NDArray[np.int64]] = []
    tallies: list[NDArray[np.int64]] = []
    # the cell index (ip - p0) n_q + (iq - q0), ip = floor(p/b + 1/2), block by block:
    # the temporaries stay a block's, not the map's
    for pb, qb in _cell_blocks(surface):
        kp = np.multiply(pb, 1.0 / b)
        kp += 0.5
        np.floor(kp, out=kp)
        kq = np.multiply(qb, 1.0 / b)
        kq += 0.5
        np.floor(kq, out=kq)
        key = kp.astype(np.int64)
        del kp
        key -= p0
        np.clip(key, 0, n_p - 1, out=key)  # rounding at the last cell's edge
        key *= n_q
        iq = kq.astype(np.int64)
        del kq
        iq -= q0
        np.clip(iq, 0, n_q - 1, out=iq)
        key += iq
        del iq
        if dense:
            counts += np.bincount(key, minlength=n_p * n_q)
        else:
            k, c = np.unique(key, return_counts=True)
            keys.append(k)
            tallies.append(c)
    if dense:
        cells = np.flatnonzero(counts)
        weights = counts[cells]
    elif len(keys) == 1:
        cells, weights = keys[0], tallies[0]
    else:
        cells, inverse = np.unique(np.concatenate(keys), return_inverse=True)
        weights = np.bincount(inverse, weights=np.concatenate(tallies)).astype(np.int64)
    cp = ((cells // n_q + p0) * b).astype(np.float64)
    cq = ((cells % n_q + q0) * b).astype(np.float64)
    return cp, cq, weights.astype(np.float64)


def _dense_cells_one_pass(
    surface: Surface,
) -> tuple[tuple[FloatArray, FloatArray, FloatArray], CellIndex] | None:
    """:func:`slope_cells` in one walk over the slopes: each block's cell indices
    ``floor(p / b + 1/2)``, ``floor(q / b + 1/2)`` (the same float operations) are kept as
    int16 (a quarter of the slopes' memory) while their range is found, then counted. The
    two-walk path (:attr:`~goniolab.optics.surface.Surface.slope_range` first) formed every
    slope twice. None, and nothing kept, when an index leaves int16 (``|slope| >= 32.7``),
    is not finite, or the range needs the sparse count: :func:`slope_cells` then takes its
    general path, which also names a map beyond the index.

    The walk is cut into :data:`_WALK_PARTS` spans of rows and the count into chunks of
    :data:`_ONE_PASS_COUNT` facets, shared out over threads
    (:func:`~goniolab.optics.facet_threads.run_tasks`): each span writes its own facets'
    indices, the ranges are combined by min and max, the chunks' counts are integers
    summed in order. The same cells and counts on any number of threads."""
    n = surface.n_facets
    ip = np.empty(n, dtype=np.int16)
    iq = np.empty(n, dtype=np.int16)
    spans = surface.spans(_WALK_PARTS)
    ranges = run_tasks([functools.partial(_index_span, surface, span, ip, iq) for span in spans])
    if any(r is None for r in ranges):
        return None
    lo_p = min(r[0] for r in ranges if r is not None)
    hi_p = max(r[1] for r in ranges if r is not None)
    lo_q = min(r[2] for r in ranges if r is not None)
    hi_q = max(r[3] for r in ranges if r is not None)
    p0, q0 = int(lo_p), int(lo_q)
    n_p, n_q = int(hi_p) - p0 + 1, int(hi_q) - q0 + 1
    n_cells = n_p * n_q
    if n_cells > max(_DENSE_CELLS_PER_FACET * surface.n_facets, _DENSE_MIN_CELLS):
        return None
    offset = p0 * n_q + q0
    chunks = [(lo, min(lo + _ONE_PASS_COUNT, n)) for lo in range(0, n, _ONE_PASS_COUNT)]
    parts = run_tasks(
        [functools.partial(_count_chunk, ip, iq, lo, hi, n_q, offset, n_cells) for lo, hi in chunks]
    )
    counts = parts[0]
    for part in parts[1:]:
        counts += part
    cells = np.flatnonzero(counts)
    weights = counts[cells]
    cp = ((cells // n_q + p0) * LEAN_SLOPE_BIN).astype(np.float64)
    cq = ((cells % n_q + q0) * LEAN_SLOPE_BIN).astype(np.float64)
    ip.setflags(write=False)
    iq.setflags(write=False)
    return (cp, cq, weights.astype(np.float64)), (ip, iq)


def _index_span(
    surface: Surface,
    span: tuple[int, int],
    ip: NDArray[np.int16],
    iq: NDArray[np.int16],
) -> tuple[float, float, float, float] | None:
    """The int16 cell indices of the facets of ``span`` into ``ip``, ``iq`` and their
    range ``(lo_p, hi_p, lo_q, hi_q)``; None when one leaves int16 or is not finite."""
    inv = 1.0 / LEAN_SLOPE_BIN
    buf = np.empty(0)
    lo_p = lo_q = math.inf
    hi_p = hi_q = -math.inf
    at = span[0]
    # blocks of a few rows, formed in reused arrays: the work stays in cache
    for pb, qb in surface.slope_blocks(_ONE_PASS_CHUNK, reuse=True, span=span):
        m = pb.size
        if m > buf.size:  # a block is one row at least
            buf = np.empty(m)
        k = buf[:m]
        for v, out in ((pb, ip), (qb, iq)):
            np.multiply(v, inv, out=k)
            k += 0.5
            np.floor(k, out=k)
            lo, hi = float(k.min()), float(k.max())
            if not (_I16_MIN <= lo <= _I16_MAX and _I16_MIN <= hi <= _I16_MAX):  # NaN: False
                return None
            np.copyto(out[at : at + m], k, casting="unsafe")  # exact: integers in range
            if out is ip:
                lo_p, hi_p = min(lo_p, lo), max(hi_p, hi)
            else:
                lo_q, hi_q = min(lo_q, lo), max(hi_q, hi)
        at += m
    return lo_p, hi_p, lo_q, hi_q


def _count_chunk(
    ip: NDArray[np.int16],
    iq: NDArray[np.int16],
    lo: int,
    hi: int,
    n_q: int,
    offset: int,
    n_cells: int,
) -> NDArray[np.int64]:
    """The facet counts of the cells of the facets ``lo .. hi - 1``: their int64 keys
    ``ip n_q + iq - offset`` formed a few rows at a time in one reused buffer (in cache)
    and added to the counts as they come (``np.add.at``, as fast as ``np.bincount`` since
    numpy 1.25): no key array of the facets (16 MB per 2**21 facets, freshly mapped pages
    that cost a 2048^2 curve more than the count itself)."""
    counts: NDArray[np.int64] = np.zeros(n_cells, dtype=np.int64)
    key = np.empty(min(_ONE_PASS_CHUNK, hi - lo), dtype=np.int64)
    for a in range(lo, hi, _ONE_PASS_CHUNK):
        b = min(a + _ONE_PASS_CHUNK, hi)
        kk = key[: b - a]
        np.multiply(ip[a:b], n_q, out=kk, dtype=np.int64)
        kk += iq[a:b]
        kk -= offset
        np.add.at(counts, kk, 1)
    return counts


def cell_index_of(v: float) -> int:
    """The lean histogram's cell index ``floor(v / b + 1/2)`` of a slope ``v``, by the
    float operations the facets' indices are formed with (so it orders with them)."""
    k = v * (1.0 / LEAN_SLOPE_BIN)
    k += 0.5
    return math.floor(k)


def _cell_blocks(surface: Surface) -> Iterator[tuple[FloatArray, FloatArray]]:
    """Blocks of :data:`_CELL_BLOCK` facets: a held surface's slices, a streamed map
    surface's blocks as it forms them."""
    if surface.streamed:
        yield from surface.slope_blocks()
        return
    for pb, qb in surface.slope_blocks():
        for lo in range(0, pb.size, _CELL_BLOCK):
            yield pb[lo : lo + _CELL_BLOCK], qb[lo : lo + _CELL_BLOCK]


def facets_near(
    p: FloatArray | Surface,
    q: FloatArray | None,
    wi: FloatArray,
    alpha_rad: float,
    reach_a: float,
    reach_b: float,
    index: CellIndex | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Of the slopes ``p``, ``q``: those of a superset of the facets whose mirror direction of ``wi``
    lies within ``reach_a`` in plane of the in-plane angle ``alpha_rad`` and within
    ``reach_b`` out of plane (the directions a rectangle response can reach).

    A facet reflects wi into o when its normal is along ``wi + o``, i.e. its slopes
    are ``p = -(wi + o)_x/(wi + o)_z``, ``q = -(wi + o)_y/(wi + o)_z``. This map of the
    directions onto the slopes is continuous and one-to-one, so the slopes of the
    facets that can reach the rectangle of directions lie within the bounding box of
    the image of its edge (sampled on 64 points a side, the box widened by 1 % of its
    size). All facets when a corner of the rectangle leaves the hemisphere.

    ``p`` may be a :class:`~goniolab.optics.surface.Surface` (``q`` None): its facets are
    then selected block by block, in facet order (the same arrays), or, given the facets'
    cell ``index`` (:func:`slope_cells_indexed`), from those whose cells meet the box,
    without forming the other slopes (the same facets, in the same order).
    """
    if isinstance(p, Surface):
        surface = p
        box = _near_box(wi, alpha_rad, reach_a, reach_b)
        if box is None:
            return surface.p, surface.q
        if index is not None:
            # the facets whose cells meet the box (a superset: the index is monotone in
            # the slope), then the box itself on their slopes, taken from the map
            ip, iq = index
            lo_p, hi_p = (min(max(cell_index_of(v), -(1 << 15)), (1 << 15) - 1) for v in box[:2])
            lo_q, hi_q = (min(max(cell_index_of(v), -(1 << 15)), (1 << 15) - 1) for v in box[2:])
            hit = ip >= lo_p
            hit &= ip <= hi_p
            hit &= iq >= lo_q
            hit &= iq <= hi_q
            return _inside(*surface.take(np.flatnonzero(hit)), box)
        parts = [_inside(pb, qb, box) for pb, qb in surface.slope_blocks()]
        if len(parts) == 1:
            return parts[0]
        return np.concatenate([a for a, _ in parts]), np.concatenate([b for _, b in parts])
    assert q is not None
    box = _near_box(wi, alpha_rad, reach_a, reach_b)
    if box is None:
        return p, q
    return _inside(p, q, box)


def _near_box(
    wi: FloatArray, alpha_rad: float, reach_a: float, reach_b: float
) -> tuple[float, float, float, float] | None:
    """:func:`facets_near`'s slope box ``(p_lo, p_hi, q_lo, q_hi)``; None: all facets."""
    t = np.linspace(-1.0, 1.0, 65)
    one = np.ones_like(t)
    al = alpha_rad + reach_a * np.concatenate([t, one, -t, -one])
    be = reach_b * np.concatenate([-one, t, one, -t])
    if np.any(np.abs(al) >= 0.5 * math.pi) or reach_b >= 0.5 * math.pi:
        return None
    hx = wi[0] - np.sin(al) * np.cos(be)
    hy = wi[1] + np.sin(be)
    hz = wi[2] + np.cos(al) * np.cos(be)
    if np.any(hz <= 1e-9):
        return None
    rp, rq = -hx / hz, -hy / hz
    wp = 0.01 * float(rp.max() - rp.min()) + 1e-12
    wq = 0.01 * float(rq.max() - rq.min()) + 1e-12
    return (
        float(rp.min()) - wp,
        float(rp.max()) + wp,
        float(rq.min()) - wq,
        float(rq.max()) + wq,
    )


def _inside(
    p: FloatArray, q: FloatArray, box: tuple[float, float, float, float]
) -> tuple[FloatArray, FloatArray]:
    inside = p >= box[0]
    inside &= p <= box[1]
    inside &= q >= box[2]
    inside &= q <= box[3]
    idx = np.flatnonzero(inside)
    return p[idx], q[idx]
