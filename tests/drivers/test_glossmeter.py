"""ZGM1120 and line-printing glossmeters: exact command bytes, replies to exact values."""

from __future__ import annotations

import asyncio
import dataclasses
import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.base import (
    DeviceFault,
    DeviceTimeout,
    Disconnected,
    Glossmeter,
    GlossReading,
    ProtocolError,
)
from drivers.glossmeter import (
    LineGlossmeter,
    Zgm1120,
    angle_mask,
    open_glossmeter,
    parse_gloss_line,
    parse_zgm_measure,
)
from drivers.profiles import load_line_gloss_profile

LINE_PROFILE = load_line_gloss_profile("line-gloss-example")
MANUAL_REPLY = "1| 401120999|xy|958|94|-1|-1|993|78|1|25"


async def exchange(pty: Any, reply: bytes) -> bytes:
    """Fake meter: read one ':'-terminated command, answer ``reply``."""
    command = await pty.read_until(b":")
    pty.send(reply)
    return command


def test_manual_example_reply_parses_to_exact_values() -> None:
    reading = parse_zgm_measure(MANUAL_REPLY, serial="401120999", tid="xy", with_temperature=True)
    assert reading.values_gu == {20: 95.8, 60: None, 85: 99.3}
    assert reading.overflow_deg == ()
    assert reading.temperature_c == 25.0
    assert reading.raw == MANUAL_REPLY


def test_temperature_only_when_the_command_asked_for_it() -> None:
    """Manual p. 16: with isTemp = 0 the meter returns "0" in the temperature field, which
    is no temperature (the old driver logged it as 0 deg C)."""
    line = "1| 401120999|xy|958|94|-1|-1|993|78|1|0"
    assert (
        parse_zgm_measure(line, serial="401120999", tid="xy", with_temperature=False).temperature_c
        is None
    )
    assert (
        parse_zgm_measure(line, serial="401120999", tid="xy", with_temperature=True).temperature_c
        == 0.0
    )


def test_overflow_is_read_from_the_offset_field() -> None:
    """Manual p. 16: "-2" in the OFFSET field marks an overflow, whatever the value says."""
    reading = parse_zgm_measure(
        "1| 401120999|ab|2150|-2|35|12|-1|-1|1|0", serial="401120999", tid="ab",
        with_temperature=False,
    )  # fmt: skip
    assert reading.values_gu == {20: None, 60: 3.5, 85: None}
    assert reading.overflow_deg == (20,)
    with pytest.raises(ProtocolError, match="20 deg value -2"):  # -2 in the value field only
        parse_zgm_measure("1| 401120999|ab|-2|4095|35|12|-1|-1|1|0", serial="401120999",
                          tid="ab", with_temperature=False)  # fmt: skip


def test_error_string_is_a_device_fault_with_its_code() -> None:
    with pytest.raises(DeviceFault, match="refused") as info:
        parse_zgm_measure("56| 401120999|xy|1|angle not available", serial="401120999",
                          tid="xy", with_temperature=False)  # fmt: skip
    assert info.value.code == 1


def test_angle_mask_bits() -> None:
    assert angle_mask([20]) == 1 and angle_mask([60]) == 2 and angle_mask([85]) == 4
    assert angle_mask([20, 85]) == 5 and angle_mask([20, 60, 85]) == 7
    with pytest.raises(ValueError, match="45 deg"):
        angle_mask([45])


async def test_measure_sends_manual_example_bytes(pty_pair: Any) -> None:
    meter = Zgm1120(port=pty_pair.path, serial_number="401120999", first_transaction_id="xy")
    assert isinstance(meter, Glossmeter)
    await meter.connect()
    fake = asyncio.create_task(exchange(pty_pair, MANUAL_REPLY.encode() + b"\r\n"))
    reading = await meter.measure([20, 85])
    await meter.close()
    assert await fake == b"1| 401120999|xy|5|1|0:"
    assert reading.values_gu[20] == 95.8 and reading.values_gu[85] == 99.3
    assert reading.temperature_c is None  # isTemp = 0 was sent


async def test_measure_with_temperature_sends_istemp_1(pty_pair: Any) -> None:
    meter = Zgm1120(port=pty_pair.path, serial_number="401120999", first_transaction_id="xy")
    await meter.connect()
    fake = asyncio.create_task(exchange(pty_pair, MANUAL_REPLY.encode() + b"\r\n"))
    reading = await meter.measure([20, 85], with_temperature=True)
    await meter.close()
    assert await fake == b"1| 401120999|xy|5|1|1:"
    assert reading.temperature_c == 25.0


async def test_transaction_ids_advance_and_a_stale_reply_is_skipped(pty_pair: Any) -> None:
    # the transaction id is what ties a reply to its request (manual p. 12-13): a line
    # with another id is a late answer to an earlier request and is skipped, counted; the
    # reading is the one carrying this request's id (a mismatch used to fail the request,
    # and with a late meter every later one, each reading the answer to the one before)
    meter = Zgm1120(port=pty_pair.path, first_transaction_id="az", timeout_s=0.3)
    await meter.connect()
    fake = asyncio.create_task(exchange(pty_pair, b"1| 401120999|az|958|94|-1|-1|993|78|1|25\r\n"))
    await meter.measure()
    assert await fake == b"1| 401120999|az|7|1|0:"
    late_then_own = (
        b"1| 401120999|az|111|94|-1|-1|111|78|1|25\r\n"  # the late answer to 'az'
        b"1| 401120999|ba|958|94|-1|-1|993|78|1|25\r\n"
    )
    fake = asyncio.create_task(exchange(pty_pair, late_then_own))
    reading = await meter.measure()
    assert await fake == b"1| 401120999|ba|7|1|0:"
    assert reading.values_gu[20] == 95.8 and meter.stale_replies == 1
    # only a stale line: this request got no answer of its own
    fake = asyncio.create_task(exchange(pty_pair, b"1| 401120999|xx|958|94|-1|-1|993|78|1|25\r\n"))
    with pytest.raises(DeviceTimeout):
        await meter.measure()
    assert await fake == b"1| 401120999|bb|7|1|0:"
    assert meter.stale_replies == 2
    await meter.close()


@pytest.mark.parametrize(
    ("method", "args", "command", "reply", "expected"),
    [
        ("is_on_standard", (), b"28| 401120999|aa:", b"28| 401120999|aa|1", True),
        ("measure_temperature", (), b"36| 401120999|aa:", b"36| 401120999|aa|23", 23.0),
        # ControlLEDOn/Off(SerialNo, TID, LED): the LED argument (profile led_argument = 1)
        ("set_led", (True,), b"48| 401120999|aa|1:", b"48| 401120999|aa", None),
        ("set_led", (False, 4), b"52| 401120999|aa|4:", b"52| 401120999|aa", None),
        # Calibrate(SerialNo, TID, Angle, Cal2Standard, Cal2StandValue), reply p. 22
        ("calibrate", (60,), b"72| 401120999|aa|2|0|0:", b"72| 401120999|aa|5361", 5361),
        ("calibrate", (85,), b"72| 401120999|aa|4|0|0:", b"72| 401120999|aa|-120", -120),
    ],
)
async def test_other_opcodes(
    pty_pair: Any, method: str, args: tuple[Any, ...], command: bytes, reply: bytes, expected: Any
) -> None:
    meter = Zgm1120(port=pty_pair.path)
    await meter.connect()
    fake = asyncio.create_task(exchange(pty_pair, reply + b"\r\n"))
    result = await getattr(meter, method)(*args)
    await meter.close()
    assert await fake == command
    assert result == expected


async def test_calibrate_on_a_second_standard_sends_its_value(pty_pair: Any) -> None:
    meter = Zgm1120(port=pty_pair.path)
    await meter.connect()
    fake = asyncio.create_task(exchange(pty_pair, b"72| 401120999|aa|88\r\n"))
    assert await meter.calibrate(20, second_standard_dgu=934) == 88
    await meter.close()
    assert await fake == b"72| 401120999|aa|1|1|934:"


async def test_reset_expects_no_return_string(pty_pair: Any) -> None:
    """Manual p. 20: Reset_Device has no return string; the driver must not wait for one."""
    meter = Zgm1120(port=pty_pair.path, timeout_s=0.2)
    await meter.connect()
    await asyncio.wait_for(meter.reset(), 0.1)
    assert await pty_pair.read_until(b":") == b"64| 401120999|aa:"
    await meter.close()


async def test_a_refused_command_raises_device_fault(pty_pair: Any) -> None:
    meter = Zgm1120(port=pty_pair.path)
    await meter.connect()
    fake = asyncio.create_task(exchange(pty_pair, b"56| 401120999|aa|72|not on standard\r\n"))
    with pytest.raises(DeviceFault, match="not on standard") as info:
        await meter.calibrate(60)
    await meter.close()
    assert info.value.code == 72 and await fake == b"72| 401120999|aa|2|0|0:"


async def test_autosend_yields_pushed_readings(pty_pair: Any) -> None:
    meter = Zgm1120(port=pty_pair.path, first_transaction_id="qq")
    await meter.connect()
    stream = meter.readings()

    async def next_reading() -> GlossReading:
        return await anext(stream)

    first = asyncio.create_task(next_reading())
    command = await pty_pair.read_until(b":")
    # AutoSendCluster (p. 22): enable 1, AngleBinary 7, isTemp 0
    assert command == b"6| 401120999|qq|170:"
    pty_pair.send(b"6| 401120999|qq|120|5|450|40|801|77|1|0\r\n")
    pty_pair.send(b"6| 401120999|qq|121|5|451|40|1873|-2|1|0\r\n")
    a = await first
    b = await stream.__anext__()
    await stream.aclose()
    await meter.close()
    assert a.values_gu == {20: 12.0, 60: 45.0, 85: 80.1} and a.temperature_c is None
    assert b.values_gu == {20: 12.1, 60: 45.1, 85: None} and b.overflow_deg == (85,)


async def test_missing_port_is_disconnected_naming_it() -> None:
    meter = Zgm1120(port="/dev/goniolab-no-gloss")
    with pytest.raises(Disconnected, match="/dev/goniolab-no-gloss"):
        await meter.connect()


@pytest.mark.parametrize(
    ("line", "text"),
    [
        ("1| 401120999|xy|958|94|-1|-1|993|78|1", "7 payload fields, expected 8"),
        ("1| 401120999|xy|9x8|94|-1|-1|993|78|1|25", "bad 20 deg value '9x8'"),
        ("2| 401120999|xy|958|94|-1|-1|993|78|1|25", "opcode 2, expected 1"),
        ("1| 401120998|xy|958|94|-1|-1|993|78|1|25", "serial number '401120998'"),
        ("1| 401120999|xy|958|94|-1|-1|993|78|2|25", "count 2"),
        ("garbage" * 30, "fewer than 3"),
    ],
)
def test_garbled_replies(line: str, text: str) -> None:
    with pytest.raises(ProtocolError, match=text) as info:
        parse_zgm_measure(line, serial="401120999", tid="xy", with_temperature=True)
    quoted = repr(line) if len(repr(line)) <= 80 else repr(line)[:77] + "..."
    assert quoted in str(info.value)


# ------------------------------------------------------------------ line meters
def test_line_meter_parses_example_lines() -> None:
    r = parse_gloss_line(LINE_PROFILE, "20: 85.3 GU  60: 92.1 GU  85: 98.7 GU  T=23.5C")
    assert r.values_gu == {20: 85.3, 60: 92.1, 85: 98.7} and r.temperature_c == 23.5
    r = parse_gloss_line(LINE_PROFILE, "20: OVER GU  60: 92.1 GU  85: 98.7 GU")
    assert r.values_gu == {20: None, 60: 92.1, 85: 98.7}
    assert r.overflow_deg == (20,) and r.temperature_c is None


def test_line_meter_garbled_value_quotes_line() -> None:
    with pytest.raises(ProtocolError, match=r"bad 60 deg gloss 'x1'.*'20: 1 GU  60: x1 GU"):
        parse_gloss_line(LINE_PROFILE, "20: 1 GU  60: x1 GU  85: 2 GU")
    with pytest.raises(ProtocolError, match="does not match the 'line-gloss-example' pattern"):
        parse_gloss_line(LINE_PROFILE, "hello")


async def test_line_meter_trigger_and_pushed_lines(pty_pair: Any) -> None:
    triggered = dataclasses.replace(LINE_PROFILE, trigger="M")
    meter = LineGlossmeter(port=pty_pair.path, profile=triggered)
    await meter.connect()
    pending = asyncio.create_task(meter.measure([60]))
    assert await pty_pair.read_until(b"\r\n") == b"M\r\n"
    pty_pair.send(b"20: 85.3 GU  60: 92.1 GU  85: 98.7 GU\r\n")
    reading = await pending
    assert reading.values_gu == {20: None, 60: 92.1, 85: None}
    pty_pair.send(b"20: 1.5 GU  60: 2.5 GU  85: --- GU  T=-3C\r\n")
    pushed = await anext(aiter(meter.readings()))
    await meter.close()
    assert pushed.values_gu == {20: 1.5, 60: 2.5, 85: None}
    assert pushed.overflow_deg == (85,) and pushed.temperature_c == -3.0


def assert_sane(reading: GlossReading) -> None:
    """A reading that parsed: the three geometries, each a finite GU value or None."""
    assert set(reading.values_gu) == {20, 60, 85}
    for value in reading.values_gu.values():
        assert value is None or math.isfinite(value)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=200))
def test_garbage_into_gloss_parsers_raises_only_protocol_error(line: str) -> None:
    for parse in (
        lambda: parse_zgm_measure(line, serial="401120999", tid="xy", with_temperature=True),
        lambda: parse_gloss_line(LINE_PROFILE, line),
    ):
        try:
            reading = parse()
        except ProtocolError:
            continue
        assert_sane(reading)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.sampled_from(["1", " 401120999", "xy", "-1", "-2", "958", "25", "", "x", "1e3"]),
        max_size=14,
    )
)
def test_near_miss_zgm_replies_raise_only_protocol_error(fields: list[str]) -> None:
    try:
        reading = parse_zgm_measure(
            "|".join(fields), serial="401120999", tid="xy", with_temperature=False
        )
    except ProtocolError:
        return
    assert_sane(reading)


def test_open_glossmeter_picks_driver_and_profile() -> None:
    zgm = open_glossmeter("/dev/x", serial_number="123", baudrate=19200)
    assert isinstance(zgm, Zgm1120) and zgm.command(1, "ab", 7, 1, 0) == "1| 123|ab|7|1|0:"
    line = open_glossmeter("/dev/x", protocol="line", timeout_s=0.5)
    assert isinstance(line, LineGlossmeter) and line.profile.name == "line-gloss-example"
    assert line.timeout_s == 0.5
    with pytest.raises(ValueError, match="unknown glossmeter protocol 'byk'"):
        open_glossmeter("/dev/x", protocol="byk")
