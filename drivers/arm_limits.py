"""The goniometer's axis limits and arm interlock: the one place their values and checks live.

Every validator of an arm angle reads this module: the lab config (:mod:`goniolab.config`:
the defaults of ``[goniometer.lamp]`` / ``[goniometer.detector]`` ``limits_deg`` and of
``min_separation_deg``, the floor of the latter, the park position), the drivers
(:class:`drivers.modbus_stepper.ModbusStepperAxis` defaults and limit sanity,
:meth:`drivers.goniometer.TwoArmGoniometer.check_geometry`), and through the goniometer the
scan's dry run (:func:`goniolab.scan.dryrun.dry_run`, which refuses a plan before anything
moves) and the bluesky face (its limit signals). It lives in ``drivers`` because drivers
import nothing from ``goniolab``; it imports nothing itself.

Geometry (:mod:`drivers.goniometer`): the lamp arm stands at ``theta_i`` (0 = the sample
normal, towards grazing), the detector arm at ``theta_r`` (signed: > 0 on the specular
side, < 0 on the lamp side), and the arms are ``|theta_i + theta_r|`` apart.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

__all__ = [
    "ARM_TRAVEL_DEG",
    "DEFAULT_MIN_SEPARATION_DEG",
    "DETECTOR_LIMITS_DEG",
    "LAMP_LIMITS_DEG",
    "MIN_SEPARATION_FLOOR_DEG",
    "GeometryProblem",
    "geometry_problem",
    "limits_problem",
    "outside_limits",
    "separation_floor_problem",
]

#: Default soft limits of the lamp arm (theta_i), deg: the normal to 85 deg, the grazing
#: geometry of ISO 2813 (its 85 deg gloss) and the last angle the arm's shadow leaves free.
LAMP_LIMITS_DEG: tuple[float, float] = (0.0, 85.0)
#: Default soft limits of the detector arm (theta_r), deg: 85 deg either side of the normal.
DETECTOR_LIMITS_DEG: tuple[float, float] = (-85.0, 85.0)
#: The travel any arm's limits must lie within, deg (a limit beyond half a turn is a typo).
ARM_TRAVEL_DEG: tuple[float, float] = (-180.0, 180.0)
#: Default smallest angular distance between the arms, deg.
DEFAULT_MIN_SEPARATION_DEG = 10.0
#: Smallest ``min_separation_deg`` anyone may set, deg: 0 would switch the interlock off.
MIN_SEPARATION_FLOOR_DEG = 1.0


def limits_problem(limits_deg: tuple[float, float]) -> str | None:
    """Why ``(low, high)`` cannot be an arm's soft limits, or ``None`` when it can.

    ``low < high``, both finite and within :data:`ARM_TRAVEL_DEG`.
    """
    lo, hi = limits_deg
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return f"limits must be finite, got [{lo:g}, {hi:g}]"
    if not lo < hi:
        return f"lower limit {lo:g} must be below upper limit {hi:g}"
    t_lo, t_hi = ARM_TRAVEL_DEG
    if lo < t_lo or hi > t_hi:
        return f"limits must lie within [{t_lo:g}, {t_hi:g}] deg, got [{lo:g}, {hi:g}]"
    return None


def separation_floor_problem(min_separation_deg: float) -> str | None:
    """Why ``min_separation_deg`` cannot be the arm interlock's distance, or ``None``."""
    v = min_separation_deg
    if not math.isfinite(v):
        return f"must be a finite angle, got {v}"
    if v < MIN_SEPARATION_FLOOR_DEG:
        return (
            f"{v:g} deg is below the floor {MIN_SEPARATION_FLOOR_DEG:g} deg: the arm "
            "interlock cannot be switched off"
        )
    return None


def outside_limits(value_deg: float, limits_deg: tuple[float, float]) -> bool:
    """Whether an arm angle lies outside its soft limits (a NaN angle does)."""
    lo, hi = limits_deg
    return not lo <= value_deg <= hi


class GeometryProblem(NamedTuple):
    """Why the arms must not stand at a geometry (:func:`geometry_problem`).

    ``kind`` is ``"limit"`` (an arm beyond its soft limits: the driver raises
    ``LimitError``) or ``"interlock"`` (the arms too close: ``InterlockError``); ``device``
    the arm (or ``"goniometer"``) the error names; ``message`` the reason, in the words
    every face shows.
    """

    kind: Literal["limit", "interlock"]
    device: str
    message: str


def geometry_problem(
    theta_i_deg: float,
    theta_r_deg: float,
    *,
    lamp_limits_deg: tuple[float, float],
    detector_limits_deg: tuple[float, float],
    min_separation_deg: float,
    lamp: str = "lamp",
    detector: str = "detector",
) -> GeometryProblem | None:
    """Why the arms' own angles ``theta_i_deg`` (lamp), ``theta_r_deg`` (detector) are
    unsafe, or ``None``: an arm outside its soft limits (the lamp checked first), else the
    arms ``|theta_i + theta_r|`` apart, below ``min_separation_deg``.

    The one text of the refusal: :meth:`drivers.goniometer.TwoArmGoniometer.check_geometry`
    raises it, and the lab's plan check (:func:`goniolab.app.lab_setup.check_reach`, the
    TUI form as it is typed) raises it from the config's limits before any instrument is
    reached. ``lamp``/``detector``: the arms' names.
    """
    for name, value, limits, label in (
        (lamp, theta_i_deg, lamp_limits_deg, "theta_i"),
        (detector, theta_r_deg, detector_limits_deg, "theta_r"),
    ):
        if outside_limits(value, limits):
            lo, hi = limits
            return GeometryProblem(
                "limit", name, f"{label}={value} deg outside the {name} arm limits [{lo}, {hi}] deg"
            )
    separation = abs(theta_i_deg + theta_r_deg)
    if separation < min_separation_deg:
        return GeometryProblem(
            "interlock",
            "goniometer",
            f"theta_i={theta_i_deg} deg, theta_r={theta_r_deg} deg puts the arms "
            f"{separation:.3f} deg apart, below the minimum {min_separation_deg} deg",
        )
    return None
