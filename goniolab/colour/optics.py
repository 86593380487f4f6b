"""Interface and thin-film optics per wavelength: Fresnel amplitudes, Snell, Airy films.

Vectorised over angles *and* wavelengths (complex indices broadcast), which
:mod:`goniolab.optics.fresnel` (one scalar index per call) is not.

- Fresnel amplitudes between media of complex index n1 -> n2 (Born & Wolf sec. 1.5.2;
  the seed's eq. 2, Durikovic 2007): ``r_s = (n1 c1 - n2 c2)/(n1 c1 + n2 c2)``,
  ``r_p = (n2 c1 - n1 c2)/(n2 c1 + n1 c2)``, ``c2 = sqrt(1 - (n1/n2)^2 (1 - c1^2))``
  (complex principal root: total internal reflection and metals come out right).
- Airy formula of a film (index n_f, thickness d) between media n0 and n2 (Born & Wolf
  sec. 1.6.4; the seed's recursion eq. 6 for one layer):
  ``r = (r01 + r12 e^{2 i delta}) / (1 + r01 r12 e^{2 i delta})``,
  ``delta = 2 pi n_f d cos(theta_f) / lambda``. For a high-index film in a lower-index
  medium (r01 and r12 of opposite sign) the reflectance peaks where
  ``2 n_f d cos theta_f = (m - 1/2) lambda`` (PHYSICS.md).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "airy_film",
    "cos_transmitted",
    "fresnel_amplitudes",
    "fresnel_unpolarised",
    "refract_cos",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def cos_transmitted(cos_1: ArrayLike, n1: ArrayLike, n2: ArrayLike) -> ComplexArray:
    """Complex cosine of the transmitted angle (Snell), principal root with Im >= 0."""
    c1 = np.asarray(cos_1, dtype=np.complex128)
    ratio = np.asarray(n1, dtype=np.complex128) / np.asarray(n2, dtype=np.complex128)
    c2 = np.sqrt(1.0 - ratio * ratio * (1.0 - c1 * c1))
    # choose the root that decays into medium 2 (Im(n2 c2) >= 0)
    n2c = np.asarray(n2, dtype=np.complex128) * c2
    out: ComplexArray = np.where(n2c.imag < 0, -c2, c2)
    return out


def fresnel_amplitudes(
    cos_1: ArrayLike, n1: ArrayLike, n2: ArrayLike
) -> tuple[ComplexArray, ComplexArray, ComplexArray, ComplexArray]:
    """``(r_s, r_p, t_s, t_p)`` amplitude coefficients from medium n1 into n2."""
    n1c = np.asarray(n1, dtype=np.complex128)
    n2c = np.asarray(n2, dtype=np.complex128)
    c1 = np.clip(np.asarray(cos_1, dtype=np.float64), 0.0, 1.0).astype(np.complex128)
    c2 = cos_transmitted(c1, n1c, n2c)
    rs = (n1c * c1 - n2c * c2) / (n1c * c1 + n2c * c2)
    rp = (n2c * c1 - n1c * c2) / (n2c * c1 + n1c * c2)
    ts = 2.0 * n1c * c1 / (n1c * c1 + n2c * c2)
    tp = 2.0 * n1c * c1 / (n2c * c1 + n1c * c2)
    return rs, rp, ts, tp


def fresnel_unpolarised(cos_1: ArrayLike, n2: ArrayLike, n1: ArrayLike = 1.0) -> FloatArray:
    """Unpolarised power reflectance ``(|r_s|^2 + |r_p|^2)/2`` from n1 into n2 (broadcast)."""
    rs, rp, _, _ = fresnel_amplitudes(cos_1, n1, n2)
    out: FloatArray = 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
    return out


def refract_cos(cos_out: ArrayLike, n: ArrayLike) -> FloatArray:
    """Cosine inside a coat of real index n of a direction at ``acos(cos_out)`` in air."""
    c = np.clip(np.asarray(cos_out, dtype=np.float64), 0.0, 1.0)
    n_r = np.asarray(n, dtype=np.float64)
    out: FloatArray = np.sqrt(1.0 - (1.0 - c * c) / (n_r * n_r))
    return out


def airy_film(
    cos_0: ArrayLike,
    wavelength_nm: ArrayLike,
    n0: ArrayLike,
    n_film: ArrayLike,
    thickness_nm: ArrayLike,
    n2: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Power reflectance and transmittance (unpolarised) of one film between n0 and n2.

    Parameters
    ----------
    cos_0
        Cosine of the incidence angle in medium n0.
    wavelength_nm
        Vacuum wavelength.
    n0, n_film, n2
        Indices of the incident medium, the film and the exit medium (complex allowed for
        the film and exit medium; n0 real).
    thickness_nm
        Film thickness d.

    Returns
    -------
    R, T
        ``(|r_s|^2 + |r_p|^2)/2`` and, for a real exit index, the transmitted power
        ``Re(n2 c2)/(n0 c0) (|t_s|^2 + |t_p|^2)/2`` (0 for an absorbing exit medium).
    """
    c0 = np.clip(np.asarray(cos_0, dtype=np.float64), 0.0, 1.0)
    n0c = np.asarray(n0, dtype=np.complex128)
    nf = np.asarray(n_film, dtype=np.complex128)
    n2c = np.asarray(n2, dtype=np.complex128)
    cf = cos_transmitted(c0, n0c, nf)
    c2 = cos_transmitted(c0, n0c, n2c)
    rs01, rp01, ts01, tp01 = fresnel_amplitudes(c0, n0c, nf)
    # film -> exit (the film's cosine is complex in general: use the amplitude formulas)
    rs12 = (nf * cf - n2c * c2) / (nf * cf + n2c * c2)
    rp12 = (n2c * cf - nf * c2) / (n2c * cf + nf * c2)
    ts12 = 2.0 * nf * cf / (nf * cf + n2c * c2)
    tp12 = 2.0 * nf * cf / (n2c * cf + nf * c2)
    delta = 2.0 * np.pi * nf * np.asarray(thickness_nm, dtype=np.float64) * cf
    delta = delta / np.asarray(wavelength_nm, dtype=np.float64)
    ph = np.exp(2j * delta)
    ph1 = np.exp(1j * delta)
    rs = (rs01 + rs12 * ph) / (1.0 + rs01 * rs12 * ph)
    rp = (rp01 + rp12 * ph) / (1.0 + rp01 * rp12 * ph)
    ts = ts01 * ts12 * ph1 / (1.0 + rs01 * rs12 * ph)
    tp = tp01 * tp12 * ph1 / (1.0 + rp01 * rp12 * ph)
    r: FloatArray = 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
    # s and p share the same power factor Re(n2 c2)/(n0 c0) for the exit medium
    factor = np.real(n2c * c2) / np.real(n0c * c0)
    t: FloatArray = np.where(
        np.abs(n2c.imag) > 0, 0.0, factor * 0.5 * (np.abs(ts) ** 2 + np.abs(tp) ** 2)
    )
    return r, np.real(t).astype(np.float64)
