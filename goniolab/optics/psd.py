"""Windows, tiles and the 2-D power spectral density of a height map (physical optics input).

The physical-optics models (:mod:`goniolab.optics.kirchhoff`,
:mod:`goniolab.optics.rayleigh_rice`) Fourier-transform a height map. Three things are
shared here:

- the window. The NIST appearance project (seed "nist-appearance-ray-method-and-kirchhoff",
  section "The Kirchhoff approximation") multiplies the phase integral by a smooth window
  that vanishes outside a finite region, built on the test function Schwartz uses in the
  theory of distributions, ``psi(t) = exp(-1/t)`` for ``t > 0``: the hard edge of the
  illuminated patch would otherwise add a sinc ringing to every direction.
  :func:`schwartz_taper` is 1 over the middle of the map and falls to 0 over ``taper`` of
  its length at each end through the C-infinity step ``psi(t)/(psi(t) + psi(1 - t))``, so
  its transform decays faster than any power and the coherent specular beam stays
  within a few cells of the FFT grid;
- the tiles. A big map (4096 x 4096 and more) is cut into equal tiles (at most ``tile``
  points per side, the remainder of fewer points than tiles dropped); every tile is windowed
  and transformed alone and the powers are summed (Bartlett averaging). Memory is then
  bounded by one tile's transforms whatever the map size; the angular resolution is that of
  a tile, ``lambda / (tile * step)``;
- the PSD. With the window ``W`` and the tile's heights ``h`` (window-weighted mean
  removed), ``PSD(f_m) = |DFT(W h)_m|^2 dx dy / sum(W^2)`` (um^4), averaged over the tiles,
  so that ``sum_m PSD(f_m) df_x df_y`` is the window-weighted mean square height Sq^2
  (discrete Parseval). Spatial frequencies ``f = fftfreq(n, step)`` in cycles per um.

References
----------
.. [1] NIST appearance project, "Ray method and Kirchhoff approximation" (seed text),
   section "The Kirchhoff approximation": smooth Schwartz-type window of the phase integral.
.. [2] J. C. Stover, "Optical Scattering: Measurement and Analysis", 3rd ed., SPIE 2012,
   ch. 2 and 4 (PSD of a profile/surface, its normalisation to the rms roughness).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.optics import _fft
from goniolab.optics.heightmap import HeightMap, fill_missing, level_plane, plane_fit
from goniolab.optics.taylor_fft import first_pass, weighted_phase

__all__ = [
    "DEFAULT_TAPER",
    "DEFAULT_TILE",
    "PSD2",
    "TiledMap",
    "pruned_fft2",
    "pruned_terms",
    "psd2",
    "psd_region",
    "schwartz_taper",
    "tile_starts",
    "windowed_sq_um",
    "y_axis_first",
]

FloatArray = NDArray[np.float64]

#: Fraction of each side over which the window falls from 1 to 0.
DEFAULT_TAPER: float = 0.25
#: Largest tile side (points) transformed at once.
DEFAULT_TILE: int = 1024


def schwartz_taper(n: int, taper: float = DEFAULT_TAPER) -> FloatArray:
    """1-D window of ``n`` points: 1 in the middle, a Schwartz C-infinity step at each end.

    ``w = s(d / (taper n))`` with ``d`` the distance of the sample centre from the nearest
    end and ``s(t) = psi(t)/(psi(t) + psi(1 - t))``, ``psi(t) = exp(-1/t)`` (0 for t <= 0),
    ``s = 1`` for ``t >= 1``. ``taper`` in (0, 0.5].
    """
    if n < 1:
        raise ValueError(f"window length must be >= 1, got {n}")
    if not (0.0 < taper <= 0.5):
        raise ValueError(f"taper must be in (0, 0.5], got {taper}")
    x = (np.arange(n, dtype=np.float64) + 0.5) / n
    t = np.minimum(x, 1.0 - x) / taper
    t = np.clip(t, 0.0, 1.0)

    def psi(u: FloatArray) -> FloatArray:
        pos = u > 0.0
        out: FloatArray = np.where(pos, np.exp(-1.0 / np.where(pos, u, 1.0)), 0.0)
        return out

    a, b = psi(t), psi(1.0 - t)
    out: FloatArray = np.where(t >= 1.0, 1.0, a / np.where(a + b > 0.0, a + b, 1.0))
    return out


def tile_starts(n: int, tile: int) -> tuple[list[int], int]:
    """Start indices and common length of the equal tiles along one axis of ``n`` points."""
    if tile < 8:
        raise ValueError(f"tile must be >= 8 points, got {tile}")
    n_seg = max(1, math.ceil(n / tile))
    size = n // n_seg
    return [k * size for k in range(n_seg)], size


#: Largest total size of a map's tiles (float32 bytes) that :meth:`TiledMap.tile` keeps.
_TILE_CACHE_BYTES: int = 32 << 20
#: The kept tiles of each tiled map (dropped with the map).
_TILES: weakref.WeakKeyDictionary[TiledMap, dict[int, NDArray[np.float32]]] = (
    weakref.WeakKeyDictionary()
)
#: Their transposed copies (:meth:`TiledMap.tile_transposed`), kept alike.
_TILES_T: weakref.WeakKeyDictionary[TiledMap, dict[int, NDArray[np.float32]]] = (
    weakref.WeakKeyDictionary()
)


@dataclass(frozen=True, eq=False)
class TiledMap:
    """A levelled, gap-filled height map cut into equal windowed tiles (float32).

    The levelled heights are formed on demand, block by block (:meth:`levelled`,
    :meth:`tile`), from the map's own array (float64, or float32 as a float32 file is
    read) and its best plane, in float64: a map without missing points is not copied. A map with gaps is filled (nearest valid point) and
    levelled once into a float32 copy (half the float64 map's size).

    Attributes
    ----------
    dx_um, dy_um : float
        Steps.
    shape : tuple of int
        ``(ny, nx)`` of the map.
    ys, xs : list of int
        Tile start rows and columns; ``ny_t``, ``nx_t`` the tile shape.
    wy, wx : ndarray
        The 1-D windows (float32); the tile window is their outer product.
    sum_w2 : float
        ``sum(W^2)`` of one tile.
    source : str
        Where the map came from.
    filled : int
        Number of missing points that were filled.
    """

    dx_um: float
    dy_um: float
    shape: tuple[int, int]
    ys: list[int]
    xs: list[int]
    ny_t: int
    nx_t: int
    wy: NDArray[np.float32]
    wx: NDArray[np.float32]
    sum_w2: float
    source: str
    filled: int
    #: the map's own heights (float64 or float32) with ``plane`` (a, b, c) still to
    #: subtract (in float64), or float32 levelled heights
    #: (``plane`` None)
    _src: NDArray[np.float64] | NDArray[np.float32]
    _plane: tuple[float, float, float] | None

    @classmethod
    def from_heightmap(
        cls, hm: HeightMap, *, tile: int = DEFAULT_TILE, taper: float = DEFAULT_TAPER
    ) -> TiledMap:
        """Level (best plane), fill missing points (nearest), cut into tiles."""
        ny, nx = hm.shape
        if min(ny, nx) < 16:
            raise ValueError(
                f"{hm.source}: map of {nx} x {ny} points is too small for physical optics "
                "(at least 16 x 16)"
            )
        filled = int(hm.z_um.size - hm.n_valid)
        src: NDArray[np.float64] | NDArray[np.float32]
        plane: tuple[float, float, float] | None
        if filled:
            hm = fill_missing(hm, "nearest")
            src, plane = np.asarray(level_plane(hm).z_um, dtype=np.float32), None
        else:
            src, plane = hm.z_um, plane_fit(hm)  # float64 or float32: not copied
        ys, nyt = tile_starts(ny, tile)
        xs, nxt = tile_starts(nx, tile)
        wy = schwartz_taper(nyt, taper).astype(np.float32)
        wx = schwartz_taper(nxt, taper).astype(np.float32)
        sum_w2 = float(np.sum(wy.astype(np.float64) ** 2) * np.sum(wx.astype(np.float64) ** 2))
        return cls(
            dx_um=float(hm.dx_um),
            dy_um=float(hm.dy_um),
            shape=(ny, nx),
            ys=ys,
            xs=xs,
            ny_t=nyt,
            nx_t=nxt,
            wy=wy,
            wx=wx,
            sum_w2=sum_w2,
            source=hm.source,
            filled=filled,
            _src=src,
            _plane=plane,
        )

    def levelled(self, rows: slice, cols: slice) -> NDArray[np.float32]:
        """The levelled heights ``z[rows, cols]`` (float32, a new array): the same values as
        :func:`~goniolab.optics.heightmap.level_plane` of the whole map cast to float32."""
        if self._plane is None:
            return np.array(self._src[rows, cols], dtype=np.float32)
        a, b, c = self._plane
        ny, nx = self.shape
        x_um = (np.arange(nx, dtype=np.float64)[cols] - (nx - 1) / 2.0) * self.dx_um
        y_um = (np.arange(ny, dtype=np.float64)[rows] - (ny - 1) / 2.0) * self.dy_um
        out = np.subtract(self._src[rows, cols], a + b * x_um)
        out -= (c * y_um)[:, None]
        return out.astype(np.float32)

    @property
    def z_um(self) -> NDArray[np.float32]:
        """The whole levelled map (float32; a new array of half the float64 map's size)."""
        return self.levelled(slice(None), slice(None))

    @cached_property
    def window(self) -> NDArray[np.float32]:
        """The tile window ``wy[:, None] * wx[None, :]`` (float32, formed once)."""
        w: NDArray[np.float32] = self.wy[:, None] * self.wx[None, :]
        w.setflags(write=False)
        return w

    @cached_property
    def window_transposed(self) -> NDArray[np.float32]:
        """``window.T`` as a contiguous read-only array (for transforms along y first)."""
        w: NDArray[np.float32] = np.ascontiguousarray(self.window.T)
        w.setflags(write=False)
        return w

    @property
    def n_tiles(self) -> int:
        return len(self.ys) * len(self.xs)

    def tile(self, k: int) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Heights of tile ``k`` (window-weighted mean removed) and its window (float32,
        read-only; the window is shared).

        When all the tiles together take at most :data:`_TILE_CACHE_BYTES` (a 2048 x 2048
        map: 16 MB) each is formed once and kept: a gloss report of 16 wavelengths asks
        for every tile a few dozen times (levelling it each time cost a third of the
        work beside the FFTs). Larger maps form a tile on each request (memory bounded by
        a tile, as before).
        """
        keep = self.n_tiles * self.ny_t * self.nx_t * 4 <= _TILE_CACHE_BYTES
        kept = _TILES.setdefault(self, {}) if keep else None
        if kept is not None and k in kept:
            return kept[k], self.window
        iy, ix = divmod(k, len(self.xs))
        y0, x0 = self.ys[iy], self.xs[ix]
        h = self.levelled(slice(y0, y0 + self.ny_t), slice(x0, x0 + self.nx_t))
        w = self.window
        mean = float(np.sum(w * h, dtype=np.float64) / np.sum(w, dtype=np.float64))
        h -= np.float32(mean)
        h.setflags(write=False)
        if kept is not None:
            kept[k] = h
        return h, w

    def tile_transposed(self, k: int) -> NDArray[np.float32]:
        """``tile(k)[0].T`` as a contiguous read-only array (for transforms along y first),
        kept beside the tile when the tiles are (:meth:`tile`)."""
        keep = self.n_tiles * self.ny_t * self.nx_t * 4 <= _TILE_CACHE_BYTES
        kept = _TILES_T.setdefault(self, {}) if keep else None
        if kept is not None and k in kept:
            return kept[k]
        ht = np.ascontiguousarray(self.tile(k)[0].T)
        ht.setflags(write=False)
        if kept is not None:
            kept[k] = ht
        return ht


@dataclass(frozen=True, eq=False)
class PSD2:
    """Two-sided 2-D PSD of a height map on the tile's FFT grid.

    ``psd_um4[i, j]`` at ``fy[i]``, ``fx[j]`` (cycles/um, numpy ``fftfreq`` order);
    ``sq_um`` the rms height the PSD integrates to.
    """

    fx: FloatArray
    fy: FloatArray
    psd_um4: FloatArray
    sq_um: float

    @property
    def df_x(self) -> float:
        return float(abs(self.fx[1] - self.fx[0])) if self.fx.size > 1 else 0.0

    @property
    def df_y(self) -> float:
        return float(abs(self.fy[1] - self.fy[0])) if self.fy.size > 1 else 0.0


def psd2(tiled: TiledMap) -> PSD2:
    """PSD of a tiled map, averaged over the tiles (module docstring for the normalisation)."""
    acc = np.zeros((tiled.ny_t, tiled.nx_t), dtype=np.float64)
    for k in range(tiled.n_tiles):
        h, w = tiled.tile(k)
        spec = _fft.fft(_fft.fft((w * h).astype(np.complex64), axis=1), axis=0)
        acc += np.abs(spec).astype(np.float64) ** 2
    psd = acc * tiled.dx_um * tiled.dy_um / (tiled.sum_w2 * tiled.n_tiles)
    fx = np.fft.fftfreq(tiled.nx_t, tiled.dx_um).astype(np.float64)
    fy = np.fft.fftfreq(tiled.ny_t, tiled.dy_um).astype(np.float64)
    df = (1.0 / (tiled.nx_t * tiled.dx_um)) * (1.0 / (tiled.ny_t * tiled.dy_um))
    sq = math.sqrt(float(np.sum(psd)) * df)
    return PSD2(fx=fx, fy=fy, psd_um4=psd, sq_um=sq)


def windowed_sq_um(tiled: TiledMap) -> float:
    """The rms height :func:`psd2` integrates to, ``sqrt(mean_tiles sum (W h)^2 / sum W^2)``,
    summed in real space (discrete Parseval: the same value without a transform)."""
    acc = 0.0
    for k in range(tiled.n_tiles):
        h, w = tiled.tile(k)
        wh = (w * h).astype(np.float64)
        # numpy's pairwise sum (einsum's SIMD sum moved with the arrays' alignment: the
        # same map read 1e-9 apart in two processes)
        acc += float(np.sum(np.square(wh)))
    return math.sqrt(acc / (tiled.sum_w2 * tiled.n_tiles))


#: Largest zero-padded complex64 copy of a tile the padded FFT may make (bytes).
_MAX_PADDED_BYTES: int = 64 << 20


def _dft_last(a: NDArray[np.complex64], idx: NDArray[np.int64], length: int) -> NDArray[Any]:
    """DFT of length ``length`` (``a`` zero-padded) along the last axis, at outputs ``idx``.

    Unpadded: an FFT, then the outputs kept. Padded: a matrix product with the ``idx`` rows
    of the DFT matrix when they are few (cost ``n K`` per row against ``L log L`` for the
    padded FFT, and no padded copy of the tile) or when the padded copy would exceed
    :data:`_MAX_PADDED_BYTES`, else the padded FFT.
    """
    n = a.shape[-1]
    rows = a.size // max(n, 1)
    few = idx.size < (length // n) * max(1.0, math.log2(length))
    if length == n or (not few and rows * length * 8 <= _MAX_PADDED_BYTES):
        if length != n:
            padded = np.zeros((*a.shape[:-1], length), dtype=a.dtype)
            padded[..., :n] = a
            a = padded
        out: NDArray[Any] = np.take(_fft.fft(a, axis=-1), idx, axis=-1)
        return out
    e = np.exp((-2j * math.pi / length) * np.outer(np.arange(n), idx)).astype(np.complex64)
    result: NDArray[Any] = a @ e
    return result


def _pass_cost(lines: int, n: int, length: int, kept: int) -> float:
    """Work of :func:`_dft_last` on ``lines`` lines of ``n`` points (length ``length``,
    ``kept`` outputs): an FFT ``L log2 L`` per line, or ``n K`` for the DFT-matrix product
    it picks for few outputs (the same rule)."""
    fft_line = length * max(1.0, math.log2(length))
    if length == n:
        return lines * fft_line
    few = kept < (length // n) * max(1.0, math.log2(length))
    if few or lines * length * 8 > _MAX_PADDED_BYTES:
        return float(lines * n * kept)
    return lines * fft_line


def y_axis_first(
    ny: int, nx: int, ky_size: int, kx_size: int, lengths: tuple[int, int] | None = None
) -> bool:
    """Whether :func:`pruned_fft2` should run its first (full) pass along y: the order of
    the two passes with less work. The full pass transforms every line of the tile, the
    second only the lines kept; with zero padding a full pass along the padded axis costs
    the padding factor more, so the padded axis goes second (the ISO 85 deg receptor: a
    3 x padded x axis first took twice the work). Unpadded: y first when ``ky`` is the
    smaller."""
    ly, lx = (ny, nx) if lengths is None else lengths
    x_first = _pass_cost(ny, nx, lx, kx_size) + _pass_cost(kx_size, ny, ly, ky_size)
    y_first = _pass_cost(nx, ny, ly, ky_size) + _pass_cost(ky_size, nx, lx, kx_size)
    if (ly, lx) == (ny, nx) and ny == nx:
        return ky_size <= kx_size
    return y_first <= x_first


def pruned_fft2(
    term: NDArray[np.complex64],
    ky: NDArray[np.int64],
    kx: NDArray[np.int64],
    y_first: bool,
    out: NDArray[np.complex64],
    lengths: tuple[int, int] | None = None,
) -> complex:
    """2-D DFT of ``term`` at rows ``ky`` and columns ``kx`` only, into ``out``; returns the
    zero-frequency value (summed in complex128).

    ``term`` is laid out ``(x, y)`` when ``y_first`` (the transposed tile), else ``(y, x)``:
    the first pass runs over the whole tile along its contiguous last axis, keeps the
    outputs the region needs, and the second pass transforms only those. Same values as
    ``fft2(...)[ky][:, kx]`` (to float32 rounding) at a fraction of the work when the
    region is narrow. ``lengths = (L_y, L_x)``: transform lengths of the zero-padded tile
    (a grid of directions ``L / n`` times finer; default the tile's own).
    """
    ny, nx = (term.shape[1], term.shape[0]) if y_first else term.shape
    ly, lx = (ny, nx) if lengths is None else lengths
    if (ly, lx) == (ny, nx):
        a = _fft.fft(term, axis=1)
        dc = complex(np.sum(a[:, 0], dtype=np.complex128))
        first, second = (ky, kx) if y_first else (kx, ky)
        a = _fft.fft(np.take(a, first, axis=1), axis=0)
        a = np.take(a, second, axis=0)
        out[...] = a.T if y_first else a
        return dc
    dc = complex(np.sum(term, dtype=np.complex128))
    (first, l1), (second, l2) = ((ky, ly), (kx, lx)) if y_first else ((kx, lx), (ky, ly))
    a = _dft_last(term, first, l1)
    b = _dft_last(np.ascontiguousarray(a.T), second, l2)  # (first, second)
    out[...] = b if y_first else b.T
    return dc


def pruned_terms(
    h: NDArray[np.float32],
    w: NDArray[np.float32],
    h_max: float,
    vc: float,
    ky: NDArray[np.int64],
    kx: NDArray[np.int64],
    y_first: bool,
    out: NDArray[np.complex64],
    lengths: tuple[int, int] | None = None,
) -> NDArray[np.complex128]:
    """:func:`pruned_fft2` of each Taylor term ``T_n = W exp(-i v_c h) (h / h_max)^n`` of
    a band, ``n = 0..N`` (``N + 1 = out.shape[0]``), into ``out[n]``; returns the terms'
    zero-frequency values. ``h`` and ``w`` are laid out as ``term`` there.

    The first pass, an FFT along the contiguous axis, runs for all the terms of a block of
    lines at once (:func:`goniolab.optics.taylor_fft.first_pass`: the terms stay in cache;
    no tile-sized output per term); the second pass transforms the outputs kept, term by
    term, as :func:`pruned_fft2` does: the same values, bit for bit. A first pass along a
    zero-padded axis (not chosen by :func:`y_axis_first` unless both axes are padded) is
    :func:`pruned_fft2` itself, term by term."""
    n_t = out.shape[0]
    ny, nx = (h.shape[1], h.shape[0]) if y_first else h.shape
    ly, lx = (ny, nx) if lengths is None else lengths
    (first, l1), (second, l2) = ((ky, ly), (kx, lx)) if y_first else ((kx, lx), (ky, ly))
    dc = np.empty(n_t, dtype=np.complex128)
    if l1 != h.shape[1]:
        term = weighted_phase(h, w, vc)
        u = h / np.float32(h_max) if h_max > 0 else h
        for n in range(n_t):
            dc[n] = pruned_fft2(term, ky, kx, y_first, out[n], lengths)
            if n < n_t - 1:
                term *= u
        return dc
    keep = first.astype(np.intp)
    a = np.empty((n_t, h.shape[0], keep.size), dtype=np.complex64)
    if (ly, lx) == (ny, nx):
        lines = np.empty((n_t, h.shape[0]), dtype=np.complex64)
        first_pass(h, w, h_max, vc, keep, a, dc_rows=lines)
        for n in range(n_t):
            dc[n] = complex(np.sum(lines[n], dtype=np.complex128))
            b = np.take(_fft.fft(a[n], axis=0), second, axis=0)
            out[n] = b.T if y_first else b
        return dc
    first_pass(h, w, h_max, vc, keep, a, dc_points=dc)
    for n in range(n_t):
        b = _dft_last(np.ascontiguousarray(a[n].T), second, l2)
        out[n] = b if y_first else b.T
    return dc


def psd_region(
    tiled: TiledMap,
    ky: NDArray[np.int64],
    kx: NDArray[np.int64],
    os: tuple[int, int],
    progress: Callable[[int, int, str], None] | None = None,
) -> FloatArray:
    """The PSD (um^4) of :func:`psd2` at the cells ``(ky, kx)`` (non-negative indices) of
    the tile's transform zero-padded ``os = (os_x, os_y)`` times: the same windowed
    periodogram sampled on a grid of frequencies ``1 / (os n step)``, so that a sum over
    the padded cells times their area ``df_x df_y / (os_x os_y)`` still gives Sq^2.
    ``progress(done, total, what)`` hears of each tile of a map of several."""
    acc = np.zeros((ky.size, kx.size))
    spec = np.empty((ky.size, kx.size), dtype=np.complex64)
    lengths = (os[1] * tiled.ny_t, os[0] * tiled.nx_t)
    y_first = y_axis_first(tiled.ny_t, tiled.nx_t, ky.size, kx.size, lengths)
    for k in range(tiled.n_tiles):
        h, w = tiled.tile(k)
        term = (w * h).astype(np.complex64)
        if y_first:
            term = np.ascontiguousarray(term.T)
        pruned_fft2(term, ky, kx, y_first, spec, lengths)
        acc += np.abs(spec).astype(np.float64) ** 2
        if progress is not None and tiled.n_tiles > 1:
            progress(k + 1, tiled.n_tiles, "rayleigh-rice PSD tiles")
    out: FloatArray = acc * tiled.dx_um * tiled.dy_um / (tiled.sum_w2 * tiled.n_tiles)
    return out
