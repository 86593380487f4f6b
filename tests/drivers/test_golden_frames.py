"""The drivers against the golden frames of tests/golden/frames.toml (manual examples, or
frames built from a documented layout): the exact bytes a driver sends, and what it makes
of the exact bytes a device answers. The simulator is checked against the same frames, on
its own, in tests/sim/test_golden_frames_sim.py."""

from __future__ import annotations

import asyncio
import tomllib
from pathlib import Path
from typing import Any

import pytest

from drivers.base import DeviceTimeout, GlossReading
from drivers.glossmeter import Zgm1120
from drivers.modbus_stepper import ModbusStepperAxis

GOLDEN = tomllib.loads(
    (Path(__file__).resolve().parents[1] / "golden" / "frames.toml").read_text(encoding="utf-8")
)
ZGM = GOLDEN["zgm"]
MODBUS = GOLDEN["modbus"]


def crc16_modbus(data: bytes) -> bytes:
    """CRC-16/MODBUS (poly 0xA001 reflected, init 0xFFFF), low byte first."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes([crc & 0xFF, crc >> 8])


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text)


def test_crc_matches_the_modbus_specification_example() -> None:
    assert crc16_modbus(hexbytes(GOLDEN["crc"]["frame"])) == hexbytes(GOLDEN["crc"]["crc"])


@pytest.mark.parametrize("name", sorted(MODBUS))
def test_golden_modbus_frames_carry_a_valid_crc(name: str) -> None:
    for key in ("request", "reply"):
        frame = hexbytes(MODBUS[name][key])
        if frame:
            assert crc16_modbus(frame[:-2]) == frame[-2:], f"{name}.{key}"


def values(case: dict[str, Any]) -> dict[int, float | None]:
    given = {int(k): float(v) for k, v in case.get("values_gu", {}).items()}
    return {a: given.get(a) for a in (20, 60, 85)}


# ------------------------------------------------------------------ ZGM 1120
async def meter(pty_pair: Any) -> Zgm1120:
    m = Zgm1120(port=pty_pair.path, serial_number="401120999", first_transaction_id="xy")
    await m.connect()
    return m


@pytest.mark.parametrize("name", ["measure_printed", "measure_with_temperature", "overflow"])
async def test_zgm_measure(pty_pair: Any, name: str) -> None:
    case = ZGM[name]
    m = await meter(pty_pair)
    task = asyncio.create_task(
        m.measure(case["angles_deg"], with_temperature=case["with_temperature"])
    )
    assert await pty_pair.read_until(b":") == case["request"].encode()
    pty_pair.send(case["reply"].encode() + b"\r\n")
    reading = await task
    await m.close()
    assert reading.values_gu == values(case)
    assert reading.overflow_deg == tuple(case.get("overflow_deg", ()))
    assert reading.temperature_c == case.get("temperature_c")


async def test_zgm_calibrate(pty_pair: Any) -> None:
    case = ZGM["calibrate"]
    m = await meter(pty_pair)
    task = asyncio.create_task(m.calibrate(case["angle_deg"]))
    assert await pty_pair.read_until(b":") == case["request"].encode()
    pty_pair.send(case["reply"].encode() + b"\r\n")
    assert await task == case["deviation_ppm"]
    await m.close()


async def test_zgm_autosend(pty_pair: Any) -> None:
    case = ZGM["autosend"]
    m = await meter(pty_pair)
    stream = m.readings()

    async def first() -> GlossReading:
        return await anext(stream)

    task = asyncio.create_task(first())
    assert await pty_pair.read_until(b":") == case["request"].encode()
    pty_pair.send(case["push"].encode() + b"\r\n")
    reading = await task
    await stream.aclose()
    await m.close()
    assert reading.values_gu == values(case) and reading.temperature_c is None


async def test_zgm_led_and_reset(pty_pair: Any) -> None:
    m = await meter(pty_pair)
    task = asyncio.create_task(m.set_led(True))
    assert await pty_pair.read_until(b":") == ZGM["led_on"]["request"].encode()
    pty_pair.send(ZGM["led_on"]["reply"].encode() + b"\r\n")
    await task
    m._tid_index -= 1  # the next command reuses the manual's TID "xy"
    await asyncio.wait_for(m.reset(), 1.0)  # no return string to wait for
    assert await pty_pair.read_until(b":") == ZGM["reset"]["request"].encode()
    await m.close()


# ------------------------------------------------------------------ Modbus RTU
class ScriptedRtuDevice:
    """A device that answers each request with the next scripted reply (``b""``: silence),
    recording the request bytes; it knows nothing of Modbus beyond the frame lengths."""

    def __init__(self, replies: list[bytes]) -> None:
        self.replies = list(replies)
        self.requests: list[bytes] = []
        self.server: asyncio.Server | None = None
        self.port = 0

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while self.replies:
            head = await reader.readexactly(2)
            if head[1] == 0x10:  # write multiple: address, count, byte count, data, CRC
                rest = await reader.readexactly(5)
                rest += await reader.readexactly(rest[4] + 2)
            else:  # read: address, count, CRC
                rest = await reader.readexactly(6)
            self.requests.append(head + rest)
            reply = self.replies.pop(0)
            if reply:
                writer.write(reply)
                await writer.drain()
        await reader.read()  # until the driver closes

    async def __aenter__(self) -> ScriptedRtuDevice:
        self.server = await asyncio.start_server(self._handle, "127.0.0.1", 0)
        self.port = self.server.sockets[0].getsockname()[1]
        return self

    async def __aexit__(self, *exc: object) -> None:
        assert self.server is not None
        self.server.close()


def axis(port: int, profile: str, **kw: Any) -> ModbusStepperAxis:
    return ModbusStepperAxis("arm", profile=profile, transport="rtu", timeout_s=0.3,
                             serial_port=f"socket://127.0.0.1:{port}", unit_id=1,
                             steps_per_deg=1000.0, limits_deg=(-170.0, 170.0),
                             retries=0, **kw)  # fmt: skip


async def test_az_position_read() -> None:
    case = MODBUS["az_read_feedback"]
    async with ScriptedRtuDevice([hexbytes(case["reply"])]) as dev:
        a = axis(dev.port, "oriental-az")
        await a.connect()
        assert await a.position_deg() == case["position_deg"]
        await a.close()
    assert dev.requests == [hexbytes(case["request"])]


async def test_az_move_is_one_direct_data_write() -> None:
    status, move = MODBUS["az_read_status"], MODBUS["az_move"]
    async with ScriptedRtuDevice([hexbytes(status["reply"]), hexbytes(move["reply"])]) as dev:
        a = axis(dev.port, "oriental-az", speed_deg_s=move["speed_deg_s"],
                 accel_deg_s2=move["accel_deg_s2"])  # fmt: skip
        await a.connect()  # direct-data drives: connect sends nothing
        await a.move_to(move["target_deg"])
        await a.close()
    assert dev.requests == [hexbytes(status["request"]), hexbytes(move["request"])]


async def test_az_silence_on_the_line_is_a_timeout() -> None:
    """What the driver makes of an AZ that does not answer (wrong unit id on the line)."""
    async with ScriptedRtuDevice([b""]) as dev:
        a = axis(dev.port, "oriental-az")
        await a.connect()
        with pytest.raises(DeviceTimeout):
            await a.position_deg()
        await a.close()


async def test_stq_enable_then_status_reads_one_status_register() -> None:
    enable, status, position = (MODBUS[k] for k in ("stq_enable", "stq_read_status",
                                                    "stq_read_position"))  # fmt: skip
    replies = [hexbytes(c["reply"]) for c in (enable, status, position)]
    async with ScriptedRtuDevice(replies) as dev:
        a = axis(dev.port, "applied-motion-stq")
        await a.connect()  # ME
        st = await a.status()
        await a.close()
    assert dev.requests == [hexbytes(c["request"]) for c in (enable, status, position)]
    assert st.ready and st.in_position and not st.moving and st.alarm_code is None
    assert st.position_deg == position["position_deg"]
