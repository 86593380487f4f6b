"""The wire simulator with the project's real stepper driver: the Applied Motion ST-Q
register map (920-0072 Rev E p. 7; 16-bit alarm and status codes), the default Applied
Motion profile, over Modbus TCP."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from drivers.base import DeviceFault
from drivers.modbus_stepper import ModbusStepperAxis
from drivers.profiles import load_stepper_profile
from drivers.timing import SimClock, trapezoid_duration_s
from goniolab.lab_wiring import Lab
from sim.instruments import SimAxis
from sim.motion import ALARM_OVERLOAD, SimMotor
from sim.wire import ModbusAxisServer, WireAxis
from tests.contract.contract_support import MODEL, lab_toml

pytestmark = pytest.mark.wire


@pytest.fixture
async def stq() -> AsyncIterator[tuple[ModbusAxisServer, SimClock]]:
    clock = SimClock(0)
    motor = SimMotor("lamp", speed_deg_s=20, accel_deg_s2=40, soft_limits_deg=(-80, 85),
                     start_deg=45.0, homed=True)  # fmt: skip
    prof = load_stepper_profile("applied-motion-stq")
    server = ModbusAxisServer([WireAxis(SimAxis("lamp", motor, clock), prof, 1000.0, 1)], port=0)
    await server.start()
    try:
        yield server, clock
    finally:
        await server.stop()


async def test_real_driver_moves_an_st_q_arm(stq: tuple[ModbusAxisServer, SimClock]) -> None:
    server, clock = stq
    axis = ModbusStepperAxis("lamp", profile="applied-motion-stq", port=server.port, unit_id=1,
                             limits_deg=(0.0, 85.0), speed_deg_s=20.0, accel_deg_s2=40.0,
                             timeout_s=2.0)  # fmt: skip
    await axis.connect()  # ME into 40125
    try:
        assert server.axes[1].enabled
        st = await axis.status()  # status code 40002: ONE register
        assert st.ready and st.in_position and st.position_deg == 45.0
        t0 = clock.now()
        await axis.move_to(32.5)  # AC 40028, DE 40029, VE 40030, DI 40031-32, then FP
        assert await axis.wait_in_position(5.0) == pytest.approx(32.5, abs=1e-3)
        assert clock.now() - t0 == pytest.approx(trapezoid_duration_s(12.5, 20.0, 40.0), rel=1e-6)
        server.axes[1].axis.motor.inject_alarm(40.0)
        await axis.move_to(45.0)
        with pytest.raises(DeviceFault) as info:
            await axis.wait_in_position(5.0)
        assert info.value.code == ALARM_OVERLOAD  # alarm code 40001: ONE register
        await axis.reset_alarm()  # AX, then ME
        assert (await axis.status()).alarm_code is None
    finally:
        await axis.close()


@pytest.mark.parametrize("backend", ["wire", "wire-rtu"])
async def test_a_lab_config_selects_the_st_q_map(tmp_path: Path, backend: str) -> None:
    """``profile = "applied-motion-stq"`` in a lab config: the config validates, the
    simulated lab serves the ST-Q map and the real drivers move both arms through it."""
    path = lab_toml(tmp_path, backend,
                    extra={'profile = "oriental-az"': 'profile = "applied-motion-stq"'})  # fmt: skip
    async with Lab.from_config(path, model=MODEL) as lab:
        assert lab.server is not None
        profiles = {w.profile.name for s in lab.server.modbus for w in s.axes.values()}
        assert profiles == {"applied-motion-stq"}
        await lab.goniometer.move_to(30.0, 40.0, 30.0)
        assert await lab.goniometer.positions_deg() == pytest.approx((30.0, 40.0), abs=1e-3)
