"""Scalar Kirchhoff scattering of the twin's true surface, integrated over an instrument's apertures.

The twin's optics (:class:`sim.truth.TruthOptics`) build an :class:`OrderTable` per
(wavelength, q_z band) and read it through the instrument's apertures
(:meth:`OrderTable.reading`); :func:`smith_shadowing` adds the coat's own shadowing and
masking.

**Scalar Kirchhoff (tangent-plane) scattering** on the true tile, not the facet model
(docs/PHYSICS.md, "Where the facet model stops: physical optics"; Beckmann & Spizzichino
1963; the NIST seed's "Kirchhoff" method). For a band of ``q_z = cos ti + cos ts`` the
field scattered into the direction-cosine offset ``(du, dv)`` from the specular direction is the FFT of the phase
screen ``exp(i k q_z z(x, y))``; on the periodic tile it is a grating, whose order
``(m, n)`` carries the fraction ``P = |U|^2 / N^2`` of the power (Parseval: they sum to
one). Each order is weighted by the Fresnel reflectance at the local incidence
``cos(iota) = |wi + wo| / 2`` and by the obliquity factor

.. math:: Q = \\frac{|w_i + w_o|^4}{4 \\cos\\theta_i \\cos\\theta_s q_z^2}
          = F_{geom}^2 \\frac{\\cos\\theta_i}{\\cos\\theta_s},

Beckmann's geometric factor ``F_geom = (1 + cos ti cos ts - sin ti sin ts cos ps) /
(cos ti (cos ti + cos ts))`` squared, times the change from solid angle to direction
cosines. ``Q = 1`` at the specular direction, so a flat surface is the Fresnel mirror,
a slightly rough one loses ``exp(-(k q_z Sq)^2)`` to diffuse scatter (Debye-Waller), and
in the geometrical-optics limit the stationary phase picks the facet of slope
``du / q_z`` that mirrors wi into wo, with the facet BRDF
``F P22 / (4 cos ti cos ts cos^4 theta_h)`` (PHYSICS.md): the limits the tests check.
It includes diffraction by features near the wavelength, the smooth-surface limit and
the grazing-incidence behaviour the seed's sec. 5.4 (eq. 14) finds the facet model
missing; shadowing and masking by the coat's roughness are applied to each reading as
Smith's ``G1(ti) G1(tr)`` for the tile's rms slope in the plane (:func:`smith_shadowing`:
felt at grazing angles on rough coats); no multiple reflections (on a dielectric these
are small, seed sec. 5.4).

``q_z`` varies over a sweep; the FFT is done for bands of ``q_z`` whose phase error
``k dq Sq`` stays below ``band_phase_rad`` (at least ``min_band_dq``, at most 0.25
apart); a reading rescales the two bands around its own ``q_z`` to it (exact in the
geometrical-optics and the smooth limits) and interpolates linearly between them. Each band is
evaluated at three wavelengths (450, 550, 650 nm by default) and interpolated over the
spectrum.

**The instrument integration** in direction-cosine space (Harvey-Shack shift
invariance): the source cone is an ellipse of semi-axes ``a_s cos ti`` x ``a_s`` around
the specular order (uniform), convolved with the waviness Gaussian; the detector cone an
ellipse ``a_d cos tr`` x ``a_d`` around its own direction cosine. The ISO 2813 rectangles
are rectangles. A reading is the convolved order power summed over the detector, by
row-wise cumulative sums (partial cells interpolated).

References
----------
.. [1] B. Wittmann et al., Prog. Org. Coat. 156 (2021) 106247, secs. 5.2-5.4.
.. [2] P. Beckmann, A. Spizzichino, "The Scattering of Electromagnetic Waves from Rough
   Surfaces" (1963), ch. 3 (Kirchhoff, geometric factor F).
.. [3] J. E. Harvey et al., "Diffracted radiance: a fundamental quantity in nonparaxial
   scalar diffraction theory", Appl. Opt. 38 (1999) 6469 (direction-cosine space).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.apertures import Aperture, Cone, Rect
from goniolab.optics.fresnel import fresnel

__all__ = ["OrderTable", "gauss_blur", "smith_shadowing"]

FloatArray = NDArray[np.float64]


@dataclass
class OrderTable:
    """Order powers of one (wavelength, q_z band) phase screen: the fraction ``|U|^2/N^2``
    of the power each diffraction order carries, at offsets ``(du, dv)`` from the specular
    direction (direction cosines; u along the specular side of the plane of incidence),
    rows ``|dv| <= reach``, blurred by the spot-scale waviness."""

    du: FloatArray  # (ncol,) ascending, uniform
    dv: FloatArray  # (nrow,) ascending, uniform
    p: NDArray[np.float32]  # (nrow, ncol)
    qz: float  # the band's q_z

    def reading(
        self,
        theta_i_deg: float,
        u_d: float,
        q_exact: float,
        n: complex,
        source: Aperture,
        detector: Aperture,
    ) -> float:
        """Flux fraction reaching ``detector`` centred on the in-plane direction cosine
        ``u_d`` for incidence ``theta_i_deg``.

        The band's orders are first rescaled by ``c = q_exact / qz`` about the specular
        direction: in the geometrical-optics regime the pattern of a phase screen scales
        with q_z (an order at du comes from slopes du/q_z), and the coherent specular
        order stays where it is, so the rescaling makes the band exact at the reading's
        own q_z in both limits. Each order is weighted by the Fresnel reflectance at its
        local incidence and by the obliquity factor Q, and spreads the source's image
        around its own direction (a cap of the source's size: cap overlap with the
        detector; rectangles for ISO 2813).
        """
        ti = math.radians(theta_i_deg)
        sin_ti, cos_ti = math.sin(ti), math.cos(ti)
        if isinstance(source, Cone) and isinstance(detector, Cone):
            a_s = math.radians(source.half_angle_deg)
            a_d = math.radians(detector.half_angle_deg)
            reach = math.sin(min(a_s + a_d, math.pi / 2))
        elif isinstance(source, Rect) and isinstance(detector, Rect):
            reach = math.radians(0.5 * (source.in_plane_deg + detector.in_plane_deg))
        else:
            raise TypeError("source and detector must both be Cones or both Rects")
        c = q_exact / self.qz
        h = float(self.du[1] - self.du[0])
        lo = max(0, math.floor(((u_d - sin_ti - reach) / c - self.du[0]) / h) - 1)
        hi = min(self.du.size, math.ceil(((u_d - sin_ti + reach) / c - self.du[0]) / h) + 2)
        if hi <= lo:
            return 0.0
        u = sin_ti + c * self.du[None, lo:hi]
        v = c * self.dv[:, None]
        p = self.p[:, lo:hi].astype(np.float64)
        g2 = 1.0 - u * u - v * v
        ok = g2 > 0.0
        g = np.sqrt(np.where(ok, g2, 1.0))
        q = cos_ti + g
        s2 = (sin_ti - u) ** 2 + v * v + q * q  # |wi + wo|^2
        obliq = s2 * s2 / (4.0 * cos_ti * g * q * q)
        fr_lut = _fresnel_lut(n)
        pos_f = np.clip(0.5 * np.sqrt(s2), 0.0, 1.0) * (fr_lut.size - 2)
        i_f = pos_f.astype(np.int64)
        fr = fr_lut[i_f] + (pos_f - i_f) * (fr_lut[i_f + 1] - fr_lut[i_f])
        g_d = math.sqrt(max(0.0, 1.0 - u_d * u_d))
        if isinstance(source, Cone) and isinstance(detector, Cone):
            chord2 = (u - u_d) ** 2 + v * v + (g - g_d) ** 2
            x_max, lut = _cone_lut(source.half_angle_deg, detector.half_angle_deg)
            pos = np.minimum(chord2 * ((lut.size - 2) / x_max), lut.size - 2)
            i0 = pos.astype(np.int64)
            w = lut[i0] + (pos - i0) * (lut[i0 + 1] - lut[i0])
        else:
            assert isinstance(source, Rect) and isinstance(detector, Rect)
            t_o = np.arcsin(np.clip(u / np.sqrt(np.clip(1.0 - v * v, 1e-12, None)), -1.0, 1.0))
            b_o = np.arcsin(np.clip(v, -1.0, 1.0))
            t_d = math.asin(max(-1.0, min(1.0, u_d)))
            w = _overlap_1d(
                t_o - t_d, math.radians(source.in_plane_deg), math.radians(detector.in_plane_deg)
            ) * _overlap_1d(b_o, math.radians(source.perp_deg), math.radians(detector.perp_deg))
        return float(np.sum(np.where(ok, p * fr * obliq * w, 0.0)))


def smith_shadowing(theta_deg: float | FloatArray, slope_rms: float) -> FloatArray:
    """Smith's shadowing (masking) function G1 of a Gaussian surface of rms slope
    ``slope_rms`` in the plane, seen at ``theta_deg`` from the normal (B. G. Smith, IEEE
    Trans. Antennas Propag. 15 (1967) 668; Walter et al., EGSR 2007, eq. 27)::

        nu = cot(theta) / (sqrt(2) sigma),   Lambda = (exp(-nu^2) / (nu sqrt(pi)) - erfc(nu)) / 2
        G1 = 1 / (1 + Lambda)

    1 at normal incidence and for a smooth coat, falling at grazing angles for a rough one.
    """
    from scipy.special import erfc

    t = np.radians(np.abs(np.asarray(theta_deg, dtype=np.float64)))
    if slope_rms <= 0.0:
        return np.ones_like(t)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = 1.0 / np.tan(np.clip(t, 1e-9, math.pi / 2 - 1e-9)) / (math.sqrt(2.0) * slope_rms)
        lam = 0.5 * (np.exp(-(nu**2)) / (nu * math.sqrt(math.pi)) - erfc(nu))
    return np.asarray(1.0 / (1.0 + np.maximum(lam, 0.0)))


def _overlap_1d(d: FloatArray, a: float, b: float) -> FloatArray:
    """Fraction of an interval of width ``a`` centred at ``d`` inside one of width ``b``
    centred at 0."""
    if a <= 0.0:
        return np.asarray(np.where(np.abs(d) <= 0.5 * b, 1.0, 0.0))
    ov = np.minimum(d + 0.5 * a, 0.5 * b) - np.maximum(d - 0.5 * a, -0.5 * b)
    return np.asarray(np.clip(ov, 0.0, None) / a)


@functools.lru_cache(maxsize=16)
def _fresnel_lut(n: complex) -> FloatArray:
    """Fresnel reflectance on a uniform grid of 16384 intervals of cos(iota) in [0, 1]
    (plus a repeated last value), for linear interpolation."""
    c = np.linspace(0.0, 1.0, 16385)
    f = fresnel(c, n)
    return np.append(f, f[-1])


@functools.lru_cache(maxsize=16)
def _cone_lut(src_half_deg: float, det_half_deg: float) -> tuple[float, FloatArray]:
    """Cap overlap (:func:`goniolab.optics.facet.cap_overlap_fraction`) against the squared
    chord ``|wo - d|^2 = 4 sin^2(gamma/2)`` between an image centre and the detector axis,
    on a uniform grid ``[0, x_max]`` of 8192 intervals with a trailing 0 beyond."""
    from goniolab.optics.apertures import cap_overlap_fraction

    a_s, a_d = math.radians(src_half_deg), math.radians(det_half_deg)
    g_max = min(a_s + a_d, math.pi / 2)
    x_max = (2.0 * math.sin(0.5 * g_max)) ** 2 * 1.0001
    x = np.linspace(0.0, x_max, 8193)
    gamma = 2.0 * np.arcsin(np.clip(np.sqrt(x) / 2.0, 0.0, 1.0))
    return x_max, np.append(cap_overlap_fraction(gamma, a_s, a_d), 0.0)


def gauss_blur(p: FloatArray, sigma_v: float, sigma_u: float) -> FloatArray:
    """Separable Gaussian blur (sigmas in cells); the rows/cols beyond the edges are zero."""
    out = p
    for axis, sig in ((0, sigma_v), (1, sigma_u)):
        if sig < 0.05:
            continue
        r = math.ceil(4.0 * sig)
        k = np.exp(-0.5 * (np.arange(-r, r + 1) / sig) ** 2)
        k /= k.sum()
        acc = np.zeros_like(out)
        n = out.shape[axis]
        for j, kj in zip(range(-r, r + 1), k, strict=True):
            src = [slice(None)] * 2
            dst = [slice(None)] * 2
            src[axis] = slice(max(0, -j), n - max(0, j))
            dst[axis] = slice(max(0, j), n - max(0, -j))
            acc[tuple(dst)] += kj * out[tuple(src)]
        out = acc
    return out
