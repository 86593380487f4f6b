"""StilSpectro over a pty with a scripted fake instrument; colour maths against colour's data."""

from __future__ import annotations

import asyncio
import os
import string
from typing import Any

import numpy as np
import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.base import (
    DeviceFault,
    DeviceTimeout,
    Disconnected,
    LimitError,
    ProtocolError,
    Spectrocolorimeter,
)
from drivers.profiles import load_stil_profile
from drivers.stil import (
    StilSpectro,
    match_reply,
    parse_measure_reply,
    spectrum_to_lab,
    spectrum_to_xyz,
)

PROFILE = load_stil_profile("stil-ruby")
SPECTRUM = [round(10.0 + 0.25 * i, 2) for i in range(81)]  # 380..780 nm, 5 nm
SPEC_LINE = "SPEC 380 5 81 " + ",".join(f"{v:g}" for v in SPECTRUM)


async def serve(pty: Any, replies: dict[bytes, bytes], log: list[bytes]) -> None:
    """Fake instrument: answer each CR-terminated command from ``replies``."""
    while True:
        command = await pty.read_until(b"\r")
        log.append(command)
        pty.send(replies.get(command, b"ERR 1 unknown command\r\n"))


REPLIES = {
    b"IDN?\r": b"STIL RUBY SN 12345 FW 2.1\r\n",
    b"EXP 10000\r": b"EXP=10000\r\n",
    b"EXP 250000\r": b"EXP=250000\r\n",
    b"EXP 600\r": b"EXP=601\r\n",
    b"MEAS\r": b"Y=12.3456\r\n" + SPEC_LINE.encode() + b"\r\n",
}


@pytest.fixture
async def spectro(pty_pair: Any) -> Any:
    log: list[bytes] = []
    task = asyncio.create_task(serve(pty_pair, REPLIES, log))
    dev = StilSpectro("spectro", port=pty_pair.path, timeout_s=2.0)
    await dev.connect()
    yield dev, log
    await dev.close()
    task.cancel()


async def test_connect_identifies_and_sets_exposure(spectro: Any) -> None:
    dev, log = spectro
    assert log == [b"IDN?\r", b"EXP 10000\r"]
    assert dev.ident == "STIL RUBY SN 12345 FW 2.1"
    assert dev.exposure_us == 10000
    assert isinstance(dev, Spectrocolorimeter)


async def test_measure_parses_luminance_and_spectrum(spectro: Any) -> None:
    dev, log = spectro
    reading = await dev.measure()
    # the measurement, then its fence: the exposure set again, whose echo closes the reply
    assert log[-2:] == [b"MEAS\r", b"EXP 10000\r"]
    assert reading.stale_lines == 0
    assert reading.luminance_pct == 12.3456
    assert reading.values == tuple(SPECTRUM)
    assert reading.wavelengths_nm == tuple(float(w) for w in range(380, 781, 5))
    assert reading.exposure_us == 10000


async def test_exposure_range_checked_before_sending(spectro: Any, pty_pair: Any) -> None:
    dev, log = spectro
    for bad in (499, 250001):
        with pytest.raises(LimitError, match=r"500\.\.250000 us"):
            await dev.set_exposure_us(bad)
    await dev.set_exposure_us(250000)
    assert log[2:] == [b"EXP 250000\r"]


async def test_wrong_exposure_echo_is_protocol_error(spectro: Any) -> None:
    dev, _ = spectro
    with pytest.raises(ProtocolError, match="confirmed 601 us"):
        await dev.set_exposure_us(600)


async def test_error_reply_is_device_fault(spectro: Any) -> None:
    dev, _ = spectro
    with pytest.raises(DeviceFault, match="unknown command") as info:
        await dev.set_exposure_us(700)  # not scripted: fake answers ERR 1
    assert info.value.code == 1


async def test_garbled_reply_is_protocol_error_with_quoted_line(pty_pair: Any) -> None:
    garbage = b"\x07Y:" + b"x" * 200 + b"\r\n"
    task = asyncio.create_task(serve(pty_pair, {b"IDN?\r": b"ok\r\n", b"EXP 10000\r": garbage}, []))
    dev = StilSpectro(port=pty_pair.path, timeout_s=2.0)
    with pytest.raises(ProtocolError) as info:
        await dev.connect()
    task.cancel()
    message = str(info.value)
    assert "'\\x07Y:xxx" in message and message.count("x") < 90 and "..." in message


async def test_no_reply_is_timeout(pty_pair: Any) -> None:
    dev = StilSpectro(port=pty_pair.path, timeout_s=0.05)
    with pytest.raises(DeviceTimeout, match=r"within 0\.05 s"):
        await dev.connect()
    assert os.read(pty_pair.fd, 100) == b"IDN?\r"


async def test_missing_port_is_disconnected_naming_it() -> None:
    dev = StilSpectro(port="/dev/goniolab-no-spectro")
    with pytest.raises(Disconnected, match="/dev/goniolab-no-spectro"):
        await dev.connect()


async def test_busy_port_is_disconnected_and_names_it(pty_pair: Any) -> None:
    with serial.Serial(pty_pair.path, exclusive=True):  # another program holds the port
        dev = StilSpectro(port=pty_pair.path, timeout_s=0.2)
        with pytest.raises(Disconnected, match=f"{pty_pair.path}.*port busy: another program"):
            await dev.connect()
    os.set_blocking(pty_pair.fd, False)
    with pytest.raises(BlockingIOError):  # nothing reached the instrument the other holds
        os.read(pty_pair.fd, 100)


def test_count_mismatch_is_protocol_error() -> None:
    with pytest.raises(ProtocolError, match="announces 3 values but carries 2"):
        parse_measure_reply(PROFILE, ["Y=1.0", "SPEC 380 5 3 1,2"])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.text(max_size=120), min_size=2, max_size=2))
def test_garbage_into_measure_parser_raises_only_protocol_errors(lines: list[str]) -> None:
    try:
        parse_measure_reply(PROFILE, lines)
    except DeviceFault:
        assert any(line.startswith("ERR ") for line in lines)  # a genuine error reply
    except ProtocolError:
        pass


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=120))
def test_garbage_into_every_reply_template(line: str) -> None:
    for template in (PROFILE.reply_identify, PROFILE.reply_set_exposure, *PROFILE.reply_measure):
        try:
            fields = match_reply(PROFILE, template, line)
        except DeviceFault as exc:
            assert line.startswith("ERR ") and isinstance(exc.code, int)
            continue
        except ProtocolError as exc:
            assert "does not match" in str(exc)
            continue
        names = {f for _, f, _, _ in string.Formatter().parse(template) if f}
        assert set(fields) == names  # every field of the template was captured


@settings(max_examples=100, deadline=None)
@given(
    st.floats(-1e6, 1e6, allow_nan=False),
    st.lists(st.floats(0, 200, allow_nan=False), min_size=1, max_size=90),
)
def test_measure_parser_round_trips_the_profile_templates(
    luminance: float, values: list[float]
) -> None:
    # format with the profile's own templates, as the simulator does
    lum_t, spec_t = PROFILE.reply_measure
    lines = [
        lum_t.format(luminance_pct=luminance),
        spec_t.format(
            start_nm=380, step_nm=5, count=len(values), values=",".join(repr(v) for v in values)
        ),
    ]
    lum, wl, vals = parse_measure_reply(PROFILE, lines)
    assert lum == pytest.approx(luminance, abs=5e-5)
    assert vals == tuple(values)
    assert wl[-1] == 380 + 5 * (len(values) - 1)


# ----------------------------------------------------------------- colour
def test_perfect_reflecting_diffuser_is_white() -> None:
    wl = np.arange(380.0, 781.0, 5.0)
    xyz = spectrum_to_xyz(wl, np.full_like(wl, 100.0))
    lab = spectrum_to_lab(wl, np.full_like(wl, 100.0))
    assert xyz[1] == pytest.approx(100.0, abs=1e-9)  # Y normalised to the white
    # CIE 1964 10 deg D65 white point x = 0.31382, y = 0.33100 (CIE 15:2004 table T.3):
    # Xn = 100 x / y = 94.811, Zn = 100 (1 - x - y) / y = 107.304
    assert xyz[0] == pytest.approx(94.811, abs=0.01)
    assert xyz[2] == pytest.approx(107.304, abs=0.03)
    assert lab[0] == pytest.approx(100.0, abs=1e-9)
    assert lab[1] == pytest.approx(0.0, abs=0.02)
    assert lab[2] == pytest.approx(0.0, abs=0.02)


# colour-science's own test sample (colour/colorimetry/tests/test_tristimulus_values.py,
# SD_SAMPLE, 340..830 nm by 5 nm) and its expected XYZ under illuminant C, CIE 1964 10 deg,
# plain integration: [10.77002699, 9.44876636, 6.62415290].
SD_SAMPLE_400_720 = [
    0.0641, 0.0650, 0.0654, 0.0652, 0.0645, 0.0629, 0.0605, 0.0581, 0.0562, 0.0551,
    0.0543, 0.0539, 0.0537, 0.0538, 0.0541, 0.0547, 0.0559, 0.0578, 0.0603, 0.0629,
    0.0651, 0.0667, 0.0680, 0.0691, 0.0705, 0.0720, 0.0736, 0.0753, 0.0772, 0.0791,
    0.0809, 0.0833, 0.0870, 0.0924, 0.0990, 0.1061, 0.1128, 0.1190, 0.1251, 0.1308,
    0.1360, 0.1403, 0.1439, 0.1473, 0.1511, 0.1550, 0.1590, 0.1634, 0.1688, 0.1753,
    0.1828, 0.1909, 0.1996, 0.2088, 0.2187, 0.2291, 0.2397, 0.2505, 0.2618, 0.2733,
    0.2852,
]  # fmt: skip


def test_reference_sample_from_colour_test_data() -> None:
    wl = np.arange(340.0, 831.0, 5.0)
    r = np.zeros_like(wl)
    r[12 : 12 + len(SD_SAMPLE_400_720)] = SD_SAMPLE_400_720
    xyz = spectrum_to_xyz(wl, 100.0 * r, illuminant="C", method="Integration")
    np.testing.assert_allclose(xyz, [10.77002699, 9.44876636, 6.62415290], atol=1e-7)


def test_colour_input_errors() -> None:
    with pytest.raises(ValueError, match="matching 1-D"):
        spectrum_to_xyz([400.0, 410.0], [1.0])
    with pytest.raises(ValueError, match="unknown illuminant"):
        spectrum_to_xyz([400.0, 410.0], [1.0, 2.0], illuminant="D99")
