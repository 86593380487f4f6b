"""The abstract instrument interface every goniolab driver and simulator implements.

Small, runtime-checkable :class:`typing.Protocol` classes in the style of bluesky's
``protocols.py`` (Readable, Movable, Stoppable): one per instrument role, async end to
end, angles in degrees at every interface. Real drivers (``drivers.modbus_stepper``,
``drivers.stil``, ``drivers.glossmeter``) and the simulated lab (``sim.instruments``)
both satisfy them, so the scan runner never knows which it talks to.

Every driver raises only the errors defined here (subclasses of :class:`DeviceError`),
so callers can handle "timeout", "garbled frame", "alarm", "limit", "interlock" and
"disconnected" uniformly whatever the bus.
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

__all__ = [
    "GLOSS_ANGLES_DEG",
    "Axis",
    "AxisStatus",
    "DeviceError",
    "DeviceFault",
    "DeviceTimeout",
    "Disconnected",
    "GlossReading",
    "Glossmeter",
    "Goniometer",
    "InterlockError",
    "LimitError",
    "ProfileError",
    "ProtocolError",
    "SpectroReading",
    "Spectrocolorimeter",
    "StallError",
]

#: The three ISO 2813 / ASTM D523 geometries.
GLOSS_ANGLES_DEG: tuple[int, int, int] = (20, 60, 85)


# --------------------------------------------------------------------------- errors
class DeviceError(Exception):
    """Base of every error a driver raises.

    Parameters
    ----------
    message
        What went wrong, in words a technician can act on.
    device
        The instrument's configured name (``"lamp"``, ``"detector"``, ``"spectro"``,
        ``"glossmeter"``...), empty when not known.
    """

    def __init__(self, message: str, *, device: str = "") -> None:
        self.device = device
        self.message = message
        super().__init__(f"{device}: {message}" if device else message)


class DeviceTimeout(DeviceError):
    """The instrument did not answer, or did not reach a state, in time."""


class ProtocolError(DeviceError):
    """A reply could not be understood: garbled frame, wrong echo, bad checksum, bad field."""


class DeviceFault(DeviceError):
    """The instrument reports an alarm or fault (``code`` is the device's own alarm code)."""

    def __init__(self, message: str, *, device: str = "", code: int | None = None) -> None:
        self.code = code
        super().__init__(message, device=device)


class StallError(DeviceFault):
    """Commanded and feedback position disagree by more than the allowed following error."""


class LimitError(DeviceError):
    """A requested position lies outside the axis' soft limits (or a limit switch tripped)."""


class InterlockError(DeviceError):
    """A requested two-arm geometry would bring the lamp and detector arms too close."""


class Disconnected(DeviceError):
    """The port or connection is missing, busy, closed or was lost."""


class ProfileError(ValueError):
    """A device profile (register map, command table, line pattern) is invalid.

    The message names the profile file, the key and the reason.
    """


# --------------------------------------------------------------------------- data
@dataclass(frozen=True, slots=True)
class AxisStatus:
    """A snapshot of one arm's controller state.

    Attributes
    ----------
    position_deg
        Feedback (encoder) position converted to degrees.
    command_deg
        Commanded position in degrees (``None`` when the controller does not expose it).
    moving
        The controller reports motion in progress.
    in_position
        The controller reports the target reached (IN-POS).
    homed
        The axis has been homed since power-up / connection.
    alarm_code
        ``None`` when no alarm is active, else the controller's alarm code.
    ready
        The controller accepts motion commands.
    """

    position_deg: float
    command_deg: float | None = None
    moving: bool = False
    in_position: bool = True
    homed: bool = False
    alarm_code: int | None = None
    ready: bool = True


@dataclass(frozen=True, slots=True)
class SpectroReading:
    """One spectro-colorimeter reading.

    Attributes
    ----------
    wavelengths_nm
        Sample wavelengths in nm, ascending.
    values
        Spectral reflectance factor at each wavelength, in % of the reference (mirror).
    luminance_pct
        Relative luminance Y in % of the reference (mirror), as the STIL Ruby reports it.
    exposure_us
        Exposure (integration) time used, in microseconds.
    timestamp
        Unix time of the reading.
    peak_fraction
        Counts of the strongest channel over the detector's full scale (1.0 = saturated:
        the values understate the light), when the instrument reports it; ``None`` if not.
        Auto-exposure aims at a peak fraction well below 1 and well above the noise.
    stale_lines
        Reply lines that belonged to earlier requests (a late or repeated answer) and were
        dropped before this reading was taken as the answer to its own request; 0 normally.
    """

    wavelengths_nm: tuple[float, ...]
    values: tuple[float, ...]
    luminance_pct: float
    exposure_us: int = 0
    timestamp: float = field(default_factory=time.time)
    peak_fraction: float | None = None
    stale_lines: int = 0


@dataclass(frozen=True, slots=True)
class GlossReading:
    """One glossmeter reading (ISO 2813 gloss units per geometry).

    Attributes
    ----------
    values_gu
        Gloss per geometry in GU; ``None`` where not measured. Only keys 20, 60, 85.
    overflow_deg
        Geometries whose value overflowed the meter's range.
    temperature_c
        Instrument temperature if reported.
    timestamp
        Unix time of the reading.
    raw
        The raw line as received (kept for the record).
    """

    values_gu: dict[int, float | None]
    overflow_deg: tuple[int, ...] = ()
    temperature_c: float | None = None
    timestamp: float = field(default_factory=time.time)
    raw: str = ""


# --------------------------------------------------------------------------- protocols
@runtime_checkable
class Axis(Protocol):
    """One stepper-driven goniometer arm, in degrees.

    ``move_to`` starts a move and returns once the controller accepted it;
    ``wait_in_position`` then waits for IN-POS. Both check soft limits and alarms.
    """

    name: str
    limits_deg: tuple[float, float]

    async def connect(self) -> None: ...
    async def close(self) -> None: ...
    async def status(self) -> AxisStatus: ...
    async def position_deg(self) -> float: ...
    async def move_to(self, target_deg: float) -> None: ...
    async def wait_in_position(self, timeout_s: float) -> float: ...
    async def home(self, timeout_s: float) -> None: ...
    async def stop(self) -> None: ...
    async def reset_alarm(self) -> None: ...


@runtime_checkable
class Goniometer(Protocol):
    """The two-arm in-plane goniometer: lamp arm (theta_i) and detector arm (theta_r).

    theta_r is signed: > 0 on the specular side, < 0 on the lamp side. Every move is
    checked against both arms' limits and the minimum arm separation *before* any motion,
    and every motion holds the goniometer for its whole travel: two moves never overlap, so
    a move of one arm (``move_arm``) is checked against where the other one really stands.
    """

    lamp: Axis
    detector: Axis
    min_separation_deg: float

    def check_geometry(self, theta_i_deg: float, theta_r_deg: float) -> None: ...
    async def connect(self) -> None: ...
    async def close(self) -> None: ...
    async def home(self, timeout_s: float) -> None: ...
    async def move_to(
        self, theta_i_deg: float, theta_r_deg: float, timeout_s: float
    ) -> tuple[float, float]: ...
    async def move_arm(
        self, arm: str, target_deg: float, timeout_s: float
    ) -> tuple[float, float]: ...
    async def positions_deg(self) -> tuple[float, float]: ...
    async def park(self, timeout_s: float) -> None: ...
    async def stop(self) -> None: ...


@runtime_checkable
class Spectrocolorimeter(Protocol):
    """A spectro-colorimeter reading relative luminance and a spectrum (STIL Ruby)."""

    name: str

    async def connect(self) -> None: ...
    async def close(self) -> None: ...
    async def identify(self) -> str: ...
    async def set_exposure_us(self, exposure_us: int) -> None: ...
    async def measure(self) -> SpectroReading: ...


@runtime_checkable
class Glossmeter(Protocol):
    """An ISO 2813 glossmeter with up to three geometries (20/60/85 deg)."""

    name: str

    async def connect(self) -> None: ...
    async def close(self) -> None: ...
    async def measure(self, angles_deg: Sequence[int] = GLOSS_ANGLES_DEG) -> GlossReading: ...
    def readings(self) -> AsyncIterator[GlossReading]:
        """Readings pushed by the meter (button presses / auto-send), as they come."""
        ...
