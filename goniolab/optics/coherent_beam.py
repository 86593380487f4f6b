"""The coherent specular beam of the physical-optics models, summed analytically.

Every source direction ``s`` sends ``R(s) C(s)`` (its own Fresnel reflectance and the
coherent factor of the map, :func:`coherent_reflectance`) to its mirror direction; an
instrument collects the part of the source's mirror image inside its receptor
(:func:`coherent_sums`), whatever the FFT cell size of the diffuse part
(:mod:`goniolab.optics.physical`, "No silent fallback").

References
----------
.. [1] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eq. 15 (the source's
   flux normalised by its solid angle).
.. [2] P. Beckmann, A. Spizzichino, "The Scattering of Electromagnetic Waves from Rough
   Surfaces", 1963 (the coherent factor exp(-g) of Gaussian heights).
"""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.apertures import Aperture, Cone, Rect
from goniolab.optics.fresnel import fresnel

__all__ = ["coherent_reflectance", "coherent_sums"]

FloatArray = NDArray[np.float64]


@functools.cache
def _gauss_legendre(n: int) -> tuple[FloatArray, FloatArray]:
    """``numpy.polynomial.legendre.leggauss(n)``, formed once per n (an eigenvalue
    problem each call: a 16-wavelength gloss asked for it a hundred times)."""
    x, w = np.polynomial.legendre.leggauss(n)
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


def coherent_reflectance(
    cos_s: FloatArray, theta_i_deg: float, c_nominal: float, n: complex
) -> FloatArray:
    """``R(theta_s) C(theta_s)`` of the coherent beam for source directions of cosine
    ``cos_s``: Fresnel per direction and the coherent factor carried from the nominal
    incidence as for Gaussian heights, ``C(theta_s) = C(ti)^((cos ts / cos ti)^2)``
    (``exp(-g)`` with ``g ~ cos^2``)."""
    ci = math.cos(math.radians(theta_i_deg))
    cs = np.clip(np.asarray(cos_s, dtype=np.float64), 0.0, 1.0)
    if c_nominal <= 0.0:
        return np.zeros_like(cs)
    c = np.exp(math.log(min(c_nominal, 1.0)) * (cs / ci) ** 2)
    out: FloatArray = np.where(cs > 0.0, fresnel(cs, n) * c, 0.0)
    return out


def coherent_sums(
    theta_i_deg: float,
    c_nominal: float,
    theta_r_deg: FloatArray,
    source: Aperture,
    receptor: Aperture,
    n: complex,
) -> FloatArray:
    """Flux fraction of the coherent specular beam reaching the receptor at each angle
    (of a surface of index ``n``).

    Analytic, whatever the FFT cell: every source direction ``s`` sends
    ``R(s) C(s)`` (:func:`coherent_reflectance`) to its mirror direction, which the
    receptor collects when it lies inside it, so the reading is the integral over the
    source of that product, normalised by the source's solid angle (Mihalik eq. 15).
    Cones: the source's mirror cap in polar coordinates about its centre, Gauss-Legendre
    in the polar angle (split where the circle meets the receptor's rim) and, on each
    circle, over the arc inside the receptor (spherical law of cosines); source
    directions below the horizon send nothing. Rectangles: the product of the in-plane
    and out-of-plane intervals, Gauss-Legendre over their intersection with the mirror
    image, as the rectangle sums measure them (:mod:`._cell_kernels`).
    """
    tr = np.radians(np.asarray(theta_r_deg, dtype=np.float64))
    ti = math.radians(theta_i_deg)
    out = np.zeros(tr.size)
    if isinstance(source, Rect) and isinstance(receptor, Rect):
        a_s, b_s = math.radians(source.in_plane_deg), math.radians(source.perp_deg)
        a_r, b_r = math.radians(receptor.in_plane_deg), math.radians(receptor.perp_deg)
        xb, wb = _gauss_legendre(8)
        xa, wa = _gauss_legendre(12)
        # out of plane: the mirror image of beta is -beta, inside when |beta| <= b_r / 2
        if b_s == 0.0:
            bb, wbb, norm_b = np.zeros(1), np.ones(1), 1.0
        else:
            hb = 0.5 * min(b_s, b_r)
            bb, wbb = hb * xb, hb * wb * np.cos(hb * xb)
            norm_b = 2.0 * math.sin(0.5 * b_s)
        for k, a_c in enumerate(tr):
            # in plane: source offset a, mirror at ti + a, inside when |ti + a - tr| <= a_r/2
            if a_s == 0.0:
                if abs(ti - a_c) > 0.5 * a_r + 1e-15:
                    continue
                aa, waa, norm_a = np.zeros(1), np.ones(1), 1.0
            else:
                lo = max(-0.5 * a_s, a_c - ti - 0.5 * a_r)
                hi = min(0.5 * a_s, a_c - ti + 0.5 * a_r)
                if hi <= lo:
                    continue
                aa, waa = 0.5 * (hi + lo) + 0.5 * (hi - lo) * xa, 0.5 * (hi - lo) * wa
                norm_a = a_s
            cos_s = np.cos(ti + aa)[:, None] * np.cos(bb)[None, :]
            f = coherent_reflectance(cos_s, theta_i_deg, c_nominal, n)
            out[k] = float(waa @ f @ wbb) / (norm_a * norm_b)
        return out
    assert isinstance(source, Cone) and isinstance(receptor, Cone)
    a_s, a_d = math.radians(source.half_angle_deg), math.radians(receptor.half_angle_deg)
    m0 = np.array([-math.sin(ti), 0.0, math.cos(ti)])  # the specular direction
    e1 = np.array([-math.cos(ti), 0.0, -math.sin(ti)])  # in plane, towards larger theta
    e2 = np.array([0.0, 1.0, 0.0])
    d = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
    cg = np.clip(d @ m0, -1.0, 1.0)
    gam = np.arccos(cg)
    psi = np.arctan2(d @ e2, d @ e1)
    if a_s == 0.0:
        r0 = float(coherent_reflectance(np.array([m0[2]]), theta_i_deg, c_nominal, n)[0])
        return np.where(gam < a_d, r0, np.where(gam == a_d, 0.5 * r0, 0.0))
    xu, wu = _gauss_legendre(12)
    xv, wv = _gauss_legendre(16)
    omega_s = 2.0 * math.pi * (1.0 - math.cos(a_s))
    # the horizon cuts circles of polar radius u > pi/2 - ti about the mirror centre:
    # z = cos u cos ti - sin u sin ti cos v > 0 leaves |v| > acos(cos u cos ti / (sin u sin ti))
    u_h = 0.5 * math.pi - ti
    for k in range(tr.size):
        g = float(gam[k])
        if g >= a_s + a_d:
            continue
        kinks = (abs(g - a_d), g + a_d, u_h)
        cuts = sorted({0.0, a_s, *(c for c in kinks if 0.0 < c < a_s)})
        acc = 0.0
        for u0, u1 in itertools.pairwise(cuts):
            u = 0.5 * (u0 + u1) + 0.5 * (u1 - u0) * xu
            wuu = 0.5 * (u1 - u0) * wu * np.sin(u)
            su, cu = np.sin(u), np.cos(u)
            if g < 1e-12:
                half = np.where(u < a_d, math.pi, 0.0)
            else:
                cc = (math.cos(a_d) - cu * math.cos(g)) / (su * math.sin(g))
                half = np.arccos(np.clip(cc, -1.0, 1.0))
            with np.errstate(divide="ignore", invalid="ignore"):
                hh = np.where(su * math.sin(ti) > 0, cu * math.cos(ti) / (su * math.sin(ti)), 2.0)
            a_h = np.arccos(np.clip(hh, -1.0, 1.0))
            lo, hi = float(psi[k]) - half, float(psi[k]) + half
            for i_lo, i_hi in (
                (np.maximum(lo, a_h - 2.0 * math.pi), np.minimum(hi, -a_h)),
                (np.maximum(lo, a_h), np.minimum(hi, 2.0 * math.pi - a_h)),
            ):
                hw = 0.5 * np.maximum(i_hi - i_lo, 0.0)
                v = (0.5 * (i_lo + i_hi))[:, None] + hw[:, None] * xv[None, :]
                z = cu[:, None] * m0[2] + su[:, None] * (np.cos(v) * e1[2])
                f = coherent_reflectance(np.where(z > 0, z, 0.0), theta_i_deg, c_nominal, n)
                acc += float(np.sum(wuu[:, None] * (hw[:, None] * wv[None, :]) * f))
        out[k] = acc / omega_s
    return out
