"""Scalar Kirchhoff (tangent-plane) scattering from a height map, by FFT of the phase screen.

The NIST appearance project (seed "nist-appearance-ray-method-and-kirchhoff", section
"The Kirchhoff approximation") computes the BRDF of its epoxy coatings from the measured
topography with Beckmann's Kirchhoff integral, windowed by a smooth Schwartz-type function;
docs/PHYSICS.md ("Where the facet model stops: physical optics") gives the form used here.
For the incident
direction ``wi`` (towards the lamp), an outgoing ``wo``, ``v = k (wi + wo)`` and
``k = 2 pi / lambda``, the scattered field is

.. math:: U(w_o) = \\sum_{x,y} W(x, y)\\, e^{-i (v_x x + v_y y + v_z h(x, y))},

one FFT of the windowed phase screen ``W exp(-i v_z h)`` giving every ``(v_x, v_y)`` of the
grid at once (:mod:`goniolab.optics.physical`). The flux fraction of a cell is

.. math:: P = R(w_i\\cdot\\hat h)\\,|G|^2\\,\\frac{|U|^2}{N\\,\\sum W^2},\\qquad
          |G|^2 = \\frac{|w_i + w_o|^4}{4\\cos\\theta_i\\cos\\theta_o
                  (\\cos\\theta_i + \\cos\\theta_o)^2}
                = F_3^2\\,\\frac{\\cos\\theta_i}{\\cos\\theta_o},

with ``F_3 = (1 + wi.wo)/(cos ti (cos ti + cos to))`` Beckmann's geometric factor
(PHYSICS.md's ``F_geom``) and ``R`` the Fresnel reflectance at the local incidence angle of
the stationary-phase facet (half vector ``h``). The normalisation is the discrete Parseval
identity: a flat map puts ``sum P = R(ti)`` into the few cells of the window's transform
around specular (``G = 1`` there), the exact Fresnel mirror. The factor ``cos ti / cos to``
turns Beckmann's intensity ratio into a BRDF; with it the Kirchhoff BRDF tends, for
``Sq >> lambda``, to the facet BRDF ``R P22 / (4 cos ti cos to cos^4 theta_h)`` exactly
(stationary phase: ``|U|^2 -> 4 pi^2 P22 / v_z^2`` per unit area).

The screen depends on ``v_z = k (cos ti + cos to)``, different for every direction. It is
expanded about band centres ``v_c``:
``exp(-i v_z h) = exp(-i v_c h) sum_n (-i (v_z - v_c) h)^n / n!``; one FFT per term and band
serves every cell (and every wavelength: ``(v_x, v_y, v_z)`` fix the cell's value, lambda
only moves which directions the cells are). Each FFT forms only the outputs the
requested cells read (the first pass over the whole tile along one axis, the second only
on the rows or columns kept), and a band's terms are summed per cell by Horner's scheme. The bands and orders are chosen so that
``(|v_z - v_c| h_max)^(N+1)/(N+1)! <= tol`` (default 1e-4, a bound on the per-pixel phase
factor) at the fewest FFTs (:func:`band_plan`). Heights are float32 and tiles of at most
``tile`` points (:mod:`goniolab.optics.psd`), levelled from the map block by block, so the
transforms' memory is bounded by the tile whatever the map size: a traced peak of about 8
float32 tiles (32 MB for 1024 x 1024; ``tests/optics/test_kirchhoff.py`` checks it does
not grow with the map). What grows with the map is the map itself (not copied; a float32
``.npy`` stays float32) and nothing else: the facet model a geometry falls back to forms its
slopes from the map block by block (:class:`goniolab.optics.surface.MapSurface`); an
8192 x 8192 float32 map predicts within 2.1 x its size (``bench/bench_memory.py``,
bench/README.md).

Coherent and diffuse parts: the coherent specular reflectance is
``R(ti) |sum W exp(-i v_z h)|^2 / (sum W)^2`` (:meth:`KirchhoffModel.specular_reflectance`),
which is ``R exp(-(4 pi Sq cos ti / lambda)^2)`` for Gaussian heights (the Debye-Waller /
TIS relation); the diffuse part is the rest of ``P``.

Limits: PHYSICS.md's Gaussian-ACF series is the test truth for the diffuse part; the map
resolves directions within ``lambda/(2 step)`` of specular in direction cosines, and a
receptor narrower than a few cells ``lambda / field`` is read on a zero-padded grid
(PHYSICS.md, "No silent fallback"). The phase screen is only meaningful when neighbouring
pixels differ in phase by less than pi, ``v_z * slope * step < pi``: a map that does not
sample it hands the geometry over, stated (:meth:`KirchhoffModel._validity`). The diffuse
part carries Smith's G2 as the geometric limit needs it and, from 70 deg, scalar energy
conservation over the hemisphere (PHYSICS.md, "Energy").

References
----------
.. [1] NIST appearance project, "Ray method and Kirchhoff approximation" (seed text),
   section "The Kirchhoff approximation" (window, map spline-sampled about ten points per
   wavelength, normalisation to the flat specular).
.. [2] P. Beckmann, A. Spizzichino, "The Scattering of Electromagnetic Waves from Rough
   Surfaces", Pergamon 1963, ch. 3 and 5 (F_3, Gaussian-surface series).
.. [3] J. E. Harvey, "Light-scattering characteristics of optical surfaces", PhD thesis,
   1976 (direction-cosine form).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.optics import _cell_kernels as CK
from goniolab.optics import _fft
from goniolab.optics.cell_apertures import CellBox
from goniolab.optics.energy_budget import NonFiniteEnergySums
from goniolab.optics.fresnel import fresnel
from goniolab.optics.kirchhoff_coherent import coherent_direct
from goniolab.optics.physical import (
    ENERGY_CHECK_FROM_DEG,
    FACET_MIN_HANDOVER_G,
    MAX_PHASE_STEP_RAD,
    RR_VALID_SDQ,
    FloatArray,
    PhysicalOpticsModel,
    check_theta_i,
)
from goniolab.optics.psd import pruned_terms, y_axis_first
from goniolab.optics.taylor_fft import first_pass, g_planes
from goniolab.optics.wave_tasks import row_parts, run_reporting

__all__ = ["DEFAULT_TAYLOR_TOL", "KirchhoffModel", "band_plan"]

#: Bound on the truncated Taylor remainder of the phase factor, per pixel.
DEFAULT_TAYLOR_TOL: float = 1e-4
_BAND_X: tuple[float, ...] = (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)
#: Cells per block of the energy check's Horner sums (all wavelengths together) and of its
#: per-cell weights: the block's arrays stay in cache. 65536 rather than 32768 (issue 26,
#: g16c): as fast on one thread, and half the numpy calls, each of which takes the GIL
#: back, on two (bench map gloss, 30 runs each at load 0.9-1.05: 124.8 ms median
#: against 128.8 with 32768).
_HORNER_BLOCK: int = 65536
#: Parts of rows per wavelength the energy check's per-cell weights are formed in (tasks:
#: fine enough that a thread joining late finds some left).
_PARTS: int = 4
#: At most this many directions' G2 kept for the map (:meth:`KirchhoffModel._diffuse_g2`),
#: and at most this many sets of them.
_G2_MEMO_DIRS: int = 4
_G2_MEMO_SIZE: int = 64
#: ``D_1`` at or below this is the float32 transforms' rounding, not diffuse light (a flat
#: map's ``D_1`` is 1e-14 to 1e-13; a coat of Sq 0.1 nm has about 3e-9: review of 2026-11-26).
_D1_FLOOR: float = 1e-10


def band_plan(
    v_lo: float, v_hi: float, h_max_um: float, tol: float = DEFAULT_TAYLOR_TOL
) -> list[tuple[float, float, float, int]]:
    """Bands ``(lo, hi, centre, order)`` of ``v_z`` (1/um) covering ``[v_lo, v_hi]``.

    Each band of half-width ``d`` uses Taylor order N with ``(d h_max)^(N+1)/(N+1)! <= tol``;
    the band width is picked among a few multiples of ``1/h_max`` for the fewest FFTs
    (bands x (N + 1)).
    """
    span = max(float(v_hi) - float(v_lo), 0.0)
    if h_max_um <= 0.0 or span == 0.0:
        c = 0.5 * (v_lo + v_hi)
        order = 0
        x = 0.5 * span * h_max_um
        while x ** (order + 1) / math.factorial(order + 1) > tol:
            order += 1
        return [(v_lo, v_hi, c, order)]
    best: tuple[int, int, int] | None = None
    for x in _BAND_X:
        nb = max(1, math.ceil(span * h_max_um / (2.0 * x)))
        xa = span * h_max_um / (2.0 * nb)
        order = 0
        while xa ** (order + 1) / math.factorial(order + 1) > tol:
            order += 1
        cost = nb * (order + 1)
        if best is None or cost < best[0]:
            best = (cost, nb, order)
    assert best is not None
    _, nb, order = best
    edges = np.linspace(v_lo, v_hi, nb + 1)
    return [
        (float(edges[b]), float(edges[b + 1]), float(0.5 * (edges[b] + edges[b + 1])), order)
        for b in range(nb)
    ]


class KirchhoffModel(PhysicalOpticsModel):
    """Scalar Kirchhoff model of a height map (module docstring; parameters as
    :class:`~goniolab.optics.physical.PhysicalOpticsModel`).

    Example (API for spectral code)::

        base = KirchhoffModel(hm, n=1.5, wavelength_nm=550)
        for lam, n in zip(lams, indices):
            r = base.with_optics(n=n, wavelength_nm=lam).luminance_pct(45, [45])
    """

    kind = "kirchhoff"
    taylor_tol: float = DEFAULT_TAYLOR_TOL

    def _raw_power(
        self,
        theta_i_deg: float,
        lams_um: Sequence[float],
        boxes: Sequence[CellBox],
        geo: Sequence[tuple[FloatArray, NDArray[np.bool_]]],
        os: tuple[int, int] = (1, 1),
    ) -> tuple[list[FloatArray], list[float]]:
        """Diffuse ``sum_tiles |U_d|^2 / (n_tiles N sum W^2 os_x os_y)`` per cell (0 for
        evanescent cells) and the coherent factor ``mean_tiles |sum W e^(-i v_z h)|^2 /
        (sum W)^2`` at the specular ``v_z = 2 k cos ti``, per wavelength; ``geo`` holds each
        box's ``(z, ok)`` (:meth:`_geometry`), ``os`` the zero padding of the grid.

        ``U_d`` is the field minus the tile's mean field times the window's transform: the
        coherent beam is a delta in the specular direction (the lit spot is far larger than
        the map), kept out of the cells it would smear over and summed analytically
        (:func:`goniolab.optics.coherent_beam.coherent_sums`).

        Only the transform outputs the boxes read are formed: each Taylor term is transformed
        along the axis needing fewer outputs first (over the whole tile, contiguous), those
        outputs kept, then along the other axis (``psd.pruned_terms``: all of a band's terms
        at once, the first pass in blocks of lines; zero-padded to ``os`` times the tile
        when the receptor needs a finer grid); a band's terms are then
        summed per cell by Horner's scheme in one pass per wavelength
        (:func:`goniolab.optics._cell_kernels.kirchhoff_band_numba`; with numpy, four
        wavelengths' boxes at a time, :func:`~goniolab.optics._cell_kernels.kirchhoff_bands_numpy`).
        """
        sh = self._shared
        t = sh.tiled
        if sh.h_max_um == 0.0:
            # a flat map (levelled to exactly 0): each tile's screen is the window itself and
            # its field the coherent beam alone, so no cell holds diffuse light and C = 1,
            # exactly (the transforms gave their float32 rounding, some 1e-14 of the beam,
            # over every cell, which a split source's 169 sub-cones then summed for seconds)
            if self.progress is not None:
                self.progress(1, 1, "kirchhoff FFT")
            zeros = [np.zeros((b.iy1 - b.iy0 + 1, b.ix1 - b.ix0 + 1)) for b in boxes]
            return zeros, [1.0 for _ in boxes]
        cz_i = math.cos(math.radians(theta_i_deg))
        vzs = [(2.0 * math.pi / lam) * (cz_i + z) for lam, (z, _) in zip(lams_um, geo, strict=True)]
        v_spec = [(2.0 * math.pi / lam) * 2.0 * cz_i for lam in lams_um]
        v_all_lo, v_all_hi = min(v_spec), max(v_spec)
        for vz, (_, ok) in zip(vzs, geo, strict=True):
            if np.any(ok):
                v_all_lo = min(v_all_lo, float(vz[ok].min()))
                v_all_hi = max(v_all_hi, float(vz[ok].max()))
        acc = [np.zeros((b.iy1 - b.iy0 + 1, b.ix1 - b.ix0 + 1)) for b in boxes]
        coh_acc = [0.0 for _ in boxes]
        h_max = sh.h_max_um
        plan = band_plan(v_all_lo, v_all_hi, h_max, self.taylor_tol)
        total = t.n_tiles * sum(order + 1 for *_, order in plan)
        last = len(plan) - 1

        def owns(b: int, v: Any) -> Any:
            lo, hi = plan[b][0], plan[b][1]
            return (v >= lo) & ((v <= hi) if b == last else (v < hi))

        # the bands that own some cell or specular direction (the others cost no FFT)
        active = [
            b
            for b in range(len(plan))
            if any(np.any(ok & owns(b, vz)) for vz, (_, ok) in zip(vzs, geo, strict=True))
            or any(bool(owns(b, v)) for v in v_spec)
        ]
        # the region of the (padded) grid the boxes read (signed indices)
        ly, lx = os[1] * t.ny_t, os[0] * t.nx_t
        y0, y1 = min(b.iy0 for b in boxes), max(b.iy1 for b in boxes)
        x0, x1 = min(b.ix0 for b in boxes), max(b.ix1 for b in boxes)
        ky = np.arange(y0, y1 + 1, dtype=np.int64) % ly
        kx = np.arange(x0, x1 + 1, dtype=np.int64) % lx
        # the window's own transform (separable), normalised at DC: the coherent field's
        # shape per cell
        wy_hat = np.fft.fft(t.wy.astype(np.float64), n=ly)
        wx_hat = np.fft.fft(t.wx.astype(np.float64), n=lx)
        wy_shape = wy_hat[ky] / wy_hat[0]
        wx_shape = wx_hat[kx] / wx_hat[0]
        per_box = [(b.iy - y0, b.ix - x0, wy_shape[b.iy - y0], wx_shape[b.ix - x0]) for b in boxes]
        sum_w = float(np.sum(t.wy, dtype=np.float64) * np.sum(t.wx, dtype=np.float64))
        lengths = None if os == (1, 1) else (ly, lx)
        y_first = y_axis_first(ly // os[1], lx // os[0], ky.size, kx.size, lengths)
        done = 0
        for k in range(t.n_tiles):
            h, w = t.tile(k)
            if y_first:  # the first (full) pass runs along the contiguous axis
                h, w = t.tile_transposed(k), t.window_transposed
            coh = [0j for _ in boxes]
            for b, (lo, hi, vc, order) in enumerate(plan):
                done += order + 1  # (a band without cells too: the display must reach 100 %)
                if b not in active:
                    if self.progress is not None:
                        self.progress(done, total, "kirchhoff FFT")
                    continue
                spec = np.empty((order + 1, ky.size, kx.size), dtype=np.complex64)
                dc = pruned_terms(h, w, h_max, vc, ky, kx, y_first, spec, lengths)
                if self.progress is not None:
                    self.progress(done, total, "kirchhoff FFT")
                if self.backend != "numba":  # the boxes a few at once (same values)
                    CK.kirchhoff_bands_numpy(
                        spec, dc, [(r, c) for r, c, _, _ in per_box], vzs, [g[1] for g in geo],
                        lo, hi, b == last, vc, h_max, wy_shape, wx_shape, acc,
                    )  # fmt: skip
                for li, ((rows, cols, w_r, w_c), vz, (_, ok)) in enumerate(
                    zip(per_box, vzs, geo, strict=True)
                ):
                    if self.backend == "numba":
                        CK.kirchhoff_band_numba(
                            spec, dc, rows, cols, vz, ok, lo, hi, b == last, vc, h_max, w_r,
                            w_c, acc[li],
                        )  # fmt: skip
                    if owns(b, v_spec[li]):
                        step = -1j * (v_spec[li] - vc) * h_max
                        e, c = 0j, 1.0 + 0j
                        for n_term in range(order + 1):
                            if n_term:
                                c *= step / n_term
                            e += complex(dc[n_term]) * c
                        coh[li] += e
            for li in range(len(boxes)):
                coh_acc[li] += abs(coh[li]) ** 2 / sum_w**2
        norm = t.n_tiles * t.ny_t * t.nx_t * t.sum_w2 * os[0] * os[1]
        diffuse = [np.where(g[1], a / norm, 0.0) for a, g in zip(acc, geo, strict=True)]
        return diffuse, [c / t.n_tiles for c in coh_acc]

    def _cell_powers(
        self,
        theta_i_deg: float,
        lams_um: Sequence[float],
        boxes: Sequence[CellBox],
        os: tuple[int, int] = (1, 1),
    ) -> tuple[list[FloatArray], list[float]]:
        key = (
            "kirchhoff",
            round(theta_i_deg, 9),
            tuple(round(v, 12) for v in lams_um),
            tuple((b.ix0, b.ix1, b.iy0, b.iy1) for b in boxes),
            os,
        )
        geo = [
            self._geometry(theta_i_deg, lam, box, os)
            for lam, box in zip(lams_um, boxes, strict=True)
        ]

        def readings() -> tuple[list[FloatArray], list[float], list[tuple[Any, Any]]]:
            raw: list[FloatArray]
            coh: list[float]
            raw, coh = self._shared.cached(
                key,
                lambda: self._raw_power(
                    theta_i_deg, lams_um, boxes, [(g[2], g[3]) for g in geo], os
                ),
            )
            # each cell's obliquity and Fresnel factors here, beside the energy check,
            # so that only their product with the scale is left when it ends
            factors = [
                (
                    self._obliquity(theta_i_deg, x, y, z, ok),
                    self._fresnel_geom(theta_i_deg, x, y, z, ok),
                )
                for x, y, z, ok in geo
            ]
            return raw, coh, factors

        def scales_of() -> list[float]:
            return self._energy_scales(theta_i_deg, lams_um)

        if theta_i_deg >= ENERGY_CHECK_FROM_DEG:
            # the readings and the energy check are independent until the scale is
            # applied: two tasks (two threads when the load leaves a core free), the
            # energy check first (the longer)
            got: list[Any] = run_reporting([scales_of, readings], self.progress)
            scales, (raw, coh, factors) = got
        else:
            (raw, coh, factors), scales = readings(), scales_of()
        out = [s * r * geom * fg for r, (geom, fg), s in zip(raw, factors, scales, strict=True)]
        return out, list(coh)

    @staticmethod
    def _obliquity(
        theta_i_deg: float, x: FloatArray, y: FloatArray, z: FloatArray, ok: NDArray[np.bool_]
    ) -> FloatArray:
        """``|G|^2 = |wi + wo|^4 / (4 cos ti cos to (cos ti + cos to)^2)`` per cell."""
        t = math.radians(theta_i_deg)
        ci = math.cos(t)
        s2 = (x + math.sin(t)) ** 2 + y * y + (z + ci) ** 2
        co = np.where(ok, z, 1.0)
        out: FloatArray = np.where(ok, s2 * s2 / (4.0 * ci * co * (ci + co) ** 2), 0.0)
        return out

    def _energy_scales_at(self, theta_i_deg: float, lams_um: Sequence[float]) -> list[float]:
        """Scalar energy conservation of the diffuse part, from
        :data:`~goniolab.optics.energy_budget.ENERGY_CHECK_FROM_DEG` on.

        With a perfect reflector (``R = 1``) the scalar Kirchhoff diffuse flux over the
        hemisphere, ``D_1 = sum_cells |G|^2 |U_d|^2 / norm`` (with the diffuse shadowing),
        cannot exceed what the coherent beam leaves, ``1 - C``. Beckmann's obliquity factor
        ``|G|^2`` grows as ``1 / cos ti`` out of the plane of incidence towards grazing, and
        unchecked the model's albedo reached 1.1-1.7 times Fresnel at 85-89 deg on smooth
        metals; the diffuse cells are scaled by ``min(1, (1 - C) / D_1)``, computed over the
        whole Nyquist window once per incidence and wavelength set (cached,
        :meth:`PhysicalOpticsModel._energy_scales`; the sums: :meth:`_energy_sums`).

        ``D_1`` is summed over every cell of the window. (A sum over every second cell
        times 4 was tried for speed and taken out: the specular cell, whose diffuse power is
        0 once the coherent beam is taken out, is always one of the sampled cells, and on
        wavy maps nearly all of the diffuse power lies in the few cells around it, so the
        strided sum ran 15-56 % low at 86-89 deg and let that much more diffuse light
        through; ``tests/optics/test_kirchhoff.py``'s wavy-map test holds the factor.)"""
        coh, d1 = self._energy_sums(theta_i_deg, lams_um)
        if not all(math.isfinite(v) for v in (*coh, *d1)):  # never a silent factor of 1
            raise NonFiniteEnergySums(
                f"kirchhoff energy check at {theta_i_deg:g} deg: C = {coh}, D_1 = {d1}"
            )
        # D_1 at or below the float32 transforms' rounding (a flat map: 1e-14 to 1e-13)
        # is no diffuse light: nothing to scale (the ratio of two roundings is no factor)
        return [
            min(1.0, max(0.0, 1.0 - c) / d) if d > _D1_FLOOR else 1.0
            for c, d in zip(coh, d1, strict=True)
        ]

    def _energy_sums(
        self, theta_i_deg: float, lams_um: Sequence[float]
    ) -> tuple[list[float], list[float]]:
        """The coherent factor ``C`` and the diffuse sum ``D_1`` over every cell of the
        Nyquist window (:meth:`_energy_scales_at`), per wavelength.

        The sum as :meth:`_raw_power` forms a box's cells (the same Taylor bands of the
        phase screen, :func:`band_plan`; the coherent field taken out), arranged for a
        window that is the whole transform grid; ``C`` is summed over the map's points
        (:meth:`_coherent_direct`), not from the bands:

        - the transform outputs stay in the FFT's own order (the cells' directions are
          formed in that order instead: no reordering or transposed copy of a 1024^2
          complex tile per Taylor term);
        - the columns evanescent at every wavelength (``|wo_x| >= 1``, about half the
          window from 70 deg on) are not transformed along y, and rows likewise;
        - the terms' x passes run over blocks of rows, all the band's terms of a block
          at once (:func:`goniolab.optics.taylor_fft.first_pass`), their y passes in
          place on the kept columns;
        - the coherent field ``dc_n w`` is taken out of each term's transform (and
          ``1/n!`` put in) once, not per wavelength after the Horner sums, so one real
          Horner step is 4 float32 operations per cell, run over all wavelengths together
          in blocks of rows that stay in cache (:meth:`_energy_horner`);
        - ``dc_n`` is the term's sum in complex128 (not the float32 transform's row sums);
        - the obliquity and Smith's G2 in blocks of rows too (large temporaries cost more
          than the arithmetic), ``Lambda(wi)`` one value, not one per cell.

        ``D_1`` equals the box form's every-cell sum to float32 rounding (the transforms
        run x first instead of y first), a few 1e-7 (``tests/optics/test_kirchhoff.py``,
        at 70/85/89 deg on smooth, wavy and rough coats, with the box form kept there as
        the reference, and against the Kirchhoff sum formed directly over the map); ``C``
        equals the direct complex128 mean within 1e-13. ``1 - C`` is small towards
        grazing (5e-5 to 1e-4 at 89 deg on smooth and wavy coats) and amplifies any error
        of ``C``: the band sum's ``C`` (a Taylor remainder of up to ``taylor_tol`` per
        point, and float32) was 1e-8 to 2e-7 off, the factor up to 0.4 %."""
        c_i = math.cos(math.radians(theta_i_deg))
        v_spec = [(2.0 * math.pi / lam) * 2.0 * c_i for lam in lams_um]
        # C and D_1 are independent: two tasks (:func:`run_reporting`)
        d1, coh = run_reporting(
            [lambda: self._energy_d1(theta_i_deg, lams_um), lambda: self._coherent_direct(v_spec)]
        )
        return coh, d1

    def _energy_d1(self, theta_i_deg: float, lams_um: Sequence[float]) -> list[float]:
        """``D_1`` per wavelength (:meth:`_energy_sums`). The Horner sums and the per-cell
        weights run as tasks on blocks of rows in parts (:func:`row_parts`; two
        threads when the load leaves a core free): every cell is formed by the same
        operations on either thread and the sums over cells are taken in this thread, so
        ``D_1`` is the same bits on one thread or two (``tests/optics/test_kirchhoff.py``)."""
        sh = self._shared
        t = sh.tiled
        ny, nx = t.ny_t, t.nx_t
        tr = math.radians(theta_i_deg)
        s_i, c_i = math.sin(tr), math.cos(tr)
        # the Nyquist window is the whole transform grid: each output's signed frequency
        # in the transform's own order (0, 1, ..., -2, -1; no reordering of the outputs)
        _, nx1, _, ny1 = self._nyquist()
        fx = np.arange(nx, dtype=np.float64)
        fx[fx > nx1] -= nx
        fy = np.arange(ny, dtype=np.float64)
        fy[fy > ny1] -= ny
        # per wavelength 1 - wo_x^2 of the columns and wo_y^2 of the rows; a column (row)
        # holds a real direction (1 - x^2 - y^2 > 1e-12) at some wavelength or is not
        # transformed at all (the row through specular has y = 0)
        one_x2, y2 = [], []
        col_any = np.zeros(nx, dtype=bool)
        row_any = np.zeros(ny, dtype=bool)
        for lam in lams_um:
            cx, cy = self._cell_size(lam)
            ox = 1.0 - (fx * cx - s_i) ** 2
            oy = (fy * cy) ** 2
            col_any |= ox > 1e-12
            row_any |= float(ox.max()) - oy > 1e-12
            one_x2.append(ox)
            y2.append(oy)
        cols = np.flatnonzero(col_any)
        rows = np.flatnonzero(row_any)
        n_l, n_r, n_c = len(lams_um), rows.size, cols.size
        ok = np.empty((n_l, n_r, n_c), dtype=bool)
        z = np.zeros((n_l, n_r, n_c))  # 0 on the evanescent cells
        z2 = np.empty((n_r, n_c))
        for li in range(n_l):
            np.subtract(one_x2[li][cols][None, :], y2[li][rows][:, None], out=z2)
            np.greater(z2, 1e-12, out=ok[li])
            np.sqrt(z2, out=z[li], where=ok[li])
        del z2
        # v_z = k (z + cos ti) per cell, formed where it is read (the Horner sums) rather
        # than stored: its extremes over the real cells are those of z, as rounding is
        # monotonic (fl(fl(z + c) k) never decreases with z), the same values as a pass
        # over a stored v_z
        kz = np.array([2.0 * math.pi / lam for lam in lams_um])[:, None, None]
        v_spec = [(2.0 * math.pi / lam) * 2.0 * c_i for lam in lams_um]
        v_lo, v_hi = min(v_spec), max(v_spec)
        for li in range(n_l):
            if np.any(ok[li]):  # z is 0 on the others (max) and excluded from the min
                z_lo = float(np.min(z[li], where=ok[li], initial=np.inf))
                z_hi = float(np.max(z[li]))
                k_li = float(kz[li, 0, 0])
                v_lo = min(v_lo, (z_lo + c_i) * k_li)
                v_hi = max(v_hi, (z_hi + c_i) * k_li)
        h_max = sh.h_max_um
        plan = band_plan(v_lo, v_hi, h_max, self.taylor_tol)
        last = len(plan) - 1
        # the window's transform normalised at DC at the kept outputs (separable): the
        # coherent field's shape, taken out of each Taylor term's transform
        wy_hat = np.fft.fft(t.wy.astype(np.float64))
        wx_hat = np.fft.fft(t.wx.astype(np.float64))
        w_shape = np.multiply.outer(wy_hat[rows] / wy_hat[0], wx_hat[cols] / wx_hat[0])
        w_shape = w_shape.astype(np.complex64)
        acc = np.zeros((n_l, n_r, n_c))
        # per band: the cells it owns and the rows and columns holding them (a band owning
        # none costs no transform); one band owns every real cell (its edges are the
        # extremes of v_z over them)
        owners: list[tuple[NDArray[np.bool_] | None, NDArray[np.intp], NDArray[np.intp]]] = []
        if len(plan) == 1:
            owners.append(
                (None, np.flatnonzero(ok.any(axis=(0, 2))), np.flatnonzero(ok.any(axis=(0, 1))))
            )
        else:
            vz = z + c_i
            vz *= kz
            for b, (lo, hi, _, _) in enumerate(plan):
                mask = ok & (vz >= lo) & ((vz <= hi) if b == last else (vz < hi))
                rr = np.flatnonzero(mask.any(axis=(0, 2)))
                cc = np.flatnonzero(mask.any(axis=(0, 1)))
                owners.append((mask, rr, cc))
            del vz
        total = t.n_tiles * sum(order + 1 for *_, order in plan)
        done = 0
        keep_rows = None if n_r == ny else rows
        for k in range(t.n_tiles):
            h, w = t.tile(k)
            for (_, _, vc, order), (own, rr, cc) in zip(plan, owners, strict=True):
                if rr.size == 0:
                    done += order + 1  # reported too: the display must reach 100 %
                    if self.progress is not None:
                        self.progress(done, total, "kirchhoff energy check")
                    continue
                # F_n, the transform of the term W exp(-i v_c h) u^n at the kept outputs:
                # the x pass of all the terms over blocks of rows (taylor_fft.first_pass),
                # then the y pass of each on the kept columns, in place; G_n = (F_n -
                # dc_n w_shape) / n! is formed block by block where the Horner sums read it
                spec = np.empty((order + 1, ny, n_c), dtype=np.complex64)
                dc = np.empty(order + 1, dtype=np.complex128)
                first_pass(h, w, h_max, vc, cols, spec, dc_points=dc)
                for n in range(order + 1):
                    _fft.fft_into(spec[n], 0, spec[n])
                    done += 1
                    if self.progress is not None:
                        self.progress(done, total, "kirchhoff energy check")
                r0, r1, c0, c1 = int(rr[0]), int(rr[-1]) + 1, int(cc[0]), int(cc[-1]) + 1
                h_step = max(1, _HORNER_BLOCK // max(1, n_l * (c1 - c0)))
                run_reporting(
                    [
                        functools.partial(
                            self._energy_horner, spec[:, :, c0:c1], keep_rows,
                            w_shape[:, c0:c1], dc, z[:, :, c0:c1], kz, c_i, vc, h_max, a, b,
                            None if own is None else own[:, :, c0:c1], acc[:, :, c0:c1],
                        )
                        for a, b in row_parts(r0, r1, h_step)
                    ]
                )  # fmt: skip
                del spec
        norm = t.n_tiles * ny * nx * t.sum_w2
        wi = np.array([[s_i, 0.0, c_i]])  # Lambda(wi): one value for all cells
        # the per-cell weights in blocks of rows (large temporaries cost more than the
        # arithmetic: the obliquity and G2 of 1.4 M cells took 3-5 times longer unblocked)
        step = max(1, _HORNER_BLOCK // max(1, n_c))
        parts = row_parts(0, n_r, step, _PARTS)
        wo_xy = []
        for lam in lams_um:
            cx, cy = self._cell_size(lam)
            wo_xy.append((fx[cols] * cx - s_i, fy[rows] * cy))
        # each cell's share of D_1, |G|^2 |U_d|^2 / norm, written over its |U_d|^2 in acc
        contrib = acc

        def weights(li: int, a: int, b: int) -> None:
            wox = wo_xy[li][0]
            # the obliquity |G|^2 (:meth:`_obliquity`) with |wo| = 1 used:
            # |wi + wo|^2 = 2 (1 + wi.wo), so |G|^2 = (1 + wi.wo)^2 / (ci co (ci + co)^2),
            # wi.wo = s_i wo_x + c_i co (one column term and one cell term; 8 operations
            # per cell instead of 15, the same values to ~1e-16)
            one_wx = 1.0 + s_i * wox
            num = np.empty((min(step, b - a), n_c))
            den = np.empty_like(num)
            for r0 in range(a, b, step):
                r1 = min(b, r0 + step)
                zb, nb, db = z[li, r0:r1], num[: r1 - r0], den[: r1 - r0]
                np.multiply(zb, c_i, out=nb)
                nb += one_wx[None, :]
                nb *= nb
                np.add(zb, c_i, out=db)
                db *= db
                db *= zb
                db *= c_i
                okb, cb = ok[li, r0:r1], contrib[li, r0:r1]
                np.divide(nb, db, out=nb, where=okb)
                cb *= nb
                cb /= norm
                np.copyto(cb, 0.0, where=~okb)  # the evanescent cells carry nothing

        def shadowing(li: int, a: int, b: int, floor: float) -> None:
            wox, woy = wo_xy[li]
            for r0 in range(a, b, step):
                r1 = min(b, r0 + step)
                blk = contrib[li, r0:r1]
                big = blk > floor
                n_big = int(np.count_nonzero(big))
                if n_big == 0:
                    continue
                # (3, cells) transposed: each component contiguous for the ufuncs
                wo = np.empty((3, n_big))
                wo[0] = np.broadcast_to(wox[None, :], big.shape)[big]
                wo[1] = np.broadcast_to(woy[r0:r1, None], big.shape)[big]
                wo[2] = z[li, r0:r1][big]
                blk[big] *= self._diffuse_g2(wi, wo.T, lams_um[li])

        cells = [(li, a, b) for li in range(n_l) for a, b in parts]
        run_reporting([functools.partial(weights, *c) for c in cells])
        if self.masking:
            # the shadowing of the cells that carry the flux (>= 1e-6 of the largest);
            # the others count unshadowed (an upper bound on D_1)
            floors = [1e-6 * float(contrib[li].max(initial=0.0)) for li in range(n_l)]
            run_reporting([functools.partial(shadowing, *c, floors[c[0]]) for c in cells])
        return [float(np.sum(contrib[li])) for li in range(n_l)]

    def _coherent_direct(self, vs: Sequence[float]) -> list[float]:
        """The coherent factor ``C`` at each ``v`` (1/um), summed over the map's points in
        float64, not from the Taylor bands
        (:func:`goniolab.optics.kirchhoff_coherent.coherent_direct`)."""
        return coherent_direct(self._shared, vs)

    @staticmethod
    def _energy_horner(
        spec: NDArray[np.complex64],
        rows: NDArray[np.intp] | None,
        w_shape: NDArray[np.complex64],
        dc: NDArray[np.complex128],
        z: FloatArray,
        kz: FloatArray,
        c_i: float,
        vc: float,
        h_max: float,
        r0: int,
        r1: int,
        own: NDArray[np.bool_] | None,
        acc: FloatArray,
    ) -> None:
        """``acc += |sum_n G_n (-i x)^n|^2`` (``x = (v_z - v_c) h_max``, ``v_z = k (z +
        cos ti)`` with ``k`` = ``kz`` per wavelength, per wavelength and cell; ``G_n =
        (spec[n] - dc_n w_shape) / n!`` at the kept ``rows`` (None: all), shared by the
        wavelengths and formed per block, :func:`~goniolab.optics.taylor_fft.g_planes`)
        over rows ``r0:r1``, by
        Horner's scheme in float32 (``x`` formed in float64, then rounded; the ``G_n`` are
        float32 transforms already), in blocks of rows small enough to stay in cache; only
        where ``own`` (the band's cells) when given; ``acc`` is float64.

        float32 instead of float64 (energy16b, issue 26): 16 instead of 22-26 ms per check
        on the 1024^2 bench map; ``D_1`` moved by at most 1.4e-9 relative on smooth and
        rough coats and 9e-8 on a wavy one (70/85/89 deg, 400/550/700 nm), below the
        float32 transforms' own rounding of ``D_1`` (a few 1e-7;
        ``tests/optics/test_kirchhoff.py`` holds both). The ``G_n`` as contiguous real
        and imaginary planes (issue 26, g16): 8 instead of 16 ms, the same values; formed
        per block in cache rather than in a pass of their own over the window (g16c)."""
        n_terms, _, n_c = spec.shape
        n_l = z.shape[0]
        step = max(1, _HORNER_BLOCK // max(1, n_l * n_c))
        for a in range(r0, r1, step):
            b = min(r1, a + step)
            x64 = z[:, a:b] + c_i
            x64 *= kz
            x64 -= vc
            x64 *= h_max
            if own is not None:
                # cells of the block outside the band (evanescent or another band's) are
                # multiplied by 0 below: their x, up to (v_hi - v_lo) h_max, must not
                # overflow float32 in x^order (inf * 0 = NaN in acc)
                x64 *= own[:, a:b]
            x = x64.astype(np.float32)
            spec_r, spec_i = g_planes(spec, rows, w_shape, dc, a, b)
            fr = np.empty(x.shape, dtype=np.float32)
            fi = np.empty(x.shape, dtype=np.float32)
            fr[...] = spec_r[n_terms - 1]
            fi[...] = spec_i[n_terms - 1]
            t1 = np.empty(x.shape, dtype=np.float32)
            t2 = np.empty(x.shape, dtype=np.float32)
            for n in range(n_terms - 2, -1, -1):
                # f <- G_n + (-i x) f
                np.multiply(x, fi, out=t1)
                t1 += spec_r[n]
                np.multiply(x, fr, out=t2)
                np.subtract(spec_i[n], t2, out=t2)
                fr, t1 = t1, fr
                fi, t2 = t2, fi
            fr *= fr
            fi *= fi
            fr += fi
            if own is not None:
                fr *= own[:, a:b]
            acc[:, a:b] += fr

    # ------------------------------------------------------------------ shadowing, validity
    def _diffuse_g2(self, wi: FloatArray, wo: FloatArray, lam_um: float) -> FloatArray | float:
        """Smith's G2 of the map's slopes, weighed in as the geometric limit needs it:
        ``G2^(1 - exp(-g_d))`` with ``g_d = (k Sq (cos ti + cos to))^2`` the Rayleigh factor
        of the direction. Where the roughness is small against the wavelength (g_d -> 0)
        light does not see the slopes as shadowing facets and nothing is removed (as in
        Rayleigh-Rice, which ``auto`` uses there); where it is large (the facet limit,
        ``g_d`` >> 1) this is the facet model's G2. With ``masking=False``: 1.

        ``G2`` itself does not depend on the wavelength: for a few directions (a gloss's
        detector, asked once per wavelength) it is kept for the map and read again (the
        same values; 2 of its 96 Smith Lambda calls on one- or two-element arrays per
        16-wavelength gloss were each a few dozen numpy calls holding the GIL: issue 26,
        g16c)."""
        if not self.masking:
            return 1.0
        sq = self._shared.stats.sq_um
        k = 2.0 * math.pi / lam_um
        gd = (k * sq * (wi[..., 2] + np.clip(wo[..., 2], 0.0, None))) ** 2
        if np.size(wo) <= 3 * _G2_MEMO_DIRS:
            wi_a, wo_a = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
            key = (wi_a.shape, wi_a.tobytes(), wo_a.shape, wo_a.tobytes())
            # one entry of the map's shared cache for them all (dropped with the cache)
            memo: dict[Any, FloatArray] = self._shared.cached(("kirchhoff few G2",), dict)
            g2 = memo.get(key)
            if g2 is None:
                g2 = self._shared.masking_model.masking_g2(wi, wo)
                if len(memo) >= _G2_MEMO_SIZE:
                    memo.clear()
                memo[key] = g2
        else:
            g2 = self._shared.masking_model.masking_g2(wi, wo)
        out: FloatArray = np.power(np.clip(g2, 1e-300, 1.0), -np.expm1(-gd))
        return out

    @property
    def _g2_per_source(self) -> bool:
        return self.masking

    def _validity(self, theta_i_deg: float, lam_nm: float) -> str | None:
        """Outside validity when the map does not sample the phase screen: neighbouring
        points differ in phase by more than :data:`MAX_PHASE_STEP_RAD` rms."""
        st = self._shared.stats
        lam = lam_nm * 1e-3
        phase = (
            (4.0 * math.pi * math.cos(math.radians(theta_i_deg)) / lam)
            * (st.sdq / math.sqrt(2.0))
            * st.step_um
        )
        if phase > MAX_PHASE_STEP_RAD:
            return (
                f"needs the phase screen sampled: the map step {st.step_um:g} um gives "
                f"{phase:.2g} rad rms per point at {lam_nm:g} nm (> {MAX_PHASE_STEP_RAD:g})"
            )
        return None

    def _alternative(self, theta_i_deg: float, lam_nm: float, g: float) -> str:
        """Rayleigh-Rice while ``g < 1`` and the slopes are small (beyond its own
        ``RR_VALID_G`` it says so and answers all the same: the facet model would miss the
        coherent beam); else the facet model."""
        st = self._shared.stats
        if g < FACET_MIN_HANDOVER_G and st.sdq <= RR_VALID_SDQ:
            return "rayleigh-rice"
        return "facet"

    def coherent_factor(self, theta_i_deg: float) -> float:
        """``|sum W exp(-i v_z h)|^2 / (sum W)^2`` at specular, averaged over the tiles."""
        ti = check_theta_i(theta_i_deg)
        t = self._shared.tiled
        v = 2.0 * (2.0 * math.pi / (self.wavelength_nm * 1e-3)) * math.cos(math.radians(ti))
        acc = 0.0
        for k in range(t.n_tiles):
            h, w = t.tile(k)
            c = np.sum(w * np.exp(-1j * v * h.astype(np.float64))) / np.sum(w, dtype=np.float64)
            acc += float(abs(c) ** 2)
        return acc / t.n_tiles

    def specular_reflectance(self, theta_i_deg: float) -> float:
        """Coherent specular reflectance ``R(ti) |<exp(-i v_z h)>_W|^2`` (module docstring)."""
        ti = check_theta_i(theta_i_deg)
        r = float(fresnel(math.cos(math.radians(ti)), self.n))
        return r * self.coherent_factor(ti)
