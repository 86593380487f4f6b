"""Latched controller alarms: what a failed run says about them and how they are cleared.

A stepper controller (Oriental Motor AZ, Applied Motion STF/SWF) latches an alarm (overload,
excessive position deviation, overtravel) until an alarm reset (ALM-RST) while the cause
is gone. A latched alarm refuses every move, so a scan -- and ``scan resume`` -- fails the
same way again until someone resets it; the CLI had no way to (issue 23.15). Now a run that
fails on a controller alarm says how (:func:`failure_reason`), and ``goniolab lab
reset-alarm`` (:func:`reset_alarms`) reads both arms, resets the alarmed ones and reads
them again, saying which alarm remains (its cause is still there).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from drivers.base import DeviceError, DeviceFault

__all__ = ["RESET_COMMAND", "ArmAlarm", "alarm_hint", "failure_reason", "reset_alarms"]

#: The command that clears a latched alarm (``--config`` as the scan's).
RESET_COMMAND = "goniolab lab reset-alarm"


def alarm_hint(exc: DeviceError) -> str:
    """How to clear the controller alarm behind ``exc`` (empty for other errors)."""
    if not isinstance(exc, DeviceFault) or exc.code is None:
        return ""
    return (
        f"the controller alarm stays latched and refuses every move: check the arm, then "
        f"clear it with '{RESET_COMMAND} --config CONFIG' (the scan's config) and resume"
    )


def failure_reason(exc: DeviceError) -> str:
    """The stored reason of a run that failed on ``exc``, with :func:`alarm_hint`."""
    hint = alarm_hint(exc)
    return f"{exc}; {hint}" if hint else str(exc)


@dataclass(frozen=True, slots=True)
class ArmAlarm:
    """One arm's alarm before and after the reset (``None``: no alarm)."""

    arm: str
    before: int | None
    after: int | None

    @property
    def cleared(self) -> bool:
        return self.before is not None and self.after is None

    def describe(self) -> str:
        if self.before is None:
            return f"{self.arm}: no alarm"
        code = f"alarm {self.before} (0x{self.before:X})"
        if self.after is None:
            return f"{self.arm}: {code} cleared"
        return (
            f"{self.arm}: {code} still active after the reset (now {self.after} "
            f"(0x{self.after:X})): its cause is still there (a limit switch, an obstacle, "
            "the driver's power)"
        )


async def reset_alarms(goniometer: Any) -> list[ArmAlarm]:
    """Read both arms' alarms, reset the alarmed ones (nothing moves), read them again."""
    out: list[ArmAlarm] = []
    for arm, axis in (("lamp", goniometer.lamp), ("detector", goniometer.detector)):
        before = (await axis.status()).alarm_code
        after = before
        if before is not None:
            await axis.reset_alarm()
            after = (await axis.status()).alarm_code
        out.append(ArmAlarm(arm, before, after))
    return out
