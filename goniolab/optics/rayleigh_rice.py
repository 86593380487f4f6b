"""Rayleigh-Rice (first-order vector perturbation) scattering from a height map's PSD.

For a surface much smoother than the wavelength (``4 pi Sq cos t / lambda << 1``) and of
small slopes, the BRDF is (Stover, "Optical Scattering", ch. 5; NIST SCATMECH
``Microroughness_BRDF_Model``, after Germer, Appl. Opt. 36 (1997) 8798)

.. math:: f = \\frac{16\\pi^2}{\\lambda^4}\\cos\\theta_i\\cos\\theta_s\\,Q\\,
          \\mathrm{PSD}_2(f_x, f_y),\\qquad
          (f_x, f_y) = (w_i + w_o)_{x,y} / \\lambda,

with the unpolarised polarisation factor ``Q = (|q_ss|^2 + |q_pp|^2 + |q_sp|^2 + |q_ps|^2)/2``
of the dielectric constant ``eps = n^2`` (complex for conductors), ``A_i = sqrt(eps -
sin^2 ti)``, ``A_s = sqrt(eps - sin^2 ts)`` and the scattering azimuth ``phi_s`` (0 in the
forward, specular direction):

- ``q_ss = (eps - 1) cos phi_s / ((cos ti + A_i)(cos ts + A_s))``
- ``q_pp = (eps - 1)(eps sin ti sin ts - A_s A_i cos phi_s) / ((eps cos ti + A_i)(eps cos ts + A_s))``
- ``q_ps = -(eps - 1) A_i sin phi_s / ((eps cos ti + A_i)(cos ts + A_s))``
- ``q_sp = -(eps - 1) A_s sin phi_s / ((cos ti + A_i)(eps cos ts + A_s))``

In the specular direction ``q_ss = -r_s`` and ``q_pp = -r_p`` (Fresnel amplitudes), so
``Q -> R(ti)``. The PSD is the map's (:func:`goniolab.optics.psd.psd2`, Schwartz-windowed
tiles), on the same direction-cosine cells as the Kirchhoff model
(:mod:`goniolab.optics.physical`); a cell's flux fraction is ``exp(-g) f`` times its area
``lambda^2 df_x df_y`` (energy: PHYSICS.md, "Energy"; zero-padded cells when the receptor
needs a finer grid, :func:`goniolab.optics.psd.psd_region`). The coherent beam
``R exp(-(4 pi Sq cos t / lambda)^2)`` (Debye-Waller) is summed analytically over the source
(:func:`~goniolab.optics.coherent_beam.coherent_sums`). The PSD does not
depend on the wavelength or the angles: one FFT per tile serves every geometry and
wavelength. Outside ``g <= RR_VALID_G``, ``Sdq <= RR_VALID_SDQ`` the Kirchhoff model of the
same map answers, and the reading's provenance says so.

References
----------
.. [1] J. C. Stover, "Optical Scattering: Measurement and Analysis", 3rd ed., SPIE 2012,
   ch. 5 (Rayleigh-Rice, the Q factor), ch. 2 (TIS).
.. [2] T. A. Germer, "Angular dependence and polarization of out-of-plane optical
   scattering from particulate contamination, subsurface defects, and surface
   microroughness", Appl. Opt. 36 (1997) 8798; NIST SCATMECH ``Microroughness_BRDF_Model``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from goniolab.optics.cell_apertures import CellBox
from goniolab.optics.fresnel import fresnel
from goniolab.optics.physical import (
    FACET_MIN_HANDOVER_G,
    RR_VALID_G,
    RR_VALID_SDQ,
    FloatArray,
    PhysicalOpticsModel,
    check_theta_i,
)
from goniolab.optics.psd import PSD2, psd2, psd_region, windowed_sq_um
from goniolab.optics.wave_tasks import row_parts, run_reporting

__all__ = ["RayleighRiceModel", "rr_q_factor"]

#: Rows of the Nyquist window per block of the energy check's sums (16 rows of a
#: 1024-wide window: 16 k cells, whose float64 and complex temporaries stay in cache).
_ENERGY_ROWS: int = 16
#: Parts of rows per wavelength the energy check's terms are formed in (tasks: fine enough
#: that a thread joining late finds some left).
_ENERGY_PARTS: int = 4


def rr_q_factor(
    theta_i_deg: float, theta_s_deg: ArrayLike, phi_s_deg: ArrayLike, n: complex | float
) -> FloatArray:
    """Unpolarised Rayleigh-Rice polarisation factor Q (module docstring).

    ``phi_s_deg`` is the scattering azimuth measured from the forward (specular) direction.
    """
    eps = complex(n) ** 2
    ti = math.radians(float(theta_i_deg))
    ts = np.radians(np.asarray(theta_s_deg, dtype=np.float64))
    ps = np.radians(np.asarray(phi_s_deg, dtype=np.float64))
    si, ci = math.sin(ti), math.cos(ti)
    ss, cs = np.sin(ts), np.cos(ts)
    cp, sp = np.cos(ps), np.sin(ps)
    if eps.imag == 0.0 and eps.real >= 1.0:
        # a real index n >= 1 (a dielectric coat): every square root below is of a
        # positive number and every factor real, so the same formulas in real
        # arithmetic (issue 26: a third of the complex work; the same Q to ~1e-15)
        er = eps.real
        ar_i = math.sqrt(er - si * si)
        ar_s = np.sqrt(er - ss * ss)
        e1r = er - 1.0
        r_ss = e1r * cp / ((ci + ar_i) * (cs + ar_s))
        r_pp = e1r * (er * si * ss - ar_s * ar_i * cp) / ((er * ci + ar_i) * (er * cs + ar_s))
        r_ps = -e1r * ar_i * sp / ((er * ci + ar_i) * (cs + ar_s))
        r_sp = -e1r * ar_s * sp / ((ci + ar_i) * (er * cs + ar_s))
        real: FloatArray = 0.5 * (r_ss * r_ss + r_pp * r_pp + r_ps * r_ps + r_sp * r_sp)
        return real
    a_i = np.sqrt(eps - si * si + 0j)
    a_s = np.sqrt(eps - ss * ss + 0j)
    e1 = eps - 1.0
    q_ss = e1 * cp / ((ci + a_i) * (cs + a_s))
    q_pp = e1 * (eps * si * ss - a_s * a_i * cp) / ((eps * ci + a_i) * (eps * cs + a_s))
    q_ps = -e1 * a_i * sp / ((eps * ci + a_i) * (cs + a_s))
    q_sp = -e1 * a_s * sp / ((ci + a_i) * (eps * cs + a_s))
    out: FloatArray = 0.5 * (
        np.abs(q_ss) ** 2 + np.abs(q_pp) ** 2 + np.abs(q_ps) ** 2 + np.abs(q_sp) ** 2
    )
    return out


class RayleighRiceModel(PhysicalOpticsModel):
    """Rayleigh-Rice model of a height map (module docstring; parameters as
    :class:`~goniolab.optics.physical.PhysicalOpticsModel`)."""

    kind = "rayleigh-rice"

    @cached_property
    def psd(self) -> PSD2:
        """The map's PSD (shared by every sibling model)."""
        out: PSD2 = self._shared.cached(("psd",), lambda: psd2(self._shared.tiled))
        return out

    @property
    def psd_sq_um(self) -> float:
        """The rms height the PSD integrates to (:func:`~goniolab.optics.psd.windowed_sq_um`:
        summed in real space, no transform; shared by every sibling model)."""
        out: float = self._shared.cached(("psd-sq",), lambda: windowed_sq_um(self._shared.tiled))
        return out

    def rayleigh_g(self, theta_i_deg: float) -> float:
        """Rayleigh factor ``g = (4 pi Sq cos ti / lambda)^2`` of the specular beam."""
        return self._g_at(theta_i_deg, self.wavelength_nm * 1e-3)

    def specular_reflectance(self, theta_i_deg: float) -> float:
        """``R(ti) exp(-g)``: the coherent specular beam (Debye-Waller)."""
        ti = check_theta_i(theta_i_deg)
        r = float(fresnel(math.cos(math.radians(ti)), self.n))
        return r * math.exp(-self._g_at(ti, self.wavelength_nm * 1e-3))

    def _g_at(self, theta_i_deg: float, lam_um: float) -> float:
        return (4.0 * math.pi * self.psd_sq_um * math.cos(math.radians(theta_i_deg)) / lam_um) ** 2

    def _cell_powers(
        self,
        theta_i_deg: float,
        lams_um: Sequence[float],
        boxes: Sequence[CellBox],
        os: tuple[int, int] = (1, 1),
    ) -> tuple[list[FloatArray], list[float]]:
        """Diffuse flux per cell, ``exp(-g)`` times the first-order BRDF times the cell's
        area (module docstring: energy), and the coherent factor ``exp(-g)``, per wavelength.

        On the tile's own grid the cached PSD serves every geometry; on a zero-padded grid
        (a receptor narrower than a few cells) the periodogram is formed on the box's
        cells only (:func:`goniolab.optics.psd.psd_region`)."""
        t = self._shared.tiled
        ti = math.radians(theta_i_deg)
        ci = math.cos(ti)
        df2 = 1.0 / (os[0] * t.nx_t * t.dx_um * os[1] * t.ny_t * t.dy_um)
        out, coh = [], []
        scales = self._energy_scales(theta_i_deg, lams_um)
        union = functools.reduce(CellBox.union, boxes)
        # on a padded grid one periodogram of the boxes' union serves every wavelength
        # (each region costs a pass over the whole tile: 16 of them were most of a gloss)
        whole = self._psd_cells(union, os) if os != (1, 1) and len(boxes) > 1 else None
        for lam, box, scale in zip(lams_um, boxes, scales, strict=True):
            x, y, z, ok = self._geometry(theta_i_deg, lam, box, os)
            # the real cells only (the evanescent ones carry 0), put back in place below
            xo, yo, zo = x[ok], y[ok], z[ok]
            st = np.sqrt(xo * xo + yo * yo)
            ts_deg = np.degrees(np.arctan2(st, zo))
            # azimuth from the forward direction: phi_ours - 180 deg
            phi_deg = np.where(st > 0, np.degrees(np.arctan2(-yo, -xo)), 0.0)
            q = rr_q_factor(theta_i_deg, ts_deg, phi_deg, self.n)
            if whole is None:
                pv = self._psd_cells(box, os)
            else:
                pv = whole[
                    box.iy0 - union.iy0 : box.iy1 - union.iy0 + 1,
                    box.ix0 - union.ix0 : box.ix1 - union.ix0 + 1,
                ]
            dw = math.exp(-self._g_at(theta_i_deg, lam))
            p = 16.0 * math.pi**2 * ci * zo * q * pv[ok] * df2 / lam**2
            cells = np.zeros(ok.shape)
            cells[ok] = scale * dw * p
            out.append(cells)
            coh.append(dw)
        return out, coh

    def _energy_scales_at(self, theta_i_deg: float, lams_um: Sequence[float]) -> list[float]:
        """From :data:`~goniolab.optics.energy_budget.ENERGY_CHECK_FROM_DEG` on, the diffuse
        flux over the hemisphere, ``exp(-g) D`` (D the first-order total), is held to what
        the coherent beam leaves of the Fresnel reflectance, ``R(ti) (1 - exp(-g))``: the
        factor is ``min(1, R (1 - exp(-g)) / (exp(-g) D))``. (Below that angle
        ``exp(-g) D <= R (1 - exp(-g))`` holds by itself: ``g exp(-g) <= 1 - exp(-g)`` and Q
        stays near R.) D is summed over every cell of the window: a sum over every second
        cell times 4 ran low where the periodogram is not smooth at that scale, a wavy map's
        power lying in the few cells around specular (the Kirchhoff check's finding,
        :meth:`goniolab.optics.kirchhoff.KirchhoffModel._energy_scales_at`)."""
        t = self._shared.tiled
        ci = math.cos(math.radians(theta_i_deg))
        nx0, nx1, ny0, ny1 = self._nyquist()
        box = CellBox(nx0, nx1, ny0, ny1)
        ix, iy = box.ix, box.iy
        pv = self.psd.psd_um4[np.ix_(iy % t.ny_t, ix % t.nx_t)]
        df2 = 1.0 / (t.nx_t * t.dx_um * t.ny_t * t.dy_um)
        r_spec = float(fresnel(ci, self.n))
        out = []
        shape = (iy.size, ix.size)
        c16 = 16.0 * math.pi**2 * ci
        s_i = math.sin(math.radians(theta_i_deg))
        # the terms of the real (not evanescent) cells only, put back in place and summed
        # over the whole window: the same values in the same order (towards grazing
        # incidence half of the window or more is evanescent, and Q's complex arithmetic
        # was most of a gloss report's Rayleigh-Rice work), formed in blocks of rows whose
        # temporaries stay in cache (:data:`_ENERGY_ROWS`); the blocks of each wavelength
        # in parts, tasks on up to two threads (:func:`run_reporting`: each cell by
        # the same operations on either thread, the sum in this one: the same bits)
        terms = np.zeros((len(lams_um), *shape))
        xs, ys = [], []
        for lam in lams_um:
            cx, cy = self._cell_size(lam)
            xs.append(ix.astype(np.float64)[None, :] * cx - s_i)
            ys.append(iy.astype(np.float64)[:, None] * cy)

        def block_terms(li: int, a: int, b: int) -> None:
            x = xs[li]
            for r0 in range(a, b, _ENERGY_ROWS):
                rows = slice(r0, min(r0 + _ENERGY_ROWS, b))
                yb = ys[li][rows]
                z2 = 1.0 - x * x - yb * yb
                ok = z2 > 1e-12
                if not ok.any():
                    continue
                part = (yb.shape[0], shape[1])
                xo, yo = np.broadcast_to(x, part)[ok], np.broadcast_to(yb, part)[ok]
                z = np.sqrt(z2[ok])
                st = np.sqrt(xo * xo + yo * yo)
                ts_deg = np.degrees(np.arctan2(st, z))
                phi_deg = np.where(st > 0, np.degrees(np.arctan2(-yo, -xo)), 0.0)
                q = rr_q_factor(theta_i_deg, ts_deg, phi_deg, self.n)
                terms[li][rows][ok] = c16 * z * q * pv[rows][ok]

        run_reporting(
            [
                functools.partial(block_terms, li, a, b)
                for li in range(len(lams_um))
                for a, b in row_parts(0, shape[0], _ENERGY_ROWS, _ENERGY_PARTS)
            ]
        )
        for li, lam in enumerate(lams_um):
            d = float(np.sum(terms[li]))
            d *= df2 / lam**2
            dw = math.exp(-self._g_at(theta_i_deg, lam))
            room = r_spec * (1.0 - dw)
            out.append(min(1.0, room / (dw * d)) if d > 0.0 else 1.0)
        return out

    def _psd_cells(self, box: CellBox, os: tuple[int, int]) -> FloatArray:
        t = self._shared.tiled
        ly, lx = os[1] * t.ny_t, os[0] * t.nx_t
        if os == (1, 1):
            return self.psd.psd_um4[np.ix_(box.iy % ly, box.ix % lx)]
        key = ("psd-region", (box.ix0, box.ix1, box.iy0, box.iy1), os)
        out: FloatArray = self._shared.cached(
            key, lambda: psd_region(t, box.iy % ly, box.ix % lx, os, self.progress)
        )
        return out

    def _validity(self, theta_i_deg: float, lam_nm: float) -> str | None:
        """First-order perturbation needs ``g <= RR_VALID_G`` and ``Sdq <= RR_VALID_SDQ``."""
        g = self.rayleigh_factor(theta_i_deg, lam_nm)  # the map's Sq, as the auto rule
        sdq = self._shared.stats.sdq
        if g > RR_VALID_G:
            return f"is outside its validity: g = {g:.3g} > {RR_VALID_G:g} at {lam_nm:g} nm"
        if sdq > RR_VALID_SDQ:
            return f"is outside its validity: Sdq = {sdq:.3g} > {RR_VALID_SDQ:g}"
        return None

    def _alternative(self, theta_i_deg: float, lam_nm: float, g: float) -> str:
        """Kirchhoff where it samples its phase screen; else, while g < 1, this model all
        the same (the facet model would miss the coherent beam); else the facet model."""
        if self._sibling("kirchhoff")._validity(theta_i_deg, lam_nm) is None:
            return "kirchhoff"
        return "self" if g < FACET_MIN_HANDOVER_G else "facet"

    _why_self = (
        "used all the same: the map does not sample Kirchhoff's phase screen and the "
        "facet model would miss the coherent beam (g < 1)"
    )
