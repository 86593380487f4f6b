"""The paint under the clear coat (Durikovic et al. 2007): pigment body and effect flakes.

The composite BRDF of the seed's eq. 1 is ``f = rho + tau (...)``: ``rho`` is the clear coat's
surface reflection -- here the rough-interface model of :mod:`goniolab.optics` (facet,
analytic, Kirchhoff...) evaluated with the coat's n(lambda) -- and the bracket is what lies
beneath, computed here per wavelength and returned as an *outside* BRDF (sr^-1):

- Body: a Kubelka-Munk pigment layer (:mod:`goniolab.colour.km`, seed eqs. 3-4) of
  reflectance R_b, Lambertian inside the coat. Light enters with ``T(t_i) = 1 - F(t_i)``,
  leaves with ``T(t_o)``, radiance is divided by n^2 on leaving, and the interface returns
  r_i of the upwelling diffuse flux (Saunderson)::

      f_body = (1 - A_m - A_p) T(t_i) T(t_o) R_b / (pi n^2 (1 - r_i R_b))

  whose hemispherical integral is Saunderson's ``(1 - r_e)(1 - r_i) R_b / (1 - r_i R_b)``.
- Metallic flakes: small mirrors covering the area fraction A_m, normals spread around the
  coat normal with a Beckmann distribution of rms tilt ``spread_deg`` (alpha = tan spread).
  Inside the coat (directions refracted by Snell, half vector h' of wi', wo')::

      f'_m = A_m R_m(wi'.h') D(h') / (4 cos t_i' cos t_o')

  (the seed's Cook-Torrance lobe, eq. 1, in Walter's normalisation; no masking for
  near-parallel flakes), and outside ``f_m = T(t_i) T(t_o) f'_m / n^2``. R_m is the flake's
  Fresnel reflectance against the binder (complex metal index / n), seen through the
  pigment of thickness X' (``depth_um``) above the flake. The seed's eq. 5 puts the whole
  KM reflectance of that layer over the flake into the lobe, i.e. also the pigment's own
  *diffuse* backscatter R_l(X') -- light that never reached the flake and has lost its
  direction (42 % of R_m for the built-in silver). Here the lobe keeps only the light that
  went to the flake and back, attenuated twice by the layer's KM transmittance
  ``T_l(X')`` (Kubelka 1948): ``R_m -> T_l^2 R_m``; the layer's backscatter
  ``A_m R_l(X')`` joins the Lambertian body term (through the same Saunderson interface).
  Flake-pigment inter-reflections (order ``T_l^2 R_m^2 R_l``) are left out.
  The lobe is centred on the mirror direction of the flakes: the refracted specular
  direction, which leaves the coat at theta_o = theta_i.
- Pearlescent flakes: the same lobe with the reflectance of a TiO2-coated mica platelet:
  an Airy film (binder | TiO2 d | mica) and, the mica being too thick for coherence (seed
  sec. 5.4), the film on the far side added incoherently:
  ``R = R1 + T1^2 R2 / (1 - R1 R2)``; the pigment above it as for metal flakes (the
  seed's eq. 8, with the same correction).
- Saunderson form. ``saunderson = "directional"`` (default) is the radiance form above:
  the body seen through T(t_i) T(t_o) / n^2, right for a goniometer. K/S databases and
  colour-matching software use the textbook form for a hemispherical/45-0 instrument,
  ``R = (1 - k1)(1 - k2) R_b / (1 - k2 R_b)`` (k1: external specular reflectance, by
  default F(0; n) = 0.04 for n = 1.5; k2: internal diffuse reflectance, by default r_i(n)
  = 0.596; specular component excluded), a constant radiance factor R / pi.
  ``saunderson = "textbook"`` uses it for the body so that K and S from such software
  reproduce their reflectances. The two differ by ``T(t_i) T(t_o) / (n^2 (1 - k1)(1 - k2))``
  = 1.046 at 45/0 for n = 1.5 (Y of a white is 4.6 % higher in the directional form).

Stated approximations: the coat's surface transmission uses the mean normal (a smooth
interface) for the light that reaches the body; flake reflections are single (no flake-flake
or flake-body inter-reflection), and light the flakes transmit is not followed.

References
----------
.. [1] R. Durikovic, K. Kolchin, S. Ershov, "Prediction of optical properties of paints",
   Cent. Eur. J. Phys. 5 (2007) 416, eqs. 1-8, sec. 7.
.. [2] B. Walter et al., "Microfacet models for refraction through rough surfaces", EGSR
   2007 (normalisation of D and the 4 cos cos denominator).
.. [3] J. L. Saunderson, JOSA 32 (1942) 727 (k1, k2); D. B. Judd, G. Wyszecki, Color in
   Business, Science and Industry, 3rd ed. (1975), ch. 8.
.. [4] P. Kubelka, JOSA 38 (1948) 448 (transmittance of a layer, composition of layers).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.colour.dispersion import (
    ALUMINIUM,
    Cauchy,
    Constant,
    Dispersion,
    DispersionError,
    Sellmeier,
    Tabulated,
    dispersion_from_dict,
)
from goniolab.colour.km import internal_diffuse_reflectance, km_reflectance, km_transmittance
from goniolab.colour.optics import airy_film, fresnel_unpolarised

__all__ = [
    "MICA_N",
    "TIO2",
    "MetallicFlakes",
    "Paint",
    "PaintError",
    "PearlFlakes",
    "PigmentLayer",
    "Spectrum",
    "beckmann_flake_d",
    "paint_from_dict",
    "paint_to_dict",
    "refracted_inside",
]

FloatArray = NDArray[np.float64]

#: TiO2 (anatase-like) film index, Cauchy fit (approximate: 2.68 at 400 nm, 2.49 at 700 nm).
TIO2 = Cauchy(A=2.40, B=0.045)
#: Muscovite mica (platelet core of pearl pigments).
MICA_N = 1.58


class PaintError(ValueError):
    """A paint definition is unusable (the message names the key)."""


@dataclass(frozen=True, slots=True)
class Spectrum:
    """A spectral quantity given at a few wavelengths, linearly interpolated (ends held)."""

    wavelengths_nm: tuple[float, ...]
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.wavelengths_nm) != len(self.values) or not self.values:
            raise PaintError("a spectrum needs one value per wavelength")
        if len(self.values) > 1 and np.any(np.diff(self.wavelengths_nm) <= 0):
            raise PaintError("spectrum wavelengths must be ascending")
        if not all(math.isfinite(v) for v in self.values):
            raise PaintError("spectrum values must be finite")

    @classmethod
    def flat(cls, value: float) -> Spectrum:
        """The same value at every wavelength."""
        return cls((550.0,), (float(value),))

    def at(self, wavelength_nm: ArrayLike) -> FloatArray:
        """Values at the given wavelengths."""
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        if len(self.values) == 1:
            return np.full(wl.shape, self.values[0])
        out: FloatArray = np.interp(wl, self.wavelengths_nm, self.values)
        return out

    def describe(self) -> dict[str, Any]:
        return {"wavelengths_nm": list(self.wavelengths_nm), "values": list(self.values)}


@dataclass(frozen=True, slots=True)
class PigmentLayer:
    """The Kubelka-Munk body: K and S (per um), thickness (um), substrate reflectance."""

    k_per_um: Spectrum
    s_per_um: Spectrum
    thickness_um: float
    substrate: Spectrum

    def __post_init__(self) -> None:
        if not (math.isfinite(self.thickness_um) and self.thickness_um >= 0):
            raise PaintError("body thickness_um must be >= 0")
        if min(self.k_per_um.values) < 0 or min(self.s_per_um.values) <= 0:
            raise PaintError("body K must be >= 0 and S > 0")
        if min(self.substrate.values) < 0 or max(self.substrate.values) > 1:
            raise PaintError("body substrate reflectance must be in [0, 1]")

    def ks(self, wavelength_nm: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """K and S per um at the wavelengths."""
        return self.k_per_um.at(wavelength_nm), self.s_per_um.at(wavelength_nm)

    def reflectance(self, wavelength_nm: ArrayLike) -> FloatArray:
        """KM reflectance R_b of the layer over its substrate (seed eq. 3)."""
        k, s = self.ks(wavelength_nm)
        return km_reflectance(k, s, self.thickness_um, self.substrate.at(wavelength_nm))

    def over(self, depth_um: float, r_flake: FloatArray, wavelength_nm: ArrayLike) -> FloatArray:
        """The seed's eqs. 5 and 8 as printed: the KM reflectance of the pigment of
        thickness ``depth_um`` over a flake (its diffuse backscatter included)."""
        k, s = self.ks(wavelength_nm)
        return km_reflectance(k, s, depth_um, r_flake)

    def above_flake(
        self, depth_um: float, wavelength_nm: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """``(T_l, R_l)``: KM transmittance and reflectance (over black) of the pigment of
        thickness ``depth_um`` above a flake (Kubelka 1948)."""
        k, s = self.ks(wavelength_nm)
        return km_transmittance(k, s, depth_um), km_reflectance(k, s, depth_um, 0.0 * k)


def beckmann_flake_d(cos_h: ArrayLike, alpha: float) -> FloatArray:
    """Beckmann distribution of flake normals, ``int D cos dOmega = 1``:
    ``D = exp(-tan^2 th / a^2) / (pi a^2 cos^4 th)``."""
    c = np.clip(np.asarray(cos_h, dtype=np.float64), 1e-9, 1.0)
    c2 = c * c
    tan2 = (1.0 - c2) / c2
    out: FloatArray = np.exp(-tan2 / (alpha * alpha)) / (np.pi * alpha * alpha * c2 * c2)
    return out


@dataclass(frozen=True, slots=True)
class MetallicFlakes:
    """Metal mirror flakes (the seed's sec. 5.3; its fig. 5b: spread 0.25, area ratio 0.4)."""

    area_fraction: float
    spread_deg: float
    depth_um: float = 0.0
    metal: Dispersion = ALUMINIUM
    #: Flake diameter (um): sparkle and graininess (:mod:`goniolab.colour.sparkle`); the
    #: averaged colour does not depend on it. Automotive aluminium flakes: D50 10-30 um.
    size_um: float = 20.0

    def __post_init__(self) -> None:
        _check_flakes(self.area_fraction, self.spread_deg, self.depth_um, "metallic")
        _check_size(self.size_um, "metallic")

    def reflectance(
        self, cos_local: FloatArray, n_binder: FloatArray, wl: FloatArray
    ) -> FloatArray:
        """Fresnel reflectance of the metal against the binder, ``(..., n_wl)``."""
        m = self.metal.index(wl)
        return fresnel_unpolarised(cos_local, m, n_binder)


@dataclass(frozen=True, slots=True)
class PearlFlakes:
    """TiO2-on-mica platelets (the seed's sec. 5.4): interference colour from the film."""

    area_fraction: float
    spread_deg: float
    film_nm: float
    depth_um: float = 0.0
    film: Dispersion = TIO2
    mica_n: float = MICA_N
    #: Platelet diameter (um), for sparkle and graininess; pearl pigments: D50 10-25 um.
    size_um: float = 15.0

    def __post_init__(self) -> None:
        _check_flakes(self.area_fraction, self.spread_deg, self.depth_um, "pearl")
        _check_size(self.size_um, "pearl")
        if not (math.isfinite(self.film_nm) and self.film_nm > 0):
            raise PaintError("pearl film_nm must be > 0")

    def reflectance(
        self, cos_local: FloatArray, n_binder: FloatArray, wl: FloatArray
    ) -> FloatArray:
        """Reflectance of the coated platelet in the binder, ``(..., n_wl)``."""
        nf = self.film.index(wl)
        r1, t1 = airy_film(cos_local, wl, n_binder, nf, self.film_nm, self.mica_n)
        # angle inside the mica, then the far film seen from the mica
        sin2 = (1.0 - np.clip(cos_local, 0, 1) ** 2) * (n_binder / self.mica_n) ** 2
        cos_m = np.sqrt(np.clip(1.0 - sin2, 0.0, 1.0))
        r2, _ = airy_film(cos_m, wl, self.mica_n, nf, self.film_nm, n_binder)
        out: FloatArray = r1 + t1 * t1 * r2 / (1.0 - r1 * r2)
        return out


def _check_size(size_um: float, what: str) -> None:
    if not (math.isfinite(size_um) and 0.5 <= size_um <= 500.0):
        raise PaintError(f"{what} size_um must be in [0.5, 500] um")


def _check_flakes(area: float, spread: float, depth: float, what: str) -> None:
    if not (math.isfinite(area) and 0.0 <= area <= 1.0):
        raise PaintError(f"{what} area_fraction must be in [0, 1]")
    if not (math.isfinite(spread) and 0.05 <= spread <= 45.0):
        raise PaintError(f"{what} spread_deg must be in [0.05, 45] deg")
    if not (math.isfinite(depth) and depth >= 0):
        raise PaintError(f"{what} depth_um must be >= 0")


def refracted_inside(w: ArrayLike, n: ArrayLike) -> FloatArray:
    """Directions inside the coat of the outside unit vectors ``w (..., 3)``, per index.

    The refracted ray, reversed so that it points up: ``(w_x/n, w_y/n, sqrt(1 - s^2/n^2))``.
    Returns ``(..., n_wl, 3)``.
    """
    w_a = np.asarray(w, dtype=np.float64)
    n_a = np.asarray(n, dtype=np.float64)
    xy = w_a[..., None, :2] / n_a[:, None]
    s2 = np.sum(xy * xy, axis=-1, keepdims=True)
    z = np.sqrt(np.clip(1.0 - s2, 0.0, 1.0))
    out: FloatArray = np.concatenate([xy, z], axis=-1)
    return out


#: Largest clear-coat index accepted (as ``[sample] n``: real coatings are 1.3-2.5).
COAT_INDEX_MAX = 4.0
_VISIBLE_NM = np.linspace(380.0, 780.0, 41)


@dataclass(frozen=True, slots=True)
class Paint:
    """A paint system: clear coat index, pigment body, optional metallic and pearl flakes.

    Parameters
    ----------
    saunderson, k1, k2
        The body's interface form: ``"directional"`` (radiance through T(t_i) T(t_o) / n^2,
        default) or ``"textbook"`` ((1 - k1)(1 - k2) R / (1 - k2 R), for K/S databases).
    coat
        The clear coat's n(lambda) (binder of the same index, seed sec. 5.1).
    body
        Kubelka-Munk pigment layer; ``None`` = a black body (the coat alone).
    metallic, pearl
        Flake populations (``None``: none).
    """

    coat: Dispersion = field(default_factory=lambda: Constant(1.5))
    body: PigmentLayer | None = None
    metallic: MetallicFlakes | None = None
    pearl: PearlFlakes | None = None
    #: ``"directional"`` (default) or ``"textbook"`` Saunderson form for the body.
    saunderson: str = "directional"
    #: Textbook Saunderson k1, k2 (``None``: F(0; n) and r_i(n) of the coat).
    k1: float | None = None
    k2: float | None = None

    def __post_init__(self) -> None:
        if self.saunderson not in ("directional", "textbook"):
            raise PaintError(f"saunderson: {self.saunderson!r} is not 'directional' or 'textbook'")
        for name, v in (("k1", self.k1), ("k2", self.k2)):
            if v is not None and not (math.isfinite(v) and 0.0 <= v < 1.0):
                raise PaintError(f"saunderson.{name}: must be in [0, 1), got {v!r}")
        a = (self.metallic.area_fraction if self.metallic else 0.0) + (
            self.pearl.area_fraction if self.pearl else 0.0
        )
        if a > 1.0:
            raise PaintError("flake area fractions add up to more than 1")
        # a clear coat is a dielectric of a real coating's index over the visible range
        # (a coat of n = 1.2e16 loaded and gave an infinite flake lobe)
        try:
            n = self.coat.index(_VISIBLE_NM)
        except DispersionError as exc:
            raise PaintError(f"coat: {exc}") from None
        if not (np.all(np.isfinite(n)) and np.all(n.imag == 0)):
            raise PaintError("coat: the clear coat needs a real, finite index")
        lo, hi = float(np.min(n.real)), float(np.max(n.real))
        if lo <= 1.0 or hi > COAT_INDEX_MAX:
            raise PaintError(
                f"coat: index {lo:.4g}..{hi:.4g} over 380-780 nm is outside "
                f"(1, {COAT_INDEX_MAX:g}] (a clear coat's refractive index)"
            )

    def coat_n(self, wl: ArrayLike) -> FloatArray:
        """Real coat index per wavelength (a dielectric coat is required)."""
        n = self.coat.index(wl)
        if np.any(n.imag != 0) or np.any(n.real <= 1.0):
            raise PaintError("the clear coat needs a real index > 1 (a dielectric)")
        return np.asarray(n.real, dtype=np.float64)

    def body_reflectance(self, wl: ArrayLike) -> FloatArray:
        """R_b per wavelength (0 without a body)."""
        wl_a = np.asarray(wl, dtype=np.float64)
        if self.body is None:
            return np.zeros(wl_a.shape)
        return self.body.reflectance(wl_a)

    def _flake_lobe(
        self,
        flakes: MetallicFlakes | PearlFlakes,
        wi_in: FloatArray,
        wo_in: FloatArray,
        n: FloatArray,
        wl: FloatArray,
    ) -> FloatArray:
        h = wi_in + wo_in
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        cos_h = h[..., 2]
        cos_d = np.clip(np.sum(wi_in * h, axis=-1), 0.0, 1.0)
        alpha = math.tan(math.radians(flakes.spread_deg))
        d = beckmann_flake_d(cos_h, alpha)
        rho = flakes.reflectance(cos_d, n, wl)
        if self.body is not None and flakes.depth_um > 0:
            t_l, _ = self.body.above_flake(flakes.depth_um, wl)
            rho = t_l * t_l * rho  # attenuation only: the backscatter is diffuse (body_term)
        out: FloatArray = flakes.area_fraction * rho * d / (4.0 * wi_in[..., 2] * wo_in[..., 2])
        return out

    @property
    def has_flakes(self) -> bool:
        """Whether any flake population is present."""
        return self.metallic is not None or self.pearl is not None

    def coat_transmission(self, cos_theta: ArrayLike, wavelength_nm: ArrayLike) -> FloatArray:
        """``T = 1 - F(theta; n(lambda))`` of the coat surface, ``(N, n_wl)`` (0 below the horizon)."""
        wl = np.asarray(wavelength_nm, dtype=np.float64).ravel()
        c = np.asarray(cos_theta, dtype=np.float64).reshape(-1, 1)
        t = 1.0 - fresnel_unpolarised(np.clip(c, 0.0, 1.0), self.coat_n(wl))
        out: FloatArray = np.where(c > 0, t, 0.0)
        return out

    def diffuse_reflectance(self, wavelength_nm: ArrayLike) -> FloatArray:
        """The diffuse reflectance under the coat: ``(1 - A) R_b`` of the body between the
        flakes plus ``A_f R_l(X'_f)``, the backscatter of the pigment above each flake
        population (0 without a body)."""
        wl = np.asarray(wavelength_nm, dtype=np.float64).ravel()
        if self.body is None:
            return np.zeros(wl.shape)
        a_flakes = 0.0
        above = np.zeros(wl.shape)
        for flakes in (self.metallic, self.pearl):
            if flakes is not None:
                a_flakes += flakes.area_fraction
                if flakes.depth_um > 0:
                    above = (
                        above + flakes.area_fraction * self.body.above_flake(flakes.depth_um, wl)[1]
                    )
        out: FloatArray = (1.0 - a_flakes) * self.body.reflectance(wl) + above
        return out

    def saunderson_k(self, wavelength_nm: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(k1, k2)`` of the textbook Saunderson form per wavelength: the given values, or
        F(0; n) and r_i(n) of the coat."""
        wl = np.asarray(wavelength_nm, dtype=np.float64).ravel()
        n = self.coat_n(wl)
        k1 = (
            np.full(wl.shape, self.k1)
            if self.k1 is not None
            else fresnel_unpolarised(np.ones(wl.shape), n).reshape(wl.shape)
        )
        k2 = np.full(wl.shape, self.k2) if self.k2 is not None else internal_diffuse_reflectance(n)
        return np.asarray(k1, dtype=np.float64), np.asarray(k2, dtype=np.float64)

    def body_term(self, wavelength_nm: ArrayLike) -> FloatArray:
        """The Lambertian part of :meth:`subsurface_brdf` divided by
        :meth:`body_transmission` at both ends, per wavelength (0 without a body):
        ``R_d / (pi n^2 (1 - r_i R_b))`` (directional Saunderson) or
        ``(1 - k1)(1 - k2) R_d / (pi (1 - k2 R_b))`` (textbook), R_d the
        :meth:`diffuse_reflectance`, R_b the body's."""
        wl = np.asarray(wavelength_nm, dtype=np.float64).ravel()
        if self.body is None:
            return np.zeros(wl.shape)
        rd = self.diffuse_reflectance(wl)
        # the flux the interface returns meets the body and the flakes' mirrors alike: the
        # inter-reflection denominator keeps the body's own R_b (as before the flakes'
        # share was split out), not the flake-diluted R_d
        rb = self.body.reflectance(wl)
        if self.saunderson == "textbook":
            k1, k2 = self.saunderson_k(wl)
            tb: FloatArray = (1.0 - k1) * (1.0 - k2) * rd / (np.pi * (1.0 - k2 * rb))
            return tb
        n = self.coat_n(wl)
        ri = internal_diffuse_reflectance(n)
        out: FloatArray = rd / (np.pi * (1.0 - ri * rb) * n * n)
        return out

    def body_transmission(self, cos_theta: ArrayLike, wavelength_nm: ArrayLike) -> FloatArray:
        """What the body term is seen through at each end, ``(N, n_wl)``: the coat's
        ``1 - F`` (directional Saunderson) or 1 above the horizon (textbook: the k1, k2
        losses are in :meth:`body_term`)."""
        if self.saunderson == "textbook":
            wl = np.asarray(wavelength_nm, dtype=np.float64).ravel()
            c = np.asarray(cos_theta, dtype=np.float64).reshape(-1, 1)
            out: FloatArray = np.where(c > 0, 1.0, 0.0) * np.ones((1, wl.size))
            return out
        return self.coat_transmission(cos_theta, wavelength_nm)

    def flake_brdf(self, wi: ArrayLike, wo: ArrayLike, wavelength_nm: ArrayLike) -> FloatArray:
        """The flake lobes of :meth:`subsurface_brdf` alone (outside, sr^-1), ``(N, n_wl)``."""
        wl = np.asarray(wavelength_nm, dtype=np.float64).ravel()
        wi_a = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo_a = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        out = np.zeros((wi_a.shape[0], wl.size))
        if not self.has_flakes:
            return out
        n = self.coat_n(wl)
        wi_in = refracted_inside(wi_a, n)
        wo_in = refracted_inside(wo_a, n)
        for flakes in (self.metallic, self.pearl):
            if flakes is not None:
                out = out + self._flake_lobe(flakes, wi_in, wo_in, n, wl)
        t = self.coat_transmission(wi_a[:, 2], wl) * self.coat_transmission(wo_a[:, 2], wl)
        result: FloatArray = t * out / (n * n)
        return result

    def subsurface_brdf(self, wi: ArrayLike, wo: ArrayLike, wavelength_nm: ArrayLike) -> FloatArray:
        """BRDF (sr^-1, outside) of everything under the coat surface, ``(N, n_wl)``.

        Parameters
        ----------
        wi, wo
            ``(N, 3)`` unit vectors towards the lamp and the detector (z = coat normal).
        wavelength_nm
            ``(n_wl,)`` wavelengths.
        """
        wl = np.asarray(wavelength_nm, dtype=np.float64).ravel()
        wi_a = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo_a = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        t = self.body_transmission(wi_a[:, 2], wl) * self.body_transmission(wo_a[:, 2], wl)
        out: FloatArray = t * self.body_term(wl)[None, :] + self.flake_brdf(wi_a, wo_a, wl)
        return out

    def describe(self) -> dict[str, Any]:
        """Parameters as stored with a run or printed by ``predict colour``."""
        out: dict[str, Any] = {"coat": self.coat.describe()}
        if self.saunderson != "directional" or self.k1 is not None or self.k2 is not None:
            out["saunderson"] = {"form": self.saunderson, "k1": self.k1, "k2": self.k2}
        if self.body is not None:
            out["body"] = {
                "K_per_um": self.body.k_per_um.describe(),
                "S_per_um": self.body.s_per_um.describe(),
                "thickness_um": self.body.thickness_um,
                "substrate": self.body.substrate.describe(),
            }
        if self.metallic is not None:
            m = self.metallic
            out["metallic"] = {
                "area_fraction": m.area_fraction,
                "spread_deg": m.spread_deg,
                "depth_um": m.depth_um,
                "size_um": m.size_um,
                "metal": m.metal.describe(),
            }
        if self.pearl is not None:
            p = self.pearl
            out["pearl"] = {
                "area_fraction": p.area_fraction,
                "spread_deg": p.spread_deg,
                "film_nm": p.film_nm,
                "depth_um": p.depth_um,
                "size_um": p.size_um,
            }
        return out


# ---------------------------------------------------------------------------- config
def _spectrum(value: Any, where: str) -> Spectrum:
    """A number (flat) or ``{wavelengths_nm = [...], values = [...]}``."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return Spectrum.flat(float(value))
    if isinstance(value, Mapping):
        try:
            return Spectrum(
                tuple(float(w) for w in value["wavelengths_nm"]),
                tuple(float(v) for v in value["values"]),
            )
        except KeyError as exc:
            raise PaintError(f"{where}: needs {exc.args[0]!r}") from None
        except (TypeError, ValueError) as exc:
            raise PaintError(f"{where}: {exc}") from None
    if isinstance(value, Sequence) and not isinstance(value, str):
        raise PaintError(f"{where}: give a number or a table with wavelengths_nm and values")
    raise PaintError(f"{where}: expected a number or a spectrum table, got {value!r}")


def _number(table: Mapping[str, Any], key: str, where: str, default: float | None = None) -> float:
    if key not in table:
        if default is None:
            raise PaintError(f"{where}.{key}: missing")
        return default
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise PaintError(f"{where}.{key}: expected a number, got {v!r}")
    return float(v)


def _short(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (an error stays one short line)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _key(where: str, key: str) -> str:
    """``paint.toml: body`` under a file, ``paint.body`` under a key (a file's name and the
    key inside it are not one dotted word: ``paint.toml.body`` read as a key)."""
    return f"{where}: {key}" if where.endswith(".toml") else f"{where}.{key}"


def _known(table: Any, keys: set[str], where: str) -> None:
    if not isinstance(table, Mapping):
        raise PaintError(f"{where}: expected a table, got {_short(table)}")
    extra = sorted(set(table) - keys)
    if extra:
        raise PaintError(f"{where}: unknown key {extra[0]!r} (known: {', '.join(sorted(keys))})")


def paint_from_dict(
    spec: Mapping[str, Any], *, where: str = "paint", tables: Mapping[str, str] = {}
) -> Paint:
    """Build a :class:`Paint` from a TOML table (see ``configs/samples.toml``).

    Keys: ``coat`` (index: number or dispersion table), ``[body]`` with ``K``, ``S``
    (per um; number or spectrum table), ``thickness_um``, ``substrate``; ``[metallic]`` with
    ``area_fraction``, ``spread_deg``, ``depth_um``, ``metal`` (dispersion, default
    aluminium); ``[pearl]`` with ``area_fraction``, ``spread_deg``, ``film_nm``, ``depth_um``.

    Raises
    ------
    PaintError
        ``where.key: reason``.
    """
    _known(spec, {"coat", "body", "metallic", "pearl", "saunderson"}, where)
    try:
        coat = dispersion_from_dict(spec.get("coat", 1.5), where=_key(where, "coat"), tables=tables)
        body = None
        if "body" in spec:
            b = spec["body"]
            w = _key(where, "body")
            _known(b, {"K", "S", "thickness_um", "substrate"}, w)
            body = PigmentLayer(
                k_per_um=_spectrum(b.get("K", 0.0), f"{w}.K"),
                s_per_um=_spectrum(b.get("S", 1.0), f"{w}.S"),
                thickness_um=_number(b, "thickness_um", w, 1e6),
                substrate=_spectrum(b.get("substrate", 0.0), f"{w}.substrate"),
            )
        metallic = None
        if "metallic" in spec:
            m = spec["metallic"]
            w = _key(where, "metallic")
            _known(m, {"area_fraction", "spread_deg", "depth_um", "metal", "size_um"}, w)
            metal = (
                dispersion_from_dict(m["metal"], where=f"{w}.metal", tables=tables)
                if "metal" in m
                else ALUMINIUM
            )
            metallic = MetallicFlakes(
                area_fraction=_number(m, "area_fraction", w),
                spread_deg=_number(m, "spread_deg", w),
                depth_um=_number(m, "depth_um", w, 0.0),
                metal=metal,
                size_um=_number(m, "size_um", w, 20.0),
            )
        pearl = None
        if "pearl" in spec:
            p = spec["pearl"]
            w = _key(where, "pearl")
            _known(p, {"area_fraction", "spread_deg", "film_nm", "depth_um", "size_um"}, w)
            pearl = PearlFlakes(
                area_fraction=_number(p, "area_fraction", w),
                spread_deg=_number(p, "spread_deg", w),
                film_nm=_number(p, "film_nm", w),
                depth_um=_number(p, "depth_um", w, 0.0),
                size_um=_number(p, "size_um", w, 15.0),
            )
        form, k1, k2 = "directional", None, None
        if "saunderson" in spec:
            sd = spec["saunderson"]
            w = _key(where, "saunderson")
            _known(sd, {"form", "k1", "k2"}, w)
            form = str(sd.get("form", "directional"))
            k1 = _number(sd, "k1", w) if "k1" in sd else None
            k2 = _number(sd, "k2", w) if "k2" in sd else None
        return Paint(
            coat=coat, body=body, metallic=metallic, pearl=pearl, saunderson=form, k1=k1, k2=k2
        )
    except DispersionError as exc:
        raise PaintError(str(exc)) from None
    except PaintError as exc:
        msg = str(exc)
        raise PaintError(msg if msg.startswith(where) else f"{where}: {msg}") from None


def _spectrum_value(sp: Spectrum) -> float | dict[str, list[float]]:
    if len(sp.values) == 1:
        return sp.values[0]
    return {"wavelengths_nm": list(sp.wavelengths_nm), "values": list(sp.values)}


def _dispersion_value(d: Dispersion, name: str, tables: dict[str, str]) -> Any:
    if d is ALUMINIUM:
        return {"kind": "aluminium"}
    if isinstance(d, Constant):
        n = complex(d.n)
        return n.real if n.imag == 0 else {"kind": "constant", "n": n.real, "k": n.imag}
    if isinstance(d, Cauchy):
        return {"kind": "cauchy", "A": d.A, "B": d.B, "C": d.C}
    if isinstance(d, Sellmeier):
        return {"kind": "sellmeier", "B": list(d.B), "C": list(d.C)}
    if isinstance(d, Tabulated):
        rows = ["# wavelength_nm n k"] + [
            f"{w:g} {n!r} {k!r}"
            for w, n, k in zip(d.wavelengths_nm, d.n, d.k or (0.0,) * len(d.n), strict=True)
        ]
        tables[name] = "\n".join(rows) + "\n"
        return {"kind": "table", "file": name}
    raise PaintError(f"cannot write a {type(d).__name__} index as a paint table")


def paint_to_dict(paint: Paint, *, stem: str = "paint") -> tuple[dict[str, Any], dict[str, str]]:
    """The inverse of :func:`paint_from_dict`: the TOML table of ``paint`` and the text of
    any n,k table it refers to (``{file name: text}``, names ``STEM-coat.nk``,
    ``STEM-metal.nk``, to be written beside the TOML file)."""
    tables: dict[str, str] = {}
    out: dict[str, Any] = {"coat": _dispersion_value(paint.coat, f"{stem}-coat.nk", tables)}
    if paint.saunderson != "directional" or paint.k1 is not None or paint.k2 is not None:
        sd: dict[str, Any] = {"form": paint.saunderson}
        if paint.k1 is not None:
            sd["k1"] = paint.k1
        if paint.k2 is not None:
            sd["k2"] = paint.k2
        out["saunderson"] = sd
    if paint.body is not None:
        b = paint.body
        out["body"] = {
            "K": _spectrum_value(b.k_per_um),
            "S": _spectrum_value(b.s_per_um),
            "thickness_um": b.thickness_um,
            "substrate": _spectrum_value(b.substrate),
        }
    if paint.metallic is not None:
        m = paint.metallic
        out["metallic"] = {
            "area_fraction": m.area_fraction,
            "spread_deg": m.spread_deg,
            "depth_um": m.depth_um,
            "size_um": m.size_um,
            "metal": _dispersion_value(m.metal, f"{stem}-metal.nk", tables),
        }
    if paint.pearl is not None:
        p = paint.pearl
        out["pearl"] = {
            "area_fraction": p.area_fraction,
            "spread_deg": p.spread_deg,
            "film_nm": p.film_nm,
            "depth_um": p.depth_um,
            "size_um": p.size_um,
        }
    return out, tables
