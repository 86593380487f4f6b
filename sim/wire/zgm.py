"""The simulated Zehntner ZGM 1120's command interpreter, written from the manual.

Source: ZGM 1120 Glossmeter Technical Manual rev 3.0 (18 May 2021), section 6, printed
pp. 12-24; every fact with its page and confidence mark in docs/PROTOCOLS.md. This module
parses command strings and formats return strings on its own: it does not import
``drivers.glossmeter`` (a test checks it), so the driver and the simulator can disagree and
the golden frames of ``tests/golden/frames.toml`` catch the one that is wrong.

What the meter does (confirmed unless marked):

* a command string is ``<op>|<blank><serial>|<TID>[|<arg>...]`` ended by ``:``; a command
  for another serial number is ignored (RS-232 multi-drop; the pty device drops it);
* ``1`` MeasureValue(AngleBinary, Count, isTemp): per angle 20/60/85 the value in dGU and
  the offset (raw A/D zero-current value), ``-1|-1`` when not measured, ``-2`` in the
  offset field on overflow (the value field then carries :data:`OVERFLOW_VALUE_DGU`: the
  manual does not say what it holds, unconfirmed); then count ``1`` and the temperature,
  ``0`` when isTemp = 0;
* ``28`` GetIsOnStandard -> flag; ``36`` MeasureTemp -> integer deg C (opcode echo
  inferred from the p. 16 / p. 22 examples);
* ``48`` / ``52`` ControlLEDOn / Off(LED) -> header echo (inferred); without the LED
  argument -> error string;
* ``64`` Reset_Device: no return string; AutoSend is switched off;
* ``72`` Calibrate(Angle, Cal2Standard, Cal2StandValue) -> deviation in ppm; missing or
  bad arguments -> error string;
* ``6`` AutoSend(AutoSendCluster): 3 characters, enable / AngleBinary / isTemp (3rd
  character inferred); no acknowledgement (unconfirmed); while enabled, every press of the
  measure button pushes a measure return string with opcode ``6`` (unconfirmed) and the
  AutoSend TID; a malformed cluster -> error string;
* any other opcode, or wrong arguments -> the error string
  ``56|<blank><serial>|<TID>|<ErrorCode>|<ErrorDetails>`` with ErrorCode = the opcode that
  failed (field layout inferred from the Error() signature, p. 20 / 24).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

__all__ = ["OVERFLOW_VALUE_DGU", "AutoSend", "GlossSource", "ZgmProtocol", "split_command"]

#: Angles A1, A2, A3 of a three-angle meter (p. 15) and their AngleBinary bits.
_ANGLES = (20, 60, 85)
#: What the value field holds on an overflow: the manual does not say (unconfirmed); the
#: simulator writes a plausible number, so a driver that reads the overflow from the value
#: field instead of the offset field (p. 16) reports a reading and fails the tests.
OVERFLOW_VALUE_DGU = 9999


class GlossSource(Protocol):
    """What the interpreter needs from a simulated glossmeter (``sim.instruments.SimGlossmeter``)."""

    async def read_values_gu(
        self, angles_deg: Sequence[int]
    ) -> tuple[dict[int, float | None], tuple[int, ...]]:
        """GU per angle (``None`` not measured) and the angles that overflowed."""
        ...

    def current_temperature_c(self) -> float:
        """The instrument's temperature in deg C."""
        ...

    def calibrate_ppm(self, angle_deg: int | None = None) -> int:
        """Calibrate ``angle_deg`` on the standard; the deviation from the factory
        calibration in ppm."""
        ...


@dataclass(frozen=True)
class AutoSend:
    """AutoSend state set by opcode 6: the TID the pushes carry, angles, isTemp."""

    tid: str
    mask: int
    with_temperature: bool


def split_command(text: str) -> tuple[str, str, str, list[str]] | None:
    """``(opcode, serial, tid, args)`` of a command string without its ``:``, or ``None``
    when it has fewer than 3 components or the serial lacks its leading blank."""
    parts = text.split("|")
    if len(parts) < 3 or not parts[1].startswith(" "):
        return None
    return parts[0], parts[1][1:], parts[2], parts[3:]


def _small_int(text: str, lo: int, hi: int) -> int | None:
    if not text.isdigit() or len(text) > 6:
        return None
    value = int(text)
    return value if lo <= value <= hi else None


class ZgmProtocol:
    """The ZGM 1120 command interpreter of one simulated meter.

    Parameters
    ----------
    gloss
        The reading source (values, temperature, calibration).
    serial_number
        The meter's 9-digit serial number (without the leading blank).
    offsets_adc
        The zero-current A/D offset reported per angle 20/60/85. The default is the
        manual's p. 24 example (94, 91, 78), so a reading of 95.8 / 98.4 / 99.3 GU gives
        its printed return string byte for byte.
    on_standard
        What GetIsOnStandard reports.
    """

    def __init__(
        self,
        gloss: GlossSource,
        serial_number: str,
        *,
        offsets_adc: tuple[int, int, int] = (94, 91, 78),
        on_standard: bool = False,
    ) -> None:
        self.gloss = gloss
        self.serial_number = serial_number.strip()
        self.offsets_adc = offsets_adc
        self.on_standard = on_standard
        self.autosend: AutoSend | None = None
        self.leds_on: set[int] = set()
        self.resets = 0

    # ------------------------------------------------------------------ framing
    def _string(self, opcode: str, tid: str, *values: object) -> str:
        return "|".join([opcode, f" {self.serial_number}", tid, *(str(v) for v in values)])

    def error(self, tid: str, code: str, details: str) -> str:
        """The error string sent instead of a return string (p. 20, 24)."""
        return self._string("56", tid, code, details)

    def addressed(self, text: str) -> bool:
        """The command string is for this meter (else a real meter keeps quiet)."""
        parts = split_command(text)
        return parts is not None and parts[1] == self.serial_number

    # ------------------------------------------------------------------ replies
    async def measure_string(self, opcode: str, tid: str, mask: int, with_temperature: bool) -> str:
        """The measure return string (p. 16) for AngleBinary ``mask``."""
        angles = [a for bit, a in enumerate(_ANGLES) if mask >> bit & 1]
        values, overflow = await self.gloss.read_values_gu(angles)
        fields: list[object] = []
        for angle, offset in zip(_ANGLES, self.offsets_adc, strict=True):
            value = values.get(angle)
            if angle not in angles:
                fields += [-1, -1]
            elif angle in overflow:
                fields += [OVERFLOW_VALUE_DGU, -2]  # p. 16: -2 in the offset field
            elif value is None:
                fields += [-1, -1]
            else:
                fields += [round(value * 10), offset]
        temperature = round(self.gloss.current_temperature_c()) if with_temperature else 0
        return self._string(opcode, tid, *fields, 1, temperature)

    async def handle(self, text: str) -> str | None:
        """The return string (or error string) for one command string without its ``:``;
        ``None`` when the meter sends nothing (another serial number, Reset_Device,
        AutoSend)."""
        parts = split_command(text)
        if parts is None or parts[1] != self.serial_number:
            return None
        opcode, _serial, tid, args = parts
        if opcode in ("1", "01"):
            if len(args) != 3:
                return self.error(tid, opcode, "MeasureValue needs AngleBinary|Count|isTemp")
            mask, count, is_temp = (_small_int(a, 0, 7) for a in args)
            if not mask or count != 1 or is_temp not in (0, 1):
                return self.error(tid, opcode, "bad AngleBinary, Count or isTemp")
            return await self.measure_string("1", tid, mask, is_temp == 1)
        if opcode == "6":
            cluster = args[0] if len(args) == 1 else ""
            digits = [_small_int(c, 0, 7) for c in cluster]
            if (
                len(cluster) != 3
                or digits[0] not in (0, 1)
                or digits[2] not in (0, 1)
                or (digits[0] == 1 and not digits[1])
            ):
                return self.error(tid, opcode, "AutoSendCluster must be 3 characters")
            self.autosend = (
                AutoSend(tid, int(digits[1] or 0), digits[2] == 1) if digits[0] == 1 else None
            )
            return None
        if opcode == "28" and not args:
            return self._string(opcode, tid, int(self.on_standard))
        if opcode == "36" and not args:
            return self._string(opcode, tid, round(self.gloss.current_temperature_c()))
        if opcode in ("48", "52"):
            led = _small_int(args[0], 0, 99) if len(args) == 1 else None
            if led is None:
                return self.error(tid, opcode, "ControlLED needs its LED argument")
            if opcode == "48":
                self.leds_on.add(led)
            else:
                self.leds_on.discard(led)
            return self._string(opcode, tid)
        if opcode == "64" and not args:
            self.resets += 1
            self.autosend = None
            self.leds_on.clear()
            return None
        if opcode == "72":
            if len(args) != 3:
                return self.error(tid, opcode, "Calibrate needs Angle|Cal2Standard|Cal2StandValue")
            angle, second, value = (_small_int(a, 0, 99999) for a in args)
            if angle not in (1, 2, 4) or second not in (0, 1) or value is None:
                return self.error(tid, opcode, "bad Angle, Cal2Standard or Cal2StandValue")
            if second == 1 and value == 0:
                return self.error(tid, opcode, "second standard without its value")
            return self._string(
                opcode, tid, self.gloss.calibrate_ppm(_ANGLES[angle.bit_length() - 1])
            )
        return self.error(tid, opcode, "unknown command or arguments")

    async def pushed(self) -> str | None:
        """The string AutoSend pushes when the measure button is pressed (``None``: off)."""
        state = self.autosend
        if state is None:
            return None
        return await self.measure_string("6", state.tid, state.mask, state.with_temperature)
