"""The wire simulator with the project's real stepper driver: the Applied Motion MDX+
register map (command-opcode) over Modbus TCP, and Modbus RTU on a serial pty pair."""

from __future__ import annotations

import asyncio
import shutil
import subprocess
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest
from pymodbus.client import AsyncModbusTcpClient

from drivers.base import DeviceFault
from drivers.modbus_stepper import ModbusStepperAxis
from drivers.profiles import load_stepper_profile
from drivers.timing import SimClock, trapezoid_duration_s
from sim.instruments import SimAxis
from sim.motion import ALARM_OVERLOAD, SimMotor
from sim.wire import ModbusAxisServer, WireAxis

pytestmark = pytest.mark.wire

# MDX+ holding registers 40001.. (PROTOCOLS.md), as protocol addresses (minus 40001)
ALARM, STATUS, FEEDBACK, COMMAND, ACCEL, VELOCITY, TARGET = 0, 2, 6, 124, 344, 348, 350
OP_FP, OP_ME, OP_MD = 0x67, 0x9F, 0x9E
READY, IN_POSITION, MOVING, ALARM_BIT = 1 << 0, 1 << 3, 1 << 4, 1 << 9


def arm(clock: SimClock, name: str, start_deg: float) -> SimAxis:
    motor = SimMotor(name, speed_deg_s=20, accel_deg_s2=40, soft_limits_deg=(-80, 85),
                     start_deg=start_deg, homed=True)  # fmt: skip
    return SimAxis(name, motor, clock)


@pytest.fixture
async def amp() -> AsyncIterator[tuple[ModbusAxisServer, SimClock]]:
    clock = SimClock(0)
    prof = load_stepper_profile("applied-motion-mdx")
    # 20000 steps/rev, 1000 steps/deg: 20 deg/s = 1 rps = 240 counts, 40 deg/s^2 = 12 counts
    server = ModbusAxisServer([WireAxis(arm(clock, "lamp", 45.0), prof, 1000.0, 1)], port=0)
    await server.start()
    try:
        yield server, clock
    finally:
        await server.stop()


def driver(port: int, **kw: object) -> ModbusStepperAxis:
    return ModbusStepperAxis("lamp", profile="applied-motion-mdx", port=port, unit_id=1,
                             limits_deg=(0.0, 85.0), speed_deg_s=20.0, accel_deg_s2=40.0,
                             timeout_s=2.0, **kw)  # type: ignore[arg-type]  # fmt: skip


async def test_real_driver_moves_an_applied_motion_arm_over_tcp(amp) -> None:  # type: ignore[no-untyped-def]
    server, clock = amp
    axis = driver(server.port)
    await axis.connect()  # writes ME (enable)
    try:
        assert server.axes[1].enabled
        st = await axis.status()
        assert st.ready and st.in_position and st.position_deg == 45.0
        t0 = clock.now()
        await axis.move_to(32.5)
        assert await axis.wait_in_position(5.0) == pytest.approx(32.5, abs=1e-3)
        # the velocity / accel registers (1/240 rps, 1/6 rps/s) set the simulated profile
        assert clock.now() - t0 == pytest.approx(trapezoid_duration_s(12.5, 20.0, 40.0), rel=1e-6)
        server.axes[1].axis.motor.inject_alarm(40.0)
        await axis.move_to(45.0)
        with pytest.raises(DeviceFault) as info:
            await axis.wait_in_position(5.0)
        assert info.value.code == ALARM_OVERLOAD
        await axis.reset_alarm()  # AR, then ME
        assert (await axis.status()).alarm_code is None
        await axis.home(5.0)  # SH
        assert await axis.position_deg() == 0.0
    finally:
        await axis.close()


async def test_applied_motion_register_map_with_a_plain_master(amp) -> None:  # type: ignore[no-untyped-def]
    server, _ = amp
    client = AsyncModbusTcpClient("127.0.0.1", port=server.port, timeout=2, retries=0)
    await client.connect()

    async def read(address: int, count: int = 2) -> list[int]:
        rr = await client.read_holding_registers(address, count=count, device_id=1)
        assert not rr.isError(), rr
        return list(rr.registers)

    try:
        assert await read(FEEDBACK) == [0x0000, 0xAFC8]  # 45000 steps, high word first
        await client.write_registers(ACCEL, [12], device_id=1)
        await client.write_registers(VELOCITY, [240], device_id=1)
        await client.write_registers(TARGET, [0xFFFF, 0xD8F0], device_id=1)  # -10000 steps
        await client.write_registers(COMMAND, [OP_FP], device_id=1)
        assert await read(FEEDBACK) == [0x0000, 0xAFC8]  # disabled drive: FP ignored
        assert not (await read(STATUS))[1] & READY
        await client.write_registers(COMMAND, [OP_ME], device_id=1)
        await client.write_registers(COMMAND, [OP_FP], device_id=1)
        for _ in range(2000):  # the scale-0 clock runs the move between requests
            if not (await read(STATUS))[1] & MOVING:
                break
        assert (await read(STATUS))[1] & (READY | IN_POSITION) == READY | IN_POSITION
        assert await read(FEEDBACK) == [0xFFFF, 0xD8F0]
        await client.write_registers(COMMAND, [OP_MD], device_id=1)
        assert not (await read(STATUS))[1] & READY
        assert await read(ALARM) == [0, 0]
    finally:
        client.close()


@pytest.fixture
def pty_pair(tmp_path: Path) -> Iterator[tuple[Path, Path]]:
    """Two linked ptys from socat (the test's serial cable)."""
    if shutil.which("socat") is None:
        pytest.skip("socat is not installed (Debian package socat): no pty pair for Modbus RTU")
    a, b = tmp_path / "rtu-master", tmp_path / "rtu-slave"
    proc = subprocess.Popen(
        ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 10.0
        while not (a.exists() and b.exists()):
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail("socat did not create the pty pair")
            time.sleep(0.02)
        yield a, b
    finally:
        proc.terminate()
        proc.wait(timeout=5)


@pytest.mark.parametrize("profile", ["oriental-az", "applied-motion-mdx"])
async def test_modbus_rtu_on_a_pty_pair(pty_pair: tuple[Path, Path], profile: str) -> None:
    master_end, slave_end = pty_pair
    clock = SimClock(0)
    prof = load_stepper_profile(profile)
    server = ModbusAxisServer(
        [WireAxis(arm(clock, "detector", 45.0), prof, 1000.0, 2)],
        transport="rtu", serial_port=str(slave_end), baudrate=prof.serial.baudrate,
    )  # fmt: skip
    await server.start()
    # parity N: a pty has no UART framing, and Linux refuses (EINVAL) to set PARENB on a
    # pty that already has it, so the AZ's even parity would fail its second open
    axis = ModbusStepperAxis("detector", profile=profile, transport="rtu",
                             serial_port=str(master_end), unit_id=2, limits_deg=(-70.0, 70.0),
                             timeout_s=2.0, parity="N")  # fmt: skip
    try:
        await axis.connect()
        assert await axis.position_deg() == 45.0
        await axis.move_to(-12.25)
        assert await axis.wait_in_position(5.0) == pytest.approx(-12.25, abs=1e-3)
        assert server.axes[2].axis.motor.position_deg(clock.now()) == pytest.approx(-12.25)
    finally:
        await axis.close()
        await server.stop()
        await asyncio.sleep(0)
