"""The simulator against the golden frames of tests/golden/frames.toml, on its own: raw
request bytes in, exact reply bytes (or silence) out. The drivers are checked against the
same frames in tests/drivers/test_golden_frames.py; the simulator's ZGM 1120 interpreter
shares no code with the driver (checked below)."""

from __future__ import annotations

import ast
import asyncio
import contextlib
import os
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sim.wire.zgm as zgm_module
from drivers.profiles import load_stepper_profile
from drivers.timing import SimClock
from sim.instruments import SimAxis
from sim.motion import SimMotor
from sim.wire import ModbusAxisServer, WireAxis
from sim.wire.zgm import ZgmProtocol

GOLDEN = tomllib.loads(
    (Path(__file__).resolve().parents[1] / "golden" / "frames.toml").read_text(encoding="utf-8")
)
ZGM = GOLDEN["zgm"]
MODBUS = GOLDEN["modbus"]


def test_the_zgm_interpreter_does_not_import_the_driver() -> None:
    tree = ast.parse(Path(zgm_module.__file__).read_text(encoding="utf-8"))
    imported = {
        n.module if isinstance(n, ast.ImportFrom) else a.name
        for n in ast.walk(tree)
        if isinstance(n, ast.Import | ast.ImportFrom)
        for a in (n.names if isinstance(n, ast.Import) else [n])  # type: ignore[list-item]
    }
    assert not any(str(m).startswith("drivers") for m in imported), imported


class Scripted:
    """A reading source with fixed values (the golden cases' readings)."""

    def __init__(self, gu: dict[int, float], *, overflow: Sequence[int] = (),
                 temperature_c: float = 25.0, ppm: int = 0) -> None:  # fmt: skip
        self.gu, self.overflow = gu, tuple(overflow)
        self.temperature_c, self.ppm = temperature_c, ppm

    async def read_values_gu(
        self, angles_deg: Sequence[int]
    ) -> tuple[dict[int, float | None], tuple[int, ...]]:
        values: dict[int, float | None] = {a: None for a in (20, 60, 85)}
        for a in angles_deg:
            values[a] = None if a in self.overflow else self.gu.get(a)
        return values, tuple(a for a in angles_deg if a in self.overflow)

    def current_temperature_c(self) -> float:
        return self.temperature_c

    def calibrate_ppm(self, angle_deg: int | None = None) -> int:
        return self.ppm


def gu(case: dict[str, Any]) -> dict[int, float]:
    return {int(k): float(v) for k, v in case.get("values_gu", {}).items()}


def command(case: dict[str, Any]) -> str:
    text = str(case["request"])
    assert text.endswith(":")
    return text[:-1]


@pytest.mark.parametrize("name", ["measure_printed", "measure_with_temperature", "overflow"])
async def test_zgm_measure(name: str) -> None:
    case = ZGM[name]
    source = Scripted(gu(case), overflow=case.get("overflow_deg", ()))
    meter = ZgmProtocol(source, "401120999")  # offsets 94 / 91 / 78: the manual's example
    assert await meter.handle(command(case)) == case["sim_reply"]


async def test_zgm_calibrate_and_its_arguments() -> None:
    case = ZGM["calibrate"]
    meter = ZgmProtocol(Scripted({}, ppm=case["deviation_ppm"]), "401120999")
    assert await meter.handle(command(case)) == case["reply"]
    # without its arguments (what the old driver sent) the meter answers its error string
    assert (
        await meter.handle("72| 401120999|xy")
        == "56| 401120999|xy|72|Calibrate needs Angle|Cal2Standard|Cal2StandValue"
    )


async def test_zgm_autosend_push() -> None:
    case = ZGM["autosend"]
    meter = ZgmProtocol(Scripted(gu(case)), "401120999")
    assert await meter.pushed() is None  # off
    assert await meter.handle(command(case)) is None  # no acknowledgement
    assert await meter.pushed() == case["push"]
    refused = await meter.handle("6| 401120999|xz|7|1|0")  # the old driver's layout
    assert refused is not None and refused.startswith("56| 401120999|xz|6|")


async def test_zgm_led_reset_and_other_serial_numbers() -> None:
    meter = ZgmProtocol(Scripted({}), "401120999")
    assert await meter.handle(command(ZGM["led_on"])) == ZGM["led_on"]["reply"]
    assert meter.leds_on == {1}
    refused = await meter.handle("48| 401120999|xy")  # LED argument missing
    assert refused is not None and refused.startswith("56| 401120999|xy|48|")
    assert await meter.handle(command(ZGM["reset"])) is None and meter.resets == 1
    assert meter.leds_on == set()
    assert await meter.handle("1| 401120998|xy|5|1|0") is None  # another meter's command


# ------------------------------------------------------------------ Modbus RTU
async def exchange(port: int, request: bytes, wait_s: float = 0.5) -> bytes:
    """Send one raw RTU frame over the socket line; what comes back within ``wait_s``."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(request)
        await writer.drain()
        data = b""
        try:
            while True:
                data += await asyncio.wait_for(reader.read(256), wait_s)
                if not data:
                    break
        except TimeoutError:
            pass
        return data
    finally:
        writer.close()


async def server_for(profile: str, start_deg: float) -> tuple[ModbusAxisServer, SimClock]:
    clock = SimClock(0)
    motor = SimMotor("arm", speed_deg_s=20, accel_deg_s2=40, soft_limits_deg=(-170, 170),
                     start_deg=start_deg, homed=True)  # fmt: skip
    wire = WireAxis(SimAxis("arm", motor, clock), load_stepper_profile(profile), 1000.0, 1)
    server = ModbusAxisServer([wire], port=0, transport="rtu")
    await server.start()
    return server, clock


def frame(name: str, key: str) -> bytes:
    return bytes.fromhex(MODBUS[name][key])


async def test_az_reads_unknown_unit_and_function_04() -> None:
    server, _ = await server_for("oriental-az", 100.0)
    try:
        for name in ("az_read_status", "az_read_feedback", "az_read_input_registers",
                     "az_unknown_unit"):  # fmt: skip
            assert await exchange(server.port, frame(name, "request")) == frame(name, "reply"), name
    finally:
        await server.stop()


async def test_az_direct_data_write_starts_the_move() -> None:
    server, clock = await server_for("oriental-az", 100.0)
    try:
        reply = await exchange(server.port, frame("az_move", "request"))
        assert reply == frame("az_move", "reply")
        motor = server.axes[1].axis.motor
        assert motor.command_deg(clock.now()) == MODBUS["az_move"]["target_deg"]
    finally:
        await server.stop()


async def test_stq_enable_status_and_position() -> None:
    server, _ = await server_for("applied-motion-stq", 2.0)
    try:
        for name in ("stq_enable", "stq_read_status", "stq_read_position"):
            assert await exchange(server.port, frame(name, "request")) == frame(name, "reply"), name
        assert server.axes[1].enabled
    finally:
        await server.stop()


async def test_tcp_gateway_answers_0b_for_an_unknown_unit() -> None:
    """Over Modbus TCP the arms sit behind a gateway: a unit id with no arm gets exception
    0Bh (gateway target device failed to respond), not pymodbus' 04h."""
    clock = SimClock(0)
    motor = SimMotor("arm", speed_deg_s=20, accel_deg_s2=40, soft_limits_deg=(-170, 170))
    wire = WireAxis(SimAxis("arm", motor, clock), load_stepper_profile("oriental-az"), 1000.0, 1)
    server = ModbusAxisServer([wire], port=0, transport="tcp")
    await server.start()
    try:
        request = bytes.fromhex("00 01 00 00 00 06 02 03 00 7E 00 02")
        reply = await exchange(server.port, request)
        assert reply == bytes.fromhex("00 01 00 00 00 03 02 83 0B")
    finally:
        await server.stop()


async def test_zgm_pty_answers_the_printed_request_byte_for_byte(tmp_path: Path) -> None:
    """Through the pseudo-terminal (``:``-terminated command, the profile's reply
    terminator): the manual's p. 16 example with isTemp 1 gives its printed return string."""
    from drivers.profiles import load_zgm_profile
    from sim.instruments import SimGlossmeter
    from sim.wire import ZgmPtyDevice
    from tests.sim.lobe import LobeModel

    case = ZGM["measure_with_temperature"]
    clock = SimClock(0)
    device = ZgmPtyDevice(SimGlossmeter(LobeModel(), clock), load_zgm_profile("zgm1120"),
                          tmp_path / "gloss", serial_number="401120999")  # fmt: skip
    device.protocol = ZgmProtocol(Scripted(gu(case)), "401120999")
    await device.start()
    try:
        fd = os.open(device.link_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            os.write(fd, case["request"].encode())
            data = b""
            loop = asyncio.get_running_loop()
            deadline = loop.time() + 5.0
            while not data.endswith(b"\r\n") and loop.time() < deadline:
                await asyncio.sleep(0.01)
                with contextlib.suppress(BlockingIOError):
                    data += os.read(fd, 256)
        finally:
            os.close(fd)
    finally:
        await device.stop()
    assert data == case["sim_reply"].encode() + b"\r\n"


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet=st.sampled_from(list("0123456789|: -xyA\x00")), max_size=40))
def test_zgm_interpreter_answers_any_line_without_raising(line: str) -> None:
    meter = ZgmProtocol(Scripted({20: 1.0, 60: 2.0, 85: 3.0}), "401120999")
    reply = asyncio.run(meter.handle(f"1| 401120999{line}"))
    assert reply is None or reply.startswith(("1| 401120999|", "56| 401120999|", "6| ",
                                              "28| ", "36| ", "48| ", "52| ", "72| "))  # fmt: skip
