"""Time for drivers, the sequencer and the simulated lab: clocks and trapezoid move timing.

Clocks: virtual time that can run instantly, fast, slow or real. Everything in :mod:`sim`
and the scan sequencer that takes time (a move, an exposure, an auto-send interval)
asks a clock for ``now()`` and ``await clock.sleep(dt_s)`` instead of calling
:func:`time.monotonic` / :func:`asyncio.sleep` directly. That makes the whole simulated
lab run at any pace:

* ``SimClock(0)``: instant. ``sleep`` does not wait for wall time; virtual time jumps to
  the wake time of the earliest sleeper once the event loop has nothing else ready to do.
  Concurrent sleepers wake strictly in virtual-time order (ties in call order), so tests
  are deterministic and need no real sleeps.
* ``SimClock(1)``: real time. ``SimClock(10)``: ten times faster than real time;
  ``SimClock(0.5)``: half speed.
* :class:`RealClock`: wall time, for real drivers; same interface.

Motion timing: :func:`trapezoid_duration_s` and :class:`MoveProfile` give the duration
and the position at any time of a trapezoidal (constant-acceleration) move, what the
sequencer's dry run and ETA and the simulated motors (:mod:`sim.motion`) both need.

References
----------
.. [1] Trapezoidal velocity profile: e.g. L. Biagiotti, C. Melchiorri, "Trajectory
   Planning for Automatic Machines and Robots", Springer 2008, sec. 3.2 (constant
   acceleration, "trapezoidal speed" law) -- duration d/v + v/a when d >= v^2/a,
   else 2 sqrt(d/a) with peak speed sqrt(a d).
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

__all__ = ["Clock", "MoveProfile", "RealClock", "SimClock", "trapezoid_duration_s"]


@runtime_checkable
class Clock(Protocol):
    """What the simulated instruments need from a clock (times in seconds)."""

    def now(self) -> float:
        """Current time in seconds (virtual for sim clocks)."""
        ...

    async def sleep(self, dt_s: float) -> None:
        """Let ``dt_s`` seconds of this clock's time pass."""
        ...


class RealClock:
    """Wall-clock time (monotonic), with the :class:`Clock` interface."""

    scale: float = 1.0

    def now(self) -> float:
        """Monotonic wall time in seconds."""
        return time.monotonic()

    async def sleep(self, dt_s: float) -> None:
        """Sleep ``dt_s`` wall seconds (0 or negative just yields to the loop)."""
        await asyncio.sleep(max(0.0, dt_s))


class SimClock:
    """Virtual time running at ``scale`` times real time (0 = instant).

    Parameters
    ----------
    scale
        Virtual seconds per wall second; 0 makes every sleep instant (virtual time jumps
        to the next wake time when the loop is otherwise idle). Must be >= 0.
    start_s
        Virtual time at creation.
    settle_iterations
        With ``scale == 0``: how many event-loop iterations the clock lets other ready
        tasks run (and register their own sleeps) before it advances virtual time to the
        earliest wake time. A few iterations suffice for chains of ``await`` between
        sleeps; more make the ordering robust to longer chains.
    """

    def __init__(
        self,
        scale: float = 1.0,
        *,
        start_s: float = 0.0,
        settle_iterations: int = 8,
        wall_clock: Callable[[], float] = time.monotonic,
    ):
        if not scale >= 0.0:
            raise ValueError(f"clock time scale must be >= 0, got {scale}")
        if settle_iterations < 1:
            raise ValueError(f"settle_iterations must be >= 1, got {settle_iterations}")
        self.scale = float(scale)
        self._settle = settle_iterations
        self._virtual_s = float(start_s)
        self._wall = wall_clock
        self._real_ref_s = wall_clock()
        self._sleepers: list[tuple[float, int, asyncio.Future[None]]] = []
        self._seq = itertools.count()
        self._driver: asyncio.Task[None] | None = None

    def now(self) -> float:
        """Current virtual time in seconds."""
        if self.scale == 0.0:
            return self._virtual_s
        return self._virtual_s + (self._wall() - self._real_ref_s) * self.scale

    async def sleep(self, dt_s: float) -> None:
        """Let ``dt_s`` virtual seconds pass.

        With ``scale > 0`` this waits ``dt_s / scale`` wall seconds. With ``scale == 0``
        it returns as soon as every sleeper due earlier has woken, and ``now()`` reads
        exactly the wake time at that moment.
        """
        if self.scale > 0.0:
            await asyncio.sleep(max(0.0, dt_s) / self.scale)
            return
        if dt_s <= 0.0:
            await asyncio.sleep(0)
            return
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[None] = loop.create_future()
        heapq.heappush(self._sleepers, (self._virtual_s + dt_s, next(self._seq), fut))
        if self._driver is None or self._driver.done() or self._driver.get_loop() is not loop:
            self._driver = loop.create_task(self._drive(), name="SimClock-driver")
        await fut

    async def _drive(self) -> None:
        """Wake sleepers one by one in virtual-time order (scale 0 only)."""
        while self._sleepers:
            for _ in range(self._settle):
                await asyncio.sleep(0)
            wake_s, _, fut = heapq.heappop(self._sleepers)
            if fut.done():  # the sleeper was cancelled
                continue
            self._virtual_s = max(self._virtual_s, wake_s)
            fut.set_result(None)

    def __repr__(self) -> str:
        return f"SimClock(scale={self.scale}, now={self.now():.6f})"


def trapezoid_duration_s(distance_deg: float, speed_deg_s: float, accel_deg_s2: float) -> float:
    """Duration of a rest-to-rest move with a symmetric trapezoidal velocity profile.

    Parameters
    ----------
    distance_deg
        Move length (its sign is ignored).
    speed_deg_s, accel_deg_s2
        Maximum speed and acceleration (= deceleration), both > 0.

    Returns
    -------
    float
        ``d/v + v/a`` when the move reaches full speed (``d >= v^2/a``), else the
        triangular-profile duration ``2 sqrt(d/a)`` (Biagiotti & Melchiorri, sec. 3.2).
    """
    d = abs(distance_deg)
    v, a = speed_deg_s, accel_deg_s2
    if d >= v * v / a:
        return d / v + v / a
    return 2.0 * math.sqrt(d / a)


@dataclass(frozen=True, slots=True)
class MoveProfile:
    """A rest-to-rest trapezoidal (or triangular) move, positions in degrees.

    Attributes
    ----------
    start_deg, target_deg
        Start and end positions (same coordinate frame).
    speed_deg_s, accel_deg_s2
        Maximum speed and acceleration; the peak speed is lower for short moves.
    t0_s
        Clock time at which the move starts.
    """

    start_deg: float
    target_deg: float
    speed_deg_s: float
    accel_deg_s2: float
    t0_s: float

    def __post_init__(self) -> None:
        if not (self.speed_deg_s > 0.0 and self.accel_deg_s2 > 0.0):
            raise ValueError(
                f"speed and acceleration must be > 0, got {self.speed_deg_s} deg/s, "
                f"{self.accel_deg_s2} deg/s^2"
            )

    @property
    def distance_deg(self) -> float:
        """Unsigned move length."""
        return abs(self.target_deg - self.start_deg)

    @property
    def direction(self) -> float:
        """+1 for increasing angle, -1 for decreasing, 0 for a null move."""
        return math.copysign(1.0, self.target_deg - self.start_deg) if self.distance_deg else 0.0

    @property
    def peak_speed_deg_s(self) -> float:
        """Speed at the end of the acceleration phase: ``min(v, sqrt(a d))``."""
        return min(self.speed_deg_s, math.sqrt(self.accel_deg_s2 * self.distance_deg))

    @property
    def accel_time_s(self) -> float:
        """Length of the acceleration (and of the deceleration) phase."""
        return self.peak_speed_deg_s / self.accel_deg_s2

    @property
    def duration_s(self) -> float:
        """Total move time, :func:`trapezoid_duration_s`."""
        return trapezoid_duration_s(self.distance_deg, self.speed_deg_s, self.accel_deg_s2)

    @property
    def end_s(self) -> float:
        """Clock time at which the move ends."""
        return self.t0_s + self.duration_s

    def travelled_deg(self, t_s: float) -> float:
        """Unsigned distance covered ``t_s`` after the start (clamped to [0, d])."""
        a, vp, ta, total = (
            self.accel_deg_s2,
            self.peak_speed_deg_s,
            self.accel_time_s,
            self.duration_s,
        )
        d = self.distance_deg
        if t_s <= 0.0:
            return 0.0
        if t_s >= total:
            return d
        if t_s < ta:
            return 0.5 * a * t_s * t_s
        t_dec = total - ta
        if t_s <= t_dec:
            return 0.5 * a * ta * ta + vp * (t_s - ta)
        rem = total - t_s
        return d - 0.5 * a * rem * rem

    def position_at(self, now_s: float) -> float:
        """Position at clock time ``now_s`` (start before ``t0_s``, target after the end)."""
        return self.start_deg + self.direction * self.travelled_deg(now_s - self.t0_s)

    def velocity_at(self, now_s: float) -> float:
        """Signed velocity at clock time ``now_s``."""
        t = now_s - self.t0_s
        total, ta, a = self.duration_s, self.accel_time_s, self.accel_deg_s2
        if t <= 0.0 or t >= total:
            return 0.0
        speed = a * t if t < ta else (a * (total - t) if t > total - ta else self.peak_speed_deg_s)
        return self.direction * speed

    def time_at(self, position_deg: float) -> float | None:
        """First clock time the move passes ``position_deg``, ``None`` if it never does."""
        s = (position_deg - self.start_deg) * self.direction
        d = self.distance_deg
        if d == 0.0 or s < 0.0 or s > d:
            return None
        a, vp, ta, total = (
            self.accel_deg_s2,
            self.peak_speed_deg_s,
            self.accel_time_s,
            self.duration_s,
        )
        s_acc = 0.5 * a * ta * ta
        if s <= s_acc:
            t = math.sqrt(2.0 * s / a)
        elif s <= d - s_acc:
            t = ta + (s - s_acc) / vp
        else:
            t = total - math.sqrt(max(0.0, 2.0 * (d - s) / a))
        return self.t0_s + t
