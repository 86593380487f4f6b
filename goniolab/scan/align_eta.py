"""The alignment's ETA: the scans' estimator (:mod:`goniolab.scan.eta`) over the
alignment's nominal sweeps (issue 27: an alignment sent "ETA 0 s" for 100 s of readings).

The sweeps an alignment will make depend on what it measures (each fine sweep is centred on
its coarse maximum, and extended where it misses a half-maximum crossing), so the time left
is that of its *nominal* readings: every peak at its nominal specular, as many readings
from the end of that list as the run has left. Each move is sized as the alignment makes it
(:func:`legs`: through a point 0.5 deg below both targets when an arm must go down).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from goniolab.scan.dryrun import ArmMotion
from goniolab.scan.eta import EtaEstimator, PointParts

if TYPE_CHECKING:
    from goniolab.scan.align import AlignPlan

__all__ = ["Leg", "eta_left", "legs", "move_size", "nominal_parts", "sweep"]

Leg = tuple[tuple[float, float], tuple[float, float]]


def sweep(
    plan: AlignPlan, limits_deg: tuple[float, float], ti: float, centre_deg: float
) -> list[tuple[float, float]]:
    """The coarse sweep around the specular of ``ti`` and the fine one around
    ``centre_deg``, within the detector's limits."""
    lo, hi = limits_deg
    coarse, _ = plan.sweeps(ti)
    fine = plan.fine(centre_deg)
    return [(ti, float(t)) for t in (*coarse, *fine) if lo <= t <= hi]


def legs(pos: tuple[float, float], ti: float, tr: float) -> list[Leg]:
    """The moves from ``pos`` to (ti, tr): through a point 0.5 deg below both when either
    arm must go down (every target is approached from below, the scans' direction)."""
    if ti < pos[0] - 1e-9 or tr < pos[1] - 1e-9:
        pre = (min(ti, pos[0]) - 0.5, min(tr, pos[1]) - 0.5)
        return [(pos, pre), (pre, (ti, tr))]
    return [(pos, (ti, tr))]


def move_size(motion: ArmMotion | None, moves: Sequence[Leg]) -> float:
    """A move's size for the ETA: the motion model's seconds, else the degrees travelled."""
    if motion is not None:
        return math.fsum(motion.move_time_s(a, b) for a, b in moves)
    return math.fsum(max(abs(b[0] - a[0]), abs(b[1] - a[1])) for a, b in moves)


def nominal_parts(
    nominal: Sequence[tuple[float, float]],
    start: tuple[float, float],
    motion: ArmMotion | None,
    reading_lab_s: float,
) -> list[PointParts]:
    """The parts of the ``nominal`` readings (in order) from the arms at ``start``."""
    parts, pos = [], start
    for g in nominal:
        x = move_size(motion, legs(pos, *g)) if g != pos else None
        parts.append(PointParts(x, 0.0, reading_lab_s))
        pos = g
    return parts


def eta_left(eta: EtaEstimator | None, n_left: int) -> float:
    """Wall seconds of the last ``n_left`` nominal readings (readings beyond the nominal
    list, the fine sweeps' extensions, each like its last one)."""
    if eta is None:
        return math.nan
    points = eta.points
    start = len(points) - max(0, n_left)
    extra = 0.0 if start >= 0 or not points else -start * eta.point_s(points[-1])
    return eta.left_s(max(0, start)) + extra
