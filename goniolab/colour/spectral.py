"""The predicted spectrum of a goniometer reading: rough coat surface + paint beneath.

A reading at (theta_i, theta_r) through the lamp and detector cones is, per wavelength,

    reading(lambda) = 100 x [ Phi_surface(n(lambda), lambda) + Phi_paint(lambda) ]   (% of mirror)

- ``Phi_surface``: the coat surface's reflection from *any* surface model
  (:class:`goniolab.optics.models.ReflectanceModel`: facet, analytic, Kirchhoff...), built
  by a :class:`SurfaceFactory` for the coat index n(lambda) and the wavelength, and
  integrated over the apertures by the model itself (``luminance_pct``).
- ``Phi_paint``: the subsurface BRDF of :class:`goniolab.colour.paint.Paint` integrated over
  the same apertures (Mihalik & Durikovic eq. 15, source-normalised, with the cone
  quadrature of :func:`goniolab.optics.apertures.sample_aperture`).

Building and evaluating a surface model per wavelength is the expensive part. A model whose
only wavelength dependence is n (geometric optics: facet, analytic) is smooth in n, so it is
evaluated at three Chebyshev nodes spanning the coat's n range and interpolated
quadratically in n (the Fresnel term is analytic in n; the error against a per-wavelength
evaluation is measured in the tests, < 1e-4 relative for Cauchy coats); a constant n needs
one evaluation. Physical-optics models (their BRDF depends on lambda itself) are evaluated
at wavelength nodes ``node_step_nm`` apart and interpolated with a cubic spline;
``exact=True`` evaluates every wavelength.

Colour from a reading: a multi-angle spectrophotometer reports the reflectance factor
relative to the perfect reflecting diffuser. A Lambertian sample of reflectance R sends
``R sin^2(a_d) cos(theta_r)`` of the flux into a detector cone of half angle a_d at
theta_r (the cone integral of ``(R/pi) cos`` is exact), so the goniometer's fraction
Phi becomes the factor ``Phi / (sin^2 a_d cos theta_r)`` (:func:`reflectance_factor_scale`);
``scale = "mirror"`` keeps the reading as measured (fraction of the mirror).

References
----------
.. [1] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eqs. 15-17, fig. 6
   (spectral flux of a virtual sample under D65).
.. [2] R. Durikovic et al., Cent. Eur. J. Phys. 5 (2007) 416, eq. 1.
.. [3] ASTM E2194: reflectance factors at aspecular angles.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.colour.dispersion import Constant
from goniolab.colour.paint import Paint
from goniolab.optics.apertures import Cone, inplane_centre, sample_aperture, solid_angle_sr
from goniolab.optics.models import ReflectanceModel

__all__ = [
    "Scale",
    "SpectralPredictor",
    "SurfaceFactory",
    "reflectance_factor_scale",
    "surface_colour_note",
    "wavelength_free",
]

FloatArray = NDArray[np.float64]
Scale = Literal["diffuser", "mirror"]


def reflectance_factor_scale(
    theta_r_deg: ArrayLike, detector_cone_deg: float, scale: Scale = "diffuser"
) -> FloatArray:
    """Factor turning a reading (fraction of the incident flux) into a reflectance factor.

    ``1 / (sin^2(a_d) cos theta_r)`` with ``a_d`` the detector cone's half angle (exact for a
    Lambertian sample); 1 for ``scale="mirror"``.

    Raises
    ------
    ValueError
        For a point detector (no solid angle) with the diffuser scale, or |theta_r| >= 90.
    """
    tr = np.asarray(theta_r_deg, dtype=np.float64)
    if scale == "mirror":
        return np.ones_like(tr)
    if scale != "diffuser":
        raise ValueError(f"colour scale must be 'diffuser' or 'mirror', got {scale!r}")
    a = math.radians(0.5 * detector_cone_deg)
    if a <= 0:
        raise ValueError("a reflectance factor needs a detector cone with a solid angle")
    if np.any(np.abs(tr) + math.degrees(a) >= 90.0):
        raise ValueError("the detector cone must lie above the horizon")
    out: FloatArray = 1.0 / (math.sin(a) ** 2 * np.cos(np.radians(tr)))
    return out


def wavelength_free(model: str) -> bool:
    """Whether the surface model named ``model`` (a provenance name:
    :func:`goniolab.optics.provenance.provenance_of`) has no wavelength in its scattering:
    the facet model and the analytic microfacet models are geometric optics, their only
    wavelength dependence is the coat's n(lambda) in the Fresnel term."""
    return model == "facet" or model.startswith("analytic")


def surface_colour_note(model: str, theta_r_deg: Sequence[float] = ()) -> str:
    """What the user must know about a predicted colour whose coat-surface part comes from
    a :func:`wavelength_free` model.

    A surface whose features are near the wavelength scatters light differently at each
    wavelength (diffraction): identical 5 um filler caps of 0.9 um make the scalar
    Kirchhoff reading of ``sample:wittmann-3`` swing by C* up to ~20 within 25 deg of
    specular, at 0.25 um steps, where the Kirchhoff model is valid
    (``bench/near_specular_colour.py``). A geometric-optics model has none of that: its
    predicted a*, b* near specular come from the coat's dispersion and the paint only, and
    are not a prediction of the surface's colour.
    """
    where = ""
    if len(theta_r_deg):
        lo, hi = min(theta_r_deg), max(theta_r_deg)
        where = f" (theta_r {lo:g} deg)" if lo == hi else f" (theta_r {lo:g}..{hi:g} deg)"
    return (
        f"predicted colour{where}: the {model} model is wavelength-independent: near-specular "
        "colour from surface scattering is not predicted (its a*, b* come from the coat's "
        "dispersion and the paint only)"
    )


@dataclass(frozen=True, slots=True)
class SurfaceFactory:
    """Builds the coat-surface model for a (complex) index and a wavelength in nm.

    ``wavelength_dependent`` says whether the model uses the wavelength itself (physical
    optics) or only n (geometric optics: then the wavelength argument is ignored).
    """

    build: Callable[[complex, float], ReflectanceModel]
    wavelength_dependent: bool = False
    name: str = "surface"


@dataclass
class SpectralPredictor:
    """Predicted spectra (% of the mirror) for in-plane geometries.

    Parameters
    ----------
    surface
        The coat surface's model factory; ``None`` = no surface reflection (paint only).
    paint
        What lies beneath (its ``coat`` gives n(lambda) for the surface model too).
    source, detector
        The lamp and detector cones.
    wavelengths_nm
        The grid (default 380..780 nm, 10 nm).
    node_step_nm
        Wavelength node spacing for wavelength-dependent surface models.
    exact
        Evaluate the surface model at every wavelength (no interpolation).
    quadrature_rings
        Rings of the cone quadrature for the paint term (1 + 3 r (r - 1) directions per cone;
        the default 2 is within 0.4 % of 5 rings for the silver metallic's 7 deg flakes).
    """

    surface: SurfaceFactory | None
    paint: Paint
    source: Cone = field(default_factory=lambda: Cone(6.0))
    detector: Cone = field(default_factory=lambda: Cone(6.0))
    wavelengths_nm: FloatArray = field(default_factory=lambda: np.linspace(380.0, 780.0, 41))
    node_step_nm: float = 40.0
    exact: bool = False
    quadrature_rings: int = 2
    _models: dict[tuple[complex, float], ReflectanceModel] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self.wavelengths_nm = np.asarray(self.wavelengths_nm, dtype=np.float64).ravel()
        if self.wavelengths_nm.size < 1:
            raise ValueError("need at least one wavelength")
        self.paint.coat.check_covers(self.wavelengths_nm)

    # ----------------------------------------------------------------- surface part
    def _model(self, n: complex, wavelength_nm: float) -> ReflectanceModel:
        assert self.surface is not None
        key = (complex(n), float(wavelength_nm) if self.surface.wavelength_dependent else 0.0)
        model = self._models.get(key)
        if model is None:
            model = self.surface.build(complex(n), float(wavelength_nm))
            self._models[key] = model
        return model

    def _surface_at(self, n: complex, wl: float, ti: float, tr: FloatArray) -> FloatArray:
        out = self._model(n, wl).luminance_pct(ti, tr, source=self.source, detector=self.detector)
        return np.asarray(out, dtype=np.float64).reshape(tr.shape) / 100.0

    def surface_fraction(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """Coat-surface fraction of the flux, ``(n_geometries, n_wavelengths)``."""
        tr = np.atleast_1d(np.asarray(theta_r_deg, dtype=np.float64))
        wl = self.wavelengths_nm
        if self.surface is None:
            return np.zeros((tr.size, wl.size))
        n_wl = self.paint.coat.index(wl)
        if self.exact:
            cols = [
                self._surface_at(complex(n), float(w), theta_i_deg, tr)
                for n, w in zip(n_wl, wl, strict=True)
            ]
            return np.stack(cols, axis=-1)
        if self.surface.wavelength_dependent or np.any(n_wl.imag != 0):
            nodes = _wavelength_nodes(wl, self.node_step_nm)
            n_nodes = self.paint.coat.index(nodes)
            vals = np.stack(
                [
                    self._surface_at(complex(n), float(w), theta_i_deg, tr)
                    for n, w in zip(n_nodes, nodes, strict=True)
                ],
                axis=-1,
            )
            if nodes.size == 1:
                return np.repeat(vals, wl.size, axis=-1)
            from scipy.interpolate import CubicSpline  # lazy: scipy is slow to import

            k = min(nodes.size - 1, 3)
            if k < 3:
                return np.stack([np.interp(wl, nodes, v) for v in vals], axis=0)
            out: FloatArray = CubicSpline(nodes, vals, axis=-1)(wl)
            return out
        n_re = n_wl.real
        lo, hi = float(n_re.min()), float(n_re.max())
        mid_wl = float(np.median(wl))
        if hi - lo < 1e-9:
            v = self._surface_at(complex(lo), mid_wl, theta_i_deg, tr)
            return np.repeat(v[:, None], wl.size, axis=1)
        # three Chebyshev nodes over [lo, hi], quadratic Lagrange interpolation in n
        c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
        xs = c + h * np.cos(np.pi * (2 * np.arange(3) + 1) / 6.0)
        # a factory that ignores n (a model used as it is) gives one model for all three
        # nodes: evaluated once (the Lagrange weights sum to 1)
        by_model: dict[int, FloatArray] = {}
        ys = []
        for x in xs:
            model = self._model(complex(x), mid_wl)
            if id(model) not in by_model:
                by_model[id(model)] = self._surface_at(complex(x), mid_wl, theta_i_deg, tr)
            ys.append(by_model[id(model)])
        weights = _lagrange_weights(xs, n_re)  # (3, n_wl)
        out2: FloatArray = sum(ys[j][:, None] * weights[j][None, :] for j in range(3))
        return out2

    # ----------------------------------------------------------------- paint part
    def paint_fraction(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """Subsurface fraction of the flux into the detector, ``(n_geometries, n_wavelengths)``."""
        tr = np.atleast_1d(np.asarray(theta_r_deg, dtype=np.float64))
        wl = self.wavelengths_nm
        if self.paint.body is None and self.paint.metallic is None and self.paint.pearl is None:
            return np.zeros((tr.size, wl.size))
        wi, w_s = sample_aperture(self.source, float(theta_i_deg), 0.0, n=self.quadrature_rings)
        if solid_angle_sr(self.source) == 0.0:
            w_s = np.full_like(w_s, 1.0 / w_s.size)
        point_detector = solid_angle_sr(self.detector) == 0.0
        src = np.where(wi[:, 2] > 0, w_s, 0.0)
        total = float(src.sum())
        if total == 0.0:
            return np.zeros((tr.size, wl.size))
        src = src / total
        # the body term is separable: T(t_i) T(t_o) g(lambda)
        t_src = src @ self.paint.body_transmission(wi[:, 2], wl)  # (n_wl,)
        body = self.paint.body_term(wl)
        dets = []
        for t in tr:
            t_r, p_r = inplane_centre(float(t))
            wo, w_d = sample_aperture(self.detector, t_r, p_r, n=self.quadrature_rings)
            if point_detector:
                w_d = np.full_like(w_d, 1.0 / w_d.size)
            dets.append((wo, np.clip(wo[:, 2], 0.0, None) * w_d))
        out = np.empty((tr.size, wl.size))
        for g, (wo, proj) in enumerate(dets):
            out[g] = t_src * body * (proj @ self.paint.body_transmission(wo[:, 2], wl))
        if self.paint.has_flakes:
            ns = wi.shape[0]
            wo_all = np.concatenate([wo for wo, _ in dets])
            nd = dets[0][0].shape[0]
            f = self.paint.flake_brdf(
                np.tile(wi, (wo_all.shape[0], 1)), np.repeat(wo_all, ns, axis=0), wl
            ).reshape(tr.size, nd, ns, wl.size)
            proj_all = np.stack([p for _, p in dets])  # (n_geom, nd)
            out += np.einsum("s,gdsl,gd->gl", src, f, proj_all)
        return out

    # ----------------------------------------------------------------- together
    def spectrum_pct(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """Predicted reading per wavelength in % of the mirror, ``(n_geometries, n_wl)``."""
        return 100.0 * (
            self.surface_fraction(theta_i_deg, theta_r_deg)
            + self.paint_fraction(theta_i_deg, theta_r_deg)
        )

    def luminance_pct(
        self, theta_i_deg: float, theta_r_deg: ArrayLike, y_weights: FloatArray
    ) -> FloatArray:
        """Y of the predicted spectra (``y_weights``: the Y row of the XYZ weights, / 100)."""
        return self.spectrum_pct(theta_i_deg, theta_r_deg) @ y_weights

    def describe(self) -> dict[str, object]:
        return {
            "surface": None if self.surface is None else self.surface.name,
            "paint": self.paint.describe(),
            "wavelengths_nm": [
                float(self.wavelengths_nm[0]),
                float(self.wavelengths_nm[-1]),
                int(self.wavelengths_nm.size),
            ],
            "source_cone_deg": self.source.full_angle_deg,
            "detector_cone_deg": self.detector.full_angle_deg,
        }


def _wavelength_nodes(wl: FloatArray, step_nm: float) -> FloatArray:
    lo, hi = float(wl.min()), float(wl.max())
    if hi - lo <= step_nm or wl.size <= 4:
        return np.unique(wl) if wl.size <= 4 else np.array([lo, 0.5 * (lo + hi), hi])
    k = max(4, math.ceil((hi - lo) / step_nm) + 1)
    return np.linspace(lo, hi, k)


def _lagrange_weights(xs: Sequence[float] | FloatArray, x: FloatArray) -> FloatArray:
    xs_a = np.asarray(xs, dtype=np.float64)
    out = np.ones((xs_a.size, x.size))
    for j in range(xs_a.size):
        for m in range(xs_a.size):
            if m != j:
                out[j] *= (x - xs_a[m]) / (xs_a[j] - xs_a[m])
    return out


def constant_coat(n: complex) -> Paint:
    """A paint with nothing under a coat of constant index (the grey luminance model)."""
    return Paint(coat=Constant(complex(n)))
