"""Analytic microfacet BRDFs to compare with (and fit to) the facet model and real readings.

Four specular models, each a :class:`goniolab.optics.models.ReflectanceModel`:

``"beckmann"``
    Beckmann distribution with the exact Smith masking of Beckmann surfaces,
    ``f = D G1(wi) G1(wo) F(wi.h) / (4 cos ti cos to)`` (Walter et al. 2007, eqs. 20, 25, 27).
``"ggx"``
    GGX (Trowbridge-Reitz) distribution with its exact Smith Lambda (Walter eqs. 33-34;
    Heitz 2014, eq. 72), same microfacet BRDF.
``"cook-torrance"``
    Beckmann distribution with the V-cavity attenuation of Cook & Torrance (1982), Mihalik
    eq. 12; the normalisation is Walter's ``1/(4 cos ti cos to)`` (the 1982 paper has ``1/pi``,
    which does not conserve energy: docs/PHYSICS.md, "Analytic comparison models").
``"ward"``
    The specular lobe of Ward (1992), Mihalik eq. 14,
    ``f = rho_s exp(-tan^2 th_h / s^2) / (4 pi s^2 sqrt(cos ti cos to))``, with ``s = alpha``
    and ``rho_s = F(wi.h)`` so that all four models share the same Fresnel (Mihalik's rho_s is
    a free colour factor; the diffuse terms are omitted as in Mihalik sec. 3.3).

``alpha`` is the Beckmann/GGX roughness: for Beckmann the total rms slope (Sdq; per-axis rms
slope ``alpha / sqrt 2``), for Ward the slope standard deviation ``sigma``.

References
----------
.. [1] B. Walter, S. Marschner, H. Li, K. Torrance, "Microfacet models for refraction through
   rough surfaces", EGSR 2007, eqs. 20-34.
.. [2] E. Heitz, "Understanding the masking-shadowing function in microfacet-based BRDFs",
   JCGT 3(2) 2014, sec. 5 (Smith Lambda of Beckmann and GGX).
.. [3] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eqs. 10-17.
.. [4] G. Ward, "Measuring and modeling anisotropic reflection", SIGGRAPH 1992.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import erf

from goniolab.optics.apertures import (
    DEFAULT_N_RECEPTOR,
    DEFAULT_N_SOURCE,
    GONIO_CONE,
    ISO2813_BLACK_GLASS_N,
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Aperture,
    Rect,
    direction,
    integrate_brdf,
    lobe_subdivisions,
)
from goniolab.optics.fresnel import fresnel, fresnel_dielectric

__all__ = [
    "DEFAULT_CONE_RINGS",
    "KINDS",
    "AnalyticKind",
    "AnalyticModel",
    "beckmann_d",
    "beckmann_g1",
    "beckmann_lambda",
    "ggx_d",
    "ggx_g1",
    "ggx_lambda",
    "vcavity_g",
    "ward_lobe",
]

FloatArray = NDArray[np.float64]
AnalyticKind = Literal["beckmann", "ggx", "cook-torrance", "ward"]
#: The model kinds :class:`AnalyticModel` accepts.
KINDS: tuple[str, ...] = get_args(AnalyticKind)

_SQRT_PI = math.sqrt(math.pi)

#: Minimum rings of a cone receptor (1 + 3 k (k - 1) patches); more for narrow lobes.
DEFAULT_CONE_RINGS: int = 8


def _tan2(cos_t: FloatArray) -> FloatArray:
    c2 = np.clip(cos_t, 1e-300, 1.0) ** 2
    return np.asarray((1.0 - c2) / c2)


def beckmann_d(cos_th: ArrayLike, alpha: float) -> FloatArray:
    """Beckmann normal distribution ``D = exp(-tan^2 th / a^2) / (pi a^2 cos^4 th)`` (sr^-1).

    Walter et al. (2007) eq. 25; normalised so that ``int D(h) cos th_h dOmega_h = 1``.
    Zero for ``cos th <= 0``.
    """
    c = np.asarray(cos_th, dtype=np.float64)
    pos = c > 0.0
    cs = np.where(pos, c, 1.0)
    d = np.exp(-_tan2(cs) / alpha**2) / (np.pi * alpha**2 * cs**4)
    return np.where(pos, d, 0.0)


def ggx_d(cos_th: ArrayLike, alpha: float) -> FloatArray:
    """GGX distribution ``D = 1 / (pi a^2 cos^4 th (1 + tan^2 th / a^2)^2)`` (sr^-1).

    Walter et al. (2007) eq. 33. Zero for ``cos th <= 0``.
    """
    c = np.asarray(cos_th, dtype=np.float64)
    pos = c > 0.0
    cs = np.where(pos, c, 1.0)
    d = 1.0 / (np.pi * alpha**2 * cs**4 * (1.0 + _tan2(cs) / alpha**2) ** 2)
    return np.where(pos, d, 0.0)


def beckmann_lambda(cos_t: ArrayLike, alpha: float) -> FloatArray:
    """Smith Lambda of a Beckmann surface, ``(erf(u) - 1)/2 + exp(-u^2) / (2 u sqrt(pi))``.

    ``u = 1 / (a tan t)`` (Heitz 2014, eq. 80; Walter eq. 27 gives ``G1 = 1 / (1 + Lambda)``).
    Zero at normal incidence (u -> infinity).
    """
    c = np.clip(np.asarray(cos_t, dtype=np.float64), 1e-12, 1.0)
    tan_t = np.sqrt(_tan2(c))
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        u = 1.0 / (alpha * tan_t)
        lam = 0.5 * (erf(u) - 1.0) + np.exp(-(u**2)) / (2.0 * u * _SQRT_PI)
    return np.where(np.isfinite(u), lam, 0.0)


def beckmann_g1(cos_t: ArrayLike, alpha: float) -> FloatArray:
    """Exact Smith masking of Beckmann, ``G1 = 2 / (1 + erf(u) + exp(-u^2) / (u sqrt(pi)))``.

    ``u = 1 / (a tan t)`` (Walter et al. 2007, eq. 27; docs/PHYSICS.md, "Analytic comparison models"). Equals ``1 / (1 + Lambda)``.
    """
    return np.asarray(1.0 / (1.0 + beckmann_lambda(cos_t, alpha)))


def ggx_lambda(cos_t: ArrayLike, alpha: float) -> FloatArray:
    """Smith Lambda of GGX, ``(-1 + sqrt(1 + a^2 tan^2 t)) / 2`` (Heitz 2014, eq. 72)."""
    c = np.clip(np.asarray(cos_t, dtype=np.float64), 1e-12, 1.0)
    return np.asarray(0.5 * (-1.0 + np.sqrt(1.0 + alpha**2 * _tan2(c))))


def ggx_g1(cos_t: ArrayLike, alpha: float) -> FloatArray:
    """Smith masking of GGX, ``G1 = 2 / (1 + sqrt(1 + a^2 tan^2 t))`` (Walter eq. 34)."""
    return np.asarray(1.0 / (1.0 + ggx_lambda(cos_t, alpha)))


def vcavity_g(
    cos_th: ArrayLike, cos_i: ArrayLike, cos_o: ArrayLike, i_dot_h: ArrayLike
) -> FloatArray:
    """Cook-Torrance V-cavity attenuation (Mihalik eq. 12).

    ``G = min(1, 2 cos th_h cos to / (wo.h), 2 cos th_h cos ti / (wi.h))``; ``wo.h = wi.h``
    for the half vector.
    """
    ch = np.asarray(cos_th, dtype=np.float64)
    ih = np.clip(np.asarray(i_dot_h, dtype=np.float64), 1e-300, None)
    g = np.minimum(2.0 * ch * np.asarray(cos_o) / ih, 2.0 * ch * np.asarray(cos_i) / ih)
    return np.asarray(np.clip(g, 0.0, 1.0))


def ward_lobe(wi: ArrayLike, wo: ArrayLike, s: float) -> FloatArray:
    """Ward's specular lobe with ``rho_s = 1`` (Mihalik eq. 14; Ward 1992, eq. 4a isotropic).

    ``exp(-tan^2 th_h / s^2) / (4 pi s^2 sqrt(cos ti cos to))`` in sr^-1, zero when either
    direction is at or below the horizon.
    """
    a = np.asarray(wi, dtype=np.float64)
    b = np.asarray(wo, dtype=np.float64)
    ci, co = a[..., 2], b[..., 2]
    ok = (ci > 0.0) & (co > 0.0)
    h = a + b
    hn = np.linalg.norm(h, axis=-1)
    cos_h = np.where(hn > 0.0, h[..., 2] / np.where(hn > 0.0, hn, 1.0), 0.0)
    ok &= cos_h > 0.0
    cs = np.where(ok, cos_h, 1.0)
    val = np.exp(-_tan2(cs) / s**2) / (4.0 * np.pi * s**2 * np.sqrt(np.where(ok, ci * co, 1.0)))
    return np.where(ok, val, 0.0)


class AnalyticModel:
    """An analytic specular BRDF with the instrument responses of the ReflectanceModel protocol.

    Parameters
    ----------
    kind
        ``"beckmann"``, ``"ggx"``, ``"cook-torrance"`` or ``"ward"`` (module docstring).
    alpha
        Roughness, > 0: Beckmann/GGX ``alpha`` (Beckmann: total rms slope), Ward ``sigma``.
    n
        Refractive index; complex ``n + ik`` for conductors (Mihalik eq. 10).
    n_source, n_receptor, n_cone_rings
        Aperture subdivisions used by :func:`goniolab.optics.apertures.integrate_brdf`:
        source, rectangular receptor (per axis) and cone receptor (rings). The receptor
        counts are minima, raised per axis so that the grid step stays below the
        lobe width (:func:`goniolab.optics.apertures.lobe_subdivisions`, at most 400 per axis:
        very small ``alpha`` at 85 deg is then under-resolved).
    """

    def __init__(
        self,
        kind: str,
        *,
        alpha: float,
        n: complex = 1.55,
        n_source: int = DEFAULT_N_SOURCE,
        n_receptor: int = DEFAULT_N_RECEPTOR,
        n_cone_rings: int = DEFAULT_CONE_RINGS,
    ) -> None:
        if kind not in KINDS:
            raise ValueError(f"unknown analytic model kind {kind!r}; known: {', '.join(KINDS)}")
        a = float(alpha)
        if not (math.isfinite(a) and a > 0.0):
            raise ValueError(f"alpha must be finite and > 0, got {alpha!r}")
        nc = complex(n)
        if not (nc.real > 0.0 and nc.imag >= 0.0):
            raise ValueError(f"refractive index must have n > 0 and k >= 0, got {n!r}")
        self.kind: str = kind
        self.alpha: float = a
        self.n: complex = nc
        self.n_source = int(n_source)
        self.n_receptor = int(n_receptor)
        self.n_cone_rings = int(n_cone_rings)

    def __repr__(self) -> str:
        return f"AnalyticModel({self.kind!r}, alpha={self.alpha:g}, n={self.n!r})"

    # -- the BRDF -----------------------------------------------------------------------
    def _fresnel(self, cos_i: FloatArray) -> FloatArray:
        n: complex | float = self.n if self.n.imag != 0.0 else self.n.real
        return np.asarray(fresnel(cos_i, n), dtype=np.float64)

    def brdf(self, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
        """Vectorised BRDF ``f(wi, wo)`` in sr^-1 for unit vectors of shape ``(..., 3)``.

        ``wi`` points to the lamp, ``wo`` to the receptor; zero when either is at or below
        the horizon. Reciprocal: ``f(wi, wo) = f(wo, wi)``.
        """
        a = np.asarray(wi, dtype=np.float64)
        b = np.asarray(wo, dtype=np.float64)
        a, b = np.broadcast_arrays(a, b)
        ci, co = a[..., 2], b[..., 2]
        h = a + b
        hn = np.linalg.norm(h, axis=-1)
        ok = (ci > 0.0) & (co > 0.0) & (hn > 0.0)
        h = h / np.where(ok, hn, 1.0)[..., None]
        cos_h = h[..., 2]
        i_dot_h = np.clip(np.sum(a * h, axis=-1), 0.0, 1.0)
        fr = self._fresnel(i_dot_h)
        if self.kind == "ward":
            return np.where(ok, fr * ward_lobe(a, b, self.alpha), 0.0)
        cis, cos_ = np.where(ok, ci, 1.0), np.where(ok, co, 1.0)
        if self.kind == "ggx":
            d = ggx_d(cos_h, self.alpha)
            g = ggx_g1(cis, self.alpha) * ggx_g1(cos_, self.alpha)
        elif self.kind == "beckmann":
            d = beckmann_d(cos_h, self.alpha)
            g = beckmann_g1(cis, self.alpha) * beckmann_g1(cos_, self.alpha)
        else:  # cook-torrance
            d = beckmann_d(cos_h, self.alpha)
            g = vcavity_g(cos_h, cis, cos_, i_dot_h)
        f = d * g * fr / (4.0 * cis * cos_)
        return np.where(ok, f, 0.0)

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        """BRDF in sr^-1 for the lamp at (theta_i, 0) and the receptor at (theta_r, phi_r)."""
        wi = direction(theta_i_deg, 0.0)
        wo = direction(theta_r_deg, phi_r_deg)
        return float(self.brdf(wi, wo))

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """In-plane BRDF (sr^-1) at signed ``theta_r_deg`` (> 0 specular side)."""
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        wi = direction(theta_i_deg, 0.0)
        wo = direction(np.abs(tr), np.where(tr >= 0.0, 180.0, 0.0))
        return np.asarray(self.brdf(np.broadcast_to(wi, wo.shape), wo), dtype=np.float64)

    # -- instrument responses -----------------------------------------------------------
    def reflected_fraction(
        self, theta_i_deg: float, theta_r_deg: float, source: Aperture, receptor: Aperture
    ) -> float:
        """Fraction of the flux from ``source`` (at theta_i) reaching ``receptor`` (signed theta_r).

        Mihalik eq. 15 normalised by the source (:func:`integrate_brdf`).
        """
        # Per-axis rms slope alpha / sqrt(2); the mirror direction turns by twice the facet
        # tilt, foreshortened by cos(theta_r) out of the plane of incidence.
        s_axis = self.alpha / math.sqrt(2.0)
        cos_r = max(math.cos(math.radians(abs(theta_r_deg))), 1e-3)
        minimum = self.n_receptor if isinstance(receptor, Rect) else self.n_cone_rings
        n_rec = lobe_subdivisions(
            receptor, abs(theta_r_deg), 2.0 * s_axis, 2.0 * s_axis * cos_r, minimum=minimum
        )
        return integrate_brdf(
            self.brdf,
            theta_i_deg,
            theta_r_deg,
            source,
            receptor,
            n_source=self.n_source,
            n_receptor=n_rec,
        )

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = GONIO_CONE,
        detector: Aperture = GONIO_CONE,
    ) -> FloatArray:
        """Goniometer reading in % of a perfect mirror at each signed ``theta_r_deg``.

        ``100 x`` :meth:`reflected_fraction` with the lamp cone and detector cone of the
        Wittmann goniospectrophotometer (6 deg each, Wittmann sec. 2.3).
        """
        tr = np.atleast_1d(np.asarray(theta_r_deg, dtype=np.float64))
        out = np.array(
            [100.0 * self.reflected_fraction(theta_i_deg, float(t), source, detector) for t in tr]
        )
        return out.reshape(np.shape(theta_r_deg))

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        """ISO 2813 specular gloss in GU (Mihalik eqs. 15-17).

        ``G(t) = 100 Phi_sample / F(1.567, t)``: ``Phi_sample`` from :meth:`reflected_fraction`
        with the ISO 2813 source and receptor apertures, the black-glass flux being its
        Fresnel reflectance at t (its mirror image lies inside the receptor).
        """
        out: dict[int, float] = {}
        for t in angles_deg:
            if t not in ISO2813_RECEPTOR:
                raise ValueError(
                    f"no ISO 2813 geometry at {t} deg; known: {sorted(ISO2813_RECEPTOR)}"
                )
            phi = self.reflected_fraction(float(t), float(t), ISO2813_SOURCE, ISO2813_RECEPTOR[t])
            ref = float(fresnel_dielectric(math.cos(math.radians(t)), ISO2813_BLACK_GLASS_N))
            out[int(t)] = 100.0 * phi / ref
        return out
