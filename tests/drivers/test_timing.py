"""SimClock: virtual time, deterministic ordering at scale 0, scaled real time."""

from __future__ import annotations

import asyncio

import pytest

from drivers.timing import Clock, RealClock, SimClock


async def test_scale0_sleep_advances_virtual_time_exactly() -> None:
    clock = SimClock(0, start_s=100.0)
    await clock.sleep(3600.0)  # one virtual hour, no wall time
    assert clock.now() == 3700.0


async def test_scale0_concurrent_sleepers_wake_in_virtual_time_order() -> None:
    clock = SimClock(0)
    woke: list[tuple[str, float]] = []

    async def sleeper(name: str, dt: float) -> None:
        await clock.sleep(dt)
        woke.append((name, clock.now()))

    # started in an order different from their wake order
    await asyncio.gather(
        sleeper("c", 3.0), sleeper("a", 1.0), sleeper("b", 2.0), sleeper("a2", 1.0)
    )
    assert woke == [("a", 1.0), ("a2", 1.0), ("b", 2.0), ("c", 3.0)]


async def test_scale0_chained_sleeps_interleave_by_wake_time() -> None:
    clock = SimClock(0)
    log: list[tuple[str, float]] = []

    async def ticker(name: str, period: float, n: int) -> None:
        for _ in range(n):
            await clock.sleep(period)
            log.append((name, clock.now()))

    await asyncio.gather(ticker("fast", 1.0, 3), ticker("slow", 1.5, 2))
    # ties wake in the order the sleeps were requested: "slow" asked at 1.5, "fast" at 2.0
    assert log == [("fast", 1.0), ("slow", 1.5), ("fast", 2.0), ("slow", 3.0), ("fast", 3.0)]


async def test_scale0_cancelled_sleeper_does_not_advance_time() -> None:
    clock = SimClock(0)
    long = asyncio.ensure_future(clock.sleep(1000.0))
    await asyncio.sleep(0)
    long.cancel()
    await clock.sleep(2.0)
    assert clock.now() == 2.0


async def test_scaled_clock_uses_scaled_wall_time(monkeypatch: pytest.MonkeyPatch) -> None:
    wall = [50.0]
    clock = SimClock(10.0, start_s=5.0, wall_clock=lambda: wall[0])
    wall[0] += 2.0  # two wall seconds = twenty virtual seconds
    assert clock.now() == pytest.approx(25.0)
    slept: list[float] = []

    async def fake_sleep(dt: float) -> None:
        slept.append(dt)

    monkeypatch.setattr("drivers.timing.asyncio.sleep", fake_sleep)
    await clock.sleep(30.0)
    assert slept == [3.0]


def test_bad_scale_is_rejected() -> None:
    with pytest.raises(ValueError, match="scale"):
        SimClock(-1.0)


def test_clocks_satisfy_protocol() -> None:
    assert isinstance(SimClock(0), Clock)
    assert isinstance(RealClock(), Clock)
