"""STIL (Marposs) "Ruby" spectro-colorimeter over a serial line, plus CIE colour maths.

The Ruby's raw serial command set is NOT public (docs/PROTOCOLS.md). The driver speaks the
line-based ASCII protocol described by a ``kind = "stil-spectro"`` profile
(``configs/profiles/stil-ruby.toml``, every command UNCONFIRMED): one command line, then
the profile's reply line(s) or one error line. With the built-in profile::

    > IDN?\\r                      < STIL RUBY SN 12345 FW 2.1\\r\\n
    > EXP 10000\\r                 < EXP=10000\\r\\n
    > MEAS\\r                      < Y=12.3456\\r\\n
                                   < SPEC 380 5 81 12.1,12.3,...\\r\\n      (81 values, %)
    > EXP 100\\r                   < ERR 2 exposure out of range\\r\\n

Every reply is matched to its request. The protocol carries no sequence number, so the
driver relies on the device answering in order: after each measurement it sends a *fence*,
the set-exposure command with the exposure already set, and reads up to that command's
echo. The measurement's own reply is the last complete reply before the echo; any lines
before it are a late or repeated answer to an earlier request and are dropped (counted in
:attr:`drivers.base.SpectroReading.stale_lines`). After a request went unanswered or a
reply was malformed, the next request first drains the line until it has been quiet for
``resync_quiet_s``. Without this a spectro that answered one MEAS after the timeout shifted
every later reading to the next geometry (issue 23, item 1)::

    > MEAS\r                      (no reply within the timeout: the runner retries)
    > MEAS\r                      < Y=...  (late answer to the first MEAS)
                                   < SPEC ...
    > EXP 10000\r                 < Y=...  (answer to the retry: this one is kept)
                                   < SPEC ...
                                   < EXP=10000   (the fence)

Colour is computed on our side from the returned spectrum with colour-science
(:func:`spectrum_to_xyz`, :func:`spectrum_to_lab`): CIE 15:2004 tristimulus integration
(ASTM E308 weighting by default) and CIE 1976 L*a*b* (CIE 15:2004 eqs. 8.1-8.3).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from drivers.base import (
    DeviceFault,
    DeviceTimeout,
    LimitError,
    ProtocolError,
    SpectroReading,
)
from drivers.profiles import StilProfile, load_stil_profile, template_regex
from drivers.serial_io import LineTransport, quote

__all__ = [
    "StilSpectro",
    "match_reply",
    "parse_measure_reply",
    "spectrum_to_lab",
    "spectrum_to_xyz",
]

#: Observer used for every colour computation (PROTOCOLS.md: the Ruby DLL offers 1931 2 deg
#: and 1964 10 deg; gloss/appearance work uses 10 deg).
OBSERVER_10DEG = "CIE 1964 10 Degree Standard Observer"


def _float(text: str, what: str, line: str, device: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ProtocolError(f"bad {what} {text!r} in reply {quote(line)}", device=device) from None
    if not math.isfinite(value):
        raise ProtocolError(f"non-finite {what} in reply {quote(line)}", device=device)
    return value


def parse_measure_reply(
    profile: StilProfile, lines: list[str], *, device: str = "spectro"
) -> tuple[float, tuple[float, ...], tuple[float, ...]]:
    """Parse the measure reply lines into ``(luminance_pct, wavelengths_nm, values_pct)``.

    Raises
    ------
    ProtocolError
        A line does not match its template, a number is malformed, ``count`` disagrees
        with the number of values, or the wavelength step is not positive.
    DeviceFault
        A line is the profile's error reply.
    """
    if len(lines) != len(profile.reply_measure):
        raise ProtocolError(
            f"expected {len(profile.reply_measure)} reply lines, got {len(lines)}", device=device
        )
    fields: dict[str, str] = {}
    for template, line in zip(profile.reply_measure, lines, strict=True):
        fields.update(match_reply(profile, template, line, device))
    lum_line = lines[0]
    luminance = _float(fields["luminance_pct"], "luminance", lum_line, device)
    values_text = fields["values"]
    values = tuple(_float(v, "spectral value", values_text, device) for v in values_text.split(","))
    count = int(fields.get("count", len(values)))
    if count != len(values):
        raise ProtocolError(
            f"spectrum announces {count} values but carries {len(values)}", device=device
        )
    start = _float(fields.get("start_nm", "380"), "start wavelength", values_text, device)
    step = _float(fields.get("step_nm", "5"), "wavelength step", values_text, device)
    if step <= 0:
        raise ProtocolError(f"wavelength step {step} nm is not positive", device=device)
    wavelengths = tuple(start + i * step for i in range(count))
    return luminance, wavelengths, values


def match_reply(
    profile: StilProfile, template: str, line: str, device: str = "spectro"
) -> dict[str, str]:
    """Match one reply line: the profile's error line first, then ``template``.

    Returns the template's fields. Raises :class:`DeviceFault` (with the device's error
    code) for an error line and :class:`ProtocolError` quoting the line otherwise.
    """
    error = template_regex(profile.reply_error).match(line)
    if error is not None:
        code = int(error.group("code")) if "code" in error.groupdict() else None
        message = error.groupdict().get("message") or ""
        raise DeviceFault(
            f"device error {code}: {message} (reply {quote(line)})", device=device, code=code
        )
    found = template_regex(template).match(line)
    if found is None:
        raise ProtocolError(
            f"reply {quote(line)} does not match the expected {template!r}", device=device
        )
    return {k: v for k, v in found.groupdict().items() if v is not None}


class StilSpectro:
    """STIL Ruby spectro-colorimeter (implements ``drivers.base.Spectrocolorimeter``).

    Parameters
    ----------
    name
        Configured instrument name (used in errors).
    port
        Serial device or pyserial URL (``socket://host:port``).
    profile
        A :class:`~drivers.profiles.StilProfile` or profile name / path.
    baudrate
        Overrides the profile's baud rate.
    exposure_us
        Exposure set on :meth:`connect` (profile default when ``None``).
    timeout_s
        Reply timeout (profile default when ``None``).
    fence
        Confirm each measurement's reply with the fence (module docstring). Only a device
        that cannot take a command right after a measurement needs ``False``; a late reply
        is then caught by the drain alone, which cannot tell a repeated answer.
    resync_quiet_s
        After a failed request: how long the line must stay quiet before the next request.
    """

    def __init__(
        self,
        name: str = "spectro",
        *,
        port: str,
        profile: StilProfile | str = "stil-ruby",
        baudrate: int | None = None,
        exposure_us: int | None = None,
        timeout_s: float | None = None,
        fence: bool = True,
        resync_quiet_s: float = 0.2,
    ) -> None:
        self.name = name
        self.fence = bool(fence)
        self.resync_quiet_s = float(resync_quiet_s)
        #: Set when a request went unanswered or its reply was malformed: the line may
        #: still carry that request's answer, so the next request first drains it.
        self._dirty = False
        #: Bytes dropped by the drains and reply lines dropped by the fences since connect.
        self.stale_bytes = 0
        self.stale_lines = 0
        self.profile = profile if isinstance(profile, StilProfile) else load_stil_profile(profile)
        settings = self.profile.serial
        if baudrate is not None:
            settings = dataclasses.replace(settings, baudrate=baudrate)
        self.port = port
        self.timeout_s = self.profile.timeout_s if timeout_s is None else float(timeout_s)
        self._initial_exposure_us = (
            self.profile.exposure_default_us if exposure_us is None else int(exposure_us)
        )
        self._check_exposure(self._initial_exposure_us)
        self.exposure_us = self._initial_exposure_us
        self.ident = ""
        self._io = LineTransport(port, settings, device=name, encoding=self.profile.encoding)

    def _check_exposure(self, exposure_us: int) -> None:
        lo, hi = self.profile.exposure_min_us, self.profile.exposure_max_us
        if not lo <= exposure_us <= hi:
            raise LimitError(
                f"exposure {exposure_us} us outside the range {lo}..{hi} us", device=self.name
            )

    async def connect(self) -> None:
        """Open the port, identify the device and set the configured exposure."""
        await self._io.open()
        self._dirty = False
        try:
            await self.identify()
            await self.set_exposure_us(self._initial_exposure_us)
        except BaseException:
            await self._io.close()
            raise

    async def close(self) -> None:
        """Close the port."""
        await self._io.close()

    async def _begin(self) -> None:
        """Before a request: drop what is buffered, and after a failed request wait for the
        line to go quiet (its late answer may still be coming)."""
        if self._dirty:
            max_s = self.timeout_s + self.exposure_us * 1e-6
            self.stale_bytes += await self._io.drain_quiet(self.resync_quiet_s, max_s)
            self._dirty = False
        else:
            self.stale_bytes += self._io.discard_input()

    async def _read(self, timeout_s: float) -> str:
        """One reply line; a timeout or an unreadable line marks the link for a resync."""
        try:
            return await self._io.read_line(self.profile.reply_terminator, timeout_s)
        except (DeviceTimeout, ProtocolError):
            self._dirty = True
            raise

    async def _transact(
        self, command: str, templates: tuple[str, ...], timeout_s: float
    ) -> list[tuple[str, dict[str, str]]]:
        """Send one command; return each reply line with its template fields."""
        await self._begin()
        await self._io.write(command + self.profile.command_terminator)
        replies: list[tuple[str, dict[str, str]]] = []
        for template in templates:
            line = await self._read(timeout_s)
            try:
                replies.append((line, match_reply(self.profile, template, line, self.name)))
            except ProtocolError:
                self._dirty = True
                raise
        return replies

    async def identify(self) -> str:
        """Ask the device for its identification string."""
        ((line, fields),) = await self._transact(
            self.profile.cmd_identify, (self.profile.reply_identify,), self.timeout_s
        )
        self.ident = fields.get("ident", line)
        return self.ident

    async def set_exposure_us(self, exposure_us: int) -> None:
        """Set the exposure (integration) time; checked against the profile's range first."""
        self._check_exposure(exposure_us)
        command = self.profile.cmd_set_exposure.format(exposure_us=exposure_us)
        ((line, fields),) = await self._transact(
            command, (self.profile.reply_set_exposure,), self.timeout_s
        )
        echoed = fields.get("exposure_us")
        if echoed is not None and int(echoed) != exposure_us:
            raise ProtocolError(
                f"asked for exposure {exposure_us} us, device confirmed {echoed} us "
                f"(reply {quote(line)})",
                device=self.name,
            )
        self.exposure_us = exposure_us

    async def measure(self) -> SpectroReading:
        """Take one reading: relative luminance and the spectrum, both in % of the reference."""
        p = self.profile
        timeout_s = self.timeout_s + self.exposure_us * 1e-6
        n = len(p.reply_measure)
        error_re = template_regex(p.reply_error)
        await self._begin()
        await self._io.write(p.cmd_measure + p.command_terminator)
        lines: list[str] = []
        for _ in range(n):
            line = await self._read(timeout_s)
            if error_re.match(line):  # the device refused the measurement: its one reply
                match_reply(p, p.reply_measure[0], line, self.name)  # raises DeviceFault
            lines.append(line)
        if self.fence:
            lines = await self._fenced(lines)
        stale = len(lines) - n
        own = lines[stale:]
        try:
            luminance, wavelengths, values = parse_measure_reply(p, own, device=self.name)
        except ProtocolError:
            self._dirty = True
            raise
        self.stale_lines += stale
        return SpectroReading(
            wavelengths_nm=wavelengths,
            values=values,
            luminance_pct=luminance,
            exposure_us=self.exposure_us,
            timestamp=time.time(),
            stale_lines=stale,
            peak_fraction=self._peak_fraction(own),
        )

    def _peak_fraction(self, lines: list[str]) -> float | None:
        """The signal level (``{peak_fraction}``, strongest channel over full scale) when the
        profile's measure reply carries it (``stil-ruby-level``, UNCONFIRMED); ``None``
        without the field or for ``-1`` (the instrument does not report it)."""
        p = self.profile
        if not any("{peak_fraction" in t for t in p.reply_measure):
            return None
        fields: dict[str, str] = {}
        for template, line in zip(p.reply_measure, lines, strict=True):
            fields.update(match_reply(p, template, line, self.name))
        text = fields.get("peak_fraction")
        if text is None:
            return None
        value = _float(text, "signal level", text, self.name)
        if value == -1:
            return None
        if not 0.0 <= value <= 1.0:
            raise ProtocolError(f"signal level {value} outside 0..1 (or -1)", device=self.name)
        return value

    async def _fenced(self, lines: list[str]) -> list[str]:
        """Send the fence and read every line up to its echo; return ``lines`` plus the
        lines that came before the echo (the measurement's reply is the last of them).

        The fence is idempotent (it sets the exposure already set), so a fence that goes
        unanswered or comes back garbled is sent once more after a drain: one lost or
        corrupted line does not cost the measurement."""
        p = self.profile
        command = p.cmd_set_exposure.format(exposure_us=self.exposure_us)
        echo_re = template_regex(p.reply_set_exposure)
        error_re = template_regex(p.reply_error)
        reply_res = [template_regex(t) for t in p.reply_measure]
        # at most one stale reply per earlier request of this reading (first try, retries)
        limit = len(lines) + 4 * len(p.reply_measure) + 4
        for attempt in range(2):
            await self._io.write(command + p.command_terminator)
            try:
                while True:
                    line = await self._read(self.timeout_s)
                    echo = echo_re.match(line)
                    if (
                        echo is not None
                        and int(echo.groupdict().get("exposure_us") or self.exposure_us)
                        == self.exposure_us
                    ):
                        self._dirty = False  # in step with the device again
                        return lines
                    if error_re.match(line):  # the fence refused: its answer; resync next
                        self._dirty = True
                        return lines
                    if not any(r.match(line) for r in reply_res):
                        raise ProtocolError(
                            f"unexpected line {quote(line)} while waiting for the echo of "
                            f"the fence {command!r}",
                            device=self.name,
                        )
                    lines.append(line)
                    if len(lines) > limit:
                        self._dirty = True
                        raise ProtocolError(
                            f"{len(lines)} reply lines to one measurement and no echo of the "
                            f"fence {command!r}: the device does not answer in order",
                            device=self.name,
                        )
            except (DeviceTimeout, ProtocolError):
                if attempt == 1 or len(lines) > limit:
                    self._dirty = True
                    raise
                self.stale_bytes += await self._io.drain_quiet(self.resync_quiet_s, self.timeout_s)
        raise AssertionError("unreachable")  # pragma: no cover - the loop returns or raises


# --------------------------------------------------------------------------- colour
def _colour() -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Matplotlib not available" and similar notices
        import colour
    return colour


def spectrum_to_xyz(
    wavelengths_nm: ArrayLike,
    values_pct: ArrayLike,
    *,
    illuminant: str = "D65",
    method: str = "ASTM E308",
) -> tuple[float, float, float]:
    """CIE XYZ (Y = 100 for the perfect reflecting diffuser) of a reflectance spectrum.

    Tristimulus integration of CIE 15:2004 (section 7.1, eq. 7.1-7.3: X = k * sum S R xbar
    dlambda, k = 100 / sum S ybar dlambda) with the CIE 1964 10 deg observer, done by
    ``colour.sd_to_XYZ`` (ASTM E308 tables by default, ``method="Integration"`` for the
    plain sum).

    Parameters
    ----------
    wavelengths_nm
        Ascending, evenly spaced wavelengths in nm.
    values_pct
        Spectral reflectance factor in % (100 = perfect reflecting diffuser / reference).
    illuminant
        Name in ``colour.SDS_ILLUMINANTS`` (``"D65"``, ``"A"``, ``"C"``...).
    method
        ``"ASTM E308"`` or ``"Integration"``.
    """
    colour = _colour()
    wl = np.asarray(wavelengths_nm, dtype=float)
    r = np.asarray(values_pct, dtype=float) / 100.0
    if wl.ndim != 1 or wl.shape != r.shape or wl.size < 2:
        raise ValueError(
            f"need matching 1-D wavelength and value arrays, got shapes {wl.shape} and {r.shape}"
        )
    if illuminant not in colour.SDS_ILLUMINANTS:
        raise ValueError(f"unknown illuminant {illuminant!r}")
    sd = colour.SpectralDistribution(r, wl)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # colour warns when it interpolates/extrapolates
        xyz = colour.sd_to_XYZ(
            sd,
            colour.MSDS_CMFS[OBSERVER_10DEG],
            colour.SDS_ILLUMINANTS[illuminant],
            method=method,
        )
    return float(xyz[0]), float(xyz[1]), float(xyz[2])


def spectrum_to_lab(
    wavelengths_nm: ArrayLike, values_pct: ArrayLike, *, illuminant: str = "D65"
) -> tuple[float, float, float]:
    """CIE 1976 L*a*b* (CIE 15:2004 eqs. 8.1-8.3) of a reflectance spectrum.

    XYZ from :func:`spectrum_to_xyz`, white point = the illuminant's chromaticity for the
    CIE 1964 10 deg observer (``colour.CCS_ILLUMINANTS``), via ``colour.XYZ_to_Lab``.
    """
    colour = _colour()
    xyz = np.asarray(spectrum_to_xyz(wavelengths_nm, values_pct, illuminant=illuminant))
    white = colour.CCS_ILLUMINANTS[OBSERVER_10DEG][illuminant]
    lab = colour.XYZ_to_Lab(xyz / 100.0, white)
    return float(lab[0]), float(lab[1]), float(lab[2])
