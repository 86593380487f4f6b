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
(:mod:`goniolab.optics.physical`); a cell's flux fraction is ``f`` times its area
``lambda^2 df_x df_y``. The specular term is the coherent beam
``R(ti) exp(-(4 pi Sq cos ti / lambda)^2)`` (Debye-Waller), put in the specular cell. The
PSD does not depend on the wavelength or the angles: one FFT per tile serves every
geometry and wavelength.

References
----------
.. [1] J. C. Stover, "Optical Scattering: Measurement and Analysis", 3rd ed., SPIE 2012,
   ch. 5 (Rayleigh-Rice, the Q factor), ch. 2 (TIS).
.. [2] T. A. Germer, "Angular dependence and polarization of out-of-plane optical
   scattering from particulate contamination, subsurface defects, and surface
   microroughness", Appl. Opt. 36 (1997) 8798; NIST SCATMECH ``Microroughness_BRDF_Model``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from goniolab.optics.fresnel import fresnel
from goniolab.optics.physical import FloatArray, PhysicalOpticsModel, _Box, _check_theta_i
from goniolab.optics.psd import PSD2, psd2

__all__ = ["RayleighRiceModel", "rr_q_factor"]


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

    def rayleigh_g(self, theta_i_deg: float) -> float:
        """Rayleigh factor ``g = (4 pi Sq cos ti / lambda)^2`` of the specular beam."""
        lam = self.wavelength_nm * 1e-3
        return (4.0 * math.pi * self.psd.sq_um * math.cos(math.radians(theta_i_deg)) / lam) ** 2

    def specular_reflectance(self, theta_i_deg: float) -> float:
        """``R(ti) exp(-g)``: the coherent specular beam (Debye-Waller)."""
        ti = _check_theta_i(theta_i_deg)
        r = float(fresnel(math.cos(math.radians(ti)), self.n))
        return r * math.exp(-self._g_at(ti, self.wavelength_nm * 1e-3))

    def _g_at(self, theta_i_deg: float, lam_um: float) -> float:
        return (4.0 * math.pi * self.psd.sq_um * math.cos(math.radians(theta_i_deg)) / lam_um) ** 2

    def _cell_powers(
        self, theta_i_deg: float, lams_um: Sequence[float], boxes: Sequence[_Box]
    ) -> list[FloatArray]:
        psd = self.psd
        t = self._shared.tiled
        ti = math.radians(theta_i_deg)
        ci = math.cos(ti)
        df2 = psd.df_x * psd.df_y
        r_spec = float(fresnel(ci, self.n))
        out = []
        for lam, box in zip(lams_um, boxes, strict=True):
            x, y, z, ok = self._geometry(theta_i_deg, lam, box)
            st = np.sqrt(x * x + y * y)
            ts_deg = np.degrees(np.arctan2(st, np.where(ok, z, 0.0)))
            # azimuth from the forward direction: phi_ours - 180 deg
            phi_deg = np.where(st > 0, np.degrees(np.arctan2(-y, -x)), 0.0)
            q = rr_q_factor(theta_i_deg, ts_deg, phi_deg, self.n)
            pv = psd.psd_um4[np.ix_(box.iy % t.ny_t, box.ix % t.nx_t)]
            p = 16.0 * math.pi**2 * ci * np.where(ok, z, 0.0) * q * pv * df2 / lam**2
            p = np.where(ok, p, 0.0)
            if box.ix0 <= 0 <= box.ix1 and box.iy0 <= 0 <= box.iy1:
                p[-box.iy0, -box.ix0] += r_spec * math.exp(-self._g_at(theta_i_deg, lam))
            out.append(p)
        return out
