"""Peak metrics of an in-plane reflectance curve: amplitude, position and FWHM.

Wittmann et al. compare measured and computed in-plane BRDF curves through two numbers,
the peak amplitude and the full width at half maximum (sec. 4.2, fig. 8).

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 4.2, fig. 8.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["PeakMetrics", "peak_metrics"]


@dataclass(frozen=True, slots=True)
class PeakMetrics:
    """Amplitude (curve units), position and full width at half maximum (degrees)."""

    amplitude: float
    position_deg: float
    fwhm_deg: float


def _half_crossing(x0: float, y0: float, x1: float, y1: float, half: float) -> float:
    """x where the segment (x0, y0)-(x1, y1) crosses ``half`` (linear interpolation)."""
    if y1 == y0:
        return 0.5 * (x0 + x1)
    return x0 + (half - y0) * (x1 - x0) / (y1 - y0)


def peak_metrics(theta_deg: ArrayLike, values: ArrayLike) -> PeakMetrics:
    """Peak amplitude, position and FWHM of a sampled single-peaked curve.

    Parameters
    ----------
    theta_deg : array_like
        Strictly increasing sample angles in degrees.
    values : array_like
        Curve values (same length, at least 3, finite).

    Returns
    -------
    PeakMetrics
        The maximum is refined with the parabola through the largest sample and its two
        neighbours (vertex position and height; the raw maximum when it lies at an end).
        The FWHM is the distance between the half-maximum crossings found by linear
        interpolation walking outwards from the largest sample; it is NaN when either
        crossing lies outside the sampled range.
    """
    x = np.asarray(theta_deg, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or y.shape != x.shape:
        raise ValueError(
            f"theta_deg and values must be 1-D of equal length, got {x.shape}, {y.shape}"
        )
    if x.size < 3:
        raise ValueError(f"peak_metrics needs at least 3 samples, got {x.size}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("theta_deg and values must be finite")
    if np.any(np.diff(x) <= 0):
        raise ValueError("theta_deg must be strictly increasing")
    k = int(np.argmax(y))
    amplitude = float(y[k])
    position = float(x[k])
    if 0 < k < x.size - 1:
        x0, x1, x2 = x[k - 1], x[k], x[k + 1]
        y0, y1, y2 = y[k - 1], y[k], y[k + 1]
        # Parabola through three (possibly unequally spaced) points, Lagrange form.
        d = (x0 - x1) * (x0 - x2) * (x1 - x2)
        a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / d
        b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / d
        c = (x1 * x2 * (x1 - x2) * y0 + x2 * x0 * (x2 - x0) * y1 + x0 * x1 * (x0 - x1) * y2) / d
        if a < 0:
            xv = -b / (2 * a)
            if x0 <= xv <= x2:
                position = float(xv)
                amplitude = float(c - b * b / (4 * a))
    half = 0.5 * amplitude
    left = math.nan
    for j in range(k, 0, -1):
        if y[j - 1] <= half < y[j] or y[j - 1] < half <= y[j]:
            left = _half_crossing(float(x[j - 1]), float(y[j - 1]), float(x[j]), float(y[j]), half)
            break
    right = math.nan
    for j in range(k, x.size - 1):
        if y[j + 1] <= half < y[j] or y[j + 1] < half <= y[j]:
            right = _half_crossing(float(x[j]), float(y[j]), float(x[j + 1]), float(y[j + 1]), half)
            break
    fwhm = right - left if (math.isfinite(left) and math.isfinite(right)) else math.nan
    return PeakMetrics(amplitude=amplitude, position_deg=position, fwhm_deg=float(fwhm))
