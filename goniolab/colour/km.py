"""Kubelka-Munk pigment layers and the Saunderson correction for the clear coat interface.

Kubelka-Munk (Durikovic et al. 2007, sec. 5.2): a layer of thickness X with absorption K and
scattering S per unit length (per wavelength) over a substrate of reflectance Rg, lit and
seen diffusely. With ``a = 1 + K/S``, ``b = sqrt(a^2 - 1)`` (PHYSICS.md):

.. math:: R = \\frac{1 - R_g (a - b \\coth(b S X))}{a - R_g + b \\coth(b S X)},
          \\qquad R_\\infty = 1 + K/S - \\sqrt{(K/S)^2 + 2 K/S} = a - b.

The seed's eq. 3 writes the same R with exponentials of ``S X (1/R_inf - R_inf)``; it is
kept as :func:`km_reflectance_seed` (a test checks the two agree). K and S follow from the
reflectances R_w, R_b of one layer over a white (R_gw) and a black (R_gb) substrate, the
inversion the seed cites ([4] there; Kubelka 1948, Judd & Wyszecki): see :func:`km_from_contrast`.

Saunderson: light enters the coat with ``1 - r_e`` (external Fresnel), the body reflects
R_b diffusely, the interface returns ``r_i`` of the upwelling diffuse flux, so

.. math:: R = \\frac{(1 - r_e)(1 - r_i) R_b}{1 - r_i R_b}

(PHYSICS.md). :func:`internal_diffuse_reflectance` gives r_i from n by integrating the
Fresnel reflectance over the hemisphere inside the coat (0.596 for n = 1.5).

References
----------
.. [1] R. Durikovic et al., Cent. Eur. J. Phys. 5 (2007) 416, eqs. 3-5.
.. [2] P. Kubelka, F. Munk, Z. Tech. Phys. 12 (1931) 593; P. Kubelka, JOSA 38 (1948) 448.
.. [3] J. L. Saunderson, JOSA 32 (1942) 727.
.. [4] D. B. Judd, G. Wyszecki, Color in Business, Science and Industry, 3rd ed. (1975),
   ch. 8 (internal reflectance of a diffuse flux, about 0.6 for n = 1.5).
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.colour.optics import fresnel_unpolarised

__all__ = [
    "diffuse_fresnel_reflectance",
    "internal_diffuse_reflectance",
    "km_from_contrast",
    "km_r_inf",
    "km_reflectance",
    "km_reflectance_seed",
    "km_transmittance",
    "saunderson",
]

FloatArray = NDArray[np.float64]


def _ks(k: ArrayLike, s: ArrayLike) -> tuple[FloatArray, FloatArray]:
    k_a = np.asarray(k, dtype=np.float64)
    s_a = np.asarray(s, dtype=np.float64)
    if np.any(~np.isfinite(k_a)) or np.any(k_a < 0):
        raise ValueError("K must be finite and >= 0")
    if np.any(~np.isfinite(s_a)) or np.any(s_a <= 0):
        raise ValueError("S must be finite and > 0")
    return k_a, s_a


def km_r_inf(k_over_s: ArrayLike) -> FloatArray:
    """Reflectance of an opaque layer, ``R_inf = 1 + K/S - sqrt((K/S)^2 + 2 K/S)``
    (Durikovic 2007 eq. 4)."""
    q = np.asarray(k_over_s, dtype=np.float64)
    if np.any(~np.isfinite(q)) or np.any(q < 0):
        raise ValueError("K/S must be finite and >= 0")
    out: FloatArray = 1.0 + q - np.sqrt(q * q + 2.0 * q)
    return out


def km_reflectance(
    k: ArrayLike, s: ArrayLike, thickness: ArrayLike, r_substrate: ArrayLike
) -> FloatArray:
    """Diffuse reflectance of a KM layer over a substrate (hyperbolic form, PHYSICS.md).

    Parameters
    ----------
    k, s
        Absorption and scattering coefficients per unit length (any unit, the same as
        ``thickness``'s inverse), per wavelength; S > 0.
    thickness
        Layer thickness X (>= 0); 0 returns the substrate.
    r_substrate
        Substrate reflectance Rg in [0, 1].
    """
    k_a, s_a = _ks(k, s)
    x = np.asarray(thickness, dtype=np.float64)
    rg = np.asarray(r_substrate, dtype=np.float64)
    if np.any(x < 0) or np.any(~np.isfinite(x)):
        raise ValueError("thickness must be finite and >= 0")
    # R = (1 - Rg (a - b coth(bSX))) / (a - Rg + b coth(bSX)), a = 1 + K/S, b = sqrt(a^2 - 1),
    # with numerator and denominator multiplied by S: A = aS = S + K, B = bS =
    # sqrt(K (K + 2S)), C = bS coth(bSX) = B coth(BX). The same number, without forming K/S:
    # a scattering S of 1e-256 made (K/S)^2 overflow and R negative; S -> 0 now tends to
    # the clear absorber's Rg exp(-2KX).
    A = s_a + k_a
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        B = np.sqrt(k_a * (k_a + 2.0 * s_a))
        bx = B * x
        # B coth(BX), with its limit 1/X when B -> 0 (a non-absorbing layer)
        C = np.where(bx > 1e-8, B / np.tanh(np.maximum(bx, 1e-300)), 1.0 / x)
        r = (s_a - rg * (A - C)) / (A - rg * s_a + C)
        # K so large that B overflows: the opaque layer's R_inf = a - b = S / (A + B) -> 0
        r = np.where(np.isfinite(C), r, s_a / (A + B))
    out: FloatArray = np.where(x == 0, rg + 0.0 * A, r)
    return out


def km_transmittance(k: ArrayLike, s: ArrayLike, thickness: ArrayLike) -> FloatArray:
    """Diffuse transmittance of a KM layer, ``T = b / (a sinh(b S X) + b cosh(b S X))``."""
    k_a, s_a = _ks(k, s)
    x = np.asarray(thickness, dtype=np.float64)
    a = 1.0 + k_a / s_a
    b = np.sqrt(a * a - 1.0)
    bsx = b * s_a * x
    with np.errstate(over="ignore"):
        t = np.where(
            bsx > 1e-8,
            b / (a * np.sinh(bsx) + b * np.cosh(bsx)),
            1.0 / (1.0 + s_a * x + k_a * x),
        )
    out: FloatArray = np.nan_to_num(t, nan=0.0)
    return out


def km_reflectance_seed(
    k: ArrayLike, s: ArrayLike, thickness: ArrayLike, r_substrate: ArrayLike
) -> FloatArray:
    """The seed's eq. 3 (exponential form with R_inf); equal to :func:`km_reflectance`.

    ``R = [(1-R)(Rg-R) - R(Rg-1/R) e] / [(Rg-R) - (Rg-1/R) e]`` with ``R = R_inf`` in the
    brackets and ``e = exp(S X (1/R_inf - R_inf))``. The seed prints ``(1 - R_inf)`` as the
    first factor, which breaks the X = 0 limit; Kubelka's form (Judd & Wyszecki ch. 8) has
    ``1/R_inf``: ``R = [(1/R)(Rg-R) - R(Rg-1/R) e] / [(Rg-R) - (Rg-1/R) e]``, used here.
    """
    k_a, s_a = _ks(k, s)
    x = np.asarray(thickness, dtype=np.float64)
    rg = np.asarray(r_substrate, dtype=np.float64)
    ri = km_r_inf(k_a / s_a)
    e = np.exp(s_a * x * (1.0 / ri - ri))
    out: FloatArray = ((1.0 / ri) * (rg - ri) - ri * (rg - 1.0 / ri) * e) / (
        (rg - ri) - (rg - 1.0 / ri) * e
    )
    return out


def km_from_contrast(
    r_white: ArrayLike,
    r_black: ArrayLike,
    thickness: float,
    r_white_substrate: ArrayLike = 1.0,
    r_black_substrate: ArrayLike = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """K and S of a layer from its reflectances over a white and a black substrate.

    The seed (sec. 5.2) derives K and S "by inverting the Kubelka and Munk formulae" from
    one layer over white and over black. Write the hyperbolic form as
    ``R (a - R_g + c) = 1 - R_g a + R_g c`` with ``c = b coth(b S X)``; each reading gives
    ``c = (1 - a (R + R_g) + R R_g) / (R - R_g)``. Both share ``a`` and ``c``, so

    .. math:: a = \\frac{(1 + R_b R_{gb})(R_w - R_{gw}) - (1 + R_w R_{gw})(R_b - R_{gb})}
              {2 (R_w R_{gb} - R_b R_{gw})}

    (Kubelka 1948; for R_gw = 1, R_gb = 0 it is Kubelka's
    ``a = (1/2)(R_w + (R_b - R_w + 1)/R_b)``), then ``b = sqrt(a^2 - 1)``,
    ``S = arccoth(c / b) / (b X)`` and ``K = S (a - 1)``.

    Parameters
    ----------
    r_white, r_black
        Reflectance of the layer over the white and over the black substrate.
    thickness
        Layer thickness X (K, S come out per unit of it).
    r_white_substrate, r_black_substrate
        The substrates' own reflectances (ideal: 1 and 0).
    """
    rw = np.asarray(r_white, dtype=np.float64)
    rb = np.asarray(r_black, dtype=np.float64)
    gw = np.asarray(r_white_substrate, dtype=np.float64)
    gb = np.asarray(r_black_substrate, dtype=np.float64)
    if not thickness > 0:
        raise ValueError("thickness must be > 0")
    if np.any(rb >= rw) or np.any(rb < 0) or np.any(rw > 1):
        raise ValueError("need 0 <= R_black < R_white <= 1 at every wavelength")
    a = 0.5 * ((rw - rb) * (1.0 + gw * gb) - (gw - gb) * (1.0 + rw * rb)) / (rw * gb - rb * gw)
    if np.any(~np.isfinite(a)) or np.any(a <= 1.0):
        raise ValueError("readings inconsistent with a scattering, absorbing layer (a <= 1)")
    b = np.sqrt(a * a - 1.0)
    # The hyperbolic form solved for c = b coth(b S X): R (a - Rg + c) = 1 - Rg a + Rg c
    # -> c (R - Rg) = 1 - Rg a - R a + R Rg
    c = (1.0 - gb * a - rb * a + rb * gb) / (rb - gb)
    ratio = c / b  # coth(b S X) > 1
    if np.any(ratio <= 1.0):
        raise ValueError("readings imply an infinitely thick layer (no contrast)")
    s = np.arctanh(1.0 / ratio) / (b * thickness)
    k = s * (a - 1.0)
    return np.asarray(k, dtype=np.float64), np.asarray(s, dtype=np.float64)


def diffuse_fresnel_reflectance(n: ArrayLike, *, n_theta: int = 721) -> FloatArray:
    """External diffuse reflectance ``r_e = int_0^{pi/2} F(theta; n) sin(2 theta) dtheta``
    (a Lambertian flux from air onto the coat of index n; 0.092 for n = 1.5)."""
    n_a = np.atleast_1d(np.asarray(n, dtype=np.float64))
    out = np.array([_diffuse_fresnel(float(v), n_theta) for v in n_a.ravel()]).reshape(n_a.shape)
    result: FloatArray = out.reshape(np.shape(n)) if np.ndim(n) else out.reshape(())
    return result


@functools.lru_cache(maxsize=8)
def _gauss_legendre(k: int) -> tuple[FloatArray, FloatArray]:
    """Gauss-Legendre nodes and weights (an eigenvalue problem: computed once per order)."""
    x, w = np.polynomial.legendre.leggauss(k)
    return x, w


@functools.lru_cache(maxsize=4096)
def _diffuse_fresnel(n: float, n_theta: int) -> float:
    # Gauss-Legendre in theta over [0, pi/2]
    x, w = _gauss_legendre(n_theta // 4 + 16)
    theta = 0.25 * np.pi * (x + 1.0)
    f = fresnel_unpolarised(np.cos(theta), n)
    return float(0.25 * np.pi * np.sum(w * f * np.sin(2.0 * theta)))


def internal_diffuse_reflectance(n: ArrayLike) -> FloatArray:
    """Internal diffuse reflectance of the coat-air interface, ``r_i = 1 - (1 - r_e)/n^2``.

    A Lambertian flux inside a medium of index n: the part within the critical cone leaves
    with ``1 - F``; by reciprocity of the interface (etendue ``n^2 cos dOmega`` conserved)
    the escaping fraction is ``(1 - r_e)/n^2``. 0.596 for n = 1.5 (Judd & Wyszecki: ~0.6).
    """
    n_a = np.asarray(n, dtype=np.float64)
    out: FloatArray = 1.0 - (1.0 - diffuse_fresnel_reflectance(n_a)) / n_a**2
    return out


def saunderson(r_body: ArrayLike, r_external: ArrayLike, r_internal: ArrayLike) -> FloatArray:
    """Saunderson: ``R = (1 - r_e)(1 - r_i) R_b / (1 - r_i R_b)`` (body under a clear coat,
    the coat's own surface reflection not included)."""
    rb = np.asarray(r_body, dtype=np.float64)
    re = np.asarray(r_external, dtype=np.float64)
    ri = np.asarray(r_internal, dtype=np.float64)
    out: FloatArray = (1.0 - re) * (1.0 - ri) * rb / (1.0 - ri * rb)
    return out
