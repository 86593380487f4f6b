"""The two-arm in-plane goniometer built from any two :class:`drivers.base.Axis` objects.

Geometry (docs/ARCHITECTURE.md): on a common in-plane angle scale the lamp arm sits at
``-theta_i_deg`` and the detector arm at ``+theta_r_deg`` (theta_r signed: > 0 specular
side, < 0 lamp side). The angular distance between the arms is therefore

    separation_deg = |theta_i_deg + theta_r_deg|,

and it must never drop below ``min_separation_deg`` -- not at the target and not while the
arms travel. Let ``s(t) = theta_i(t) + theta_r(t)``. Moving one arm changes ``s``
monotonically, so a single-arm move is safe iff both of its end points are safe and lie on
the same side (same sign of ``s``); the arms can never pass through each other, so a target
with the opposite sign of ``s`` is refused (:class:`~drivers.base.InterlockError`).

Ordering rule used by :meth:`TwoArmGoniometer.move_to` (``sigma`` = sign of the target's
``s``; ``d_i``, ``d_r`` = each arm's change of ``sigma * s``):

* ``d_i`` and ``d_r`` of the same sign (both arms widen, or both narrow, the gap): both arms
  move at once. ``sigma * s(t)`` is then monotone between its safe start and safe end
  whatever the relative speeds, so it stays >= ``min_separation_deg``.
* opposite signs: the arm that widens the gap moves first, then the other. The
  intermediate gap exceeds the start gap, and the second move is monotone from there to
  the (safe) target.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Sequence

from drivers.base import Axis, DeviceError, InterlockError, LimitError

__all__ = ["TwoArmGoniometer", "plan_moves"]


def plan_moves(
    start_deg: tuple[float, float], target_deg: tuple[float, float]
) -> list[tuple[str, ...]]:
    """Order the arm moves from ``start_deg`` to ``target_deg`` (both ``(theta_i, theta_r)``).

    Returns a list of stages, each a tuple of arm names (``"lamp"``, ``"detector"``) that
    move together; arms that do not change are left out. The caller must have checked the
    target geometry; see the module docstring for the safety argument.

    Raises
    ------
    InterlockError
        The target lies on the other side of the lamp arm (the arms would cross).
    """
    s0 = start_deg[0] + start_deg[1]
    s1 = target_deg[0] + target_deg[1]
    if s0 * s1 < 0.0:
        raise InterlockError(
            f"moving from theta_i={start_deg[0]:.3f}, theta_r={start_deg[1]:.3f} to "
            f"theta_i={target_deg[0]:.3f}, theta_r={target_deg[1]:.3f} deg would pass the "
            "detector arm through the lamp arm",
            device="goniometer",
        )
    sigma = 1.0 if s1 > 0.0 else -1.0
    d_i = sigma * (target_deg[0] - start_deg[0])
    d_r = sigma * (target_deg[1] - start_deg[1])
    moving = [name for name, d in (("lamp", d_i), ("detector", d_r)) if d != 0.0]
    if len(moving) < 2:
        return [tuple(moving)] if moving else []
    if (d_i > 0.0) == (d_r > 0.0):
        return [("lamp", "detector")]
    return [("lamp",), ("detector",)] if d_i > 0.0 else [("detector",), ("lamp",)]


class TwoArmGoniometer:
    """Lamp arm (theta_i) + detector arm (theta_r) with limit and separation interlocks.

    Implements :class:`drivers.base.Goniometer` for real or simulated axes.

    Parameters
    ----------
    lamp, detector
        The two axes; ``lamp`` angle = theta_i_deg, ``detector`` angle = theta_r_deg.
    min_separation_deg
        Smallest allowed ``|theta_i_deg + theta_r_deg|``.
    park_deg
        ``(theta_i_deg, theta_r_deg)`` of the park position (checked at construction).
    """

    def __init__(
        self,
        lamp: Axis,
        detector: Axis,
        *,
        min_separation_deg: float,
        park_deg: tuple[float, float] = (45.0, 45.0),
    ) -> None:
        if not (math.isfinite(min_separation_deg) and min_separation_deg >= 0.0):
            raise ValueError(
                f"goniometer: min_separation_deg must be >= 0, got {min_separation_deg}"
            )
        self.lamp = lamp
        self.detector = detector
        self.min_separation_deg = float(min_separation_deg)
        self.park_deg = (float(park_deg[0]), float(park_deg[1]))
        try:
            self.check_geometry(*self.park_deg)
        except DeviceError as exc:
            raise ValueError(
                f"goniometer: park position {self.park_deg} is invalid: {exc}"
            ) from None

    def _axis(self, name: str) -> Axis:
        return self.lamp if name == "lamp" else self.detector

    def check_geometry(self, theta_i_deg: float, theta_r_deg: float) -> None:
        """Raise unless both arms are within their limits and far enough apart.

        Raises
        ------
        LimitError
            theta_i outside the lamp's limits or theta_r outside the detector's.
        InterlockError
            ``|theta_i_deg + theta_r_deg| < min_separation_deg``.
        """
        for axis, value, label in (
            (self.lamp, theta_i_deg, "theta_i"),
            (self.detector, theta_r_deg, "theta_r"),
        ):
            lo, hi = axis.limits_deg
            if not lo <= value <= hi:
                raise LimitError(
                    f"{label}={value} deg outside the {axis.name} arm limits [{lo}, {hi}] deg",
                    device=axis.name,
                )
        separation = abs(theta_i_deg + theta_r_deg)
        if separation < self.min_separation_deg:
            raise InterlockError(
                f"theta_i={theta_i_deg} deg, theta_r={theta_r_deg} deg puts the arms "
                f"{separation:.3f} deg apart, below the minimum {self.min_separation_deg} deg",
                device="goniometer",
            )

    async def connect(self) -> None:
        """Connect both arms."""
        await self.lamp.connect()
        await self.detector.connect()

    async def close(self) -> None:
        """Close both arms (the detector is closed even if closing the lamp fails)."""
        try:
            await self.lamp.close()
        finally:
            await self.detector.close()

    async def positions_deg(self) -> tuple[float, float]:
        """``(theta_i_deg, theta_r_deg)`` from the arms' feedback."""
        return await self.lamp.position_deg(), await self.detector.position_deg()

    async def _run_stage(
        self, names: Sequence[str], target: dict[str, float], timeout_s: float
    ) -> None:
        async def one(axis: Axis, target_deg: float) -> None:
            await axis.move_to(target_deg)
            await axis.wait_in_position(timeout_s)

        jobs: list[Awaitable[None]] = [one(self._axis(n), target[n]) for n in names]
        results = await asyncio.gather(*jobs, return_exceptions=True)
        errors = [r for r in results if isinstance(r, BaseException)]
        if errors:
            await self._stop_all()
            raise errors[0]

    async def move_to(
        self, theta_i_deg: float, theta_r_deg: float, timeout_s: float
    ) -> tuple[float, float]:
        """Check the geometry, move the arms in a safe order, return the reached positions.

        ``timeout_s`` applies to each arm's move. On any error both arms are stopped and
        the error is re-raised.
        """
        self.check_geometry(theta_i_deg, theta_r_deg)
        start = await self.positions_deg()
        stages = plan_moves(start, (theta_i_deg, theta_r_deg))
        target = {"lamp": theta_i_deg, "detector": theta_r_deg}
        for stage in stages:
            await self._run_stage(stage, target, timeout_s)
        return await self.positions_deg()

    async def home(self, timeout_s: float) -> None:
        """Home the lamp arm, then the detector arm (one at a time).

        Homing runs the controllers' own home searches; their switch positions, not our
        separation check, define where the arms go, so the arms are never homed at once.
        """
        try:
            await self.lamp.home(timeout_s)
            await self.detector.home(timeout_s)
        except BaseException:
            await self._stop_all()
            raise

    async def park(self, timeout_s: float) -> None:
        """Move to the park position with the same interlocks as :meth:`move_to`."""
        await self.move_to(*self.park_deg, timeout_s)

    async def _stop_all(self) -> None:
        results = await asyncio.gather(
            self.lamp.stop(), self.detector.stop(), return_exceptions=True
        )
        del results  # stopping is best effort while another error propagates

    async def stop(self) -> None:
        """Stop both arms; both are always told to stop, the first failure is raised."""
        results = await asyncio.gather(
            self.lamp.stop(), self.detector.stop(), return_exceptions=True
        )
        for result in results:
            if isinstance(result, BaseException):
                raise result
