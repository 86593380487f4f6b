"""What every physical-optics model of one height map shares: the map and its statistics.

:class:`SharedMap` holds the levelled map cut into windowed tiles
(:class:`goniolab.optics.psd.TiledMap`), the cache of FFT cell powers, the Smith masking
model of a subsample of its slopes, the fallback facet models and the sibling wave models;
:class:`MapStats` is the roughness the regime rule of
:mod:`goniolab.optics.model_choice` reads (Sq, Sdq, correlation length, step, field).
"""

from __future__ import annotations

import functools
import math
import threading
from collections import OrderedDict
from collections.abc import Callable
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.optics import _fft
from goniolab.optics.facet import FacetModel
from goniolab.optics.facet_threads import run_tasks
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.psd import TiledMap
from goniolab.optics.surface import MapSurface, Surface

__all__ = ["MapStats", "SharedMap", "first_below"]

FloatArray = NDArray[np.float64]

#: Facets used for the Smith masking table (strided subsample of the map's slopes).
_MASKING_FACETS: int = 1 << 17
#: Rows of the levelled map per block when the roughness statistics are summed.
_STATS_ROWS: int = 64  # a block of a 2048-wide map in cache: a third faster than 256
_STATS_GROUPS: int = 2  # groups of blocks the statistics are summed in (run_tasks)
#: How far above 1/e the real-space autocorrelation must be at every lag for
#: :meth:`SharedMap._corr_at_least` to decide without the transforms.
_ACF_MARGIN: float = 1e-3
#: Cached cell-power maps per shared map.
_CACHE_SIZE: int = 24


class MapStats:
    """Roughness of the (levelled, windowed) map the physical models see.

    ``sq_um``: rms height; ``sdq``: rms gradient ``sqrt(<p^2 + q^2>)``;
    ``corr_length_um``: where the isotropic autocorrelation falls to 1/e;
    ``step_um``: the larger lateral step; ``field_um``: the smaller tile side.

    ``sdq`` and ``corr_length_um`` may be given as functions: each is then computed when
    first read (Sdq: a pass over the map's differences, about 8 ms on a 2048^2 map; the
    length: the transforms of a tile, about 15 ms), which the regime rule reads only for
    a smooth map: a rough map's rule decides on Sq alone (g >= 20 comes before any
    test of Sdq or the length). Immutable, compared by value, as a frozen dataclass of
    the five numbers.
    """

    __slots__ = ("_corr", "_corr_at_least", "_sdq", "field_um", "sq_um", "step_um")
    _FIELDS = ("sq_um", "sdq", "corr_length_um", "step_um", "field_um")

    sq_um: float
    step_um: float
    field_um: float
    _sdq: float | Callable[[], float]
    _corr: float | Callable[[], float]
    _corr_at_least: Callable[[float], bool] | None

    def __init__(
        self,
        sq_um: float,
        sdq: float | Callable[[], float],
        corr_length_um: float | Callable[[], float],
        step_um: float,
        field_um: float,
        corr_at_least: Callable[[float], bool] | None = None,
    ) -> None:
        for name, value in (("sq_um", sq_um), ("_sdq", sdq), ("step_um", step_um),
                            ("field_um", field_um), ("_corr", corr_length_um),
                            ("_corr_at_least", corr_at_least)):  # fmt: skip
            object.__setattr__(self, name, value)

    @property
    def sdq(self) -> float:
        """The rms gradient ``sqrt(<p^2 + q^2>)`` (computed when first read, if given as a
        function)."""
        sdq = self._sdq
        if callable(sdq):
            sdq = float(sdq())
            object.__setattr__(self, "_sdq", sdq)
        return float(sdq)

    def corr_length_below(self, length_um: float) -> bool:
        """``corr_length_um < length_um``, without computing the length when a cheap bound
        (``corr_at_least``, :meth:`SharedMap._corr_at_least`) shows it is not below: the
        regime rule asks this of every smooth map, whose correlation length is then
        hardly ever read."""
        corr = self._corr
        if callable(corr) and self._corr_at_least is not None and self._corr_at_least(length_um):
            return False
        return self.corr_length_um < length_um

    @property
    def corr_length_um(self) -> float:
        corr = self._corr
        if callable(corr):
            corr = float(corr())
            object.__setattr__(self, "_corr", corr)
        return float(corr)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"MapStats is immutable: cannot set {name!r}")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"MapStats is immutable: cannot delete {name!r}")

    def _values(self) -> tuple[float, ...]:
        return tuple(getattr(self, name) for name in self._FIELDS)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, MapStats):
            return NotImplemented
        return self._values() == other._values()

    def __hash__(self) -> int:
        return hash(self._values())

    def __repr__(self) -> str:
        inner = ", ".join(f"{name}={getattr(self, name)!r}" for name in self._FIELDS)
        return f"MapStats({inner})"


class SharedMap:
    """State shared by all models of one map: tiles, FFT-power cache, masking, fallback."""

    def __init__(self, hm: HeightMap, tile: int, taper: float) -> None:
        self.hm = hm
        self.tiled = TiledMap.from_heightmap(hm, tile=tile, taper=taper)
        self.cache: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
        self.lock = threading.Lock()
        self._facets: dict[tuple[complex, bool], FacetModel] = {}
        self._factories: dict[tuple[complex, bool], Callable[[], FacetModel]] = {}
        #: the other wave models of the same map, by (kind, n, wavelength, weighting, masking)
        self.siblings: dict[tuple[Any, ...], Any] = {}
        #: :meth:`_corr_at_least` by length
        self._corr_bounds: dict[float, bool] = {}
        #: where the facet models of this map report long walks (:meth:`report_to`)
        self.progress: Callable[[int, int, str], None] | None = None

    def report_to(self, fn: Callable[[int, int, str], None]) -> None:
        """Make the facet models of this map (the shared one and the fallbacks) report
        their walks over a large map's slopes to ``fn``
        (:class:`~goniolab.optics.surface.MapSurface`)."""
        with self.lock:
            self.progress = fn
            for facet in self._facets.values():
                _report(facet, fn)

    def cached(self, key: tuple[Any, ...], make: Callable[[], Any]) -> Any:
        with self.lock:
            if key in self.cache:
                self.cache.move_to_end(key)
                return self.cache[key]
        value = make()
        with self.lock:
            self.cache[key] = value
            while len(self.cache) > _CACHE_SIZE:
                self.cache.popitem(last=False)
        return value

    @cached_property
    def h_max_um(self) -> float:
        """Largest |height - tile mean| over all tiles (bounds the Taylor terms)."""
        out = 0.0
        for k in range(self.tiled.n_tiles):
            h, _ = self.tiled.tile(k)
            out = max(out, float(np.max(np.abs(h))))
        return out

    @cached_property
    def masking_model(self) -> FacetModel:
        """A facet model of a strided subsample of the map's forward slopes (for Smith G2)."""
        t = self.tiled
        ny, nx = t.shape
        stride = max(1, math.ceil(math.sqrt(ny * nx / _MASKING_FACETS)))
        mx, my = (nx - 1) // stride, (ny - 1) // stride
        rows = slice(None, None, stride)
        p = (
            t.levelled(rows, slice(1, None, stride))[:, :mx]
            - t.levelled(rows, slice(0, nx - 1, stride))[:, :mx]
        ) / t.dx_um
        cols = slice(None, None, stride)
        q = (
            t.levelled(slice(1, None, stride), cols)[:my]
            - t.levelled(slice(0, ny - 1, stride), cols)[:my]
        ) / t.dy_um
        m = min(p.shape[0], q.shape[0]), min(p.shape[1], q.shape[1])
        surf = Surface(
            p=p[: m[0], : m[1]].ravel().astype(np.float64),
            q=q[: m[0], : m[1]].ravel().astype(np.float64),
            dx_um=t.dx_um,
            dy_um=t.dy_um,
            source=t.source,
        )
        return FacetModel(surf, masking=True, backend="numpy")

    def facet(self, n: complex, masking: bool) -> FacetModel:
        """The facet model of the full map (fallback), built on first use: the one a
        factory was adopted for (:meth:`adopt_facet_factory`), else one on the slope
        cells (``backend="lean"``: no numba, within 2e-3 of the curves' peak of the
        per-facet kernels, tests/optics/test_lean_backend.py)."""
        key = (complex(n), bool(masking))
        with self.lock:
            found = self._facets.get(key)
            factory = self._factories.get(key)
        if found is not None:
            return found
        if factory is not None:
            made = factory()  # outside the lock: it may build the facet slopes
        else:
            made = FacetModel(self._facets_surface, n=n, masking=masking, backend="lean")
        with self.lock:
            out = self._facets.setdefault(key, made)
            _report(out, self.progress)
            return out

    def adopt_facet(self, facet: FacetModel) -> None:
        """Use ``facet`` (a facet model of this map) as the fallback of its index and
        masking."""
        with self.lock:
            self._facets[(facet.n, facet.masking)] = facet
            _report(facet, self.progress)

    def adopt_facet_factory(
        self, n: complex, masking: bool, factory: Callable[[], FacetModel]
    ) -> None:
        """Build the fallback of index ``n`` and ``masking`` with ``factory`` when first
        needed: the ``auto`` model shares its own facet model, built only if a geometry
        needs it."""
        with self.lock:
            self._factories[(complex(n), bool(masking))] = factory

    @cached_property
    def _facets_surface(self) -> Surface:
        return Surface.from_heightmap(self.hm)

    def _block_sums(self, diffs: bool) -> list[tuple[float, ...]]:
        """Per block of :data:`_STATS_ROWS` rows of the levelled map (float32 heights as
        the tiles hold them, summed in float64), in the blocks' order: ``(sum z, sum z^2)``
        and, with ``diffs``, the sums of the squared x and y differences (the x
        differences within the block's rows, the y differences to the next row)."""
        t = self.tiled
        ny, _ = t.shape
        # sums over blocks of rows (no copy of the whole map), one pass (the sum of squares
        # about zero, then about the mean: the levelled mean is ~0, so no precision is lost)
        blocks = [(r0, min(r0 + _STATS_ROWS, ny)) for r0 in range(0, ny, _STATS_ROWS)]

        def sums(part: list[tuple[int, int]]) -> list[tuple[float, ...]]:
            out: list[tuple[float, ...]] = []
            for r0, r1 in part:
                # one more row for the y differences (each height is levelled on its own:
                # the block's own rows are the same values either way)
                r_end = min(r1 + 1, ny) if diffs else r1
                z = t.levelled(slice(r0, r_end), slice(None)).astype(np.float64)
                zb = z[: r1 - r0]
                s1 = float(np.sum(zb))
                s2 = float(np.einsum("ij,ij->", zb, zb))
                if not diffs:
                    out.append((s1, s2))
                    continue
                d = np.diff(zb, axis=1)
                sp = float(np.einsum("ij,ij->", d, d))
                d = np.diff(z, axis=0)
                out.append((s1, s2, sp, float(np.einsum("ij,ij->", d, d))))
            return out

        # the blocks in a few fixed groups on whichever thread is free (a group walks its
        # blocks in a loop, whose temporaries the allocator reuses), each block's sums
        # added in the blocks' order by the caller: the same bits on any number of threads
        k = _STATS_GROUPS
        groups = [blocks[len(blocks) * i // k : len(blocks) * (i + 1) // k] for i in range(k)]
        return [row for part in run_tasks([functools.partial(sums, g) for g in groups if g])
                for row in part]  # fmt: skip

    def _rms_gradient(self) -> float:
        """The rms gradient of the levelled map (forward differences along x and y)."""
        t = self.tiled
        ny, nx = t.shape
        sp = sq2 = 0.0
        for _, _, bp, bq in self._block_sums(diffs=True):
            sp += bp / (t.dx_um * t.dx_um)
            sq2 += bq / (t.dy_um * t.dy_um)
        return math.sqrt(sp / (ny * (nx - 1)) + sq2 / ((ny - 1) * nx))

    @cached_property
    def stats(self) -> MapStats:
        """The map's :class:`MapStats`: Sq now (a pass over the levelled heights), Sdq and
        the correlation length when first read (the regime rule reads them for a smooth
        map only)."""
        t = self.tiled
        ny, nx = t.shape
        s1 = s2 = 0.0
        for b1, b2 in self._block_sums(diffs=False):
            s1 += b1
            s2 += b2
        n_pts = ny * nx
        mean = s1 / n_pts
        sq = math.sqrt(max(s2 / n_pts - mean * mean, 0.0))
        return MapStats(
            sq_um=sq,
            sdq=self._rms_gradient,
            corr_length_um=self._corr_length_um,
            step_um=max(t.dx_um, t.dy_um),
            field_um=min(t.nx_t * t.dx_um, t.ny_t * t.dy_um),
            corr_at_least=self._corr_at_least,
        )

    def _corr_at_least(self, length_um: float) -> bool:
        """True when :meth:`_corr_length_um` is surely at least ``length_um``: the same
        autocorrelations (of the first windowed tile, circular, summed over the other axis)
        summed in real space at the lags up to ``length_um``, each above ``1/e`` by
        :data:`_ACF_MARGIN` (far beyond the rounding by which they differ from the
        transforms' values). Both lengths are then at least that many steps: the ACF first
        falls below ``1/e`` after them. False (undecided) otherwise: the length is then
        computed. Cost: a few dot products instead of two transforms of the tile, once per
        length (the rule asks at every geometry)."""
        found = self._corr_bounds.get(length_um)
        if found is None:
            found = self._corr_bounds[length_um] = self._acf_above_level(length_um)
        return found

    def _acf_above_level(self, length_um: float) -> bool:
        t = self.tiled
        h, w = t.tile(0)
        ny, nx = h.shape
        jx = math.ceil(length_um / t.dx_um)
        jy = math.ceil(length_um / t.dy_um)
        if not (0 < jx < nx // 2 and 0 < jy < ny // 2):
            return False
        # the product _corr_length_um transforms (float32), in float64
        a = np.asarray(h * w, dtype=np.float64)
        flat = a.ravel()
        zero = float(np.dot(flat, flat))
        if not zero > 0.0:
            return False
        level = math.exp(-1.0) + _ACF_MARGIN
        for j in range(1, jx + 1):
            # along x, circular per row: the flat product pairs the last j points of a row
            # with the next row's first j; those pairs are swapped for the row's own first j
            lin = float(np.dot(flat[:-j], flat[j:]))
            cross = float(np.sum(a[:-1, nx - j :] * a[1:, :j]))
            wrap = float(np.sum(a[:, nx - j :] * a[:, :j]))
            if (lin - cross + wrap) / zero < level:
                return False
        for j in range(1, jy + 1):
            lin = float(np.dot(flat[: -j * nx], flat[j * nx :]))
            wrap = float(np.sum(a[ny - j :] * a[:j]))
            if (lin + wrap) / zero < level:
                return False
        return True

    def _corr_length_um(self) -> float:
        """Where the isotropic ACF falls to 1/e: the mean of the lengths along x and y."""
        # ACF along x and y of the first windowed tile, each from 1-D transforms: the power
        # summed over the other axis is the transform of the ACF at zero lag along it
        # (Wiener-Khinchin, Parseval over the other axis); circular, as the periodogram's
        t = self.tiled
        h, w = t.tile(0)
        hw = (h * w).astype(np.complex64)
        acf_x = _acf_along(hw, axis=1)
        acf_y = _acf_along(hw, axis=0)
        lx = first_below(acf_x[: h.shape[1] // 2], math.exp(-1.0)) * t.dx_um
        ly = first_below(acf_y[: h.shape[0] // 2], math.exp(-1.0)) * t.dy_um
        return 0.5 * (lx + ly)


def _acf_along(hw: NDArray[np.complex64], axis: int) -> FloatArray:
    """Normalised circular autocorrelation of ``hw`` along ``axis`` at zero lag across it:
    the inverse transform of ``sum_other |FFT_axis(hw)|^2``."""
    spec = _fft.fft(hw, axis=axis)
    power = np.sum(np.abs(spec).astype(np.float64) ** 2, axis=1 - axis)
    acf = np.fft.irfft(power[: power.size // 2 + 1], n=power.size)
    out: FloatArray = acf / acf[0] if acf[0] > 0 else acf
    return out


def _report(facet: FacetModel, fn: Callable[[int, int, str], None] | None) -> None:
    if fn is not None and isinstance(facet.surface, MapSurface):
        facet.surface.progress = fn


def first_below(a: FloatArray, level: float) -> float:
    """Fractional index where ``a`` first drops below ``level`` (linear interpolation)."""
    idx = np.nonzero(a < level)[0]
    if idx.size == 0:
        return float(a.size)
    i = int(idx[0])
    if i == 0:
        return 0.0
    a0, a1 = float(a[i - 1]), float(a[i])
    return (i - 1) + (a0 - level) / (a0 - a1) if a0 != a1 else float(i)
