"""Adaptive sampling: the detector angles of a scan placed where the curve bends.

A scan reconstructs the in-plane curve ``L(theta_r)`` from ``n`` readings by linear
interpolation. On an interval of width ``h`` the interpolation error is at most
``h^2 |L''| / 8`` (the remainder of linear interpolation), so for a fixed number of
points the largest error is smallest when every interval has the same ``h^2 |L''|``:
a point density ``rho ~ |L''|^(1/2)`` (de Boor, *A Practical Guide to Splines*, ch. III;
the rms error alone would ask for ``|L''|^(2/5)``, which measured on the twin's samples
did slightly worse once blurred). ``L`` is not known before the scan, but the prediction
is: its curvature sets the density, blurred by ``blur_deg`` (the measured peak may stand
a degree or two from the predicted one: misalignment, model error) and mixed with a
uniform floor (``floor``: the flanks keep a fraction of their points, and a peak the
model misses is still sampled). The ``n`` angles are the density's quantiles: the
same ``n`` readings, the same start and stop, the same monotonic sweep as the uniform
scan -- the same run time -- with the points where the curve changes fast.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["adaptive_angles", "reconstruction_error", "sampling_density"]

FloatArray = NDArray[np.float64]

#: Resolution of the adaptive angles (deg): finer than any arm's step, coarser than noise.
ANGLE_RESOLUTION_DEG = 1e-3


def sampling_density(
    theta_deg: FloatArray,
    curve: FloatArray,
    *,
    floor: float = 0.2,
    blur_deg: float = 1.0,
    exponent: float = 0.5,
) -> FloatArray:
    """Point density (mean 1 over ``theta_deg``) for sampling ``curve``.

    Parameters
    ----------
    theta_deg
        An evenly spaced, increasing grid of angles (degrees).
    curve
        The expected curve on that grid (the prediction).
    floor
        Fraction of the density that is uniform (0..1).
    blur_deg
        Standard deviation of the Gaussian blur of ``|curve''|`` (degrees).
    exponent
        ``rho ~ |curve''|^exponent`` (module docstring).
    """
    x = np.asarray(theta_deg, dtype=np.float64)
    y = np.asarray(curve, dtype=np.float64)
    if x.size < 3 or x.size != y.size:
        raise ValueError("sampling_density: needs the same number (>= 3) of angles and values")
    dx = float(x[1] - x[0])
    d2 = np.abs(np.gradient(np.gradient(y, dx), dx))
    # rounding leaves ~1e-12 of "curvature" on a straight line: that is none
    scale = float(np.max(np.abs(y))) / float(x[-1] - x[0]) ** 2
    d2[d2 <= 1e-9 * scale] = 0.0
    if blur_deg > 0:
        half = max(1, math.ceil(4 * blur_deg / dx))
        k = np.exp(-0.5 * (np.arange(-half, half + 1) * dx / blur_deg) ** 2)
        padded = np.pad(d2, half, mode="edge")
        d2 = np.convolve(padded, k / k.sum(), mode="valid")
    w = d2**exponent
    mean = float(w.mean())
    if not (math.isfinite(mean) and mean > 0):
        return np.ones_like(x)
    return np.asarray((1.0 - floor) * w / mean + floor)


def adaptive_angles(
    start_deg: float,
    stop_deg: float,
    n: int,
    predict: Callable[[FloatArray], Sequence[float] | FloatArray],
    *,
    floor: float = 0.2,
    blur_deg: float = 1.0,
    min_step_deg: float = 0.05,
) -> tuple[float, ...]:
    """``n`` angles from ``start_deg`` to ``stop_deg`` (both included, increasing), dense
    where the predicted curve bends (module docstring).

    Parameters
    ----------
    predict
        The expected curve at an array of angles (e.g. the prediction at the plan's
        incidence); called once, on a grid of 20 steps per uniform step (at most 0.05 deg).
    min_step_deg
        Smallest spacing of two angles (a step the arm and the detector cone resolve).
    floor, blur_deg
        See :func:`sampling_density`.

    Raises
    ------
    ValueError
        ``n < 2``, ``stop <= start``, or ``n`` angles cannot be ``min_step_deg`` apart.
    """
    if n < 2 or not stop_deg > start_deg:
        raise ValueError(f"adaptive sampling needs n >= 2 and stop > start, got {n}, "
                         f"{start_deg:g}..{stop_deg:g}")  # fmt: skip
    span = stop_deg - start_deg
    if (n - 1) * min_step_deg > span:
        raise ValueError(
            f"adaptive sampling: {n} angles cannot lie {min_step_deg:g} deg apart in "
            f"{start_deg:g}..{stop_deg:g} deg"
        )
    m = max(math.ceil(span / min(0.05, span / (20 * (n - 1)))), 2 * n) + 1
    x = np.linspace(start_deg, stop_deg, m)
    y = np.asarray(predict(x), dtype=np.float64)
    if y.shape != x.shape or not np.all(np.isfinite(y)):
        raise ValueError("adaptive sampling: the prediction is not finite on the sweep")
    rho = sampling_density(x, y, floor=floor, blur_deg=blur_deg)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (rho[1:] + rho[:-1]) * np.diff(x))])
    cdf /= cdf[-1]
    t = np.interp(np.linspace(0.0, 1.0, n), cdf, x)
    # at least min_step_deg apart (a forward then a backward pass keeps both ends)
    for i in range(1, n):
        t[i] = max(t[i], t[i - 1] + min_step_deg)
    t[-1] = stop_deg
    for i in range(n - 2, -1, -1):
        t[i] = min(t[i], t[i + 1] - min_step_deg)
    t[0] = start_deg
    out = np.round(t / ANGLE_RESOLUTION_DEG) * ANGLE_RESOLUTION_DEG
    return tuple(round(float(v), 9) for v in out)


def reconstruction_error(
    theta_deg: Sequence[float] | FloatArray,
    values: Sequence[float] | FloatArray,
    truth_theta_deg: FloatArray,
    truth: FloatArray,
) -> tuple[float, float]:
    """``(rms, max)`` error of the linear interpolation of ``values`` (at ``theta_deg``)
    against ``truth`` on the dense ``truth_theta_deg`` within the sampled range."""
    x = np.asarray(theta_deg, dtype=np.float64)
    order = np.argsort(x)
    x, v = x[order], np.asarray(values, dtype=np.float64)[order]
    tt = np.asarray(truth_theta_deg, dtype=np.float64)
    inside = (tt >= x[0]) & (tt <= x[-1])
    err = np.interp(tt[inside], x, v) - np.asarray(truth, dtype=np.float64)[inside]
    return float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err)))
