"""The simulated serial instruments under hostile input: garbage bytes get an error reply
as the real device gives one (issue 10, defect 5: a non-ASCII byte raised
UnicodeEncodeError, no reply, a traceback per byte), and the work per line is bounded
(defect 6: 200k queued MEAS lines grew the sim to 1.3 GB; unterminated input grew a buffer
without bound)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
import serial_asyncio_fast

from drivers.profiles import load_stil_profile, load_zgm_profile
from drivers.timing import SimClock
from sim.instruments import SimAxis, SimGlossmeter, SimSpectro
from sim.motion import SimMotor
from sim.wire import SimLabServer, StilPtyDevice, ZgmPtyDevice
from sim.wire.serial import MAX_LINE_BYTES, MAX_PENDING_LINES
from tests.sim.lobe import LobeModel

pytestmark = pytest.mark.wire


def _axis(clock: SimClock, name: str, deg: float) -> SimAxis:
    motor = SimMotor(name, speed_deg_s=20, accel_deg_s2=40, soft_limits_deg=(-80, 85),
                     start_deg=deg, homed=True)  # fmt: skip
    return SimAxis(name, motor, clock)


@pytest.fixture
async def lab(tmp_path: Path) -> AsyncIterator[tuple[SimLabServer, list[Any]]]:
    """The spectro and glossmeter ptys; every exception an event-loop callback or task
    swallows is recorded (a traceback per byte would show there)."""
    clock = SimClock(0)
    spectro = SimSpectro(LobeModel(), _axis(clock, "lamp", 45.0), _axis(clock, "detector", 47.0),
                         clock, noise_pct=0.0)  # fmt: skip
    gloss = SimGlossmeter(LobeModel(), clock, noise_pct=0.0, measure_time_s=0.0)
    server = SimLabServer(
        [],
        StilPtyDevice(spectro, load_stil_profile("stil-ruby"), tmp_path / "spectro"),
        ZgmPtyDevice(gloss, load_zgm_profile("zgm1120"), tmp_path / "gloss",
                     serial_number="401120999"),
    )  # fmt: skip
    errors: list[Any] = []
    loop = asyncio.get_running_loop()

    def record(_loop: asyncio.AbstractEventLoop, ctx: dict[str, Any]) -> None:
        # the test's own serial client (serial_asyncio_fast) trips over its write buffer
        # when flooding; only what the simulated devices raise counts
        if "SerialTransport" not in str(ctx.get("message", "")):
            errors.append(ctx)

    loop.set_exception_handler(record)
    async with server:
        yield server, errors
    loop.set_exception_handler(None)


async def _open(path: Path) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await serial_asyncio_fast.open_serial_connection(url=str(path), baudrate=115200)


async def _line(reader: asyncio.StreamReader, term: bytes = b"\r\n") -> bytes:
    return await asyncio.wait_for(reader.readuntil(term), 10)


@pytest.mark.parametrize("garbage", [b"\xff\xfe", b"ID\xe9N?", b"\x00\x80MEAS", "MEÄS".encode()])
async def test_non_ascii_bytes_get_an_error_reply(
    lab: tuple[SimLabServer, list[Any]], garbage: bytes
) -> None:
    server, errors = lab
    assert server.spectro is not None
    reader, writer = await _open(server.spectro.link_path)
    try:
        writer.write(garbage + b"\r")
        reply = await _line(reader)
        assert reply.startswith(b"ERR 1 unknown command") and reply.isascii()
        writer.write(b"IDN?\r")  # the device carries on
        assert (await _line(reader)).startswith(b"STIL RUBY")
    finally:
        writer.close()
    assert errors == []


async def test_non_ascii_transaction_id_on_the_glossmeter_is_ignored(
    lab: tuple[SimLabServer, list[Any]],
) -> None:
    server, errors = lab
    assert server.glossmeter is not None
    reader, writer = await _open(server.glossmeter.link_path)
    try:
        writer.write("1| 401120999|\xe9\xff|7|1|0:".encode("latin-1"))
        writer.write(b"36| 401120999|ab:")
        reply = await asyncio.wait_for(reader.readuntil(b"\r\n"), 10)
        assert reply.startswith(b"36| 401120999|ab|")  # only the well-formed request answered
    finally:
        writer.close()
    assert errors == []


async def test_an_unterminated_flood_is_bounded_and_answered_with_an_error(
    lab: tuple[SimLabServer, list[Any]],
) -> None:
    server, errors = lab
    device = server.spectro
    assert device is not None
    reader, writer = await _open(device.link_path)
    try:
        for _ in range(64):  # 1 MiB without a terminator
            writer.write(b"A" * 16384)
            await writer.drain()
            assert device.buffered_bytes <= MAX_LINE_BYTES
        writer.write(b"\r")
        reply = await _line(reader)
        assert reply.startswith(b"ERR 1 line too long")
        writer.write(b"IDN?\r")
        assert (await _line(reader)).startswith(b"STIL RUBY")
    finally:
        writer.close()
    assert errors == []


async def test_a_flood_of_measurements_queues_a_bounded_number(
    lab: tuple[SimLabServer, list[Any]],
) -> None:
    """200000 MEAS lines sent without reading a reply: the device keeps at most
    MAX_PENDING_LINES commands (a real one overruns its input buffer), runs one at a
    time, and answers the next command once the flood is over."""
    server, errors = lab
    device = server.spectro
    assert device is not None
    reader, writer = await _open(device.link_path)
    most_tasks = 0
    try:
        burst = b"MEAS\r" * 2000
        for _ in range(100):
            writer.write(burst)
            await writer.drain()
            assert device.pending_lines <= MAX_PENDING_LINES
            most_tasks = max(most_tasks, len(asyncio.all_tasks()))
        assert most_tasks < 50
        assert device.dropped_lines > 0
        await asyncio.wait_for(device.idle(), 120)  # the queue drains; replies pile up unread
        # drop the piled-up replies, then the device answers a fresh command
        reader._buffer.clear()  # type: ignore[attr-defined]
        writer.write(b"IDN?\r")
        for _ in range(1000):
            line = await _line(reader)
            if line.startswith(b"STIL RUBY"):
                break
        else:
            raise AssertionError("no answer to IDN? after the flood")
    finally:
        writer.close()
    assert errors == []
