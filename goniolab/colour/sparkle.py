"""Sparkle and graininess of effect paints from the flake population (BYK-mac S_a, S_i, G).

Definitions (ASTM E284-17): *sparkle* is "the aspect of the appearance of a material that
seems to emit or reveal tiny bright points of light that are strikingly brighter than their
immediate surround", seen under directional light; *graininess* is "the perceived contrast
of the light/dark irregular pattern exhibited when viewed under diffuse illumination". The
BYK-mac i images a panel with a camera along the normal, lit directionally from 15, 45 and
75 deg (sparkle) and diffusely (graininess), and reports per illumination angle a sparkle
area S_a and a sparkle intensity S_i (and a grade combining them), and a graininess G; its
image algorithms are not published, so its numbers are device scales (PTB/BiRD 2021; CIE
JTC 12). The quantities here are their radiometric counterparts from the flake model, in
the sense of Ferrero et al.'s analytical sparkle/graininess model (Opt. Express 21 (2013)
26812) and the CIE JTC 12 preliminary scales (Ferrero et al., Opt. Express 29 (2021) 7589):

- Flakes of diameter d (``size_um``) cover the area fraction A, so a camera pixel of side p
  holds on average ``N = A p^2 / (pi d^2 / 4)`` flakes. Their normals follow the paint's
  Beckmann distribution D (``spread_deg``, ``int D cos dOmega = 1``).
- A flake *sparkles* in a pixel when it mirrors the lamp into the camera: its normal lies in
  the solid angle ``Omega_h = Omega_s' / (4 cos theta_d')`` of half vectors that map the
  lamp's solid angle (inside the coat, ``Omega_s' = Omega_s cos t_i / (n^2 cos t_i')``) onto
  the view direction. The expected number of sparkling flakes per pixel is
  ``mu = N D(h') cos(theta_h') Omega_h`` (h' the half vector inside the coat); the count is
  Poisson.
- ``S_a`` (sparkle area): the fraction of pixels holding at least one sparkle,
  ``1 - exp(-mu)``, in percent.
- ``S_i`` (sparkle intensity): the mean luminance of a sparkling pixel over the surrounding
  (non-sparkling) pixels' luminance: a flake shows the lamp's radiance times
  ``R_m T_l^2 (1 - F_i)(1 - F_o)/n^2`` over its area, diluted by ``a_f / p^2`` in the pixel,
  against the diffuse background ``f_d E cos t_i``.
- ``G`` (graininess): under uniform diffuse light L the flakes show ``R_m T_l^2 (1-F) L``
  and the body ``pi f_d L``; the pixel's flake coverage c is a Poisson sum of flake areas
  with mean A and variance ``A a_f / p^2`` (at most A (1 - A)), so ``G = 100 |L_f - L_b|
  sqrt(var c) / (A L_f + (1 - A) L_b)``, the pixel contrast (coefficient of variation) in
  percent, evaluated on ``grain_pixel_um`` (default 50 um: the scale of the light/dark
  pattern E284 describes).

These are model predictions in absolute units, not BYK's calibrated scale; a lab relates
them to its instrument through its own panels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.colour.km import diffuse_fresnel_reflectance
from goniolab.colour.optics import fresnel_unpolarised
from goniolab.colour.paint import MetallicFlakes, Paint, PearlFlakes, beckmann_flake_d

__all__ = [
    "BYK_SPARKLE_ANGLES_DEG",
    "SparkleResult",
    "expected_sparkles",
    "graininess",
    "sparkle_report",
]

FloatArray = NDArray[np.float64]

#: BYK-mac i: directional illumination at 15, 45 and 75 deg, camera along the normal.
BYK_SPARKLE_ANGLES_DEG: tuple[float, ...] = (15.0, 45.0, 75.0)


def _refract_up(w: FloatArray, n: float) -> FloatArray:
    xy = w[..., :2] / n
    z = np.sqrt(np.clip(1.0 - np.sum(xy * xy, axis=-1, keepdims=True), 0.0, 1.0))
    out: FloatArray = np.concatenate([xy, z], axis=-1)
    return out


def expected_sparkles(
    wi: Any,
    wo: Any,
    flakes: MetallicFlakes | PearlFlakes,
    n: float,
    lamp_radius_deg: float,
    pixel_um: float,
) -> FloatArray:
    """``mu``: the expected number of flakes per pixel mirroring the lamp into the view.

    ``wi``, ``wo``: ``(..., 3)`` unit vectors (towards lamp, towards camera) in the local
    frame of the surface (z = normal); ``n``: coat index; ``lamp_radius_deg``: the lamp's
    angular radius; ``pixel_um``: the pixel's side on the sample.
    """
    wi_a = np.asarray(wi, dtype=np.float64)
    wo_a = np.asarray(wo, dtype=np.float64)
    ci = np.clip(wi_a[..., 2], 0.0, 1.0)
    wi_in = _refract_up(wi_a, n)
    wo_in = _refract_up(wo_a, n)
    h = wi_in + wo_in
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    cos_h = np.clip(h[..., 2], 1e-9, 1.0)
    cos_d = np.clip(np.sum(wi_in * h, axis=-1), 1e-9, 1.0)
    alpha = math.tan(math.radians(flakes.spread_deg))
    d = beckmann_flake_d(cos_h, alpha)
    rho = math.radians(lamp_radius_deg)
    omega_s = 2.0 * math.pi * (1.0 - math.cos(rho))
    omega_in = omega_s * ci / (n * n * np.clip(wi_in[..., 2], 1e-9, 1.0))  # etendue
    omega_h = omega_in / (4.0 * cos_d)
    a_flake = math.pi * flakes.size_um**2 / 4.0
    n_px = flakes.area_fraction * pixel_um**2 / a_flake
    out: FloatArray = np.where(ci > 0, n_px * d * cos_h * omega_h, 0.0)
    return out


@dataclass(frozen=True, slots=True)
class SparkleResult:
    """Sparkle per illumination angle and graininess of one flake population."""

    angles_deg: tuple[float, ...]
    mu: tuple[float, ...]
    S_a_pct: tuple[float, ...]
    S_i: tuple[float, ...]
    G: float
    pixel_um: float
    lamp_radius_deg: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "pixel_um": self.pixel_um,
            "lamp_radius_deg": self.lamp_radius_deg,
            "angles": [
                {"illumination_deg": a, "mu_per_pixel": m, "S_a_pct": sa, "S_i": si}
                for a, m, sa, si in zip(
                    self.angles_deg, self.mu, self.S_a_pct, self.S_i, strict=True
                )
            ],
            "G": self.G,
        }


def _flake_reflectance(paint: Paint, flakes: MetallicFlakes | PearlFlakes, wl: float) -> float:
    """R_m T_l^2 of a flake seen at near-normal incidence (the pigment above attenuating)."""
    wl_a = np.array([wl])
    n = paint.coat_n(wl_a)
    r = float(flakes.reflectance(np.ones((1, 1)), n, wl_a)[0, 0])
    if paint.body is not None and flakes.depth_um > 0:
        t_l, _ = paint.body.above_flake(flakes.depth_um, wl_a)
        r *= float(t_l[0]) ** 2
    return r


def graininess(paint: Paint, flakes: MetallicFlakes | PearlFlakes, pixel_um: float,
               wavelength_nm: float = 550.0) -> float:  # fmt: skip
    """G: the pixel contrast (%) under uniform diffuse light (module docstring)."""
    wl = np.array([wavelength_nm])
    n = float(paint.coat_n(wl)[0])
    r_f = _flake_reflectance(paint, flakes, wavelength_nm)
    f0 = float(fresnel_unpolarised(1.0, n))
    # a flake mirrors the diffuse light into the camera through the coat twice: R (1 - F0)^2 L
    l_f = r_f * (1.0 - f0) ** 2
    # the body under uniform light L: f_body T(t_o) int T(t_i) cos dw = pi f_body T_o (1 - r_e)
    t_o = float(paint.body_transmission(np.array([1.0]), wl)[0, 0])
    hemi = 1.0 if paint.saunderson == "textbook" else 1.0 - float(diffuse_fresnel_reflectance(n))
    l_b = math.pi * float(paint.body_term(wl)[0]) * t_o * hemi
    a = flakes.area_fraction
    a_f = math.pi * flakes.size_um**2 / 4.0
    mean = a * l_f + (1.0 - a) * l_b
    if mean <= 0:
        return 0.0
    # Poisson coverage: var(c) = A a_f / p^2, bounded by the all-or-nothing A (1 - A) of a
    # pixel smaller than a flake
    var_c = min(a * a_f / pixel_um**2, a * (1.0 - a))
    return 100.0 * abs(l_f - l_b) * math.sqrt(var_c) / mean


def sparkle_report(
    paint: Paint,
    *,
    pixel_um: float = 15.0,
    grain_pixel_um: float = 50.0,
    lamp_radius_deg: float = 1.0,
    angles_deg: tuple[float, ...] = BYK_SPARKLE_ANGLES_DEG,
    wavelength_nm: float = 550.0,
) -> dict[str, Any]:
    """S_a, S_i per illumination angle (camera along the normal) and G, per flake population
    of ``paint`` (``{}`` without flakes). Defaults: a 15 um pixel and a lamp of 1 deg
    angular radius (parameters of the model, reported with the result)."""
    if not (math.isfinite(pixel_um) and pixel_um > 0):
        raise ValueError(f"pixel_um must be > 0, got {pixel_um}")
    if not (math.isfinite(lamp_radius_deg) and 0 < lamp_radius_deg <= 30):
        raise ValueError(f"lamp_radius_deg must be in (0, 30], got {lamp_radius_deg}")
    out: dict[str, Any] = {}
    wl = np.array([wavelength_nm])
    n = float(paint.coat_n(wl)[0])
    f_d = float(paint.body_term(wl)[0])
    for name, flakes in (("metallic", paint.metallic), ("pearl", paint.pearl)):
        if flakes is None:
            continue
        r_f = _flake_reflectance(paint, flakes, wavelength_nm)
        mus, sas, sis = [], [], []
        a_px = pixel_um**2
        a_f = math.pi * flakes.size_um**2 / 4.0
        for ang in angles_deg:
            t = math.radians(ang)
            wi = np.array([math.sin(t), 0.0, math.cos(t)])
            wo = np.array([0.0, 0.0, 1.0])
            mu = float(expected_sparkles(wi, wo, flakes, n, lamp_radius_deg, pixel_um))
            f_i = float(fresnel_unpolarised(math.cos(t), n))
            f_o = float(fresnel_unpolarised(1.0, n))
            # a sparkling pixel: k >= 1 flakes, E[k | k >= 1] = mu / (1 - e^-mu)
            k_mean = mu / -math.expm1(-mu) if mu > 0 else 1.0
            spot = r_f * (1 - f_i) * (1 - f_o) / (n * n) * min(1.0, k_mean * a_f / a_px)
            rho = math.radians(lamp_radius_deg)
            omega_s = 2.0 * math.pi * (1.0 - math.cos(rho))
            bg = f_d * (1 - f_i) * (1 - f_o) * omega_s * math.cos(t)
            mus.append(mu)
            sas.append(100.0 * -math.expm1(-mu))
            sis.append(spot / bg if bg > 0 else math.inf)
        out[name] = SparkleResult(
            tuple(angles_deg), tuple(mus), tuple(sas), tuple(sis),
            graininess(paint, flakes, grain_pixel_um, wavelength_nm), pixel_um, lamp_radius_deg,
        ).as_dict()  # fmt: skip
        out[name]["grain_pixel_um"] = grain_pixel_um
        out[name]["flakes"] = {
            "size_um": flakes.size_um,
            "area_fraction": flakes.area_fraction,
            "depth_um": flakes.depth_um,
            "spread_deg": flakes.spread_deg,
        }
    return out
