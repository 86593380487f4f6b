"""The dry run of a scan: every geometry checked before any motion, and the run time estimated.

:func:`dry_run` checks every geometry (and the park position) with
``Goniometer.check_geometry`` (soft limits + arm-separation interlock), refusing the plan
with :class:`PlanRefused` before anything moves, and estimates the run time from the
trapezoidal motion model (:func:`drivers.timing.trapezoid_duration_s`, Biagiotti &
Melchiorri sec. 3.2) plus dwell and reading time and the final park move (a home search is
controller-specific and not estimated). Each reading's parts (:class:`~goniolab.scan.eta.
PointParts`) are the priors of the run's ETA (:class:`~goniolab.scan.eta.EtaEstimator`),
which measured rates replace as the run goes on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from drivers.arm_limits import geometry_problem
from drivers.base import DeviceError, Goniometer, InterlockError, LimitError
from drivers.timing import trapezoid_duration_s
from goniolab.config import GoniometerConfig
from goniolab.scan.eta import PointParts
from goniolab.scan.plans import MIRROR_INDEX, PlanPoint

__all__ = [
    "ArmMotion",
    "DryRun",
    "PlanRefused",
    "check_reach",
    "config_reach",
    "dry_run",
    "reachable_range",
]


class PlanRefused(Exception):
    """The dry run found a geometry the goniometer must not reach (names point and reason).

    ``what`` is ``"park position"``, ``"mirror reference"`` or ``"point N"``; ``cause``
    the goniometer's refusal (soft limits or arm-separation interlock).
    """

    def __init__(
        self,
        what: str,
        theta_i_deg: float,
        theta_r_deg: float,
        cause: DeviceError,
        reach: str = "",
    ) -> None:
        self.what = what
        self.theta_i_deg = theta_i_deg
        self.theta_r_deg = theta_r_deg
        self.reason = cause.message + (f"; {reach}" if reach else "")
        super().__init__(
            f"{what} (theta_i={theta_i_deg:g} deg, theta_r={theta_r_deg:g} deg) is unsafe: {cause}"
            + (f"; {reach}" if reach else "")
        )


@dataclass(frozen=True, slots=True)
class ArmMotion:
    """Speed and acceleration of both arms (config ``[goniometer.lamp|detector]``)."""

    lamp_speed_deg_s: float
    lamp_accel_deg_s2: float
    detector_speed_deg_s: float
    detector_accel_deg_s2: float

    @classmethod
    def from_config(cls, goniometer: GoniometerConfig) -> ArmMotion:
        """The arms' speeds and accelerations of a lab config's ``[goniometer]``."""
        lamp, det = goniometer.lamp, goniometer.detector
        return cls(lamp.speed_deg_s, lamp.accel_deg_s2, det.speed_deg_s, det.accel_deg_s2)

    def move_time_s(self, start: tuple[float, float], target: tuple[float, float]) -> float:
        """Time of a two-arm move; the arms move together, so the slower arm sets it."""
        t_lamp = trapezoid_duration_s(
            target[0] - start[0], self.lamp_speed_deg_s, self.lamp_accel_deg_s2
        )
        t_det = trapezoid_duration_s(
            target[1] - start[1], self.detector_speed_deg_s, self.detector_accel_deg_s2
        )
        return max(t_lamp, t_det)


@dataclass(frozen=True, slots=True)
class DryRun:
    """Result of :func:`dry_run`: every reading's estimated duration and the total."""

    n_readings: int
    n_moves: int
    point_times_s: tuple[float, ...]
    #: The move from the last geometry to the park position that ends the run.
    park_s: float = 0.0
    #: Each reading's parts (move, dwell, reading) in lab seconds, the ETA's priors.
    parts: tuple[PointParts, ...] = ()

    @property
    def eta_s(self) -> float:
        """Estimated run time in seconds of lab clock, the final park move included."""
        return math.fsum(self.point_times_s) + self.park_s


def reachable_range(goniometer: Goniometer) -> str:
    """The requested angles the arms can reach once the alignment corrections are added
    (``""`` without corrections): a sweep to a limit that an alignment moved is refused
    with this range rather than failing mid-run."""
    corr = getattr(goniometer, "corrections_deg", (0.0, 0.0))
    return _reach_text(goniometer.lamp.limits_deg, goniometer.detector.limits_deg, corr)


def _reach_text(
    lamp_limits_deg: tuple[float, float],
    detector_limits_deg: tuple[float, float],
    corr: tuple[float, float],
) -> str:
    if not any(corr):
        return ""
    parts = []
    for (lo, hi), c, label in ((lamp_limits_deg, corr[0], "theta_i"), (detector_limits_deg, corr[1], "theta_r")):  # fmt: skip
        parts.append(f"{label} {lo - c:.3f}..{hi - c:.3f} deg")
    return (
        f"with the alignment corrections (lamp {corr[0]:+.3f}, detector {corr[1]:+.3f} deg) the "
        f"arms reach {', '.join(parts)}"
    )


def check_reach(
    points: Sequence[PlanPoint],
    check_geometry: Callable[[float, float], None],
    *,
    park_deg: tuple[float, float] | None,
    reach: Callable[[], str] = str,
) -> None:
    """Refuse the plan when the park position or a point's geometry is unsafe: the check
    of :func:`dry_run`, before any motion.

    ``check_geometry`` raises :class:`~drivers.base.LimitError` or
    :class:`~drivers.base.InterlockError` (a goniometer's, or :func:`config_reach`'s);
    ``reach()`` the reachable range named beside a limit refusal.

    Raises
    ------
    PlanRefused
        Naming the park position or the first unsafe point, its geometry and the reason.
    """
    if park_deg is not None:
        try:
            check_geometry(*park_deg)
        except (LimitError, InterlockError) as exc:
            text = reach() if isinstance(exc, LimitError) else ""
            raise PlanRefused("park position", *park_deg, exc, text) from exc
    checked: set[tuple[float, float]] = set()
    for p in points:
        target = (p.theta_i_deg, p.theta_r_deg)
        if target in checked:
            continue
        try:
            check_geometry(*target)
            # then above the sample plane, whatever the arms' limits allow (a config may
            # give the lamp 95 deg of travel): at 90 deg the lamp lights no sample and the
            # detector sees none
            for arm, angle in (("lamp", target[0]), ("detector", target[1])):
                if not -90.0 < angle < 90.0:
                    raise LimitError(
                        f"{angle:g} deg is not above the sample plane (|angle| < 90 deg)",
                        device=arm,
                    )
        except (LimitError, InterlockError) as exc:
            what = "mirror reference" if p.index == MIRROR_INDEX else f"point {p.index}"
            text = reach() if isinstance(exc, LimitError) else ""
            raise PlanRefused(what, *target, exc, text) from exc
        checked.add(target)


def config_reach(
    goniometer: GoniometerConfig, corrections_deg: tuple[float, float]
) -> tuple[Callable[[float, float], None], Callable[[], str]]:
    """The goniometer's ``check_geometry`` and :func:`reachable_range` from a lab config's
    ``[goniometer]`` and the alignment's corrections, with no instrument reached: the
    driver's check (:func:`drivers.arm_limits.geometry_problem`, the arms named ``lamp``
    and ``detector`` as the lab wires them), so a plan is refused in the driver's words
    before the lab is opened (the TUI form, as it is typed)."""
    lamp, det = goniometer.lamp.limits_deg, goniometer.detector.limits_deg
    corr = (float(corrections_deg[0]), float(corrections_deg[1]))

    def check_geometry(theta_i_deg: float, theta_r_deg: float) -> None:
        problem = geometry_problem(
            theta_i_deg + corr[0],
            theta_r_deg + corr[1],
            lamp_limits_deg=lamp,
            detector_limits_deg=det,
            min_separation_deg=goniometer.min_separation_deg,
        )
        if problem is not None:
            error = LimitError if problem.kind == "limit" else InterlockError
            raise error(problem.message, device=problem.device)

    return check_geometry, lambda: _reach_text(lamp, det, corr)


def dry_run(
    points: Sequence[PlanPoint],
    goniometer: Goniometer,
    motion: ArmMotion,
    *,
    start_deg: tuple[float, float],
    dwell_s: float,
    reading_time_s: float,
    park_deg: tuple[float, float] | None = None,
) -> DryRun:
    """Check every geometry before any motion and estimate the run time.

    Parameters
    ----------
    points
        The readings still to take, in order.
    goniometer
        Its ``check_geometry`` raises :class:`~drivers.base.LimitError` or
        :class:`~drivers.base.InterlockError` for an unsafe geometry; nothing moves.
    motion
        Arm speeds and accelerations for the trapezoidal move times.
    start_deg
        Arm positions (theta_i, theta_r) before the first move.
    dwell_s, reading_time_s
        Settling time after each move and time of one reading (exposure + transfer).
    park_deg
        The park geometry, checked too (a fault or an abort drives there).

    Returns
    -------
    DryRun
        Per-reading time: move (first repeat of a geometry only) + dwell + reading; and
        the final move to ``park_deg`` (0 without one).

    Raises
    ------
    PlanRefused
        Naming the first unsafe point, its geometry and the goniometer's reason.
    """
    check_reach(
        points,
        goniometer.check_geometry,
        park_deg=park_deg,
        reach=lambda: reachable_range(goniometer),
    )
    times: list[float] = []
    parts: list[PointParts] = []
    pos = start_deg
    moves = 0
    for p in points:
        target = (p.theta_i_deg, p.theta_r_deg)
        move_s: float | None = None
        if target != pos:
            move_s = motion.move_time_s(pos, target)
            moves += 1
            pos = target
        parts.append(PointParts(move_s, dwell_s if move_s is not None else 0.0, reading_time_s))
        times.append(reading_time_s + (0.0 if move_s is None else move_s + dwell_s))
    park_s = 0.0 if park_deg is None else motion.move_time_s(pos, park_deg)
    return DryRun(n_readings=len(points), n_moves=moves, point_times_s=tuple(times),
                  park_s=park_s, parts=tuple(parts))  # fmt: skip
