"""Disconnects that recover: the link drops, the device is back ``recover_after_s`` later,
and a driver that reopens the port after that carries on (in process and on the wire)."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from drivers.base import Disconnected
from drivers.glossmeter import Zgm1120
from drivers.modbus_stepper import ModbusStepperAxis
from drivers.profiles import load_stepper_profile, load_zgm_profile
from drivers.timing import SimClock
from sim.faults import Fault, FaultInjector, FaultSpec
from sim.instruments import SimAxis, SimGlossmeter
from sim.motion import SimMotor
from sim.wire import ModbusAxisServer, SimLabServer, WireAxis, ZgmPtyDevice
from tests.sim.lobe import LobeModel

DROP_ALWAYS = FaultSpec(disconnect_rate=1.0, recover_after_s=2.0)


def test_fault_spec_rates_sum_to_at_most_one() -> None:
    with pytest.raises(ValueError, match="must be <= 1"):
        FaultSpec(timeout_rate=0.5, garble_rate=0.3, disconnect_rate=0.3)
    with pytest.raises(ValueError, match="recover_after_s"):
        FaultSpec(disconnect_rate=0.1, recover_after_s=-1.0)


def test_drop_is_drawn_after_timeout_and_garble() -> None:
    """One uniform draw per operation: [0, t) timeout, [t, t+g) garble, [t+g, t+g+d) drop."""
    spec = FaultSpec(timeout_rate=0.2, garble_rate=0.3, disconnect_rate=0.4)
    draws = np.random.default_rng(5).random(200)
    inj = FaultInjector("x", spec, np.random.default_rng(5))
    expected = [
        Fault.TIMEOUT if u < 0.2 else Fault.GARBLE if u < 0.5 else Fault.DROP if u < 0.9
        else Fault.NONE
        for u in draws
    ]  # fmt: skip
    assert [inj.decide() for _ in draws] == expected
    assert inj.injected == {f.value: expected.count(f) for f in set(expected) - {Fault.NONE}}


async def test_in_process_drop_recovers_after_the_set_time() -> None:
    clock = SimClock(0)
    faults = FaultInjector("glossmeter", DROP_ALWAYS)
    meter = SimGlossmeter(LobeModel(), clock, noise_pct=0.0, faults=faults)
    await meter.connect()
    with pytest.raises(Disconnected, match="link drop"):
        await meter.measure()
    with pytest.raises(Disconnected, match="not connected"):
        await meter.measure()  # the link is down until reopened
    await clock.sleep(1.0)
    with pytest.raises(Disconnected, match="back in 1 s"):
        await meter.connect()  # reopened too early
    await clock.sleep(1.0)
    faults.spec = FaultSpec()
    await meter.connect()
    reading = await meter.measure()
    assert reading.values_gu[60] is not None
    assert faults.drops == 1


class ManualClock:
    """Lab time that moves only when the test says so (a drop must stay down while the
    test looks at it, however slow the machine)."""

    def __init__(self) -> None:
        self.t = 0.0
        self._moved = asyncio.Event()

    def now(self) -> float:
        return self.t

    async def sleep(self, dt_s: float) -> None:
        wake = self.t + dt_s
        await asyncio.sleep(0)
        while self.t < wake:
            await self._moved.wait()

    def advance(self, dt_s: float) -> None:
        self.t += dt_s
        moved, self._moved = self._moved, asyncio.Event()
        moved.set()


async def test_zgm_pty_drop_removes_the_port_and_publishes_a_new_one(tmp_path) -> None:  # type: ignore[no-untyped-def]
    clock = ManualClock()
    faults = FaultInjector("glossmeter", DROP_ALWAYS)
    gloss = SimGlossmeter(LobeModel(), clock, noise_pct=0.0, faults=faults, measure_time_s=0.0)
    link = tmp_path / "gloss"
    device = ZgmPtyDevice(gloss, load_zgm_profile("zgm1120"), link, serial_number="401120999")
    meter = Zgm1120(port=str(link), serial_number="401120999", timeout_s=30.0)
    async with SimLabServer([], None, device):
        first_pty = device.slave_name
        await meter.connect()
        with pytest.raises(Disconnected):
            await meter.measure()
        await meter.close()
        assert not link.exists()  # unplugged: the port is gone
        with pytest.raises(Disconnected, match="cannot open"):
            await meter.connect()
        faults.spec = FaultSpec()
        clock.advance(1.9)
        await asyncio.sleep(0.05)
        assert not link.exists()
        clock.advance(0.1)
        for _ in range(2000):
            if link.exists():
                break
            await asyncio.sleep(0.005)
        assert device.open
        await meter.connect()
        reading = await meter.measure()
        await meter.close()
    assert reading.values_gu[60] == round(LobeModel().gloss((60,))[60], 1)
    assert first_pty and faults.drops == 1


@pytest.mark.wire
async def test_modbus_drop_closes_the_connection_until_the_unit_is_back() -> None:
    clock = SimClock(0)
    faults = FaultInjector("lamp", FaultSpec())
    motor = SimMotor("lamp", speed_deg_s=20, accel_deg_s2=40, soft_limits_deg=(0, 85),
                     start_deg=30.0, homed=True)  # fmt: skip
    lamp = SimAxis("lamp", motor, clock, faults=faults)
    server = ModbusAxisServer(
        [WireAxis(lamp, load_stepper_profile("oriental-az"), 1000.0, 1)], port=0
    )
    await server.start()
    axis = ModbusStepperAxis("lamp", port=server.port, timeout_s=0.5, retries=0)
    try:
        await axis.connect()
        assert await axis.position_deg() == 30.0
        faults.spec = DROP_ALWAYS
        with pytest.raises(Disconnected):
            await axis.position_deg()
        faults.spec = FaultSpec()
        await axis.close()
        await axis.connect()  # TCP accepts, but the unit is still down: dropped again
        with pytest.raises(Disconnected):
            await axis.position_deg()
        await axis.close()
        await clock.sleep(2.0)
        await axis.connect()
        assert await axis.position_deg() == 30.0
        assert faults.drops == 1
    finally:
        await axis.close()
        await server.stop()
