"""The direction grid of the physical-optics models and the sums of its cells over apertures.

A tile of ``N_x x N_y`` points of step ``dx, dy`` scatters into the cells of a regular grid
of direction cosines, ``(w_i + w_o)_{x,y} = lambda (m_x / (N_x dx), m_y / (N_y dy))``
(the grating equation; Stover 2012, ch. 2), zero-padded ``os`` times when the receptor
needs finer cells (:meth:`CellApertures._oversampling`, :data:`CELLS_ACROSS` cells across
it). :class:`CellBox` is a block of cells; :class:`CellApertures` finds the block an
aperture reaches within the map's Nyquist window (:meth:`CellApertures._box_for`) and sums
the diffuse cell powers over goniometer cones and ISO 2813 rectangles with the source's
mirror image (:meth:`CellApertures._sum_apertures`, the kernels of
:mod:`goniolab.optics._cell_kernels`; Mihalik eqs. 15-17), splitting a source cone as
the facet model does towards grazing incidence.

References
----------
.. [1] J. C. Stover, "Optical Scattering", 3rd ed., SPIE 2012, ch. 2 (grating equation).
.. [2] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eqs. 15-17.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from goniolab.optics import _cell_kernels as CK
from goniolab.optics.apertures import Aperture, Cone, Rect
from goniolab.optics.facet_apertures import (
    SPLIT_SOURCE_RINGS,
    clipped_source_parts,
    cone_table,
    reaches_horizon,
)
from goniolab.optics.fresnel import fresnel
from goniolab.optics.shared_map import SharedMap

__all__ = [
    "CELLS_ACROSS",
    "MAX_PADDED_POINTS",
    "CellApertures",
    "CellBox",
    "box_projected_solid_angle_sr",
]

FloatArray = NDArray[np.float64]

#: Cells across the receptor's narrowest side the diffuse sums aim for: the tile's transform
#: is zero-padded (sampled on a finer grid of directions) until the receptor spans them.
CELLS_ACROSS: int = 6
#: Most points of a zero-padded transform axis (bounds the padding of tiny receptors).
MAX_PADDED_POINTS: int = 1 << 15


@dataclass(frozen=True)
class CellBox:
    """Signed FFT index ranges (inclusive) of a block of cells."""

    ix0: int
    ix1: int
    iy0: int
    iy1: int

    def union(self, other: CellBox) -> CellBox:
        return CellBox(
            min(self.ix0, other.ix0),
            max(self.ix1, other.ix1),
            min(self.iy0, other.iy0),
            max(self.iy1, other.iy1),
        )

    @property
    def ix(self) -> NDArray[np.int64]:
        return np.arange(self.ix0, self.ix1 + 1, dtype=np.int64)

    @property
    def iy(self) -> NDArray[np.int64]:
        return np.arange(self.iy0, self.iy1 + 1, dtype=np.int64)


class CellApertures:
    """The FFT grid of directions of a physical-optics model and its aperture sums
    (a base of :class:`goniolab.optics.physical.PhysicalOpticsModel`, module docstring)."""

    #: the map, its tiles and caches
    _shared: SharedMap
    #: refractive index (Fresnel of the cells)
    n: complex
    #: aperture-sum kernels (:mod:`goniolab.optics._cell_kernels`)
    backend: Literal["numba", "numpy"]

    def _cell_size(self, lam_um: float, os: tuple[int, int] = (1, 1)) -> tuple[float, float]:
        t = self._shared.tiled
        return lam_um / (os[0] * t.nx_t * t.dx_um), lam_um / (os[1] * t.ny_t * t.dy_um)

    def _nyquist(self, os: tuple[int, int] = (1, 1)) -> tuple[int, int, int, int]:
        t = self._shared.tiled
        nx, ny = os[0] * t.nx_t, os[1] * t.ny_t
        # the map's own band: |f| <= 1/(2 step), whatever the padding
        hx, hy = (os[0] * t.nx_t) // 2, (os[1] * t.ny_t) // 2
        return -hx, min(hx, nx - hx - 1), -hy, min(hy, ny - hy - 1)

    def _wo_axes(
        self, theta_i_deg: float, lam_um: float, box: CellBox, os: tuple[int, int] = (1, 1)
    ) -> tuple[FloatArray, FloatArray]:
        cx, cy = self._cell_size(lam_um, os)
        wox = box.ix.astype(np.float64) * cx - math.sin(math.radians(theta_i_deg))
        woy = box.iy.astype(np.float64) * cy
        return wox, woy

    def _geometry(
        self, theta_i_deg: float, lam_um: float, box: CellBox, os: tuple[int, int] = (1, 1)
    ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
        """``wo`` components (2-D) of the cells of ``box`` and the mask of real directions."""
        wox, woy = self._wo_axes(theta_i_deg, lam_um, box, os)
        x = np.broadcast_to(wox[None, :], (woy.size, wox.size))
        y = np.broadcast_to(woy[:, None], (woy.size, wox.size))
        z2 = 1.0 - x * x - y * y
        ok = z2 > 1e-12
        return x, y, np.sqrt(np.where(ok, z2, 0.0)), ok

    def _fresnel_geom(
        self, theta_i_deg: float, x: FloatArray, y: FloatArray, z: FloatArray, ok: NDArray[np.bool_]
    ) -> FloatArray:
        """Fresnel at the local incidence ``wi.h`` of each cell (h the half vector)."""
        t = math.radians(theta_i_deg)
        sx, cz = math.sin(t), math.cos(t)
        hx, hy, hz = x + sx, y, z + cz
        hn = np.sqrt(hx * hx + hy * hy + hz * hz)
        cos_ih = np.where(ok, 0.5 * hn, 1.0)
        out: FloatArray = np.where(ok, fresnel(np.clip(cos_ih, 0.0, 1.0), self.n), 0.0)
        return out

    def _reach(self, source: Aperture, receptor: Aperture) -> tuple[float, float]:
        """Half reach in plane and out of plane (rad) of receptor plus the source image."""
        if isinstance(source, Cone) and isinstance(receptor, Cone):
            r = math.radians(source.half_angle_deg + receptor.half_angle_deg)
            return r, r
        if isinstance(source, Rect) and isinstance(receptor, Rect):
            return (
                math.radians(0.5 * (source.in_plane_deg + receptor.in_plane_deg)),
                math.radians(0.5 * (source.perp_deg + receptor.perp_deg)),
            )
        raise ValueError(
            "source and receptor apertures must both be Cone or both be Rect, got "
            f"{type(source).__name__} and {type(receptor).__name__}"
        )

    def _box_for(
        self,
        theta_i_deg: float,
        lam_um: float,
        alpha_lo: float,
        alpha_hi: float,
        half_b: float,
        os: tuple[int, int] = (1, 1),
    ) -> tuple[CellBox, bool]:
        """Cells covering in-plane angles [alpha_lo, alpha_hi] x out-of-plane [-half_b, half_b]
        (rad); ``inside`` is False when part of that region is beyond the map's Nyquist window."""
        cb = math.cos(min(half_b, 1.5))
        s_hi = -math.sin(min(alpha_hi, 0.5 * math.pi))
        s_lo = -math.sin(max(alpha_lo, -0.5 * math.pi))
        x_lo, x_hi = min(s_hi, s_hi * cb), max(s_lo, s_lo * cb)
        y_hi = math.sin(min(half_b, 1.5))
        sx = math.sin(math.radians(theta_i_deg))
        cx, cy = self._cell_size(lam_um, os)
        ix0 = math.floor((x_lo + sx) / cx) - 1
        ix1 = math.ceil((x_hi + sx) / cx) + 1
        iy1 = math.ceil(y_hi / cy) + 1
        nx0, nx1, ny0, ny1 = self._nyquist(os)
        # one cell of slack at the edges (the box has one more cell than its reach needs)
        inside = ix0 + 1 >= nx0 and ix1 - 1 <= nx1 and -iy1 + 1 >= ny0 and iy1 - 1 <= ny1
        # clipped to the window; a region wholly beyond it keeps the window's edge cell
        # (which no aperture of the region reaches: its sums are 0, as they must be)
        bx0, bx1 = min(max(ix0, nx0), nx1), max(min(ix1, nx1), nx0)
        if bx0 > bx1:
            bx0 = bx1 = nx1 if ix0 > nx1 else nx0
        box = CellBox(bx0, bx1, max(-iy1, ny0), min(iy1, ny1))
        return box, inside

    def _oversampling(
        self, lam_um: float, receptor: Aperture, theta_r_deg: FloatArray
    ) -> tuple[tuple[int, int], str | None]:
        """Zero-padding factors ``(os_x, os_y)`` giving at least :data:`CELLS_ACROSS` cells
        ``lambda / (os field)`` across the receptor's narrowest side at every angle, and a
        note when :data:`MAX_PADDED_POINTS` caps them (fewer cells: a coarser sum)."""
        t = self._shared.tiled
        if isinstance(receptor, Cone):
            w_in = w_perp = math.radians(receptor.full_angle_deg)
        else:
            w_in, w_perp = math.radians(receptor.in_plane_deg), math.radians(receptor.perp_deg)
        tmax = float(np.max(np.abs(theta_r_deg))) if np.size(theta_r_deg) else 0.0
        # the in-plane width in direction cosines shrinks as cos(theta_r) (rim: half a width)
        edge = min(math.radians(tmax) + 0.5 * w_in, 0.5 * math.pi)
        w_x = max(w_in * math.cos(edge), 1e-12)
        cx, cy = self._cell_size(lam_um)
        want_x = max(1, math.ceil(CELLS_ACROSS * cx / w_x)) if w_in > 0 else 1
        want_y = max(1, math.ceil(CELLS_ACROSS * cy / w_perp)) if w_perp > 0 else 1
        cap_x = max(1, MAX_PADDED_POINTS // t.nx_t)
        cap_y = max(1, MAX_PADDED_POINTS // t.ny_t)
        os = (min(want_x, cap_x), min(want_y, cap_y))
        note = None
        if os != (want_x, want_y):
            across = min(
                w_x / (cx / os[0]) if w_in > 0 else math.inf,
                w_perp / (cy / os[1]) if w_perp > 0 else math.inf,
            )
            note = (
                f"field of {t.nx_t * t.dx_um:g} x {t.ny_t * t.dy_um:g} um: the diffuse sum "
                f"resolves {across:.2g} cells across the receptor at {lam_um * 1e3:g} nm "
                f"(zero padding capped at {MAX_PADDED_POINTS} points; {CELLS_ACROSS} wanted)"
            )
        return os, note

    def _diffuse_g2(self, wi: FloatArray, wo: FloatArray, lam_um: float) -> FloatArray | float:
        """Shadowing applied to the diffuse cells seen from ``wo`` (rows of unit vectors)
        lit from ``wi``: none here (the coherent beam and Rayleigh-Rice take none);
        :class:`~goniolab.optics.kirchhoff.KirchhoffModel` weighs in Smith's G2 as the
        geometric limit needs it."""
        return 1.0

    @property
    def _g2_per_source(self) -> bool:
        """Whether the diffuse sums carry a shadowing term that varies across the source."""
        return False

    def _sum_apertures(
        self,
        theta_i_deg: float,
        lam_um: float,
        box: CellBox,
        p: FloatArray,
        theta_r_deg: FloatArray,
        source: Aperture,
        receptor: Aperture,
        os: tuple[int, int] = (1, 1),
        shadow: bool = True,
    ) -> FloatArray:
        """Aperture sums of the diffuse cell powers ``p`` at each detector angle (times the
        diffuse shadowing :meth:`_diffuse_g2` of the detector's direction when ``shadow``)."""
        wox, woy = self._wo_axes(theta_i_deg, lam_um, box, os)
        tr = np.radians(theta_r_deg)
        if (
            isinstance(source, Cone)
            and isinstance(receptor, Cone)
            and self._split_source(theta_i_deg, source)
        ):
            return self._clipped_cone_sums(
                theta_i_deg, lam_um, wox, woy, p, tr, source, receptor, shadow
            )
        if isinstance(source, Cone) and isinstance(receptor, Cone):
            table, g0, g1, o_in, _ = cone_table(
                math.radians(source.half_angle_deg), math.radians(receptor.half_angle_deg)
            )
            dirs = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
            fn = CK.cone_cells_numba if self.backend == "numba" else CK.cone_cells_numpy
            out = fn(wox, woy, p, np.ascontiguousarray(dirs), table, g0, g1, o_in)
        else:
            assert isinstance(source, Rect) and isinstance(receptor, Rect)
            fn2 = CK.rect_cells_numba if self.backend == "numba" else CK.rect_cells_numpy
            out = fn2(
                wox,
                woy,
                p,
                np.ascontiguousarray(tr),
                math.radians(source.in_plane_deg),
                math.radians(receptor.in_plane_deg),
                math.radians(source.perp_deg),
                math.radians(receptor.perp_deg),
            )
        result: FloatArray = np.asarray(out, dtype=np.float64)
        if shadow:
            ti = math.radians(theta_i_deg)
            wi = np.array([math.sin(ti), 0.0, math.cos(ti)])
            d = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
            result = result * self._diffuse_g2(np.broadcast_to(wi, d.shape), d, lam_um)
        return result

    def _split_source(self, theta_i_deg: float, source: Aperture) -> bool:
        """Whether a source cone is summed over sub-cones (:meth:`_clipped_cone_sums`): when it
        reaches the horizon, and, when the diffuse sums carry Smith's G2, from where the facet
        model splits it too (:data:`goniolab.optics.facet_apertures.SPLIT_SOURCE_RINGS`), so that G2 is
        that of each source direction (at grazing incidence it varies several-fold across a
        6 deg cone)."""
        if not isinstance(source, Cone) or source.half_angle_deg == 0.0:
            return False
        if reaches_horizon(theta_i_deg, source):
            return True
        edge = min(e for e, _ in SPLIT_SOURCE_RINGS)
        return self._g2_per_source and theta_i_deg + source.half_angle_deg >= edge

    def _clipped_cone_sums(
        self,
        theta_i_deg: float,
        lam_um: float,
        wox: FloatArray,
        woy: FloatArray,
        p: FloatArray,
        tr: FloatArray,
        source: Cone,
        receptor: Cone,
        shadow: bool = True,
    ) -> FloatArray:
        """Diffuse cone sums over the source's sub-cones (:meth:`_split_source`), clipped at
        the horizon when the cone reaches it.

        The source is split as in the facet model (:func:`clipped_source_parts`: sub-cones
        of the part above the horizon, shares over the whole cone). The scattered diffuse
        pattern is that of the nominal incidence, carried over the source (zeroth order in
        the source direction): a sub-cone centred at polar angle ``theta_i + delta`` and
        azimuth ``phi`` turns the pattern about z by phi and shifts it by delta in plane, so
        it reads the nominal pattern through the receptor turned back,
        ``R_y(-delta) R_z(-phi) d``, with the sub-cone's own cap-overlap table and the
        shadowing of its own direction. (The coherent beam is summed exactly per source
        direction, :func:`goniolab.optics.coherent_beam.coherent_sums`.)
        """
        a_d = math.radians(receptor.half_angle_deg)
        d = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
        if self.backend == "numba":
            fn: Any = CK.cone_cells_numba
        else:  # the window's cells formed once for every sub-cone (the same values)
            fn = functools.partial(CK.cone_cells_numpy, window=CK.cone_window(wox, woy, p))
        out = np.zeros(tr.size)
        ti = math.radians(theta_i_deg)
        for c, sub, share in clipped_source_parts(theta_i_deg, source):
            delta = math.acos(min(1.0, float(c[2]))) - ti
            phi = math.atan2(float(c[1]), float(c[0]))
            cp, sp = math.cos(phi), math.sin(phi)
            # R_z(-phi) d, then R_y(-delta): alpha = atan2(-x, z) decreases by delta
            x1, y1 = cp * d[:, 0] + sp * d[:, 1], -sp * d[:, 0] + cp * d[:, 1]
            cd, sd = math.cos(delta), math.sin(delta)
            dirs = np.stack([cd * x1 + sd * d[:, 2], y1, -sd * x1 + cd * d[:, 2]], axis=-1)
            table, g0, g1, o_in, _ = cone_table(math.radians(sub.half_angle_deg), a_d)
            part = fn(wox, woy, p, np.ascontiguousarray(dirs), table, g0, g1, o_in)
            g2 = self._diffuse_g2(np.broadcast_to(c, d.shape), d, lam_um) if shadow else 1.0
            out += share * np.asarray(part, dtype=np.float64) * g2
        return out


def box_projected_solid_angle_sr(box: Rect, theta_r_deg: float) -> float:
    """``int cos(theta) dOmega`` over a rectangle ``box`` centred on the signed in-plane
    angle ``theta_r_deg`` (its part above the horizon), in sr.

    In the aperture frame (:func:`goniolab.optics.apertures.sample_aperture`) a direction
    of in-plane offset ``a`` and out-of-plane angle ``b`` has ``cos theta = cos(tr + a)
    cos b`` and ``dOmega = cos b da db``, so the integral is
    ``[sin(min(|tr| + A/2, pi/2)) - sin(|tr| - A/2)] (B/2 + sin(B)/2)``.
    """
    t = abs(math.radians(theta_r_deg))
    ha, b = 0.5 * math.radians(box.in_plane_deg), math.radians(box.perp_deg)
    return (math.sin(min(t + ha, 0.5 * math.pi)) - math.sin(t - ha)) * (0.5 * b + 0.5 * math.sin(b))
