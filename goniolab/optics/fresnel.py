"""Fresnel reflectance of dielectrics and conductors (unpolarised light).

The facet model of Wittmann et al. weighs every facet by the unpolarised Fresnel
reflectance at its local incidence angle iota (``cos_i = wi . m``). The seed writes it in
the angle form (eq. 9)

.. math:: r = \\tfrac12\\left[\\frac{\\tan^2(\\tau-\\iota)}{\\tan^2(\\tau+\\iota)}
          + \\frac{\\sin^2(\\tau-\\iota)}{\\sin^2(\\tau+\\iota)}\\right],\\quad
          \\sin\\tau = \\sin\\iota / n,

which is 0/0 at normal incidence. Here it is evaluated in the equivalent cosine form of the
s and p amplitude coefficients, which is finite everywhere and reaches the normal-incidence
limit ((n - 1)/(n + 1))^2 without special cases. Conductors (complex n + ik) use the same
form with complex arithmetic (pbrt-v4 ``FrComplex``; Mihalik & Durikovic eq. 10).

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, eq. 9.
.. [2] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eq. 10.
.. [3] M. Pharr, W. Jakob, G. Humphreys, "Physically Based Rendering", 4th ed.,
   sec. 9.3 (FrDielectric, FrComplex).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "fresnel",
    "fresnel_conductor",
    "fresnel_dielectric",
    "fresnel_dielectric_sp",
]


def _check_real_index(n: float) -> float:
    n_f = float(n)
    if not np.isfinite(n_f) or n_f <= 0.0:
        raise ValueError(f"refractive index must be a finite positive number, got {n!r}")
    return n_f


def _clip_cos(cos_i: ArrayLike) -> NDArray[np.float64]:
    c = np.asarray(cos_i, dtype=np.float64)
    if np.any(np.isnan(c)):
        raise ValueError("cos_i contains NaN")
    return np.clip(c, 0.0, 1.0)


def fresnel_dielectric_sp(
    cos_i: ArrayLike, n: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Fresnel power reflectances (R_s, R_p) of a dielectric interface from air.

    Parameters
    ----------
    cos_i : array_like
        Cosine of the incidence angle on the (facet) surface, clipped to [0, 1].
    n : float
        Real refractive index of the material (relative to the incident medium).

    Returns
    -------
    (R_s, R_p) : tuple of ndarray
        ``R_s = |(cos i - n cos t)/(cos i + n cos t)|^2`` and
        ``R_p = |(n cos i - cos t)/(n cos i + cos t)|^2`` with ``sin t = sin i / n``
        (Born & Wolf; the two terms of Wittmann eq. 9: ``R_p = tan^2(t-i)/tan^2(t+i)``,
        ``R_s = sin^2(t-i)/sin^2(t+i)``). Total internal reflection (n < 1) gives 1.
    """
    n_f = _check_real_index(n)
    c = _clip_cos(cos_i)
    sin2_t = (1.0 - c * c) / (n_f * n_f)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    rs = (c - n_f * cos_t) / (c + n_f * cos_t)
    rp = (n_f * c - cos_t) / (n_f * c + cos_t)
    r_s = np.where(tir, 1.0, rs * rs)
    r_p = np.where(tir, 1.0, rp * rp)
    return r_s, r_p


def fresnel_dielectric(cos_i: ArrayLike, n: float) -> NDArray[np.float64]:
    """Unpolarised Fresnel reflectance of a dielectric (Wittmann eq. 9, cosine form).

    Parameters
    ----------
    cos_i : array_like
        Cosine of the local incidence angle iota (``wi . m`` for a facet), clipped to [0, 1].
    n : float
        Real refractive index (the seed's polyurethane: 1.55; ISO 2813 black glass: 1.567).

    Returns
    -------
    ndarray
        ``(R_s + R_p) / 2``; equals ``((n - 1)/(n + 1))^2`` at normal incidence and 1 at
        grazing incidence. Vectorised; never NaN for valid input.
    """
    r_s, r_p = fresnel_dielectric_sp(cos_i, n)
    out: NDArray[np.float64] = 0.5 * (r_s + r_p)
    return out


def fresnel_conductor(cos_i: ArrayLike, n_complex: complex) -> NDArray[np.float64]:
    """Unpolarised Fresnel reflectance of a conductor with complex index n + ik.

    Parameters
    ----------
    cos_i : array_like
        Cosine of the incidence angle, clipped to [0, 1].
    n_complex : complex
        Complex refractive index ``n + 1j * k`` with n > 0, k >= 0 (copper at 587 nm is
        about 0.27 + 3.41j).

    Returns
    -------
    ndarray
        ``(|r_s|^2 + |r_p|^2) / 2`` with ``cos t = sqrt(1 - sin^2 i / eta^2)`` (complex
        principal root), as pbrt-v4 ``FrComplex`` and Mihalik & Durikovic eq. 10. At normal
        incidence ``((n - 1)^2 + k^2)/((n + 1)^2 + k^2)``; for k = 0 it equals
        :func:`fresnel_dielectric`.
    """
    eta = complex(n_complex)
    if not (np.isfinite(eta.real) and np.isfinite(eta.imag)) or eta.real <= 0 or eta.imag < 0:
        raise ValueError(f"complex refractive index must have n > 0 and k >= 0, got {n_complex!r}")
    c = _clip_cos(cos_i).astype(np.complex128)
    sin2_t = (1.0 - c * c) / (eta * eta)
    cos_t = np.sqrt(1.0 - sin2_t)
    r_perp = (c - eta * cos_t) / (c + eta * cos_t)
    r_parl = (eta * c - cos_t) / (eta * c + cos_t)
    out: NDArray[np.float64] = 0.5 * (np.abs(r_perp) ** 2 + np.abs(r_parl) ** 2)
    return out


def fresnel(cos_i: ArrayLike, n: complex | float) -> NDArray[np.float64]:
    """Dispatch on the index: :func:`fresnel_dielectric` for real n (or k = 0), else conductor."""
    eta = complex(n)
    if eta.imag == 0.0:
        return fresnel_dielectric(cos_i, eta.real)
    return fresnel_conductor(cos_i, eta)
