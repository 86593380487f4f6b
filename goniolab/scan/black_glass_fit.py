"""The black-glass fit of an alignment and its quality gates (split from
:mod:`goniolab.scan.align`, which re-exports every name here).

The ISO 2813 black glass on the reference seat is swept through its specular peak at two or
more incidences; its reading is known in closed form (:func:`_standard_model`), and a
least-squares fit (:func:`fit_standard_full`) gives both arms' zeros, the scale against the
certificate, a stray floor and, with three or more incidences, the spectro's polarisation
weight. :func:`check_standard` refuses a missing, wrong or saturated standard or a fit that
does not describe the readings (:class:`AlignGates`), saying which.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.apertures import Cone, cap_overlap_fraction
from goniolab.optics.fresnel import fresnel, fresnel_dielectric_sp

__all__ = [
    "BLACK_GLASS_N",
    "AlignGates",
    "AlignRefused",
    "StandardFit",
    "check_standard",
    "fit_standard",
    "fit_standard_full",
    "half_max_midpoint",
    "parameter_sigmas",
]

#: Refractive index of the ISO 2813 black-glass standard.
BLACK_GLASS_N = 1.567

FloatArray = NDArray[np.float64]


class AlignRefused(RuntimeError):
    """The standard's readings fail a quality gate (:class:`AlignGates`): a missing, wrong
    or saturated standard, a fit that does not describe the data. Nothing is written."""


@dataclass(frozen=True, slots=True)
class AlignGates:
    """What the black-glass readings must pass before their zeros are believed.

    ``scale_tolerance``: the fitted scale ``k`` (reading / certified reading) within
    ``1 +/- scale_tolerance`` (the instrument reports % of a perfect mirror, the standard's
    certificate says what it reflects); ``max_rms_rel``: the fit's relative rms over the
    readings above 10 % of the peak; ``max_sigma_deg``: the 1-sigma uncertainty of each
    zero from the fit's covariance; ``max_geometric_gap_deg``: the fit's ``dL - dD`` against
    the peaks' own half-maximum midpoints (a check that does not rest on the Fresnel shape).
    """

    scale_tolerance: float = 0.15
    max_rms_rel: float = 0.02
    #: 0.08 deg: fitting the spectro's polarisation weight beside the zeros more than doubles
    #: their sigma (0.013 -> 0.034 deg on the realistic twin, seed 5); the ideal twin's
    #: placed standard (0.5 % noise per reading) read 0.053 deg, which 0.05 refused
    max_sigma_deg: float = 0.08
    max_geometric_gap_deg: float = 0.1
    #: the fitted detector polarisation weight ``w`` (share of its response to s light)
    #: within ``0.5 +/- max_s_weight_dev``: a polarisation dependence ``2w - 1`` beyond
    #: 20 % is no fibre-fed spectrometer's, it is a misfit
    max_s_weight_dev: float = 0.1


def half_max_midpoint(
    theta_deg: Sequence[float] | FloatArray, values: Sequence[float] | FloatArray
) -> float:
    """Midpoint of the half-maximum crossings around the largest value (linear
    interpolation); NaN when a crossing lies outside the sweep."""
    x = np.asarray(theta_deg, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    k = int(np.argmax(y))
    half = 0.5 * float(y[k])
    left = right = math.nan
    for j in range(k, 0, -1):
        if y[j - 1] <= half < y[j]:
            left = x[j - 1] + (half - y[j - 1]) * (x[j] - x[j - 1]) / (y[j] - y[j - 1])
            break
    for j in range(k, x.size - 1):
        if y[j + 1] <= half < y[j]:
            right = x[j] + (half - y[j]) * (x[j + 1] - x[j]) / (y[j + 1] - y[j])
            break
    return 0.5 * (left + right)


def _standard_model(
    params: FloatArray,
    lamp: FloatArray,
    det: FloatArray,
    source: Cone,
    detector: Cone,
    n: float = BLACK_GLASS_N,
) -> FloatArray:
    """The black glass's reading; ``params = (dL, dD, k, floor[, w])``: with ``w`` the
    detector's share of response to s-polarised light, ``R = w R_s + (1 - w) R_p``
    (Fresnel, Born & Wolf sec. 1.5.2), without it the unpolarised mean."""
    d_l, d_d, k, floor = params[:4]
    if len(params) > 4:
        w = float(params[4])
        r_s, r_p = fresnel_dielectric_sp(np.cos(np.radians(lamp + d_l)), n)
        r = w * np.asarray(r_s) + (1.0 - w) * np.asarray(r_p)
    else:
        r = fresnel(np.cos(np.radians(lamp + d_l)), n)
    gamma = np.radians(np.abs(det + d_d - lamp - d_l))
    o = cap_overlap_fraction(
        gamma, math.radians(source.half_angle_deg), math.radians(detector.half_angle_deg)
    )
    return np.asarray(k * 100.0 * r * o + floor)


@dataclass(frozen=True, slots=True)
class StandardFit:
    """The black-glass fit: zeros (deg), scale ``k`` and stray floor (%), the relative rms
    of the readings above 10 % of the peak, the zeros' 1-sigma uncertainties (deg) from
    the covariance ``s^2 (J^T J)^-1`` (``s^2`` the reduced chi-square), and ``dL - dD``
    from the peaks' half-maximum midpoints alone (the geometric check)."""

    lamp_zero_deg: float
    detector_zero_deg: float
    scale: float
    floor_pct: float
    rms_rel: float
    lamp_zero_sigma_deg: float
    detector_zero_sigma_deg: float
    geometric_difference_deg: float
    #: the detector's share of response to s-polarised light, fitted with its 1-sigma
    #: (three or more incidences), else 0.5 assumed (sigma NaN)
    s_weight: float = 0.5
    s_weight_sigma: float = math.nan

    def as_dict(self) -> dict[str, float]:
        """JSON form."""
        return {
            "s_weight": self.s_weight,
            "s_weight_sigma": self.s_weight_sigma,
            "lamp_zero_deg": self.lamp_zero_deg,
            "detector_zero_deg": self.detector_zero_deg,
            "scale": self.scale,
            "floor_pct": self.floor_pct,
            "rms_rel": self.rms_rel,
            "lamp_zero_sigma_deg": self.lamp_zero_sigma_deg,
            "detector_zero_sigma_deg": self.detector_zero_sigma_deg,
            "fit_difference_deg": self.lamp_zero_deg - self.detector_zero_deg,
            "geometric_difference_deg": self.geometric_difference_deg,
        }


def fit_standard(
    lamp_deg: Sequence[float],
    det_deg: Sequence[float],
    values_pct: Sequence[float],
    *,
    source: Cone,
    detector: Cone,
) -> tuple[float, float, float]:
    """Fit the black-glass readings: ``(lamp_zero_deg, detector_zero_deg, rms_rel)``
    (:func:`fit_standard_full`)."""
    f = fit_standard_full(lamp_deg, det_deg, values_pct, source=source, detector=detector)
    return f.lamp_zero_deg, f.detector_zero_deg, f.rms_rel


def parameter_sigmas(variances: NDArray[np.float64]) -> NDArray[np.float64]:
    """1-sigma of each fitted parameter from the covariance's diagonal. A negative or
    non-finite variance (``J^T J`` too ill-conditioned to invert) is an unknown
    uncertainty: ``inf``, which the gates refuse, never 0 (a clip to 0 made such a zero
    look exact and pass the 0.08 deg gate)."""
    v = np.asarray(variances, dtype=np.float64)
    ok = np.isfinite(v) & (v >= 0.0)
    return np.where(ok, np.sqrt(np.where(ok, v, 0.0)), math.inf)


def fit_standard_full(
    lamp_deg: Sequence[float],
    det_deg: Sequence[float],
    values_pct: Sequence[float],
    *,
    source: Cone,
    detector: Cone,
    n: float = BLACK_GLASS_N,
    fit_polarisation: bool | None = None,
) -> StandardFit:
    """Fit the black-glass readings (certified index ``n``).

    Weighted least squares (``scipy.optimize.least_squares``) of the closed-form reading
    (module docstring) over all readings, 0.3 % relative plus 5e-4 % absolute sigma; the
    parameter covariance is ``s^2 (J^T J)^-1`` at the solution (Press et al., *Numerical
    Recipes*, 3rd ed., sec. 15.5), ``s^2`` the reduced chi-square.

    ``fit_polarisation`` (default: with three or more incidences) also fits the detector's
    polarisation weight ``w`` (:func:`_standard_model`). A fibre-fed grating spectrometer
    answers s and p light unequally by a few % and the glass polarises strongly
    (R_s 18 %, R_p 0.4 % at 60 deg): an unpolarised fit of a detector with ``w = 0.51``
    (2 % polarisation dependence) puts both zeros 0.27 deg off with an rms of 0.4 %, which
    no gate sees (issue 21: "the absolute zeros rest on the shape of the Fresnel curve").
    The peaks' heights at three incidences fix ``k``, ``dL`` and ``w`` together (R_s and
    R_p change differently with incidence); with two, ``w`` is taken as 0.5 and said so
    (``s_weight_sigma`` NaN).
    """
    from scipy.optimize import least_squares

    lamp = np.asarray(lamp_deg, dtype=np.float64)
    det = np.asarray(det_deg, dtype=np.float64)
    y = np.asarray(values_pct, dtype=np.float64)
    sigma = 0.003 * np.abs(y) + 5e-4
    # start: the peaks' shift gives dL - dD; dL = 0
    shifts = []
    for t in np.unique(lamp):
        sel = lamp == t
        order = np.argsort(det[sel])
        mid = half_max_midpoint(det[sel][order], y[sel][order])
        if math.isfinite(mid):
            shifts.append(mid - t)
    s0 = float(np.mean(shifts)) if shifts else 0.0

    def resid(p: FloatArray) -> FloatArray:
        return np.asarray((_standard_model(p, lamp, det, source, detector, n) - y) / sigma)

    with_w = np.unique(lamp).size >= 3 if fit_polarisation is None else fit_polarisation
    x0 = [0.0, -s0, 1.0, 0.0] + ([0.5] if with_w else [])
    scale = [0.1, 0.1, 0.1, 1e-3] + ([0.01] if with_w else [])
    fit = least_squares(resid, x0=np.array(x0), x_scale=np.array(scale))
    d_l, d_d = float(fit.x[0]), float(fit.x[1])
    model = _standard_model(fit.x, lamp, det, source, detector, n)
    big = y > 0.1 * y.max()
    rms = float(np.sqrt(np.mean(((model - y)[big] / y[big]) ** 2)))
    dof = max(y.size - fit.x.size, 1)
    s2 = float(np.sum(fit.fun**2)) / dof
    try:
        cov = np.linalg.inv(fit.jac.T @ fit.jac) * s2
        sd = parameter_sigmas(np.diag(cov))
    except np.linalg.LinAlgError:
        sd = np.full(fit.x.size, math.inf)
    return StandardFit(
        lamp_zero_deg=d_l,
        detector_zero_deg=d_d,
        scale=float(fit.x[2]),
        floor_pct=float(fit.x[3]),
        rms_rel=rms,
        lamp_zero_sigma_deg=float(sd[0]),
        detector_zero_sigma_deg=float(sd[1]),
        geometric_difference_deg=float(np.mean(shifts)) if shifts else math.nan,
        s_weight=float(fit.x[4]) if with_w else 0.5,
        s_weight_sigma=float(sd[4]) if with_w else math.nan,
    )


def check_standard(
    fit: StandardFit,
    peaks: Sequence[Mapping[str, Any]],
    gates: AlignGates,
    *,
    n: float,
    certificate: str,
    saturated: int,
) -> None:
    """Refuse (:class:`AlignRefused`, saying which) a standard that is saturated, missing
    (a sample or nothing), wrong (the mirror reads ~20x black glass), or a fit that does not
    describe the readings; the message quotes the numbers against the certificate."""
    if saturated:
        raise AlignRefused(
            f"refused: {saturated} black-glass readings saturated the spectro even at the "
            "shortest exposure (the instrument reports a clipped channel): reduce the lamp "
            "or check the spectro"
        )
    ratios = []
    for pk in peaks:
        want = 100.0 * float(fresnel(math.cos(math.radians(float(pk["theta_i_deg"]))), n))
        ratios.append((float(pk["amplitude_pct"]) / want, pk, want))
    worst = max(ratios, key=lambda r: abs(math.log(max(r[0], 1e-9))))
    ratio, pk, want = worst
    quote = (
        f"peak {pk['amplitude_pct']:.3g} % at theta_i {pk['theta_i_deg']:g} deg where black "
        f"glass n = {n:g} (certificate {certificate}) reads {want:.3g} %"
    )
    if ratio > 5.0:
        raise AlignRefused(
            f"refused: not the black-glass standard: {quote}; this reads like a mirror. "
            "Place the black-glass standard"
        )
    if not (1.0 - gates.scale_tolerance <= ratio <= 1.0 + gates.scale_tolerance) or not (
        1.0 - gates.scale_tolerance <= fit.scale <= 1.0 + gates.scale_tolerance
    ):
        raise AlignRefused(
            f"refused: the black-glass standard is missing or misplaced: {quote} "
            f"(fitted scale {fit.scale:.3g}, allowed 1 +/- {gates.scale_tolerance:g}). "
            "Place the black-glass standard on the reference seat"
        )
    if fit.rms_rel > gates.max_rms_rel:
        raise AlignRefused(
            f"refused: the black-glass fit misses its readings by {100 * fit.rms_rel:.2f} % "
            f"rms (allowed {100 * gates.max_rms_rel:g} %): not a clean flat standard?"
        )
    sig = max(fit.lamp_zero_sigma_deg, fit.detector_zero_sigma_deg)
    if not sig <= gates.max_sigma_deg:
        raise AlignRefused(
            f"refused: the zeros are uncertain to {sig:.3g} deg (1 sigma; allowed "
            f"{gates.max_sigma_deg:g} deg): add incidences or finer sweeps"
        )
    if not abs(fit.s_weight - 0.5) <= gates.max_s_weight_dev:
        raise AlignRefused(
            f"refused: the black-glass fit needs a detector answering {100 * fit.s_weight:.1f} % "
            f"to s-polarised light (allowed 50 +/- {100 * gates.max_s_weight_dev:g} %): "
            "the readings do not follow the glass's Fresnel curve"
        )
    gap = abs(fit.lamp_zero_deg - fit.detector_zero_deg - fit.geometric_difference_deg)
    if not gap <= gates.max_geometric_gap_deg:
        raise AlignRefused(
            f"refused: the fit puts dL - dD at "
            f"{fit.lamp_zero_deg - fit.detector_zero_deg:+.3f} deg, the peaks' own midpoints "
            f"at {fit.geometric_difference_deg:+.3f} deg (allowed gap "
            f"{gates.max_geometric_gap_deg:g} deg)"
        )
