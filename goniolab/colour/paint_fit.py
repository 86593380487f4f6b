"""Fit a paint to a measured multi-angle run: K/S, flakes and the coat index from L*a*b*.

Durikovic et al. (2007, sec. 6) fit their composite model's parameters to measured
reflectance; here the data are what a multi-angle spectrophotometer reports, L*a*b* at
several aspecular angles (ASTM E2194), and the model is :class:`SpectralPredictor`: the
coat surface (its reflection tabulated once over n, below) plus :class:`Paint` beneath.

Free parameters (any subset; :func:`default_parameters` picks those the paint has):

- ``body.ks_scale``: a factor q on the body's K(lambda) (so on K/S, the seed's eq. 4: the
  only body quantity an opaque layer shows); fitted as ln q.
- ``body.s_scale``: a factor on S(lambda) (only a non-opaque layer over its substrate
  tells K and S apart); fitted as ln of the factor.
- ``metallic.area_fraction``, ``metallic.spread_deg``; ``pearl.area_fraction``,
  ``pearl.spread_deg``, ``pearl.film_nm``: the flake populations (seed secs. 5.3-5.4).
- ``coat.n``: the coat's index at the sodium D line (589.3 nm); the whole dispersion
  n(lambda) is shifted by the same amount (Cauchy A, a constant, a table's n).

The residuals are the differences predicted - measured of L*, a*, b* at every geometry
(``m = 3 x geometries``, in dE*ab units; or, with ``metric="de2000"``, the same differences
through each measured colour's local CIEDE2000 metric), minimised by
``scipy.optimize.least_squares`` (trust-region reflective, bounds). Uncertainties are the
usual linearised ones:

.. math:: \\mathrm{Cov}(x) = s^2 (J^T J)^{-1}, \\qquad s^2 = \\frac{\\sum r^2}{m - p}

(the residual variance estimates the per-component measurement noise; J is the Jacobian at
the solution, from its singular value decomposition so that a direction the data do not
determine shows as an infinite uncertainty instead of a number). A log-fitted factor q gets
``sigma_q = q sigma_{ln q}``. A parameter that ends on a bound is reported as such and left
out of the covariance. The residual colour difference is dE2000 (CIE 15:2004 / colour-science)
per geometry and its mean.

References
----------
.. [1] R. Durikovic, K. Kolchin, S. Ershov, Cent. Eur. J. Phys. 5 (2007) 416, secs. 5-6.
.. [2] W. H. Press et al., Numerical Recipes, 3rd ed., sec. 15.4 (covariance of a
   least-squares fit from the SVD of the design matrix).
.. [3] ASTM E2194-14 (multi-angle geometry).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.colour.dispersion import (
    Cauchy,
    Constant,
    Dispersion,
    Sellmeier,
    Tabulated,
)
from goniolab.colour.paint import Paint, PaintError, Spectrum
from goniolab.colour.spectra import ColourSettings, delta_e
from goniolab.colour.spectral import Scale, SpectralPredictor, reflectance_factor_scale

__all__ = [
    "PARAMETERS",
    "ColourFit",
    "FitError",
    "FittedParameter",
    "de2000_metric",
    "default_parameters",
    "fit_paint",
    "paint_with",
    "parameter_values",
    "shift_index",
]

FloatArray = NDArray[np.float64]

#: The sodium D line, where ``coat.n`` is quoted.
N_D_NM = 589.3


@dataclass(frozen=True, slots=True)
class _Spec:
    unit: str
    lower: float
    upper: float
    scale: float  # typical step (least_squares x_scale)
    log: bool = False
    what: str = ""


#: Parameters that can be fitted: unit, bounds, typical scale, whether fitted in log.
PARAMETERS: dict[str, _Spec] = {
    "body.ks_scale": _Spec("", 1e-3, 1e3, 0.1, True, "factor on K (K/S) of the body"),
    "body.s_scale": _Spec("", 1e-3, 1e3, 0.1, True, "factor on S of the body"),
    "metallic.area_fraction": _Spec("", 0.0, 1.0, 0.05, False, "metallic flake area"),
    "metallic.spread_deg": _Spec("deg", 0.05, 45.0, 1.0, False, "metallic flake rms tilt"),
    "pearl.area_fraction": _Spec("", 0.0, 1.0, 0.05, False, "pearl flake area"),
    "pearl.spread_deg": _Spec("deg", 0.05, 45.0, 1.0, False, "pearl flake rms tilt"),
    "pearl.film_nm": _Spec("nm", 5.0, 1000.0, 10.0, False, "TiO2 film thickness"),
    "coat.n": _Spec("", 1.05, 2.5, 0.01, False, f"coat index at {N_D_NM} nm"),
}


class FitError(ValueError):
    """The data or the request cannot give a fit (the message says what is wrong)."""


Metric = Literal["lab", "de2000"]


def de2000_metric(lab: ArrayLike, step: float = 1e-3) -> FloatArray:
    """Per colour, the 3 x 3 matrix R with ``|R d|^2 = dE2000(lab, lab + d)^2`` for small d.

    CIEDE2000 (CIE 142-2001; Sharma et al. 2005) is, for small differences, a quadratic
    form ``d^T G d`` in (dL*, da*, db*) at the colour (its S_L, S_C, S_H and R_T are then
    those of the colour itself); G is read off ``colour.delta_E`` by central second
    differences of dE^2 (exact for a quadratic form) and R is its Cholesky factor.
    """
    from goniolab.colour.spectra import delta_e

    base = np.atleast_2d(np.asarray(lab, dtype=np.float64))
    n = base.shape[0]
    eye = np.eye(3) * step

    def de2(d: FloatArray) -> FloatArray:
        out: FloatArray = delta_e(base, base + d, "CIE 2000") ** 2
        return out

    g = np.empty((n, 3, 3))
    for i in range(3):
        g[:, i, i] = de2(eye[i]) / step**2
        for j in range(i + 1, 3):
            both = (de2(eye[i] + eye[j]) - de2(eye[i] - eye[j])) / (4.0 * step**2)
            g[:, i, j] = g[:, j, i] = both
    out = np.asarray(np.linalg.cholesky(g).transpose(0, 2, 1), dtype=np.float64)
    return out  # R = L^T: R^T R = G


# ------------------------------------------------------------------ paint <-> parameters
def shift_index(d: Dispersion, dn: float) -> Dispersion:
    """The dispersion ``d`` with its real index shifted by ``dn`` at every wavelength.

    Exact for a constant, a Cauchy formula (A + dn) and a table (n + dn); a Sellmeier
    formula becomes a table on 380..780 nm in 5 nm steps (+ dn).
    """
    if dn == 0.0:
        return d
    if isinstance(d, Constant):
        return Constant(complex(d.n) + dn)
    if isinstance(d, Cauchy):
        return Cauchy(d.A + dn, d.B, d.C)
    if isinstance(d, Tabulated):
        return Tabulated(d.wavelengths_nm, tuple(v + dn for v in d.n), d.k, source=d.source)
    if isinstance(d, Sellmeier):
        wl = np.linspace(380.0, 780.0, 81)
        n = d.index(wl).real + dn
        return Tabulated(tuple(wl.tolist()), tuple(n.tolist()), source="sellmeier + dn")
    raise FitError(f"cannot shift the index of a {type(d).__name__} coat")


def default_parameters(paint: Paint) -> list[str]:
    """The parameters a paint offers by default: the body's K/S, each flake population's
    area and spread (and the pearl's film), and the coat index."""
    out: list[str] = []
    if paint.body is not None:
        out.append("body.ks_scale")
    if paint.metallic is not None:
        out += ["metallic.area_fraction", "metallic.spread_deg"]
    if paint.pearl is not None:
        out += ["pearl.area_fraction", "pearl.spread_deg", "pearl.film_nm"]
    out.append("coat.n")
    return out


def parameter_values(paint: Paint, names: Sequence[str]) -> dict[str, float]:
    """The current value of each named parameter (scales are 1 for the paint as given)."""
    out: dict[str, float] = {}
    for name in names:
        _check_available(paint, name)
        section, key = name.split(".")
        if section == "body":
            out[name] = 1.0
        elif section == "coat":
            out[name] = float(paint.coat.index(N_D_NM).real)
        else:
            out[name] = float(getattr(getattr(paint, section), key))
    return out


def _check_available(paint: Paint, name: str) -> None:
    if name not in PARAMETERS:
        raise FitError(f"unknown fit parameter {name!r} (known: {', '.join(PARAMETERS)})")
    section = name.split(".")[0]
    if section != "coat" and getattr(paint, section) is None:
        raise FitError(f"fit parameter {name!r}: the paint has no [{section}]")


def _scaled(spectrum: Spectrum, factor: float) -> Spectrum:
    return Spectrum(spectrum.wavelengths_nm, tuple(v * factor for v in spectrum.values))


def paint_with(paint: Paint, base: Mapping[str, float], values: Mapping[str, float]) -> Paint:
    """``paint`` with the parameters set to ``values`` (``base``: their values in ``paint``,
    from :func:`parameter_values`; scales and the index shift are relative to them)."""
    coat = paint.coat
    body = paint.body
    metallic = paint.metallic
    pearl = paint.pearl
    for name, v in values.items():
        if name == "coat.n":
            coat = shift_index(paint.coat, float(v) - base[name])
        elif name == "body.ks_scale" and body is not None:
            body = replace(body, k_per_um=_scaled(body.k_per_um, float(v) / base[name]))
        elif name == "body.s_scale" and body is not None:
            body = replace(body, s_per_um=_scaled(body.s_per_um, float(v) / base[name]))
        elif name.startswith("metallic.") and metallic is not None:
            kw: dict[str, Any] = {name.split(".")[1]: float(v)}
            metallic = replace(metallic, **kw)
        elif name.startswith("pearl.") and pearl is not None:
            kw = {name.split(".")[1]: float(v)}
            pearl = replace(pearl, **kw)
    return replace(paint, coat=coat, body=body, metallic=metallic, pearl=pearl)


# ------------------------------------------------------------------ the forward model
def _lagrange(xs: FloatArray, x: FloatArray) -> FloatArray:
    out = np.ones((xs.size, x.size))
    for j in range(xs.size):
        for m in range(xs.size):
            if m != j:
                out[j] *= (x - xs[m]) / (xs[j] - xs[m])
    return out


class _SurfaceInN:
    """The coat surface's fraction ``(n_geom, n_wl)`` as a function of the coat's n(lambda):
    evaluated once at 5 Chebyshev nodes of n (constant coats) spanning what the fit may
    reach, then interpolated per wavelength (the reflection is smooth in n: Fresnel)."""

    def __init__(
        self,
        predictor: SpectralPredictor,
        theta_i_deg: float,
        theta_r_deg: FloatArray,
        n_lo: float,
        n_hi: float,
        nodes: int = 5,
    ) -> None:
        c, h = 0.5 * (n_lo + n_hi), 0.5 * (n_hi - n_lo)
        self.nodes = c + h * np.cos(np.pi * (2 * np.arange(nodes) + 1) / (2 * nodes))
        tables = []
        for n in self.nodes:
            sp = SpectralPredictor(
                predictor.surface,
                Paint(coat=Constant(float(n))),
                source=predictor.source,
                detector=predictor.detector,
                wavelengths_nm=predictor.wavelengths_nm,
                node_step_nm=predictor.node_step_nm,
                exact=predictor.exact,
            )
            tables.append(sp.surface_fraction(theta_i_deg, theta_r_deg))
        self.tables = np.stack(tables)  # (nodes, n_geom, n_wl)

    def at(self, n_wl: FloatArray) -> FloatArray:
        w = _lagrange(self.nodes, n_wl)  # (nodes, n_wl)
        out: FloatArray = np.einsum("jgl,jl->gl", self.tables, w)
        return out


@dataclass
class _Model:
    predictor: SpectralPredictor
    theta_i_deg: float
    theta_r_deg: FloatArray
    settings: ColourSettings
    scale: Scale
    surface_fixed: FloatArray | None
    surface_in_n: _SurfaceInN | None

    def lab(self, paint: Paint) -> FloatArray:
        p = self.predictor
        wl = p.wavelengths_nm
        sub = SpectralPredictor(
            None,
            paint,
            source=p.source,
            detector=p.detector,
            wavelengths_nm=wl,
            quadrature_rings=p.quadrature_rings,
        )
        frac = sub.paint_fraction(self.theta_i_deg, self.theta_r_deg)
        if self.surface_in_n is not None:
            frac = frac + self.surface_in_n.at(paint.coat_n(wl))
        elif self.surface_fixed is not None:
            frac = frac + self.surface_fixed
        k = reflectance_factor_scale(self.theta_r_deg, p.detector.full_angle_deg, self.scale)
        xyz = (frac * k[:, None]) @ self._weights.T
        out: FloatArray = _lab(xyz, self._white_xyz)
        return out

    def __post_init__(self) -> None:
        from goniolab.colour.spectra import colour_module, xyz_weights

        self._weights = xyz_weights(self.predictor.wavelengths_nm, self.settings)
        # the white's XYZ (Y = 100) from its chromaticity, as colour.XYZ_to_Lab uses it
        x, y = self.settings.white_xy
        self._white_xyz = np.array([x / y, 1.0, (1.0 - x - y) / y]) * 100.0
        colour_module()  # imported once, before the timing-free loop


def _lab(xyz: FloatArray, white: FloatArray) -> FloatArray:
    """CIE 1976 L*a*b* (CIE 15:2004 eqs. 8.1-8.3) of ``(..., 3)`` XYZ against ``white``
    (the same numbers as ``colour.XYZ_to_Lab``; written out: the fit calls it thousands of
    times and colour-science validates its arguments on every call)."""
    t = xyz / white
    eps, kappa = 216.0 / 24389.0, 24389.0 / 27.0
    f = np.where(t > eps, np.cbrt(t), (kappa * t + 16.0) / 116.0)
    out: FloatArray = np.stack(
        [
            116.0 * f[..., 1] - 16.0,
            500.0 * (f[..., 0] - f[..., 1]),
            200.0 * (f[..., 1] - f[..., 2]),
        ],
        axis=-1,
    )
    return out


# ------------------------------------------------------------------ results
@dataclass(frozen=True, slots=True)
class FittedParameter:
    """One fitted value with its 1-sigma uncertainty (``inf``: not determined by the data;
    ``nan``: on a bound, no uncertainty)."""

    name: str
    value: float
    sigma: float
    start: float
    unit: str
    at_bound: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": self.value,
            "sigma": self.sigma if math.isfinite(self.sigma) else None,
            "start": self.start,
            "unit": self.unit,
            "at_bound": self.at_bound,
            "determined": math.isfinite(self.sigma),
        }


@dataclass(frozen=True)
class ColourFit:
    """The outcome of :func:`fit_paint`."""

    parameters: list[FittedParameter]
    paint: Paint
    theta_r_deg: FloatArray
    measured_lab: FloatArray
    start_lab: FloatArray
    fitted_lab: FloatArray
    dE2000: FloatArray
    start_dE2000: FloatArray
    correlation: FloatArray
    residual_rms: float
    dof: int
    evaluations: int
    message: str

    @property
    def mean_dE2000(self) -> float:
        return float(np.mean(self.dE2000))

    @property
    def start_mean_dE2000(self) -> float:
        return float(np.mean(self.start_dE2000))

    def value(self, name: str) -> float:
        return next(p.value for p in self.parameters if p.name == name)

    def sigma(self, name: str) -> float:
        return next(p.sigma for p in self.parameters if p.name == name)


# ------------------------------------------------------------------ the fit
def fit_paint(
    predictor: SpectralPredictor,
    theta_i_deg: float,
    theta_r_deg: ArrayLike,
    measured_lab: ArrayLike,
    *,
    parameters: Sequence[str] | None = None,
    settings: ColourSettings | None = None,
    scale: Scale = "diffuser",
    metric: Metric = "lab",
    max_evaluations: int = 400,
) -> ColourFit:
    """Fit the paint of ``predictor`` to measured L*a*b* at in-plane geometries.

    Parameters
    ----------
    predictor
        The starting model: coat surface factory (or ``None``), paint, cones, wavelengths.
    theta_i_deg, theta_r_deg
        The geometries (signed in-plane detector angles, > 0 specular side).
    measured_lab
        ``(n_geom, 3)`` measured L*, a*, b* (reflectance factors as ``scale`` says).
    parameters
        Names from :data:`PARAMETERS` (default :func:`default_parameters`).
    settings, scale
        Illuminant/observer/method and the reflectance-factor scale the data were
        computed with.
    metric
        ``"lab"``: residuals are the L*, a*, b* differences (dE*ab; every component weighs
        the same, which is what the uncertainties assume); ``"de2000"``: the differences
        through the local CIEDE2000 metric of each measured colour (:func:`de2000_metric`),
        so that the sum of squares is the sum of dE2000^2 for small differences.

    Raises
    ------
    FitError
        Unknown or unavailable parameter, non-finite data, or fewer residuals than
        parameters + 1 (too few geometries).
    """
    from scipy.optimize import least_squares  # lazy: scipy is slow to import

    settings = (settings or ColourSettings()).validated()
    tr = np.atleast_1d(np.asarray(theta_r_deg, dtype=np.float64))
    lab_m = np.asarray(measured_lab, dtype=np.float64).reshape(-1, 3)
    if lab_m.shape[0] != tr.size:
        raise FitError(f"{lab_m.shape[0]} measured colours for {tr.size} geometries")
    if not np.all(np.isfinite(lab_m)):
        raise FitError("a measured L*a*b* value is NaN or infinite")
    paint0 = predictor.paint
    names = list(parameters) if parameters is not None else default_parameters(paint0)
    if not names:
        raise FitError("no parameter to fit")
    if len(set(names)) != len(names):
        raise FitError("a fit parameter is named twice")
    base = parameter_values(paint0, names)
    p = len(names)
    m = 3 * tr.size
    need = max(2, math.ceil((p + 1) / 3))
    if tr.size < need:
        raise FitError(
            f"{tr.size} geometr{'y' if tr.size == 1 else 'ies'} with colour: fitting {p} "
            f"parameter{'s' if p > 1 else ''} needs at least {need} (3 residuals L*a*b* "
            "each, more than the parameters)"
        )
    specs = [PARAMETERS[n] for n in names]

    # bounds in the optimiser's x (ln for the scale factors); a flake area may not push
    # the total beyond 1, and n stays within +-0.3 of the start (the surface table's span)
    lo = np.array([math.log(s.lower) if s.log else s.lower for s in specs])
    hi = np.array([math.log(s.upper) if s.log else s.upper for s in specs])
    for k, name in enumerate(names):
        if name.endswith("area_fraction"):
            other = "pearl" if name.startswith("metallic") else "metallic"
            if f"{other}.area_fraction" in names:
                hi[k] = 1.0  # both free: paint_of rescales a sum above 1
            else:
                fl = getattr(paint0, other)
                hi[k] = min(hi[k], 1.0 - (fl.area_fraction if fl is not None else 0.0))
        if name == "coat.n":
            lo[k] = max(lo[k], base[name] - 0.3)
            hi[k] = min(hi[k], base[name] + 0.3)
    x0 = np.array(
        [math.log(base[n]) if s.log else base[n] for n, s in zip(names, specs, strict=True)]
    )
    x0 = np.clip(x0, lo + 1e-12 * (hi - lo), hi - 1e-12 * (hi - lo))

    surface_fixed = None
    surface_in_n = None
    if predictor.surface is not None:
        if "coat.n" in names:
            wl = predictor.wavelengths_nm
            n_wl = paint0.coat_n(wl)
            k = names.index("coat.n")
            surface_in_n = _SurfaceInN(
                predictor,
                theta_i_deg,
                tr,
                float(n_wl.min()) + (lo[k] - base["coat.n"]),
                float(n_wl.max()) + (hi[k] - base["coat.n"]),
            )
        else:
            surface_fixed = predictor.surface_fraction(theta_i_deg, tr)
    model = _Model(predictor, theta_i_deg, tr, settings, scale, surface_fixed, surface_in_n)

    def values_of(x: FloatArray) -> dict[str, float]:
        return {
            n: (math.exp(v) if s.log else float(v)) for n, s, v in zip(names, specs, x, strict=True)
        }

    def paint_of(x: FloatArray) -> Paint:
        vals = values_of(x)
        a_m = vals.get("metallic.area_fraction")
        a_p = vals.get("pearl.area_fraction")
        if a_m is not None and a_p is not None and a_m + a_p > 1.0:
            s = 1.0 / (a_m + a_p)  # keep the physics valid; the cost then rises
            vals["metallic.area_fraction"] = a_m * s
            vals["pearl.area_fraction"] = a_p * s
        try:
            return paint_with(paint0, base, vals)
        except PaintError as exc:
            raise FitError(str(exc)) from None

    if metric == "lab":
        chol = np.broadcast_to(np.eye(3), (tr.size, 3, 3))
    elif metric == "de2000":
        chol = de2000_metric(lab_m)
    else:
        raise FitError(f"unknown fit metric {metric!r} (lab or de2000)")

    def weighted(lab: FloatArray) -> FloatArray:
        out: FloatArray = np.einsum("gij,gj->gi", chol, lab - lab_m).ravel()
        return out

    def residuals(x: FloatArray) -> FloatArray:
        return weighted(model.lab(paint_of(x)))

    start_lab = model.lab(paint_of(x0))
    res = least_squares(
        residuals,
        x0,
        bounds=(lo, hi),
        x_scale=np.array([s.scale for s in specs]),
        method="trf",
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-12,
        max_nfev=max_evaluations,
    )
    x = res.x
    fitted_lab = model.lab(paint_of(x))
    r = weighted(fitted_lab)
    dof = m - p
    s2 = float(r @ r) / dof
    active = np.asarray(res.active_mask) != 0
    free = ~active
    sigma_x = np.full(p, np.nan)
    corr = np.full((p, p), np.nan)
    if np.any(free):
        jac = np.asarray(res.jac, dtype=np.float64)[:, free]
        _, sv, vt = np.linalg.svd(jac, full_matrices=False)
        # below 1e-6 of the largest: finite-difference noise (~1e-8), not information
        tol = sv.max() * 1e-6 if sv.size else 0.0
        good = sv > tol
        inv = np.where(good, 1.0 / np.where(good, sv, 1.0) ** 2, 0.0)
        cov = (vt.T * inv) @ vt * s2
        var = np.diag(cov).copy()
        # a parameter that loads on an undetermined direction has no finite uncertainty
        undetermined = np.any(np.abs(vt[~good]) > 1e-6, axis=0) if np.any(~good) else None
        if undetermined is not None:
            var[undetermined] = np.inf
        sigma_x[free] = np.sqrt(var)
        d = np.sqrt(np.where(np.isfinite(var) & (var > 0), var, np.nan))
        cf = cov / np.outer(d, d)
        corr[np.ix_(free, free)] = cf
    vals = values_of(x)
    fitted: list[FittedParameter] = []
    for k, (name, spec) in enumerate(zip(names, specs, strict=True)):
        v = vals[name]
        sig = float(sigma_x[k])
        if spec.log and math.isfinite(sig):
            sig = v * sig
        fitted.append(
            FittedParameter(name, v, sig, base[name], spec.unit, at_bound=bool(active[k]))
        )
    de = np.atleast_1d(delta_e(fitted_lab, lab_m, "CIE 2000"))
    de0 = np.atleast_1d(delta_e(start_lab, lab_m, "CIE 2000"))
    return ColourFit(
        parameters=fitted,
        paint=paint_of(x),
        theta_r_deg=tr,
        measured_lab=lab_m,
        start_lab=start_lab,
        fitted_lab=fitted_lab,
        dE2000=de,
        start_dE2000=de0,
        correlation=corr,
        residual_rms=math.sqrt(float(r @ r) / m),
        dof=dof,
        evaluations=int(res.nfev),
        message=str(res.message),
    )
