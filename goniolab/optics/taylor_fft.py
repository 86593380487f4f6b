"""The first pass of the Kirchhoff model's Taylor-term transforms, in blocks of rows.

A Taylor band of :mod:`goniolab.optics.kirchhoff` transforms the terms
``T_n = W exp(-i v_c h) u^n`` (``u = h / h_max``, ``n = 0..N``) of a tile; both its readings
(:meth:`~goniolab.optics.kirchhoff.KirchhoffModel._raw_power`) and its energy check
(:meth:`~goniolab.optics.kirchhoff.KirchhoffModel._energy_d1`) transform along the tile's
last axis first, over every line, and keep some outputs of each line. Term by term that
wrote a whole tile of complex64 outputs per term and read and rewrote the whole term to
form the next (about 40 MB of memory traffic per term on 1024^2, which two threads share:
issue 26, g16c). :func:`first_pass` forms all the band's terms of a block of rows at once
instead, while the block stays in cache: the block's phase screen, its ``N + 1`` FFTs,
the kept outputs copied out, the term multiplied by ``u`` for the next one
(:data:`_BLOCK_BYTES` says why the blocks are not smaller).

Every output is formed by the same operations on the same values as the whole-tile passes
(pocketfft transforms each line by itself, element-wise operations do not depend on the
array around the element), so the outputs are the same bits
(``tests/optics/test_kirchhoff.py``). The zero-frequency sums are those of the callers: the
lines' zero-frequency outputs (summed by the caller), or the sum of the term's points in
complex128 taken in numpy's own order: numpy sums a contiguous array in chunks of 8192
elements, each by pairwise summation, added one after the other; the chunk sums here are
the same chunks' (:data:`_SUM_CHUNK`) of the whole term, a chunk that straddles two
blocks completed from the next, added in the same order, whatever the tile's width (a
padded receptor's 1000- or 600-wide tiles summed block by block had been 6 units in the
last place off: review of 2026-11-27).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from goniolab.optics import _fft

__all__ = ["block_rows", "first_pass", "g_planes", "weighted_phase"]

#: Elements per chunk of numpy's sum of a contiguous array (its buffer size, 8192).
_SUM_CHUNK: int = 8192
#: Bytes of one block's complex64 term (256 lines of 1024): the block's term and FFT
#: outputs (4 MB) stay in the shared L3 cache, and a band's pass is a few dozen numpy
#: calls per block, not per line. Smaller blocks (32 lines, in a core's L2) were as fast
#: on one thread but slower on two: each call releases and takes back the GIL, and two
#: threads making many short calls hand it over thousands of times a gloss (a futex wake
#: each); on the bench map's gloss (two threads, load 0.3-0.9, 20 runs each, medians)
#: 256 KB blocks 150 ms, 1 MB 143, 2 MB 137, 4 MB 139, whole tiles (8 MB) 156
#: (issue 26, g16c).
_BLOCK_BYTES: int = 1 << 21


def weighted_phase(
    h: NDArray[np.float32],
    w: NDArray[np.float32],
    vc: float,
    out: NDArray[np.complex64] | None = None,
    scratch: tuple[NDArray[np.float32], NDArray[np.float32]] | None = None,
) -> NDArray[np.complex64]:
    """``W exp(-i v_c h)`` in complex64 from float32 cos/sin: the screen each Taylor band
    transforms (:func:`first_pass` forms it so, block by block, into ``out`` with two
    float32 arrays of ``h``'s shape as ``scratch``)."""
    phase, cos = (
        (np.empty(h.shape, np.float32), np.empty(h.shape, np.float32))
        if scratch is None
        else scratch
    )
    term = np.empty(h.shape, dtype=np.complex64) if out is None else out
    np.multiply(np.float32(vc), h, out=phase)
    np.cos(phase, out=cos)
    np.sin(phase, out=phase)
    np.multiply(w, cos, out=term.real)
    np.multiply(w, phase, out=term.imag)
    np.negative(term.imag, out=term.imag)
    return term


def block_rows(nx: int) -> int:
    """Rows per block of :func:`first_pass` for lines of ``nx`` points: about
    :data:`_BLOCK_BYTES` of complex64, a whole number of numpy's sum chunks when ``nx``
    divides :data:`_SUM_CHUNK`."""
    rows = max(1, _BLOCK_BYTES // (8 * max(1, nx)))
    if _SUM_CHUNK % nx == 0:
        chunk = _SUM_CHUNK // nx
        rows = max(chunk, rows - rows % chunk)
    return rows


def first_pass(
    h: NDArray[np.float32],
    w: NDArray[np.float32],
    h_max: float,
    vc: float,
    keep: NDArray[np.intp],
    out: NDArray[np.complex64],
    dc_rows: NDArray[np.complex64] | None = None,
    dc_points: NDArray[np.complex128] | None = None,
) -> None:
    """The FFTs along the last axis of the terms ``T_n = W exp(-i v_c h) (h / h_max)^n``,
    ``n = 0..N`` (``N + 1 = out.shape[0]``), at the outputs ``keep`` of every line:
    ``out[n] = fft(T_n, axis=-1)[:, keep]``.

    ``W exp(-i v_c h)`` is formed in complex64 from float32 cos/sin as
    :func:`weighted_phase` forms it, and ``T_{n+1} = T_n u`` with
    ``u = h / h_max`` (``h`` itself when ``h_max <= 0``) in float32, as the whole-tile
    passes did. ``dc_rows[n]`` (if given) receives each line's zero-frequency output,
    ``dc_points[n]`` the sum of ``T_n``'s points in complex128 (module docstring: numpy's
    order)."""
    ny, nx = h.shape
    n_terms = out.shape[0]
    step = min(block_rows(nx), max(1, ny))
    blk_t = np.empty((step, nx), dtype=np.complex64)
    blk_f = np.empty((step, nx), dtype=np.complex64)
    phase = np.empty((step, nx), dtype=np.float32)
    cos = np.empty((step, nx), dtype=np.float32)
    u = np.empty((step, nx), dtype=np.float32)
    # the kept outputs as runs of consecutive ones (the readings' and the energy check's
    # are one or two: a window that may wrap), copied as slices (np.take along the last
    # axis gathers element by element: 2-3 times slower), or gathered when scattered
    cuts = np.flatnonzero(np.diff(keep) != 1) + 1
    runs = [(int(r[0]), int(r[-1]) + 1) for r in np.split(keep, cuts)] if keep.size else []
    by_runs = len(runs) <= 4
    sums: list[list[complex]] = [[] for _ in range(n_terms)]
    # a chunk straddling two blocks (a width that does not divide the chunk), made when
    # first needed: with 256-line blocks of a power-of-two width none does
    carry: NDArray[np.complex64] | None = None
    carry_n = [0] * n_terms
    for r0 in range(0, ny, step):
        r1 = min(ny, r0 + step)
        m = r1 - r0
        t, f, ph, c, ub = blk_t[:m], blk_f[:m], phase[:m], cos[:m], u[:m]
        hb, wb = h[r0:r1], w[r0:r1]
        weighted_phase(hb, wb, vc, out=t, scratch=(ph, c))
        if h_max > 0:
            np.divide(hb, np.float32(h_max), out=ub)
        else:
            ub[...] = hb
        for n in range(n_terms):
            _fft.fft_into(t, 1, f)
            if by_runs:
                o = 0
                for a0, a1 in runs:
                    out[n, r0:r1, o : o + a1 - a0] = f[:, a0:a1]
                    o += a1 - a0
            else:
                np.take(f, keep, axis=1, out=out[n, r0:r1])
            if dc_rows is not None:
                dc_rows[n, r0:r1] = f[:, 0]
            if dc_points is not None:  # numpy's chunks of the whole term, across blocks
                flat = t.reshape(-1)
                pos, have = 0, carry_n[n]
                if have:
                    assert carry is not None
                    need = min(_SUM_CHUNK - have, flat.size)
                    carry[n, have : have + need] = flat[:need]
                    have += need
                    pos = need
                    if have == _SUM_CHUNK:
                        sums[n].append(complex(np.sum(carry[n], dtype=np.complex128)))
                        have = 0
                full = (flat.size - pos) // _SUM_CHUNK
                if full:
                    part: NDArray[np.complex128] = np.sum(
                        flat[pos : pos + full * _SUM_CHUNK].reshape(full, _SUM_CHUNK),
                        axis=1,
                        dtype=np.complex128,
                    )
                    sums[n].extend(part.tolist())
                    pos += full * _SUM_CHUNK
                if pos < flat.size:
                    if carry is None:
                        carry = np.empty((n_terms, _SUM_CHUNK), dtype=np.complex64)
                    carry[n, : flat.size - pos] = flat[pos:]
                    have = flat.size - pos
                carry_n[n] = have
            if n < n_terms - 1:
                t *= ub
    if dc_points is not None:
        for n in range(n_terms):
            if carry_n[n] and carry is not None:
                sums[n].append(complex(np.sum(carry[n, : carry_n[n]], dtype=np.complex128)))
            acc = 0j
            for s in sums[n]:  # one after the other, as numpy adds its chunks
                acc += s
            dc_points[n] = acc


def g_planes(
    x: NDArray[np.complex64],
    rows: NDArray[np.intp] | None,
    shape: NDArray[np.complex64],
    dc: NDArray[np.complex128],
    a: int,
    b: int,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The real and imaginary planes ``(n_terms, b - a, n_c)`` of
    ``G_n = (x[n][rows[a:b]] - dc_n shape[a:b]) / n!`` (``rows`` None: lines ``a:b``),
    each contiguous: the Taylor terms of a block of the energy check's cells, formed where
    its Horner sums read them (in cache) instead of in a pass of their own over the whole
    window. The products and differences are those of whole arrays (complex64
    ``shape * dc_n``, then float32 differences and the float32 ``1/n!``), the same
    values."""
    n_t = x.shape[0]
    src = x[:, a:b] if rows is None else np.take(x, rows[a:b], axis=1)
    # all the terms in one call each (few numpy calls: each takes the GIL back on two
    # threads), every element by the same operation as term by term
    coh = np.multiply(shape[None, a:b], dc.astype(np.complex64)[:, None, None])
    gr: NDArray[np.float32] = np.subtract(src.real, coh.real)
    gi: NDArray[np.float32] = np.subtract(src.imag, coh.imag)
    if n_t > 1:
        fact, inv = 1.0, []
        for n in range(1, n_t):
            fact *= n
            inv.append(np.float32(1.0 / fact))
        scale = np.array(inv, dtype=np.float32)[:, None, None]
        gr[1:] *= scale
        gi[1:] *= scale
    return gr, gi
