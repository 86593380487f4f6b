"""Clocks for the simulated lab: virtual time that can run instantly, fast, slow or real.

Everything in :mod:`sim` that takes time (a move, an exposure, an auto-send interval)
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
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable

__all__ = ["Clock", "RealClock", "SimClock"]


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
