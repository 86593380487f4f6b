"""How noise in a spectrum becomes noise in its colour: first-order propagation to CIELAB.

A reading's reflectance factors ``R`` (per wavelength) with covariance ``C_R`` give
``XYZ = W R`` (:func:`goniolab.colour.spectra.xyz_weights`, the ASTM E308 weights:
linear in ``R``), so ``C_XYZ = W C_R W^T`` exactly; CIELAB is a smooth function of XYZ
(CIE 15:2004 eqs. 8.1-8.3) and ``C_Lab = J C_XYZ J^T`` with ``J = d(L*, a*, b*) / d(X, Y, Z)``
to first order (GUM, JCGM 100:2008, sec. 5.1.2, eq. 10, in matrix form as JCGM 101 / 102
write it). Valid while the noise is small against the values (a relative noise of a few
% keeps the second-order terms below 1 % of the first).

numpy only at import (colour-science through :mod:`goniolab.colour.spectra` when weights
are built).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.colour.spectra import ColourSettings, white_xyz, xyz_weights

__all__ = ["lab_covariance", "lab_jacobian", "rms_delta_e_ab"]

FloatArray = NDArray[np.float64]

_DELTA = 6.0 / 29.0


def _f_prime(t: FloatArray) -> FloatArray:
    """Derivative of CIE 15:2004's ``f(t)``: ``t^(-2/3) / 3`` above ``(6/29)^3``, else
    ``1 / (3 (6/29)^2)`` (the linear branch)."""
    return np.where(
        t > _DELTA**3,
        np.cbrt(np.maximum(t, _DELTA**3)) ** -2 / 3.0,
        1.0 / (3.0 * _DELTA**2),
    )


def lab_jacobian(xyz: ArrayLike, white: ArrayLike) -> FloatArray:
    """``d(L*, a*, b*) / d(X, Y, Z)`` at ``xyz`` relative to ``white`` (same scale), 3 x 3.

    From CIE 15:2004 eqs. 8.1-8.3: ``L* = 116 f(Y/Yn) - 16``, ``a* = 500 (f(X/Xn) -
    f(Y/Yn))``, ``b* = 200 (f(Y/Yn) - f(Z/Zn))``; ``d f(t_k) / d X_k = f'(t_k) / X_nk``.
    """
    xyz_a = np.asarray(xyz, dtype=np.float64).reshape(3)
    w = np.asarray(white, dtype=np.float64).reshape(3)
    d = _f_prime(xyz_a / w) / w  # d f_k / d X_k
    return np.array(
        [
            [0.0, 116.0 * d[1], 0.0],
            [500.0 * d[0], -500.0 * d[1], 0.0],
            [0.0, 200.0 * d[1], -200.0 * d[2]],
        ]
    )


def lab_covariance(
    wavelengths_nm: ArrayLike,
    factors: ArrayLike,
    cov_factors: ArrayLike,
    settings: ColourSettings | None = None,
) -> FloatArray:
    """Covariance of (L*, a*, b*) of reflectance factors ``factors`` whose covariance is
    ``cov_factors`` (N x N, or the N variances of independent wavelengths), 3 x 3.

    ``C_Lab = J W C_R W^T J^T`` (module docstring), with the weights and white of
    ``settings`` (default D65, CIE 1964 10 deg, ASTM E308), the same as the colour of the
    spectrum itself (:func:`goniolab.colour.spectra.spectrum_to_colour`).

    Raises
    ------
    ValueError
        ``cov_factors`` is neither N x N nor N long.
    """
    r = np.asarray(factors, dtype=np.float64).ravel()
    cov = np.asarray(cov_factors, dtype=np.float64)
    if cov.shape == r.shape:
        cov = np.diag(cov)
    if cov.shape != (r.size, r.size):
        raise ValueError(
            f"cov_factors must be {r.size} x {r.size} or {r.size} variances, got {cov.shape}"
        )
    w = xyz_weights(wavelengths_nm, settings)
    xyz = w @ r
    j = lab_jacobian(xyz, white_xyz(settings))
    out: FloatArray = j @ (w @ cov @ w.T) @ j.T
    return out


def rms_delta_e_ab(cov_lab: ArrayLike) -> float:
    """Root-mean-square CIE 1976 dE*ab of one reading from the mean, ``sqrt(trace C_Lab)``
    (dE*ab is the Euclidean distance in L*a*b*, CIE 15:2004 eq. 8.7)."""
    return float(np.sqrt(np.trace(np.asarray(cov_lab, dtype=np.float64))))
