"""Plausibility of a spectro reading before it is stored (issue 23.13).

A spectro reports the relative luminance Y in % of its reference, the mirror. Dark
subtraction leaves noise around zero on a black sample, a fraction of a percent; a
passive sample never returns ten times the light of the mirror it is referenced to. A
reading outside ``[LUMINANCE_MIN_PCT, LUMINANCE_MAX_PCT]`` or not finite is a garbled or
broken reply, not a measurement: before this check ``Y = -50`` was stored as -50 %,
``Y = 1e300`` made the run's RMSE infinite and ``runs show --json`` print ``Infinity``.

The runner refuses such a reading as a :class:`ImplausibleReading` (a
:class:`drivers.base.ProtocolError`): it is reported with its value, read again up to the
reading retries, and the run fails with the message if the spectro keeps answering so.
Nothing implausible is stored.

The spectrum's own values are checked where its colour is computed
(:mod:`goniolab.scan.colour`: a bad spectrum keeps the reading, without colour).
"""

from __future__ import annotations

import math

from drivers.base import ProtocolError, SpectroReading

__all__ = ["LUMINANCE_MAX_PCT", "LUMINANCE_MIN_PCT", "ImplausibleReading", "check_reading"]

#: Lowest plausible Y, % of the mirror: dark-subtraction noise on a black sample is a
#: fraction of this.
LUMINANCE_MIN_PCT = -1.0
#: Highest plausible Y, % of the mirror: ten times the reference's own light.
LUMINANCE_MAX_PCT = 1000.0


class ImplausibleReading(ProtocolError):
    """A reading whose value no sample can produce (read again, never stored)."""


def check_reading(reading: SpectroReading, *, device: str = "spectro") -> SpectroReading:
    """``reading`` when its luminance is plausible, else :class:`ImplausibleReading`
    naming the value and the accepted range."""
    y = reading.luminance_pct
    if not isinstance(y, int | float) or not math.isfinite(y):
        raise ImplausibleReading(f"implausible reading: Y = {y!r} is not a number", device=device)
    if not (LUMINANCE_MIN_PCT <= y <= LUMINANCE_MAX_PCT):
        raise ImplausibleReading(
            f"implausible reading: Y = {y:.6g} % of the mirror, outside "
            f"[{LUMINANCE_MIN_PCT:g}, {LUMINANCE_MAX_PCT:g}] %",
            device=device,
        )
    return reading
