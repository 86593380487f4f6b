"""The coherent factor of the Kirchhoff model's energy check, summed over the map's points.

:meth:`goniolab.optics.kirchhoff.KirchhoffModel._energy_sums` divides by ``1 - C`` (small
towards grazing incidence), so ``C`` is summed directly over the map's points in float64
(:func:`coherent_direct`), not taken from the truncated Taylor bands of the readings.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.shared_map import SharedMap

__all__ = ["coherent_direct"]

FloatArray = NDArray[np.float64]

#: The coherent factor from binned heights (:func:`coherent_direct`): the
#: bin width is this phase over the largest ``v`` asked for (rounded up to a power of 2),
#: so a point's phase offset from its bin centre is at most half of it, and the
#: expansion of that offset's phase factor keeps terms to :data:`_COH_ORDER`
#: (remainder ``0.01^5 / 5! < 1e-12`` per point).
_COH_BIN_PHASE: float = 0.02
_COH_ORDER: int = 4
#: The bound on that remainder, per point, kept when a tall relief needs wider bins.
_COH_REMAINDER: float = 1e-12
#: Half a bin's phase span (rad) above which a tile's ``C`` is summed point by point (the
#: moments of offsets that wide lose digits to their alternating terms: 3.7e-9 instead
#: of 1e-13 for a 1 mm spike on 16^2 tiles, and an overflow for a 5 mm one; review of
#: 2026-11-26). Only a relief far taller than one bin per point gets there.
_COH_DIRECT_HALF: float = 1.0
#: Points per block of that binning (its float64 temporaries stay small).
_COH_BLOCK: int = 1 << 18


def coherent_direct(sh: SharedMap, vs: Sequence[float]) -> list[float]:
    """The coherent factor ``C = mean_tiles |sum W e^(-i v h)|^2 / (sum W)^2`` at each
    ``v`` (1/um), summed over the map's points in float64, not from the Taylor bands.

    The energy check divides by ``1 - C``, which is 1e-4 on a smooth coat at 89 deg:
    ``C`` from the truncated Taylor sum (a remainder of up to ``taylor_tol`` per
    point) moved the factor by 3e-5 to 1.4e-4 on a smooth 1024^2 coat and by 0.24 % on
    a wavy one (``tests/optics/test_kirchhoff.py``). Here each tile's heights are put
    in bins of width ``delta = 0.02 / v_max``; with ``c_b`` a bin's centre and ``d``
    a point's offset from it (``|v d| <= 0.01``),

    .. math:: \\sum W e^{-i v h} = \\sum_b e^{-i v c_b}
              \\sum_{n \\le 4} \\frac{(-i v)^n}{n!} \\sum_{h \\in b} W d^n

    to ``0.01^5 / 5! < 1e-12`` of ``sum W`` (the binned moments are formed once per
    tile and bin width, cached, in blocks of points: one pass over the tile whatever
    the number of ``v``, ~10 ms on 1024^2; a direct ``exp`` per point costs 30-40 ms
    per ``v``). A relief taller than one bin per point (``span / delta`` above the
    tile's points) gets bins ``span / points`` wide and as many more moments as keep
    the remainder below 1e-12 per point, so the moments never outgrow the tile."""
    if not vs:
        return []
    t = sh.tiled
    v_max = max(abs(float(v)) for v in vs)
    # the bin width from v_max rounded up to a power of 2: nearby calls share the bins
    v_bins = 2.0 ** math.ceil(math.log2(v_max)) if v_max > 0 else 1.0
    delta = _COH_BIN_PHASE / v_bins
    acc = [0.0 for _ in vs]

    def moments(k: int) -> tuple[FloatArray | None, FloatArray | None, float]:
        h, w = t.tile(k)
        hf, wf = h.reshape(-1), w.reshape(-1)
        lo = float(hf.min())
        span = float(hf.max()) - lo
        # at most one bin per point (a tall relief would otherwise ask for more
        # bins than the tile has points): wider bins, and more moments so the
        # offsets' remainder stays within that of the narrow bins
        width = max(delta, span / max(1, hf.size - 1))
        order = _COH_ORDER
        half = 0.5 * width * v_bins
        if half > _COH_DIRECT_HALF:
            # bins so wide that the offsets' phase reaches a radian: the moments'
            # alternating terms lose digits (and half ** order overflows on a relief
            # of mm on a small tile); such a tile is summed point by point instead
            return None, None, float(np.sum(w, dtype=np.float64))
        while half ** (order + 1) / math.factorial(order + 1) > _COH_REMAINDER:
            order += 1
        n_bins = int(span / width) + 1
        mom = np.zeros((order + 1, n_bins))
        for a in range(0, hf.size, _COH_BLOCK):
            hb = hf[a : a + _COH_BLOCK].astype(np.float64)
            hb -= lo
            idx = (hb * (1.0 / width)).astype(np.intp)
            np.minimum(idx, n_bins - 1, out=idx)  # the top height's own bin edge
            d = hb - (idx + 0.5) * width  # the offset from the bin's centre
            wd = wf[a : a + _COH_BLOCK].astype(np.float64)
            for n in range(order + 1):
                mom[n] += np.bincount(idx, weights=wd, minlength=n_bins)
                if n < order:
                    wd *= d
        centres: FloatArray = lo + (np.arange(n_bins, dtype=np.float64) + 0.5) * width
        return centres, mom, float(np.sum(w, dtype=np.float64))

    # one cache entry for all the tiles (one per tile flooded the shared LRU cache of
    # 24 entries on maps of many tiles, evicting the readings' transforms)
    tiles = sh.cached(
        ("kirchhoff coherent moments", delta),
        lambda: [moments(k) for k in range(t.n_tiles)],
    )
    for k, (centres, mom, sum_w) in enumerate(tiles):
        if centres is None or mom is None:  # a tall relief on a small tile: directly
            h, w = t.tile(k)
            hf = h.reshape(-1).astype(np.float64)
            wf = w.reshape(-1).astype(np.float64)
            for i, v in enumerate(vs):
                field = wf @ np.exp(-1j * float(v) * hf)
                acc[i] += abs(complex(field)) ** 2 / sum_w**2
            continue
        n_mom = np.arange(mom.shape[0])
        fact = np.array([1.0 / math.factorial(int(n)) for n in n_mom])
        for i, v in enumerate(vs):
            powers = (-1j * float(v)) ** n_mom * fact
            field = np.exp(-1j * float(v) * centres) @ (powers @ mom)
            acc[i] += abs(complex(field)) ** 2 / sum_w**2
    return [a / t.n_tiles for a in acc]
