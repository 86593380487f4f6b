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

Homing (:meth:`TwoArmGoniometer.home`, :func:`plan_homing`) is planned the same way: a home
search moves one arm from where it stands to its home position (encoder zero: 0 deg for
both arms), a single-arm move like any other, so it is safe when both its end points are.
Both arms at 0 deg would touch, so one arm is homed, moved clear (to its park coordinate
when that is far enough), and then the other is homed; each step is checked before it
runs and the positions are checked against the interlock after it. A home search is
assumed to run straight to the home position (a controller that first searches the other
way for its switch needs the switch on the side it searches first).

Concurrency: every motion of the two arms (:meth:`TwoArmGoniometer.move_to`,
:meth:`~TwoArmGoniometer.move_arm`, :meth:`~TwoArmGoniometer.home`,
:meth:`~TwoArmGoniometer.park`) reserves the goniometer under one lock for its whole
travel, and is checked and planned inside it against the other arm's position *read under
the lock*. Two callers that move one arm each at the same time (bluesky's
``bps.mv(lamp, 5, detector, 3)`` sets both devices at once) are thus run one after the
other, and the second is checked against where the first one really left its arm, not
against where that arm stood when the second call was made. :attr:`pending_deg` says
which targets are reserved while a move runs. Only :meth:`~TwoArmGoniometer.stop` does not
wait for the lock: it must reach the arms at any moment.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Sequence
from dataclasses import dataclass
from typing import Literal

from drivers.arm_limits import geometry_problem, separation_floor_problem
from drivers.base import Axis, DeviceError, InterlockError, LimitError

__all__ = ["HomingStep", "TwoArmGoniometer", "plan_homing", "plan_moves"]


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


@dataclass(frozen=True, slots=True)
class HomingStep:
    """One step of a homing plan: ``arm`` runs its home search (``target_deg`` = its home
    position) or, for ``action == "move"``, moves to ``target_deg``."""

    action: Literal["home", "move"]
    arm: Literal["lamp", "detector"]
    target_deg: float


def _clear_of(
    other_deg: Sequence[float],
    sigma: float,
    min_separation_deg: float,
    limits_deg: tuple[float, float],
) -> tuple[float, float] | None:
    """The range ``(low, high)`` of one arm's positions whose separation from every position in
    ``other_deg`` of the other arm is at least ``min_separation_deg`` with sign ``sigma``
    (``sigma * (mine + other) >= min_separation_deg``), within the arm's limits; ``None``
    when there is none."""
    lo, hi = limits_deg
    bound = min_separation_deg - min(sigma * o for o in other_deg)  # sigma * mine >= bound
    if sigma > 0:
        lo = max(lo, bound)
    else:
        hi = min(hi, -bound)
    return (lo, hi) if lo <= hi else None


def plan_homing(
    start_deg: tuple[float, float],
    *,
    home_deg: tuple[float, float],
    limits_deg: tuple[tuple[float, float], tuple[float, float]],
    min_separation_deg: float,
    park_deg: tuple[float, float],
    margin_deg: float = 1.0,
) -> list[HomingStep]:
    """Plan the homing of both arms from ``start_deg`` so that they never come closer than
    ``min_separation_deg`` (nor cross).

    A home search moves one arm from where it stands to its home position, as any single-arm
    move does (monotonically), so it is safe when both its end points are (module
    docstring). Both arms cannot stand at their homes together when the homes are closer
    than the minimum (the encoder zeros of both arms: 0 and 0 deg), so the plan is: home
    arm A; move A clear of B's home; home B -- with, when B stands where A's home would
    come too close, a first move of B clear of A's home. A clear position is A's park
    coordinate when that is far enough, else the nearest safe position plus ``margin_deg``
    (within the arm's limits). The lamp arm is homed first when both orders are possible.

    Parameters
    ----------
    start_deg
        ``(theta_i, theta_r)`` now, from the arms' feedback.
    home_deg
        Where each arm stands after its home search (``(theta_i, theta_r)``).
    limits_deg
        ``(lamp limits, detector limits)``, each ``(low, high)``.
    min_separation_deg
        Smallest allowed ``|theta_i + theta_r|``.
    park_deg
        The park geometry (its coordinates are the preferred clear positions).
    margin_deg
        Extra distance from the interlock boundary when a clear position is not the park's.

    Returns
    -------
    list of HomingStep
        In order; every arm is homed exactly once.

    Raises
    ------
    InterlockError
        The arms stand closer than the minimum now, or no order of homing and clearing
        moves keeps them apart with the configured homes and limits; the message says why.
    """
    m = min_separation_deg
    s0 = start_deg[0] + start_deg[1]
    if abs(s0) < m:
        raise InterlockError(
            f"cannot plan the homing: the arms stand {abs(s0):.3f} deg apart "
            f"(theta_i={start_deg[0]:.3f}, theta_r={start_deg[1]:.3f} deg), below the minimum "
            f"{m:g} deg; move them apart by hand first",
            device="goniometer",
        )
    sigma = 1.0 if s0 > 0 else -1.0
    arms = ("lamp", "detector")
    reasons: list[str] = []
    for first in (0, 1):
        a, b = first, 1 - first
        pos = list(start_deg)
        steps: list[HomingStep] = []
        # 1. A's home search: needs B clear of A's home (and of where A stands now).
        if sigma * (home_deg[a] + pos[b]) < m:
            rng = _clear_of((home_deg[a], pos[a]), sigma, m, limits_deg[b])
            if rng is None:
                reasons.append(
                    f"homing the {arms[a]} arm first needs the {arms[b]} arm "
                    f"{m:g} deg clear of the {arms[a]} home ({home_deg[a]:g} deg), "
                    f"beyond its limits {list(limits_deg[b])}"
                )
                continue
            pos[b] = _pick(rng, park_deg[b], sigma, margin_deg)
            steps.append(HomingStep("move", arms[b], pos[b]))  # type: ignore[arg-type]
        steps.append(HomingStep("home", arms[a], home_deg[a]))  # type: ignore[arg-type]
        pos[a] = home_deg[a]
        # 2. A clear of B's home and of where B stands, 3. B's home search.
        rng = _clear_of((home_deg[b], pos[b]), sigma, m, limits_deg[a])
        if rng is None:
            reasons.append(
                f"homing the {arms[b]} arm second needs the {arms[a]} arm {m:g} deg clear "
                f"of the {arms[b]} home ({home_deg[b]:g} deg), beyond its limits "
                f"{list(limits_deg[a])}"
            )
            continue
        clear = _pick(rng, park_deg[a], sigma, margin_deg)
        if clear != pos[a]:
            steps.append(HomingStep("move", arms[a], clear))  # type: ignore[arg-type]
        steps.append(HomingStep("home", arms[b], home_deg[b]))  # type: ignore[arg-type]
        return steps
    raise InterlockError(
        "the home positions cannot be reached safely: " + "; ".join(reasons),
        device="goniometer",
    )


def _pick(rng: tuple[float, float], preferred: float, sigma: float, margin_deg: float) -> float:
    """``preferred`` when it lies in ``rng``, else the boundary on the safe side plus the
    margin (the boundary itself when the margin does not fit)."""
    lo, hi = rng
    if lo <= preferred <= hi:
        return preferred
    if sigma > 0:
        return min(lo + margin_deg, hi)
    return max(hi - margin_deg, lo)


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
    home_deg
        Where each arm stands after its home search (the encoder zero: ``(0, 0)``). That
        homing can be planned from the park position is checked at construction.
    corrections_deg
        ``(lamp, detector)`` added to the requested angles before the arms are commanded,
        and subtracted from their feedback: an alignment's result (``[alignment]`` of a
        lab config, from ``goniolab scan --plan align``), so that the angles of
        :meth:`move_to` and :meth:`positions_deg` are the ones the sample sees. Limits and
        the separation interlock apply to the arms' own angles.
    """

    def __init__(
        self,
        lamp: Axis,
        detector: Axis,
        *,
        min_separation_deg: float,
        park_deg: tuple[float, float] = (45.0, 45.0),
        home_deg: tuple[float, float] = (0.0, 0.0),
        corrections_deg: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        if problem := separation_floor_problem(min_separation_deg):  # as the config checks
            raise ValueError(f"goniometer: min_separation_deg: {problem}")
        self.lamp = lamp
        self.detector = detector
        self.min_separation_deg = float(min_separation_deg)
        self.park_deg = (float(park_deg[0]), float(park_deg[1]))
        self.corrections_deg = (float(corrections_deg[0]), float(corrections_deg[1]))
        try:
            self.check_geometry(*self.park_deg)
        except DeviceError as exc:
            raise ValueError(
                f"goniometer: park position {self.park_deg} is invalid: {exc}"
            ) from None
        self.home_deg = (float(home_deg[0]), float(home_deg[1]))
        try:
            self.plan_homing(self.park_deg)
        except InterlockError as exc:
            raise ValueError(f"goniometer: {exc.message} (from the park position)") from None
        self._locks: dict[asyncio.AbstractEventLoop, asyncio.Lock] = {}
        self._pending: tuple[float, float] | None = None

    def _motion_lock(self) -> asyncio.Lock:
        """The lock that every motion holds for its whole travel (one per event loop: a
        lab opened in one loop and driven from another, as bluesky's RunEngine does, still
        gets one lock per loop that moves it)."""
        loop = asyncio.get_running_loop()
        lock = self._locks.get(loop)
        if lock is None:
            for old in [k for k in self._locks if k.is_closed()]:
                del self._locks[old]
            lock = self._locks[loop] = asyncio.Lock()
        return lock

    @property
    def pending_deg(self) -> tuple[float, float] | None:
        """``(theta_i_deg, theta_r_deg)`` reserved by the motion now running (corrected
        angles, as requested), ``None`` when the arms are not being moved."""
        return self._pending

    @property
    def busy(self) -> bool:
        """Whether a motion holds the goniometer now."""
        return self._pending is not None or any(lock.locked() for lock in self._locks.values())

    def _axis(self, name: str) -> Axis:
        return self.lamp if name == "lamp" else self.detector

    def _arms(self, theta_i_deg: float, theta_r_deg: float) -> tuple[float, float]:
        """The arms' own angles for a requested geometry (corrections applied)."""
        return theta_i_deg + self.corrections_deg[0], theta_r_deg + self.corrections_deg[1]

    def check_geometry(self, theta_i_deg: float, theta_r_deg: float) -> None:
        """Raise unless both arms are within their limits and far enough apart.

        Raises
        ------
        LimitError
            theta_i outside the lamp's limits or theta_r outside the detector's.
        InterlockError
            ``|theta_i_deg + theta_r_deg| < min_separation_deg``.
        """
        theta_i_deg, theta_r_deg = self._arms(theta_i_deg, theta_r_deg)
        problem = geometry_problem(  # drivers.arm_limits: the one text of the refusal
            theta_i_deg,
            theta_r_deg,
            lamp_limits_deg=self.lamp.limits_deg,
            detector_limits_deg=self.detector.limits_deg,
            min_separation_deg=self.min_separation_deg,
            lamp=self.lamp.name,
            detector=self.detector.name,
        )
        if problem is not None:
            error = LimitError if problem.kind == "limit" else InterlockError
            raise error(problem.message, device=problem.device)

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

    async def _arm_positions_deg(self) -> tuple[float, float]:
        """The arms' own feedback angles (no corrections)."""
        return await self.lamp.position_deg(), await self.detector.position_deg()

    async def positions_deg(self) -> tuple[float, float]:
        """``(theta_i_deg, theta_r_deg)`` from the arms' feedback (corrections removed)."""
        lamp, det = await self.lamp.position_deg(), await self.detector.position_deg()
        return lamp - self.corrections_deg[0], det - self.corrections_deg[1]

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

        The goniometer is reserved for the whole travel (module docstring, Concurrency).
        ``timeout_s`` applies to each arm's move. On any error both arms are stopped and
        the error is re-raised.
        """
        self.check_geometry(theta_i_deg, theta_r_deg)
        async with self._motion_lock():
            return await self._move_locked(theta_i_deg, theta_r_deg, timeout_s)

    async def move_arm(self, arm: str, target_deg: float, timeout_s: float) -> tuple[float, float]:
        """Move one arm (``"lamp"``: theta_i, ``"detector"``: theta_r) to ``target_deg``, the
        other arm staying where it stands when the move starts.

        The other arm's position is read under the motion lock, so a concurrent move of
        the other arm (bluesky setting both devices at once) is finished first and this
        move is checked against where it really left that arm.

        Raises
        ------
        LimitError, InterlockError
            The target is outside the arm's limits, or puts the arms too close (nothing
            moves).
        """
        if arm not in ("lamp", "detector"):
            raise ValueError(f"arm must be 'lamp' or 'detector', got {arm!r}")
        async with self._motion_lock():
            ti, tr = await self.positions_deg()
            target = (float(target_deg), tr) if arm == "lamp" else (ti, float(target_deg))
            self.check_geometry(*target)
            return await self._move_locked(*target, timeout_s)

    async def _move_locked(
        self, theta_i_deg: float, theta_r_deg: float, timeout_s: float
    ) -> tuple[float, float]:
        """:meth:`move_to` with the motion lock held by the caller."""
        self.check_geometry(theta_i_deg, theta_r_deg)
        start = await self._arm_positions_deg()
        arm_i, arm_r = self._arms(theta_i_deg, theta_r_deg)
        stages = plan_moves(start, (arm_i, arm_r))
        target = {"lamp": arm_i, "detector": arm_r}
        self._pending = (float(theta_i_deg), float(theta_r_deg))
        try:
            for stage in stages:
                await self._run_stage(stage, target, timeout_s)
        finally:
            self._pending = None
        return await self.positions_deg()

    def plan_homing(self, start_deg: tuple[float, float]) -> list[HomingStep]:
        """The homing steps from ``start_deg`` (see :func:`plan_homing`)."""
        return plan_homing(
            start_deg,
            home_deg=self.home_deg,
            limits_deg=(self.lamp.limits_deg, self.detector.limits_deg),
            min_separation_deg=self.min_separation_deg,
            park_deg=self._arms(*self.park_deg),
        )

    async def home(self, timeout_s: float) -> None:
        """Home both arms, one at a time, never closer than ``min_separation_deg``.

        The plan (:func:`plan_homing`) homes one arm, moves it clear, then homes the other
        (moving that one clear first when it stands too close to the first one's home).
        After every step the arm positions are read back and checked against the
        interlock; any error stops both arms and is re-raised.

        Raises
        ------
        InterlockError
            The arms stand too close now, the homes cannot be reached safely with these
            limits (nothing moves), or a step ended closer than allowed (arms stopped).
        """
        async with self._motion_lock():
            await self._home_locked(timeout_s)

    async def _home_locked(self, timeout_s: float) -> None:
        start = await self._arm_positions_deg()  # homing works in the arms' own angles
        steps = self.plan_homing(start)
        sigma = 1.0 if start[0] + start[1] > 0 else -1.0
        try:
            for step in steps:
                axis = self._axis(step.arm)
                if step.action == "home":
                    await axis.home(timeout_s)
                else:
                    await axis.move_to(step.target_deg)
                    await axis.wait_in_position(timeout_s)
                ti, tr = await self._arm_positions_deg()
                if sigma * (ti + tr) < self.min_separation_deg:
                    what = (
                        f"homing the {step.arm} arm"
                        if step.action == "home"
                        else (f"moving the {step.arm} arm clear to {step.target_deg:g} deg")
                    )
                    raise InterlockError(
                        f"after {what} the arms stand at theta_i={ti:.3f}, theta_r={tr:.3f} "
                        f"deg, {sigma * (ti + tr):.3f} deg apart (minimum "
                        f"{self.min_separation_deg:g} deg): homing stopped",
                        device="goniometer",
                    )
        except BaseException:
            await self._stop_all()
            raise

    async def park(self, timeout_s: float) -> None:
        """Move to the park position with the same interlocks (and lock) as :meth:`move_to`."""
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
