"""The simulated lab on the wire, checked with raw clients (not the project's drivers):
a plain pymodbus master against the AZ register map, raw bytes on the ptys."""

from __future__ import annotations

import asyncio
import shutil
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path

import numpy as np
import pytest
import serial_asyncio_fast
from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient

from drivers.profiles import load_stepper_profile, load_stil_profile, load_zgm_profile
from drivers.timing import SimClock, trapezoid_duration_s
from sim.faults import FaultInjector, FaultSpec
from sim.instruments import SimAxis, SimGlossmeter, SimSpectro
from sim.motion import ALARM_OVERLOAD, SimMotor
from sim.wire import ModbusAxisServer, SimLabServer, StilPtyDevice, WireAxis, ZgmPtyDevice
from tests.sim.lobe import LobeModel

pytestmark = pytest.mark.wire

FEEDBACK, STATUS, ALARM, INPUT, DIRECT = 0x0120, 0x007E, 0x0080, 0x007C, 0x0058
IN_POS, MOVE, ALM_A, HOME_END = 1 << 14, 1 << 13, 1 << 7, 1 << 4


def axis(clock: SimClock, name: str, start_deg: float, faults: FaultSpec | None = None) -> SimAxis:
    m = SimMotor(
        name,
        speed_deg_s=20,
        accel_deg_s2=40,
        soft_limits_deg=(-80, 85),
        start_deg=start_deg,
        homed=True,
    )
    return SimAxis(name, m, clock, faults=FaultInjector(name, faults))


def regs32(value: int) -> list[int]:
    v = value & 0xFFFFFFFF
    return [v >> 16, v & 0xFFFF]


@pytest.fixture
async def modbus(
    request: pytest.FixtureRequest,
) -> AsyncIterator[tuple[ModbusAxisServer, AsyncModbusTcpClient, SimClock]]:
    scale = getattr(request, "param", 0.0)
    clock = SimClock(scale)
    prof = load_stepper_profile("oriental-az")
    lamp = axis(clock, "lamp", 45.0)
    det = axis(clock, "detector", 45.0, FaultSpec(disconnect_after=0))
    server = ModbusAxisServer(
        [WireAxis(lamp, prof, 1000.0, 1), WireAxis(det, prof, 1000.0, 2)], host="127.0.0.1", port=0
    )
    await server.start()
    client = AsyncModbusTcpClient("127.0.0.1", port=server.port, timeout=2, retries=0)
    await client.connect()
    try:
        yield server, client, clock
    finally:
        client.close()
        await server.stop()


async def read(client: AsyncModbusTcpClient, address: int, unit: int, count: int = 2) -> list[int]:
    rr = await client.read_holding_registers(address, count=count, device_id=unit)
    assert not rr.isError(), rr
    return list(rr.registers)


async def wait_stopped(client: AsyncModbusTcpClient, unit: int) -> int:
    for _ in range(2000):  # request round trips, no sleeps: the scale-0 clock runs the move
        hi, lo = await read(client, STATUS, unit)
        word = hi << 16 | lo
        if not word & MOVE:
            return word
    raise AssertionError("move never ended")


async def test_master_reads_feedback_int32_high_word_first(modbus) -> None:  # type: ignore[no-untyped-def]
    _, client, _ = modbus
    assert await read(client, FEEDBACK, 1) == [0x0000, 0xAFC8]  # 45 deg * 1000 steps/deg = 45000
    word = await wait_stopped(client, 1)
    assert word & IN_POS and not word & ALM_A


async def test_direct_data_write_with_trigger_starts_the_move(modbus) -> None:  # type: ignore[no-untyped-def]
    _, client, clock = modbus
    block = [
        0,
        0,
        0,
        1,
        *regs32(-12500),
        *regs32(20000),
        *regs32(40000),
        *regs32(40000),
        0,
        1000,
        0,
        1,
        0,
        0,
    ]
    assert len(block) == 18
    rr = await client.write_registers(DIRECT, block, device_id=2)
    assert not rr.isError()
    hi, lo = await read(client, STATUS, 2)
    assert (hi << 16 | lo) & MOVE
    word = await wait_stopped(client, 2)
    assert word & IN_POS
    assert await read(client, FEEDBACK, 2) == [0xFFFF, 0xCF2C]  # -12500 two's complement
    assert clock.now() == pytest.approx(trapezoid_duration_s(57.5, 20.0, 40.0))
    assert await read(client, FEEDBACK, 1) == [0x0000, 0xAFC8]  # the other unit did not move
    # trigger = 0 only stores the data
    block[15] = 0
    block[4:6] = regs32(0)
    await client.write_registers(DIRECT, block, device_id=2)
    assert await read(client, FEEDBACK, 2) == [0xFFFF, 0xCF2C]


async def test_zhome_alarm_and_alarm_reset_bits(modbus) -> None:  # type: ignore[no-untyped-def]
    server, client, _ = modbus
    await client.write_registers(INPUT, regs32(1 << 4), device_id=1)  # ZHOME rising edge
    await client.write_registers(INPUT, [0, 0], device_id=1)
    word = await wait_stopped(client, 1)
    assert await read(client, FEEDBACK, 1) == [0, 0]
    assert word & HOME_END and word & IN_POS
    server.axes[1].axis.motor.inject_alarm(10.0)
    block = [
        0,
        0,
        0,
        1,
        *regs32(30000),
        *regs32(20000),
        *regs32(40000),
        *regs32(40000),
        0,
        1000,
        0,
        1,
        0,
        0,
    ]
    await client.write_registers(DIRECT, block, device_id=1)
    word = await wait_stopped(client, 1)
    assert word & ALM_A and not word & IN_POS
    assert await read(client, ALARM, 1) == [0, ALARM_OVERLOAD]
    assert await read(client, FEEDBACK, 1) == [0, 10000]
    await client.write_registers(INPUT, regs32(1 << 7), device_id=1)  # ALM-RST
    await client.write_registers(INPUT, [0, 0], device_id=1)
    assert await read(client, ALARM, 1) == [0, 0]


@pytest.mark.parametrize("modbus", [1e-9], indirect=True)
async def test_stop_bit_halts_a_move(modbus) -> None:  # type: ignore[no-untyped-def]
    server, client, _ = modbus  # a clock this slow keeps the arm mid-move
    block = [
        0,
        0,
        0,
        1,
        *regs32(80000),
        *regs32(20000),
        *regs32(40000),
        *regs32(40000),
        0,
        1000,
        0,
        1,
        0,
        0,
    ]
    await client.write_registers(DIRECT, block, device_id=1)
    hi, lo = await read(client, STATUS, 1)
    assert (hi << 16 | lo) & MOVE
    await client.write_registers(INPUT, regs32(1 << 5), device_id=1)  # STOP
    hi, lo = await read(client, STATUS, 1)
    assert not (hi << 16 | lo) & MOVE
    assert server.axes[1].axis.motor.command_deg(server.axes[1].axis.clock.now()) == pytest.approx(
        45.0, abs=1e-3
    )


async def test_disconnected_unit_answers_gateway_no_response() -> None:
    clock = SimClock(0)
    prof = load_stepper_profile("oriental-az")
    lamp = axis(clock, "lamp", 45.0, FaultSpec(disconnect_after=1))
    server = ModbusAxisServer([WireAxis(lamp, prof, 1000.0, 1)], port=0)
    async with SimLabServer([server]):
        client = AsyncModbusTcpClient("127.0.0.1", port=server.port, timeout=2, retries=0)
        await client.connect()
        assert await read(client, FEEDBACK, 1) == [0x0000, 0xAFC8]
        rr = await client.read_holding_registers(FEEDBACK, count=2, device_id=1)
        assert rr.isError() and rr.exception_code == 0x0B
        client.close()


@pytest.fixture
async def ptys(tmp_path: Path) -> AsyncIterator[tuple[SimLabServer, Path]]:
    clock = SimClock(0)
    lamp, det = axis(clock, "lamp", 45.0), axis(clock, "detector", 47.0)
    spectro = SimSpectro(LobeModel(), lamp, det, clock, noise_pct=0.0)
    gloss = SimGlossmeter(LobeModel(), clock, noise_pct=0.0, autosend_interval_s=2.0)
    lab = SimLabServer(
        [],
        StilPtyDevice(spectro, load_stil_profile("stil-ruby"), tmp_path / "sim" / "spectro"),
        ZgmPtyDevice(
            gloss,
            load_zgm_profile("zgm1120"),
            tmp_path / "sim" / "gloss",
            serial_number="401120999",
        ),
    )
    async with lab:
        yield lab, tmp_path / "sim"
    assert not (tmp_path / "sim" / "spectro").exists()  # symlinks removed on stop


async def test_stil_pty_speaks_the_profile(ptys) -> None:  # type: ignore[no-untyped-def]
    lab, d = ptys
    assert (d / "spectro").is_symlink() and lab.endpoints()["spectro"]["port"] == str(d / "spectro")
    reader, writer = await serial_asyncio_fast.open_serial_connection(
        url=str(d / "spectro"), baudrate=115200
    )
    try:
        writer.write(b"IDN?\r")
        assert (await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)).startswith(b"STIL RUBY")
        writer.write(b"EXP 100\r")
        assert (
            await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)
            == b"ERR 2 exposure out of range 500..250000 us\r\n"
        )
        writer.write(b"EXP 20000\r")
        assert await asyncio.wait_for(reader.readuntil(b"\r\n"), 5) == b"EXP=20000\r\n"
        writer.write(b"MEAS\r")
        y_line = await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)
        spec = (await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)).decode().split()
        expected = 100.0 * np.exp(-((2.0 / 4.0) ** 2))  # lamp 45, detector 47
        assert y_line == f"Y={expected:.4f}\r\n".encode()
        assert spec[:4] == ["SPEC", "380", "10", "41"] and len(spec[4].split(",")) == 41
    finally:
        writer.close()


async def test_zgm1120_pty_measure_reply_bytes(ptys) -> None:  # type: ignore[no-untyped-def]
    _, d = ptys
    reader, writer = await serial_asyncio_fast.open_serial_connection(
        url=str(d / "gloss"), baudrate=9600
    )
    try:
        writer.write(b"1| 401120999|ab|7|1|0:")
        reply = await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)
        # 81.26 -> 81.3 GU = 813 dGU, 93.04 -> 930 dGU, each with the zero-current offset
        # (94, 91: the manual's p. 24 example); 85 deg 2500 GU overflows: -2 in the OFFSET
        # field (manual p. 16; the value field's 9999 is the simulator's choice); isTemp 0 -> temperature field 0 (p. 16)
        assert reply == b"1| 401120999|ab|813|94|930|91|9999|-2|1|0\r\n"
        writer.write(b"1| 401120999|cd|2|1|1:")  # 60 deg only, with temperature
        assert (
            await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)
            == b"1| 401120999|cd|-1|-1|930|91|-1|-1|1|23\r\n"
        )
        writer.write(b"6| 401120999|ef|170:")  # AutoSend on, all angles: readings pushed
        pushed = await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)
        assert pushed == b"6| 401120999|ef|813|94|930|91|9999|-2|1|0\r\n"
        writer.write(b"72| 401120999|gh:")  # Calibrate without its arguments: error string
        error = await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)
        while error.startswith(b"6| "):  # AutoSend is still on: pushes may come first
            error = await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)
        assert error.startswith(b"56| 401120999|gh|72|")
    finally:
        writer.close()


async def test_goniolab_sim_serve_subprocess(tmp_path: Path) -> None:
    """`goniolab sim serve --json`: endpoints as one JSON line, a raw master reads a
    register, SIGINT stops it with exit code 0 and the pty links are gone."""
    import json
    import signal
    import sys

    from goniolab.config import configs_dir
    from tests.twin_configs import ideal

    text = (
        ideal((configs_dir() / "lab-sim-wire.toml").read_text())
        .replace("port = 5020", "port = 0")  # the server binds a free port, printed below
        .replace("/tmp/goniolab-sim", str(tmp_path / "sim"))
        .replace('map = "sample:wittmann-3"', 'map = "sample:gaussian-s0.05"')
    )
    cfg = tmp_path / "wire.toml"
    cfg.write_text(text)
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "goniolab.cli",
        "sim",
        "serve",
        "--config",
        str(cfg),
        "--json",
        "--time-scale",
        "0",
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        assert proc.stdout is not None
        line = await asyncio.wait_for(proc.stdout.readline(), 60)
        info = json.loads(line)
        assert info["time_scale"] == 0.0
        eps = info["endpoints"]
        port = eps["lamp"]["port"]
        assert port > 0 and eps["detector"]["port"] == port  # one server, two unit ids
        assert eps["lamp"] == {
            "transport": "tcp",
            "host": "127.0.0.1",
            "port": port,
            "unit_id": 1,
            "profile": "oriental-az",
        }
        assert eps["spectro"]["port"] == str(tmp_path / "sim" / "spectro")
        assert (tmp_path / "sim" / "gloss").is_symlink()
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=5, retries=0)
        await client.connect()
        assert await read(client, FEEDBACK, 2) == [0x0000, 0xAFC8]  # detector parked at 45 deg
        client.close()
        proc.send_signal(signal.SIGINT)
        rc = await asyncio.wait_for(proc.wait(), 30)
        assert rc == 0, (await proc.stderr.read()).decode() if proc.stderr else ""
        assert not (tmp_path / "sim" / "spectro").exists()
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def test_models_are_evaluated_before_the_ptys_accept_commands(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The first evaluation of a real facet model (kernel loading, tables) must not eat a
    driver's reply timeout: SimLabServer evaluates spectro and gloss models first."""
    clock = SimClock(0)
    model = LobeModel()
    lamp, det = axis(clock, "lamp", 45.0), axis(clock, "detector", 45.0)
    spectro = StilPtyDevice(
        SimSpectro(model, lamp, det, clock), load_stil_profile("stil-ruby"), tmp_path / "s"
    )
    gloss = ZgmPtyDevice(
        SimGlossmeter(model, clock),
        load_zgm_profile("zgm1120"),
        tmp_path / "g",
        serial_number="401120999",
    )
    seen_at_start: list[tuple[int, int]] = []
    for dev in (spectro, gloss):
        original = dev.start

        async def start(original: Callable[[], Awaitable[None]] = original) -> None:
            seen_at_start.append((len(model.calls), model.gloss_calls))
            await original()

        monkeypatch.setattr(dev, "start", start)
    async with SimLabServer([], spectro, gloss):
        assert seen_at_start == [(1, 1), (1, 1)]
        reader, writer = await serial_asyncio_fast.open_serial_connection(
            url=str(tmp_path / "g"), baudrate=9600
        )
        try:
            writer.write(b"1| 401120999|ab|7|1|0:")
            await asyncio.wait_for(reader.readuntil(b"\r\n"), 5)
        finally:
            writer.close()
        assert model.gloss_calls == 1  # the warm-up filled the cache for all three angles


async def test_rtu_server_answers_a_plain_rtu_master_over_socket() -> None:
    """RTU framing (unit, PDU, CRC-16) over TCP: pymodbus' serial master on socket://."""
    clock = SimClock(0)
    prof = load_stepper_profile("oriental-az")
    server = ModbusAxisServer(
        [WireAxis(axis(clock, "lamp", 45.0), prof, 1000.0, 1)], port=0, transport="rtu"
    )
    async with SimLabServer([server]):
        assert server.url == f"socket://127.0.0.1:{server.port}" and server.port > 0
        client = AsyncModbusSerialClient(server.url, timeout=2, retries=0)
        await client.connect()
        try:
            rr = await client.read_holding_registers(FEEDBACK, count=2, device_id=1)
            assert not rr.isError() and list(rr.registers) == [0x0000, 0xAFC8]  # 45000 steps
        finally:
            client.close()


@pytest.mark.skipif(shutil.which("mbpoll") is None, reason="mbpoll not installed (apt mbpoll)")
async def test_mbpoll_reads_feedback_and_starts_a_move(modbus) -> None:  # type: ignore[no-untyped-def]
    """The docs/WIRE_SIM.md recipe with a standard Modbus master (Debian's mbpoll):
    int32 big-endian word order, 0-based protocol addresses."""
    server, _, _ = modbus

    async def mbpoll(*args: str) -> str:
        proc = await asyncio.create_subprocess_exec(
            "mbpoll", "-m", "tcp", "-p", str(server.port), "-a", "1", "-0", "-t", "4:int", "-B",
            *args, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
        )  # fmt: skip
        out, _ = await asyncio.wait_for(proc.communicate(), 30)
        assert proc.returncode == 0, out.decode()
        return out.decode()

    read = ("-r", "288", "-c", "1", "-1", "127.0.0.1")
    assert "[288]: \t45000" in await mbpoll(*read)
    written = await mbpoll(
        "-r", "88", "127.0.0.1", "0", "1", "30000", "20000", "40000", "40000", "1000", "1", "0"
    )  # fmt: skip
    assert "Written 9 references" in written
    for _ in range(50):  # each read is a round trip; the scale-0 clock runs the move
        if "[288]: \t30000" in await mbpoll(*read):
            break
    else:
        raise AssertionError("the lamp arm never reached 30000 steps")
