"""Glossmeters: the Zehntner ZGM1120 protocol and line-printing meters.

ZGM1120 (ZGM 1120 Technical Manual rev 3.0, 2021, section 6; docs/PROTOCOLS.md)
-------------------------------------------------------------------------------
ASCII components separated by ``|``; a command ends with ``:``, a return string does not
(it ends with the profile's ``reply_terminator``, unconfirmed ``\\r\\n``). Every string is
``<opcode>| <serial>|<tid>[|<value>...]``: the serial number with one leading blank and a
2-character transaction id that the return string mirrors (p. 12-13). Measure (opcode 1,
MeasureValue(SerialNo, TID, AngleBinary, Count, isTemp), p. 16)::

    > 1| 401120999|xy|5|1|0:          angle mask (bit0 20, bit1 60, bit2 85), count 1, isTemp
    < 1| 401120999|xy|958|94|-1|-1|993|78|1|25

Per angle 20/60/85 the return string carries the value in dGU (0.1 GU) and the offset
(raw A/D zero-current value); ``-1``/``-1`` = not measured; an overflow is ``-2`` in the
OFFSET field (p. 16), whatever the value field holds. Then the count (always 1) and the
temperature in deg C, which is ``0`` when isTemp = 0 (p. 16): the reading's temperature is
``None`` unless the command asked for it.

Other commands (p. 12, 18, 20, 22): 28 GetIsOnStandard -> flag 1/0; 36 MeasureTemp ->
integer deg C; 48 / 52 ControlLEDOn / Off with their LED argument (the profile's
``led_argument``: its encoding is unconfirmed) -> header echo (inferred); 64 Reset_Device,
no return string; 72 Calibrate(Angle, Cal2Standard, Cal2StandValue) of ONE angle ->
deviation in ppm (``72| 401120999|xy|5361``); 6 AutoSend with a 3-character cluster:
enable (1/0), AngleBinary, isTemp (3rd character inferred), e.g. ``6| SN|qq|170:``; each
press of the meter's button then pushes a measure return string (opcode 6, or 1: the
pushed opcode is unconfirmed) with the AutoSend transaction id. A failed command is
answered by an error string ``56| SN|tid|<ErrorCode>|<ErrorDetails>`` (p. 20, 24; field
layout inferred), raised as :class:`~drivers.base.DeviceFault`.

Transaction ids run ``aa, ab, ..., az, ba, ..., zz`` and wrap (configurable first id).

Line-printing meters (BYK micro-tri-gloss, Rhopoint, Elcometer)
----------------------------------------------------------------
One line per reading, parsed with the ``pattern`` regex of a ``kind = "line-gloss"``
profile (named groups ``g20``/``g60``/``g85``/``temperature``).

Any line that does not parse raises :class:`~drivers.base.ProtocolError` quoting the raw
line (truncated to 80 characters).
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import re
import string
import time
from collections.abc import AsyncGenerator, Sequence

from drivers.base import (
    GLOSS_ANGLES_DEG,
    DeviceFault,
    DeviceTimeout,
    Glossmeter,
    GlossReading,
    ProtocolError,
)
from drivers.profiles import (
    LineGlossProfile,
    SerialSettings,
    ZgmProfile,
    load_line_gloss_profile,
    load_zgm_profile,
)
from drivers.serial_io import LineTransport, quote

__all__ = [
    "LineGlossmeter",
    "Zgm1120",
    "angle_mask",
    "open_glossmeter",
    "parse_gloss_line",
    "parse_zgm_measure",
]

# ZGM 1120 opcodes (Technical Manual rev 3.0, p. 12; docs/PROTOCOLS.md)
OP_MEASURE = 1
OP_AUTOSEND = 6
OP_IS_ON_STANDARD = 28
OP_MEASURE_TEMP = 36
OP_LED_ON = 48
OP_LED_OFF = 52
OP_ERROR = 56
OP_RESET = 64
OP_CALIBRATE = 72

_ANGLE_BITS = {20: 0, 60: 1, 85: 2}
_TID_CHARS = string.ascii_lowercase
_INT = re.compile(r"-?[0-9]{1,9}")
#: Field values of the measure return string (p. 16).
_NOT_MEASURED = -1
_OVERFLOW = -2


def angle_mask(angles_deg: Sequence[int]) -> int:
    """ZGM1120 AngleBinary: bit0 20 deg, bit1 60 deg, bit2 85 deg (manual p. 15)."""
    if not angles_deg:
        raise ValueError("at least one gloss angle is needed")
    mask = 0
    for angle in angles_deg:
        if angle not in _ANGLE_BITS:
            raise ValueError(f"gloss angle {angle} deg is not one of 20, 60, 85")
        mask |= 1 << _ANGLE_BITS[angle]
    return mask


def _int_field(text: str, what: str, line: str, device: str) -> int:
    stripped = text.strip()
    if _INT.fullmatch(stripped) is None:
        raise ProtocolError(f"bad {what} {text!r} in reply {quote(line)}", device=device)
    return int(stripped)


def _header(line: str, opcodes: Sequence[int], serial: str, tid: str, device: str) -> list[str]:
    """Split a reply and check the echoed opcode, serial number and transaction id.

    Raises
    ------
    DeviceFault
        The meter answered with an error string (opcode 56) for this transaction.
    ProtocolError
        Too few fields, another opcode, serial number or transaction id.
    """
    fields = line.split("|")
    if len(fields) < 3:
        raise ProtocolError(f"reply {quote(line)} has fewer than 3 '|' fields", device=device)
    opcode = _int_field(fields[0], "opcode", line, device)
    if fields[1].strip() != serial:
        raise ProtocolError(
            f"reply {quote(line)} is from serial number {fields[1].strip()!r}, expected {serial!r}",
            device=device,
        )
    if fields[2] != tid:
        raise ProtocolError(
            f"transaction id mismatch: sent {tid!r}, reply {quote(line)} carries {fields[2]!r}",
            device=device,
        )
    if opcode == OP_ERROR and OP_ERROR not in opcodes:
        detail = "|".join(fields[3:])
        code = _int_field(fields[3], "error code", line, device) if len(fields) > 3 else None
        raise DeviceFault(
            f"the glossmeter refused the command: error string {quote(line)} ({detail})",
            device=device,
            code=code,
        )
    if opcode not in opcodes:
        raise ProtocolError(
            f"reply {quote(line)} is for opcode {opcode}, expected {' or '.join(map(str, opcodes))}",
            device=device,
        )
    return fields[3:]


def parse_zgm_measure(
    line: str,
    *,
    serial: str,
    tid: str,
    with_temperature: bool,
    opcodes: Sequence[int] = (OP_MEASURE,),
    device: str = "glossmeter",
) -> GlossReading:
    """Parse a ZGM1120 measure return string (or AutoSend push) into a :class:`GlossReading`.

    Parameters
    ----------
    with_temperature
        The command's isTemp flag: with 0 the meter puts ``0`` in the temperature field
        (manual p. 16), so the reading's temperature is ``None``.

    Raises
    ------
    ProtocolError
        Wrong field count, non-numeric field, a negative value that is not ``-1`` (not
        measured) without the overflow mark ``-2`` in the offset field, count not 1,
        wrong opcode / serial / transaction id.
    DeviceFault
        The meter sent its error string instead.
    """
    payload = _header(line, opcodes, serial, tid, device)
    if len(payload) != 8:
        raise ProtocolError(
            f"measure reply {quote(line)} has {len(payload)} payload fields, expected 8 "
            "(value and offset for 20/60/85, count, temperature)",
            device=device,
        )
    values: dict[int, float | None] = {}
    overflow: list[int] = []
    for k, angle in enumerate(GLOSS_ANGLES_DEG):
        raw = _int_field(payload[2 * k], f"{angle} deg value", line, device)
        offset = _int_field(payload[2 * k + 1], f"{angle} deg offset", line, device)
        if offset == _OVERFLOW:  # p. 16: "-2" in the offset field on overflow
            values[angle] = None
            overflow.append(angle)
        elif raw == _NOT_MEASURED:
            values[angle] = None
        elif raw < 0:
            raise ProtocolError(f"{angle} deg value {raw} in reply {quote(line)}", device=device)
        else:
            values[angle] = raw / 10.0
    count = _int_field(payload[6], "count", line, device)
    if count != 1:
        raise ProtocolError(f"count {count} in reply {quote(line)}, expected 1", device=device)
    temperature = _float_field(payload[7], "temperature", line, device)
    return GlossReading(
        values_gu=values,
        overflow_deg=tuple(overflow),
        temperature_c=temperature if with_temperature else None,
        timestamp=time.time(),
        raw=line,
    )


def _float_field(text: str, what: str, line: str, device: str) -> float:
    try:
        value = float(text.strip())
    except ValueError:
        raise ProtocolError(f"bad {what} {text!r} in reply {quote(line)}", device=device) from None
    if not math.isfinite(value):
        raise ProtocolError(f"non-finite {what} in reply {quote(line)}", device=device)
    return value


def _settings(settings: SerialSettings, baudrate: int | None) -> SerialSettings:
    return settings if baudrate is None else dataclasses.replace(settings, baudrate=baudrate)


class Zgm1120:
    """Zehntner ZGM1120 glossmeter (implements ``drivers.base.Glossmeter``).

    Parameters
    ----------
    name
        Configured instrument name (used in errors).
    port
        Serial device or pyserial URL.
    serial_number
        The meter's serial number (digits), sent in every command.
    profile
        A :class:`~drivers.profiles.ZgmProfile` or profile name / path.
    baudrate, timeout_s
        Override the profile's values.
    first_transaction_id
        First 2-letter transaction id (``"aa"``).
    """

    def __init__(
        self,
        name: str = "glossmeter",
        *,
        port: str,
        serial_number: str = "401120999",
        profile: ZgmProfile | str = "zgm1120",
        baudrate: int | None = None,
        timeout_s: float | None = None,
        first_transaction_id: str = "aa",
    ) -> None:
        if not serial_number.isdigit():
            raise ValueError(f"{name}: serial_number must be digits, got {serial_number!r}")
        if len(first_transaction_id) != 2 or any(c not in _TID_CHARS for c in first_transaction_id):
            raise ValueError(
                f"{name}: transaction id must be 2 lowercase letters, got {first_transaction_id!r}"
            )
        self.name = name
        self.serial_number = serial_number
        self.profile = profile if isinstance(profile, ZgmProfile) else load_zgm_profile(profile)
        self.timeout_s = self.profile.timeout_s if timeout_s is None else float(timeout_s)
        #: Lines with another transaction id dropped while waiting for a reply.
        self.stale_replies = 0
        self._tid_index = _TID_CHARS.index(first_transaction_id[0]) * 26 + _TID_CHARS.index(
            first_transaction_id[1]
        )
        self._io = LineTransport(port, _settings(self.profile.serial, baudrate), device=name)

    def next_transaction_id(self) -> str:
        """Return the next transaction id and advance (``aa`` ... ``zz``, then ``aa``)."""
        i = self._tid_index % (26 * 26)
        self._tid_index = i + 1
        return _TID_CHARS[i // 26] + _TID_CHARS[i % 26]

    def command(self, opcode: int, tid: str, *args: int | str) -> str:
        """The command string ``<opcode>| <serial>|<tid>[|arg...]:`` (manual p. 12)."""
        fields = [str(opcode), " " + self.serial_number, tid, *(str(a) for a in args)]
        return "|".join(fields) + ":"

    async def connect(self) -> None:
        """Open the serial port."""
        await self._io.open()

    async def close(self) -> None:
        """Close the serial port."""
        await self._io.close()

    async def _send(self, opcode: int, *args: int | str) -> str:
        tid = self.next_transaction_id()
        self._io.discard_input()
        await self._io.write(self.command(opcode, tid, *args))
        return tid

    async def _reply(self, tid: str, timeout_s: float | None = None) -> str:
        """The reply line carrying transaction id ``tid``, read within the timeout.

        Lines of this meter (its serial number) carrying another transaction id are a
        late answer to an earlier request, or an AutoSend push: they are dropped (counted
        in :attr:`stale_replies`) and the reading goes on, so one late reply never shifts
        the readings after it (issue 23: the mismatch used to fail every later request,
        each reading the answer to the one before). Anything else is returned as is for
        the caller's checks.
        """
        loop = asyncio.get_running_loop()
        budget = self.timeout_s if timeout_s is None else timeout_s
        deadline = loop.time() + budget
        while True:
            left = max(0.0, deadline - loop.time())
            try:
                line = await self._io.read_line(self.profile.reply_terminator, left)
            except DeviceTimeout:
                raise DeviceTimeout(
                    f"no reply on {self._io.port!r} within {budget:g} s", device=self.name
                ) from None
            fields = line.split("|")
            if len(fields) >= 3 and fields[1].strip() == self.serial_number and fields[2] != tid:
                self.stale_replies += 1
                continue
            return line

    async def _transact(
        self, opcode: int, *args: int | str, timeout_s: float | None = None
    ) -> tuple[str, list[str]]:
        tid = await self._send(opcode, *args)
        line = await self._reply(tid, timeout_s)
        return line, _header(line, (opcode,), self.serial_number, tid, self.name)

    async def measure(
        self, angles_deg: Sequence[int] = GLOSS_ANGLES_DEG, *, with_temperature: bool = False
    ) -> GlossReading:
        """MeasureValue (opcode 1, count 1) at the given geometries; with
        ``with_temperature`` the meter also measures its temperature (isTemp = 1)."""
        mask = angle_mask(angles_deg)
        tid = await self._send(OP_MEASURE, mask, 1, int(with_temperature))
        line = await self._reply(tid)
        return parse_zgm_measure(
            line,
            serial=self.serial_number,
            tid=tid,
            with_temperature=with_temperature,
            device=self.name,
        )

    async def is_on_standard(self) -> bool:
        """Opcode 28 GetIsOnStandard: whether the meter sits on its calibration tile."""
        line, payload = await self._transact(OP_IS_ON_STANDARD)
        if len(payload) != 1 or payload[0].strip() not in ("0", "1"):
            raise ProtocolError(f"expected 0 or 1 in reply {quote(line)}", device=self.name)
        return payload[0].strip() == "1"

    async def measure_temperature(self) -> float:
        """Opcode 36 MeasureTemp: instrument temperature in deg C (an integer, p. 18)."""
        line, payload = await self._transact(OP_MEASURE_TEMP)
        if len(payload) != 1:
            raise ProtocolError(
                f"expected one temperature in reply {quote(line)}", device=self.name
            )
        return float(_int_field(payload[0], "temperature", line, self.name))

    async def set_led(self, on: bool, led: int | None = None) -> None:
        """Opcode 48 ControlLEDOn / 52 ControlLEDOff with the LED argument (p. 12).

        ``led`` ``None`` sends the profile's ``led_argument`` (its encoding is unconfirmed).
        """
        argument = self.profile.led_argument if led is None else int(led)
        line, payload = await self._transact(OP_LED_ON if on else OP_LED_OFF, argument)
        if payload not in ([], [""]):
            raise ProtocolError(f"unexpected LED reply {quote(line)}", device=self.name)

    async def reset(self) -> None:
        """Opcode 64 Reset_Device: a hardware reset of the measuring head, which sends no
        return string (p. 20)."""
        await self._send(OP_RESET)

    async def calibrate(
        self,
        angle_deg: int,
        *,
        second_standard_dgu: int | None = None,
        timeout_s: float = 10.0,
    ) -> int:
        """Opcode 72 Calibrate ONE angle (p. 20-22); returns the deviation from the factory
        calibration in ppm (``5361`` = 0.5361 %).

        Parameters
        ----------
        angle_deg
            20, 60 or 85 (sent as its AngleBinary bit: inferred, docs/PROTOCOLS.md).
        second_standard_dgu
            ``None``: calibrate on the supplied working standard (Cal2Standard 0,
            Cal2StandValue 0). Otherwise the value of a second standard in dGU (0.1 GU),
            Cal2Standard 1.

        Raises
        ------
        DeviceFault
            The meter answers with its error string (calibration refused).
        """
        angle = angle_mask([angle_deg])
        if second_standard_dgu is None:
            args: tuple[int, int, int] = (angle, 0, 0)
        else:
            if not 0 < second_standard_dgu <= 99999:
                raise ValueError(f"second_standard_dgu {second_standard_dgu} out of 1..99999")
            args = (angle, 1, int(second_standard_dgu))
        line, payload = await self._transact(OP_CALIBRATE, *args, timeout_s=timeout_s)
        if len(payload) != 1:
            raise ProtocolError(
                f"expected one deviation in ppm in reply {quote(line)}", device=self.name
            )
        return _int_field(payload[0], "ppm deviation", line, self.name)

    async def set_autosend(
        self,
        enabled: bool,
        angles_deg: Sequence[int] = GLOSS_ANGLES_DEG,
        *,
        with_temperature: bool = False,
    ) -> str:
        """Opcode 6 AutoSend with its 3-character cluster (enable, AngleBinary, isTemp);
        returns the transaction id the pushed readings carry."""
        cluster = f"{int(enabled)}{angle_mask(angles_deg)}{int(with_temperature)}"
        return await self._send(OP_AUTOSEND, cluster)

    async def readings(
        self, *, with_temperature: bool = False
    ) -> AsyncGenerator[GlossReading, None]:
        """Switch AutoSend on (all angles) and yield each pushed reading."""
        tid = await self.set_autosend(True, GLOSS_ANGLES_DEG, with_temperature=with_temperature)
        while True:
            line = await self._io.read_line(self.profile.reply_terminator, None)
            fields = line.split("|")
            if len(fields) == 3 and fields[2] == tid:
                continue  # a header-only acknowledgement of AutoSend (unconfirmed): skip it
            yield parse_zgm_measure(
                line,
                serial=self.serial_number,
                tid=tid,
                with_temperature=with_temperature,
                opcodes=(OP_AUTOSEND, OP_MEASURE),
                device=self.name,
            )


def _gloss_value(
    text: str, tokens: Sequence[str], what: str, line: str, device: str
) -> float | None:
    if text.strip() in tokens:
        return None
    return _float_field(text, what, line, device)


def parse_gloss_line(
    profile: LineGlossProfile, line: str, *, device: str = "glossmeter"
) -> GlossReading:
    """Parse one line of a line-printing meter with the profile's regex.

    Groups that did not take part in the match are "not measured"; a value equal to one of
    ``overflow_tokens`` is an overflow.

    Raises
    ------
    ProtocolError
        The line does not match the pattern or a value is not a number.
    """
    found = profile.pattern.match(line)
    if found is None:
        raise ProtocolError(
            f"line {quote(line)} does not match the {profile.name!r} pattern", device=device
        )
    groups = found.groupdict()
    values: dict[int, float | None] = {}
    overflow: list[int] = []
    for angle in GLOSS_ANGLES_DEG:
        text = groups.get(f"g{angle}")
        if text is None:
            values[angle] = None
            continue
        value = _gloss_value(text, profile.overflow_tokens, f"{angle} deg gloss", line, device)
        if value is None:
            overflow.append(angle)
        values[angle] = value
    temp_text = groups.get("temperature")
    temperature = (
        None if temp_text is None else _float_field(temp_text, "temperature", line, device)
    )
    return GlossReading(
        values_gu=values,
        overflow_deg=tuple(overflow),
        temperature_c=temperature,
        timestamp=time.time(),
        raw=line,
    )


class LineGlossmeter:
    """A glossmeter that prints one line per reading (implements ``drivers.base.Glossmeter``).

    ``measure`` sends the profile's ``trigger`` (if any) and parses the next line; the meter
    decides which geometries it reports, so ``angles_deg`` only selects which values are
    kept (the others are set to ``None``).
    """

    def __init__(
        self,
        name: str = "glossmeter",
        *,
        port: str,
        profile: LineGlossProfile | str = "line-gloss-example",
        baudrate: int | None = None,
        timeout_s: float | None = None,
    ) -> None:
        self.name = name
        self.profile = (
            profile if isinstance(profile, LineGlossProfile) else load_line_gloss_profile(profile)
        )
        self.timeout_s = self.profile.timeout_s if timeout_s is None else float(timeout_s)
        self._io = LineTransport(
            port,
            _settings(self.profile.serial, baudrate),
            device=name,
            encoding=self.profile.encoding,
        )

    async def connect(self) -> None:
        """Open the serial port."""
        await self._io.open()

    async def close(self) -> None:
        """Close the serial port."""
        await self._io.close()

    async def measure(self, angles_deg: Sequence[int] = GLOSS_ANGLES_DEG) -> GlossReading:
        """Trigger (if the profile has a trigger) and parse the next line."""
        angle_mask(angles_deg)  # validates the angles
        self._io.discard_input()
        if self.profile.trigger:
            await self._io.write(self.profile.trigger + self.profile.line_terminator)
        line = await self._io.read_line(self.profile.line_terminator, self.timeout_s)
        reading = parse_gloss_line(self.profile, line, device=self.name)
        kept = {a: (v if a in angles_deg else None) for a, v in reading.values_gu.items()}
        return dataclasses.replace(
            reading,
            values_gu=kept,
            overflow_deg=tuple(a for a in reading.overflow_deg if a in angles_deg),
        )

    async def readings(self) -> AsyncGenerator[GlossReading, None]:
        """Yield every line the meter prints, parsed."""
        while True:
            line = await self._io.read_line(self.profile.line_terminator, None)
            yield parse_gloss_line(self.profile, line, device=self.name)


def open_glossmeter(
    port: str,
    *,
    protocol: str = "zgm1120",
    profile: str | None = None,
    serial_number: str = "401120999",
    baudrate: int | None = None,
    timeout_s: float | None = None,
    name: str = "glossmeter",
) -> Glossmeter:
    """Build (not connect) the glossmeter driver of ``protocol``, a name in
    :data:`drivers.protocols.GLOSSMETERS` (``"zgm1120"``, ``"line"``, or one registered
    since).

    ``profile`` ``None`` selects the protocol's built-in profile (``zgm1120`` /
    ``line-gloss-example``). ``serial_number`` goes to the drivers whose entry lists it
    among its ``options`` (the ZGM1120).

    Raises
    ------
    ValueError
        Unknown protocol (the message lists the known ones).
    """
    from drivers.protocols import GLOSSMETERS

    try:
        entry = GLOSSMETERS[protocol]
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    options = {"serial_number": serial_number}
    driver: Glossmeter = entry.driver_class()(
        name,
        port=port,
        profile=profile or entry.default_profile,
        baudrate=baudrate,
        timeout_s=timeout_s,
        **{key: options[key] for key in entry.options},
    )
    return driver
