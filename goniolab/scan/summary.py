"""Run summary: measured vs predicted curve, RMSE, peak metrics and a misalignment hint.

The comparison metrics are those of Wittmann et al. (2021, fig. 8): peak amplitude and full
width at half maximum of the in-plane luminance curve, measured (mean of the repeats at each
geometry) against predicted, plus the RMSE of the per-geometry residuals.

Misalignment hint (Wittmann et al. 2021, sec. 5.2-5.3 attribute the scatter on glossy
samples to arm/sample misalignment). Derivation: a facet of normal ``n`` reflects
``wi`` into ``wo = 2 (wi.n) n - wi`` (seed sec. 3.2, ``M = 2 n n^T - I``). Tilting the sample
by ``tau`` about the axis normal to the plane of incidence rotates ``n`` by ``tau`` in that
plane; a reflection about a line rotated by ``tau`` is the original reflection followed by a
rotation of ``2 tau``, so the specular peak moves by ``delta = 2 tau`` (in either sense,
depending on the tilt's sense). A zero offset ``d`` of the lamp arm moves the true incidence
to ``theta_i + d`` and the peak by ``d``; a zero offset of the detector arm moves the
recorded angles, and so the peak, by ``d`` too. So a measured peak offset ``delta`` from the
predicted one points to a sample tilt of ``|delta| / 2`` or an arm zero offset of ``|delta|``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from goniolab.optics.metrics import PeakMetrics, peak_metrics
from goniolab.scan.plans import MIRROR_INDEX, BrdfPlan
from goniolab.store import PointRow

__all__ = ["CHECK_LIMITS", "misalignment_hint", "prediction_check", "summarize_brdf"]

#: Limits of :func:`prediction_check`: measured/predicted peak amplitude and FWHM ratios,
#: and the RMSE of the residuals over the predicted peak amplitude. The realistic twin's
#: own model error stays inside them for every library sample (docs/TWIN.md: amplitude
#: ratios 0.71..1.03, FWHM ratios 0.97..1.36); a wrong index or a wrong map leaves them.
CHECK_LIMITS: dict[str, tuple[float, float]] = {
    "amplitude_ratio": (0.6, 1.0 / 0.6),
    "fwhm_ratio": (0.67, 1.5),
    "nrmse": (0.0, 0.2),
}


def prediction_check(
    amplitude_ratio: float | None,
    fwhm_ratio: float | None,
    nrmse: float | None,
    limits: dict[str, tuple[float, float]] | None = None,
) -> dict[str, Any]:
    """Is the prediction consistent with the measurement? (Wittmann et al. 2021 compare
    peak amplitude and FWHM, fig. 8.) A metric that cannot be computed is not judged.

    Returns
    -------
    dict
        ``{"flagged": bool, "reasons": [...], "amplitude_ratio", "fwhm_ratio", "nrmse",
        "limits"}``.
    """
    lim = limits or CHECK_LIMITS
    values = {"amplitude_ratio": amplitude_ratio, "fwhm_ratio": fwhm_ratio, "nrmse": nrmse}
    reasons = []
    for key, v in values.items():
        lo, hi = lim[key]
        if v is not None and math.isfinite(v) and not lo <= v <= hi:
            reasons.append(f"{key} {v:.3g} outside [{lo:.3g}, {hi:.3g}]")
    return {"flagged": bool(reasons), "reasons": reasons, **values, "limits": lim}


def misalignment_hint(
    measured_peak_deg: float, predicted_peak_deg: float, threshold_deg: float
) -> str | None:
    """Explain a peak offset larger than ``threshold_deg`` (see the module docstring).

    Returns
    -------
    str or None
        ``None`` when ``|measured - predicted| <= threshold_deg``.
    """
    delta = measured_peak_deg - predicted_peak_deg
    if not math.isfinite(delta) or abs(delta) <= threshold_deg:
        return None
    return (
        f"measured peak at {measured_peak_deg:.2f} deg, predicted at {predicted_peak_deg:.2f} deg "
        f"(offset {delta:+.2f} deg > {threshold_deg:g} deg): the sample may be tilted by about "
        f"{abs(delta) / 2:.2f} deg in the plane of incidence (a tilt tau moves the specular peak "
        f"by 2 tau), or an arm zero may be off by about {abs(delta):.2f} deg; check the sample "
        "seating and the arm zeros (Wittmann et al. 2021, sec. 5.2-5.3)"
    )


def _finite(v: float) -> float | None:
    """JSON has no NaN: a FWHM whose half-maximum crossing lies outside the scan is None."""
    return float(v) if math.isfinite(v) else None


def _peak_dict(pm: PeakMetrics) -> dict[str, float | None]:
    return {
        "amplitude_pct": _finite(pm.amplitude),
        "position_deg": _finite(pm.position_deg),
        "fwhm_deg": _finite(pm.fwhm_deg),
    }


def summarize_brdf(
    plan: BrdfPlan,
    points: Sequence[PointRow],
    predictions: Mapping[int, float],
    *,
    misalignment_threshold_deg: float = 0.5,
) -> dict[str, Any]:
    """Summarise a BRDF run from what the store holds.

    Parameters
    ----------
    plan
        The run's plan.
    points
        Stored readings (``luminance_pct`` already relative to the mirror reference).
    predictions
        ``{index: predicted_pct}``.
    misalignment_threshold_deg
        Peak offset above which a hint is given.

    Returns
    -------
    dict
        JSON-serialisable: counts, per-geometry mean/std/prediction/residual, ``rmse_pct``,
        ``measured_peak``/``predicted_peak`` (:func:`goniolab.optics.metrics.peak_metrics`
        on the repeat means and on the predictions, both over the measured geometries),
        ``peak_offset_deg``, ``amplitude_ratio``, ``hint`` and ``prediction_check``
        (:func:`prediction_check`; all ``None`` unless both maxima lie inside the measured
        range and it contains the specular direction; ``peak_note`` then says why).
    """
    from goniolab.scan.exposure import EXCLUDED_QUALITY, quality_of_raw

    by_index: dict[int, list[float]] = {}
    mirror: list[float] = []
    flagged: dict[str, int] = {}
    for p in points:
        q = quality_of_raw(p.raw)
        if q in EXCLUDED_QUALITY:  # stored and exported, never averaged or fitted
            flagged[q] = flagged.get(q, 0) + 1
            continue
        if p.index == MIRROR_INDEX:
            mirror.append(p.luminance_pct)
        else:
            by_index.setdefault(p.index, []).append(p.luminance_pct)
    geometries: list[dict[str, Any]] = []
    residuals: list[float] = []
    for i, tr in enumerate(plan.theta_r_deg):
        vals = by_index.get(i, [])
        mean = math.fsum(vals) / len(vals) if vals else None
        std = float(np.std(vals, ddof=1)) if len(vals) > 1 else (0.0 if vals else None)
        pred = predictions.get(i)
        resid = None if mean is None or pred is None else mean - pred
        if resid is not None:
            residuals.append(resid)
        geometries.append(
            {
                "index": i,
                "theta_r_deg": tr,
                "n": len(vals),
                "mean_pct": mean,
                "std_pct": std,
                "predicted_pct": pred,
                "residual_pct": resid,
            }
        )
    n_readings = sum(len(v) for v in by_index.values()) + len(mirror)
    n_planned = len(plan.points())
    out: dict[str, Any] = {
        "theta_i_deg": plan.theta_i_deg,
        "sample": plan.sample,
        "readings": n_readings,
        "planned_readings": n_planned,
        "complete": n_readings == n_planned,
        "mirror_pct": (math.fsum(mirror) / len(mirror)) if mirror else None,
        "flagged_readings": flagged,
        "rmse_pct": math.sqrt(math.fsum(r * r for r in residuals) / len(residuals))
        if residuals
        else None,
        "measured_peak": None,
        "predicted_peak": None,
        "peak_offset_deg": None,
        "amplitude_ratio": None,
        "hint": None,
        "peak_note": None,
        "prediction_check": None,
        "geometries": geometries,
    }
    # peak_metrics wants increasing angles: a listed plan may scan in any order.
    order = sorted(range(plan.n_geometries), key=lambda i: plan.theta_r_deg[i])
    measured_idx = [i for i in order if geometries[i]["mean_pct"] is not None]
    if len(measured_idx) < 3:
        if n_readings:
            out["peak_note"] = "fewer than 3 geometries measured: no peak metrics"
        return out
    theta = np.array([plan.theta_r_deg[i] for i in measured_idx])
    means = np.array([geometries[i]["mean_pct"] for i in measured_idx])
    mp = peak_metrics(theta, means)
    out["measured_peak"] = _peak_dict(mp)
    if not all(i in predictions for i in measured_idx):
        return out
    # Measured and predicted curves are compared on the same geometries (an interrupted
    # run compares what it measured), and only when the measured range contains the
    # specular direction theta_r = theta_i and brackets the predicted peak of the whole
    # plan, with the measured maximum inside it: otherwise the "peak" of the curve is its
    # end or a bump of the off-specular floor, and an "offset" would be the distance to
    # it, not a misalignment.
    pred_curve = np.array([predictions[i] for i in measured_idx])
    pp = peak_metrics(theta, pred_curve)
    out["predicted_peak"] = _peak_dict(pp)
    if all(i in predictions for i in order) and len(measured_idx) < len(order):
        theta_all = np.array([plan.theta_r_deg[i] for i in order])
        pp_plan = peak_metrics(theta_all, np.array([predictions[i] for i in order]))
    else:
        pp_plan = pp
    k_meas = int(np.argmax(means))
    lo, hi = float(theta[0]), float(theta[-1])
    if not lo < plan.theta_i_deg < hi:
        out["peak_note"] = (
            f"the measured range {lo:g}..{hi:g} deg does not contain the specular direction "
            f"theta_r = {plan.theta_i_deg:g} deg: no peak comparison"
        )
        return out
    if not (lo < pp_plan.position_deg < hi and 0 < k_meas < len(measured_idx) - 1):
        out["peak_note"] = (
            f"the measured range {lo:g}..{hi:g} deg does not bracket the specular peak "
            f"(predicted maximum at {pp_plan.position_deg:.2f} deg, measured maximum at "
            f"{mp.position_deg:.2f} deg): no peak comparison"
        )
        return out
    out["peak_offset_deg"] = float(mp.position_deg - pp.position_deg)
    if pp.amplitude > 0:
        out["amplitude_ratio"] = float(mp.amplitude / pp.amplitude)
    fwhm_ratio = (
        float(mp.fwhm_deg / pp.fwhm_deg)
        if math.isfinite(mp.fwhm_deg) and math.isfinite(pp.fwhm_deg) and pp.fwhm_deg > 0
        else None
    )
    nrmse = (
        out["rmse_pct"] / pp.amplitude if out["rmse_pct"] is not None and pp.amplitude > 0 else None
    )
    out["prediction_check"] = prediction_check(out["amplitude_ratio"], fwhm_ratio, nrmse)
    out["hint"] = misalignment_hint(
        float(mp.position_deg), float(pp.position_deg), misalignment_threshold_deg
    )
    return out
