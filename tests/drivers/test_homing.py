"""Homing is planned like any move: home one arm, move it clear, home the other, checked
against the interlock at every step (issue 10, defect 1: both arms were driven to encoder 0
and ended 0 deg apart although ``min_separation_deg`` is 10).

The fake arms home in small steps like any move and a shared monitor records the
separation after every step; the wire test watches the simulated controllers with a
standard Modbus master while the real drivers home them.
"""

from __future__ import annotations

import asyncio
import contextlib
import shutil
from collections.abc import AsyncIterator, Callable

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymodbus.client import AsyncModbusTcpClient

from drivers.base import InterlockError
from drivers.goniometer import HomingStep, TwoArmGoniometer, plan_homing
from drivers.modbus_stepper import ModbusStepperAxis
from drivers.profiles import load_stepper_profile
from drivers.timing import SimClock
from sim.instruments import SimAxis
from sim.motion import SimMotor
from sim.wire import ModbusAxisServer, WireAxis
from tests.drivers.test_goniometer import FakeAxis, Monitor

LAMP_LIMITS = (0.0, 85.0)
DET_LIMITS = (-85.0, 85.0)
MIN_SEP = 10.0


class SteppingHomeAxis(FakeAxis):
    """A fake arm whose home search travels to 0 deg in steps, as a real one does."""

    async def home(self, timeout_s: float) -> None:
        self.monitor.events.append(("home", self.name, 0.0))
        self.target = 0.0
        await self.wait_in_position(timeout_s)


def rig(ti: float, tr: float, *, step: float = 0.5) -> tuple[TwoArmGoniometer, Monitor]:
    m = Monitor()
    lamp = SteppingHomeAxis("lamp", m, ti, LAMP_LIMITS, step)
    det = SteppingHomeAxis("detector", m, tr, DET_LIMITS, step)
    return TwoArmGoniometer(lamp, det, min_separation_deg=MIN_SEP, park_deg=(45.0, 45.0)), m


async def test_homing_from_park_keeps_the_arms_apart() -> None:
    g, m = rig(45.0, 45.0)
    m.sample()
    await g.home(timeout_s=1.0)
    assert m.min_separation_seen >= MIN_SEP
    assert await g.positions_deg() == (45.0, 0.0)  # lamp homed then parked clear, detector home
    assert [(e[0], e[1]) for e in m.events if e[0] in ("home", "move")] == [
        ("home", "lamp"),
        ("move", "lamp"),
        ("home", "detector"),
    ]


async def test_detector_moved_clear_first_when_it_stands_near_the_lamp_home() -> None:
    """Detector at 5 deg: the lamp cannot home to 0 deg beside it, so the detector moves
    clear first (to its park coordinate, 45 deg)."""
    g, m = rig(40.0, 5.0)
    m.sample()
    await g.home(timeout_s=1.0)
    assert m.min_separation_seen >= MIN_SEP
    assert plan_homing(
        (40.0, 5.0),
        home_deg=(0.0, 0.0),
        limits_deg=(LAMP_LIMITS, DET_LIMITS),
        min_separation_deg=MIN_SEP,
        park_deg=(45.0, 45.0),
    )[0] == HomingStep("move", "detector", 45.0)


async def test_arms_too_close_now_are_refused_before_any_motion() -> None:
    g, m = rig(20.0, -15.0)
    with pytest.raises(InterlockError, match=r"5\.000 deg apart.*by hand"):
        await g.home(timeout_s=1.0)
    assert not [e for e in m.events if e[0] in ("home", "move")]


async def test_detector_on_the_lamp_side_cannot_home_without_crossing() -> None:
    """theta_r = -60 with the lamp at 30: the detector's home (0 deg) lies beyond the lamp,
    and the lamp cannot get out of the way (its limits end at 0): refused, nothing moves."""
    g, m = rig(30.0, -60.0)
    with pytest.raises(InterlockError, match="cannot be reached safely"):
        await g.home(timeout_s=1.0)
    assert not [e for e in m.events if e[0] in ("home", "move")]


def test_home_positions_unreachable_from_park_is_a_construction_error() -> None:
    """A lamp arm limited to 0..5 deg can never stand 10 deg clear of the detector's home."""
    m = Monitor()
    with pytest.raises(ValueError, match="home positions cannot be reached safely"):
        TwoArmGoniometer(
            FakeAxis("lamp", m, 0.0, (0.0, 5.0)),
            FakeAxis("detector", m, 45.0, (-85.0, 85.0)),
            min_separation_deg=MIN_SEP,
            park_deg=(5.0, 45.0),
        )


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    start=st.tuples(st.floats(0.0, 85.0), st.floats(-85.0, 85.0)),
    step=st.sampled_from([0.5, 2.0, 7.0]),
)
def test_homing_from_anywhere_never_comes_closer_than_the_minimum(
    start: tuple[float, float], step: float
) -> None:
    """From any start: either the plan runs and the arms never come closer than the minimum
    (nor cross), or it is refused before anything moves."""

    async def run() -> None:
        g, m = rig(*start, step=step)
        m.sample()
        sign0 = start[0] + start[1]
        try:
            await g.home(timeout_s=1.0)
        except InterlockError:
            assert not [e for e in m.events if e[0] in ("home", "move")]
            return
        assert m.min_separation_seen >= MIN_SEP
        ti, tr = await g.positions_deg()
        assert (ti + tr) * sign0 > 0  # never crossed
        assert [e[1] for e in m.events if e[0] == "home"] in (
            ["lamp", "detector"],
            ["detector", "lamp"],
        )

    asyncio.run(run())


# ----------------------------------------------------------------------- on the wire
FEEDBACK = 0x0120  # AZ feedback position, int32 high word first


async def _poll_pymodbus(port: int, seen: list[tuple[int, int]], stop: asyncio.Event) -> None:
    client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
    await client.connect()
    try:
        while not stop.is_set():
            pair = []
            for unit in (1, 2):
                rr = await client.read_holding_registers(FEEDBACK, count=2, device_id=unit)
                assert not rr.isError(), rr
                hi, lo = rr.registers
                v = (hi << 16) | lo
                pair.append(v - (1 << 32) if v & 0x80000000 else v)
            seen.append((pair[0], pair[1]))
            await asyncio.sleep(0.005)
    finally:
        client.close()


async def _poll_mbpoll(port: int, seen: list[tuple[int, int]], stop: asyncio.Event) -> None:
    """Debian's mbpoll polling both units every 10 ms (``-a 1,2 -l 10``), line-buffered."""
    cmd = ["mbpoll", "-m", "tcp", "-p", str(port), "-a", "1,2", "-0", "-r", str(FEEDBACK),
           "-c", "1", "-t", "4:int", "-B", "-l", "10", "127.0.0.1"]  # fmt: skip
    if shutil.which("stdbuf"):
        cmd = ["stdbuf", "-oL", *cmd]
    proc = await asyncio.create_subprocess_exec(
        *cmd, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT
    )
    assert proc.stdout is not None
    slave = 0
    lamp: int | None = None
    try:
        while not stop.is_set():
            try:
                raw = await asyncio.wait_for(proc.stdout.readline(), 0.2)
            except TimeoutError:
                continue
            line = raw.decode(errors="replace")
            if not raw:
                raise AssertionError("mbpoll ended early")
            if "Polling slave" in line:
                slave = int(line.split("Polling slave")[1].split(".")[0])
            elif line.startswith(f"[{FEEDBACK}]:"):
                value = int(line.split(":", 1)[1])
                if slave == 1:
                    lamp = value
                elif slave == 2 and lamp is not None:
                    seen.append((lamp, value))
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.terminate()
        await proc.wait()


POLLERS: dict[str, Callable[[int, list[tuple[int, int]], asyncio.Event], object]] = {
    "mbpoll": _poll_mbpoll,
    "pymodbus": _poll_pymodbus,
}


@pytest.fixture
async def wire_goniometer() -> AsyncIterator[tuple[TwoArmGoniometer, ModbusAxisServer]]:
    """Both arms parked at 45/45 deg on one simulated Modbus TCP server (AZ map), driven by
    the real stepper drivers; the lab clock runs 5x real time."""
    clock = SimClock(5.0)
    prof = load_stepper_profile("oriental-az")

    def arm(name: str, limits: tuple[float, float]) -> SimAxis:
        motor = SimMotor(name, speed_deg_s=40.0, accel_deg_s2=80.0, soft_limits_deg=limits,
                         start_deg=45.0, homed=True)  # fmt: skip
        return SimAxis(name, motor, clock)

    server = ModbusAxisServer(
        [WireAxis(arm("lamp", LAMP_LIMITS), prof, 1000.0, 1),
         WireAxis(arm("detector", DET_LIMITS), prof, 1000.0, 2)],
        port=0,
    )  # fmt: skip
    await server.start()

    def driver(name: str, unit: int, limits: tuple[float, float]) -> ModbusStepperAxis:
        return ModbusStepperAxis(name, port=server.port, unit_id=unit, limits_deg=limits,
                                 speed_deg_s=40.0, accel_deg_s2=80.0, timeout_s=2.0)  # fmt: skip

    g = TwoArmGoniometer(
        driver("lamp", 1, LAMP_LIMITS),
        driver("detector", 2, DET_LIMITS),
        min_separation_deg=MIN_SEP,
        park_deg=(45.0, 45.0),
    )
    await g.connect()
    try:
        yield g, server
    finally:
        await g.close()
        await server.stop()


@pytest.mark.wire
@pytest.mark.parametrize("poller", sorted(POLLERS))
async def test_a_modbus_master_never_sees_the_arms_closer_than_the_minimum_while_homing(
    wire_goniometer: tuple[TwoArmGoniometer, ModbusAxisServer], poller: str
) -> None:
    if poller == "mbpoll" and shutil.which("mbpoll") is None:
        pytest.skip("mbpoll not installed (Debian package mbpoll)")
    g, server = wire_goniometer
    seen: list[tuple[int, int]] = []
    stop = asyncio.Event()
    watcher = asyncio.ensure_future(POLLERS[poller](server.port, seen, stop))  # type: ignore[arg-type]
    while not seen:  # the master is polling before the homing starts
        await asyncio.sleep(0.01)
        assert not watcher.done(), watcher
    await g.home(timeout_s=30.0)
    n_homing = len(seen)
    await asyncio.sleep(0.1)
    stop.set()
    await watcher
    # 1000 steps/deg; one arm moves at a time, so each (lamp, detector) pair is one instant
    separations = [abs(lamp + det) / 1000.0 for lamp, det in seen]
    assert n_homing >= 5, f"only {n_homing} polls during homing"
    assert min(separations) >= MIN_SEP, min(separations)
    assert seen[-1] == (45000, 0)  # lamp homed, then parked clear; detector at its home
    assert (await g.lamp.status()).homed and (await g.detector.status()).homed
