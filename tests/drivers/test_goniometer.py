"""TwoArmGoniometer: interlocks before motion, and a move order that keeps the arms apart.

The fake axes move in small steps and a shared monitor records |theta_i + theta_r| after
every step of either arm, so the tests check the separation along the whole path, not
just at the end points.
"""

from __future__ import annotations

import asyncio

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from drivers.base import (
    AxisStatus,
    DeviceFault,
    Goniometer,
    InterlockError,
    LimitError,
)
from drivers.goniometer import TwoArmGoniometer, plan_moves


class Monitor:
    def __init__(self) -> None:
        self.events: list[tuple[str, str, float]] = []
        self.arms: dict[str, FakeAxis] = {}
        self.min_separation_seen = float("inf")

    def sample(self) -> None:
        s = abs(self.arms["lamp"].pos + self.arms["detector"].pos)
        self.min_separation_seen = min(self.min_separation_seen, s)


class FakeAxis:
    def __init__(
        self,
        name: str,
        monitor: Monitor,
        pos: float,
        limits: tuple[float, float],
        step_deg: float = 0.5,
        fail: bool = False,
    ) -> None:
        self.name = name
        self.limits_deg = limits
        self.pos = pos
        self.target = pos
        self.step_deg = step_deg
        self.fail = fail
        self.monitor = monitor
        monitor.arms[name] = self

    async def connect(self) -> None:
        self.monitor.events.append(("connect", self.name, self.pos))

    async def close(self) -> None:
        self.monitor.events.append(("close", self.name, self.pos))

    async def status(self) -> AxisStatus:
        return AxisStatus(position_deg=self.pos)

    async def position_deg(self) -> float:
        return self.pos

    async def move_to(self, target_deg: float) -> None:
        self.monitor.events.append(("move", self.name, target_deg))
        self.target = target_deg

    async def wait_in_position(self, timeout_s: float) -> float:
        while self.pos != self.target:
            if self.fail:
                raise DeviceFault("alarm", device=self.name, code=7)
            delta = self.target - self.pos
            self.pos = (
                self.target
                if abs(delta) <= self.step_deg
                else self.pos + math_sign(delta) * self.step_deg
            )
            self.monitor.sample()
            await asyncio.sleep(0)
        self.monitor.events.append(("arrived", self.name, self.pos))
        return self.pos

    async def home(self, timeout_s: float) -> None:
        self.monitor.events.append(("home", self.name, 0.0))
        self.pos = 0.0

    async def stop(self) -> None:
        self.monitor.events.append(("stop", self.name, self.pos))
        self.target = self.pos

    async def reset_alarm(self) -> None:
        self.monitor.events.append(("reset", self.name, self.pos))


def math_sign(x: float) -> float:
    return 1.0 if x > 0 else -1.0


def rig(
    ti: float, tr: float, *, lamp_step: float = 0.5, det_step: float = 0.5, min_sep: float = 10.0
) -> tuple[TwoArmGoniometer, Monitor]:
    m = Monitor()
    lamp = FakeAxis("lamp", m, ti, (0.0, 85.0), lamp_step)
    det = FakeAxis("detector", m, tr, (-85.0, 85.0), det_step)
    return TwoArmGoniometer(lamp, det, min_separation_deg=min_sep, park_deg=(45.0, 45.0)), m


def moves(m: Monitor) -> list[tuple[str, str, float]]:
    return [e for e in m.events if e[0] in ("move", "arrived")]


async def test_is_a_goniometer() -> None:
    g, _ = rig(45, 45)
    assert isinstance(g, Goniometer)


@pytest.mark.parametrize(
    ("ti", "tr", "error", "text"),
    [
        (86.0, 0.0, LimitError, r"theta_i=86\.0 deg outside the lamp arm limits \[0\.0, 85\.0\]"),
        (-1.0, 30.0, LimitError, "lamp arm limits"),
        (30.0, 90.0, LimitError, "detector arm limits"),
        (30.0, -25.0, InterlockError, r"5\.000 deg apart, below the minimum 10\.0 deg"),
        (20.0, -29.9, InterlockError, r"9\.900 deg apart"),
    ],
)
async def test_geometry_checked_before_any_motion(
    ti: float, tr: float, error: type[Exception], text: str
) -> None:
    g, m = rig(45, 45)
    with pytest.raises(error, match=text):
        await g.move_to(ti, tr, timeout_s=1.0)
    assert m.events == []


def test_separation_boundary_is_allowed() -> None:
    g, _ = rig(45, 45)
    g.check_geometry(20.0, -10.0)  # exactly 10 deg apart
    g.check_geometry(0.0, -85.0)  # detector beyond the lamp, 85 deg apart


async def test_wrong_order_would_cross_so_detector_moves_first() -> None:
    # start (30, -15): gap 15. target (5, 10): gap 15. Lamp first would pass through
    # (5, -15), gap -10 (crossed); detector first goes through (30, 10), gap 40.
    g, m = rig(30.0, -15.0)
    assert await g.move_to(5.0, 10.0, timeout_s=1.0) == (5.0, 10.0)
    assert moves(m) == [
        ("move", "detector", 10.0),
        ("arrived", "detector", 10.0),
        ("move", "lamp", 5.0),
        ("arrived", "lamp", 5.0),
    ]
    assert m.min_separation_seen >= 15.0


async def test_lamp_first_when_lamp_widens_the_gap() -> None:
    g, m = rig(10.0, 5.0)  # gap 15
    await g.move_to(40.0, -20.0, timeout_s=1.0)  # gap 20: lamp +30 widens, detector -25 narrows
    assert [e[1] for e in moves(m) if e[0] == "move"] == ["lamp", "detector"]
    assert m.min_separation_seen >= 15.0


async def test_both_arms_move_together_when_both_widen() -> None:
    g, m = rig(10.0, 5.0)
    await g.move_to(40.0, 40.0, timeout_s=1.0)
    kinds = [e[0] for e in moves(m)]
    assert kinds[:2] == ["move", "move"]  # both started before either arrived
    assert m.min_separation_seen >= 15.0


async def test_crossing_target_is_refused() -> None:
    g, m = rig(20.0, 30.0)  # detector on the specular side of the lamp (gap +50)
    with pytest.raises(InterlockError, match="through the lamp arm"):
        await g.move_to(10.0, -40.0, timeout_s=1.0)  # gap -30: other side of the lamp
    assert moves(m) == []


async def test_fault_stops_both_arms() -> None:
    m = Monitor()
    lamp = FakeAxis("lamp", m, 10.0, (0.0, 85.0), fail=True)
    det = FakeAxis("detector", m, 5.0, (-85.0, 85.0))
    g = TwoArmGoniometer(lamp, det, min_separation_deg=10.0)
    with pytest.raises(DeviceFault):
        await g.move_to(40.0, 40.0, timeout_s=1.0)
    assert {e[1] for e in m.events if e[0] == "stop"} == {"lamp", "detector"}


async def test_park_home_stop_positions() -> None:
    g, m = rig(10.0, 30.0)
    await g.park(timeout_s=1.0)
    assert await g.positions_deg() == (45.0, 45.0)
    await g.home(timeout_s=1.0)
    assert [e[1] for e in m.events if e[0] == "home"] == ["lamp", "detector"]
    await g.stop()
    assert [e[1] for e in m.events if e[0] == "stop"] == ["lamp", "detector"]


def test_invalid_park_position_rejected() -> None:
    m = Monitor()
    with pytest.raises(ValueError, match="park position"):
        TwoArmGoniometer(
            FakeAxis("lamp", m, 0, (0, 85)),
            FakeAxis("detector", m, 0, (-85, 85)),
            min_separation_deg=10.0,
            park_deg=(20.0, -15.0),
        )


angles_i = st.floats(0.0, 85.0)
angles_r = st.floats(-85.0, 85.0)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    start=st.tuples(angles_i, angles_r),
    target=st.tuples(angles_i, angles_r),
    lamp_step=st.sampled_from([0.25, 1.0, 5.0]),
    det_step=st.sampled_from([0.25, 1.0, 5.0]),
)
def test_separation_never_below_minimum_on_the_way(
    start: tuple[float, float], target: tuple[float, float], lamp_step: float, det_step: float
) -> None:
    min_sep = 10.0
    # valid start and target on the same side (crossing is covered by the refusal test)
    assume(abs(sum(start)) >= min_sep and abs(sum(target)) >= min_sep)
    assume(sum(start) * sum(target) > 0)

    async def run() -> float:
        g, m = rig(*start, lamp_step=lamp_step, det_step=det_step, min_sep=min_sep)
        m.sample()
        await g.move_to(*target, timeout_s=1.0)
        assert await g.positions_deg() == target
        return m.min_separation_seen

    assert asyncio.run(run()) >= min_sep - 1e-9


def test_plan_moves_leaves_out_arms_that_stay() -> None:
    assert plan_moves((30.0, 30.0), (30.0, 40.0)) == [("detector",)]
    assert plan_moves((30.0, 30.0), (30.0, 30.0)) == []
