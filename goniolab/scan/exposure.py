"""Auto-exposure: the spectro's integration time adapts so no reading saturates or drowns.

A spectro reports, with each reading, how full its strongest channel was
(:attr:`drivers.base.SpectroReading.peak_fraction`: counts over the detector's full scale,
1.0 = clipped). The reported values are already divided by the exposure, so changing the
exposure changes only the signal-to-noise ratio and the risk of clipping, not the scale:

* a saturated reading (``peak_fraction >= 0.999``) is taken again at a quarter of the
  exposure (the clipped counts say only that the light is more than full scale);
* a reading below ``low`` of full scale (dark current, read and shot noise dominate) is
  taken again at ``exposure x target / peak_fraction``, and one above ``high`` at the same
  ratio, within the instrument's exposure range;

at most ``max_tries`` readings; the last one is returned with its exposure. An
instrument that does not report ``peak_fraction`` keeps its exposure.
"""

from __future__ import annotations

from dataclasses import dataclass

from drivers.base import Spectrocolorimeter, SpectroReading

__all__ = [
    "EXCLUDED_QUALITY",
    "NOISE_FLOOR_FRACTION",
    "QUALITY_FLAGS",
    "SATURATED",
    "AutoExposure",
    "quality_of_raw",
    "reading_quality",
]

#: A peak fraction at or above this is a clipped channel.
SATURATED = 0.999

#: A strongest channel below this fraction of full scale is under the noise floor: with a
#: 16-bit detector that is < 1300 counts, where dark-current shot noise and read noise
#: (tens of counts, sim/instruments.py SpectroChain) make the weak channels' values
#: meaningless (several % each) -- the reading is stored but flagged and left out of fits.
NOISE_FLOOR_FRACTION = 0.02

#: Per-reading quality flags (stored in each reading's ``raw["quality"]``).
QUALITY_FLAGS: tuple[str, ...] = ("ok", "saturated", "under_noise_floor", "unknown")

#: Flags whose readings are stored and exported but left out of averages and fits.
EXCLUDED_QUALITY: frozenset[str] = frozenset({"saturated", "under_noise_floor"})


def quality_of_raw(raw: dict[str, object]) -> str:
    """The stored flag of a reading's ``raw`` (``"unknown"`` for a store that predates it)."""
    q = raw.get("quality")
    return q if isinstance(q, str) else "unknown"


def reading_quality(reading: SpectroReading) -> str:
    """``"saturated"`` (a clipped channel: the values understate the light),
    ``"under_noise_floor"`` (:data:`NOISE_FLOOR_FRACTION`), ``"ok"``, or ``"unknown"`` when
    the instrument reports no signal level."""
    pf = reading.peak_fraction
    if pf is None:
        return "unknown"
    if pf >= SATURATED:
        return "saturated"
    if pf < NOISE_FLOOR_FRACTION:
        return "under_noise_floor"
    return "ok"


@dataclass(frozen=True, slots=True)
class AutoExposure:
    """Exposure control (see the module docstring); exposures in microseconds."""

    min_us: int = 500
    max_us: int = 250_000
    low: float = 0.08
    high: float = 0.85
    target: float = 0.5
    max_tries: int = 5

    def next_exposure_us(self, exposure_us: int, peak_fraction: float | None) -> int | None:
        """The exposure to try next, or ``None`` when this reading is good (or no better
        exposure exists)."""
        if peak_fraction is None:
            return None
        if peak_fraction >= SATURATED:
            new = max(self.min_us, exposure_us // 4)
        elif peak_fraction < self.low or peak_fraction > self.high:
            ratio = self.target / max(peak_fraction, 1e-6)
            new = int(min(self.max_us, max(self.min_us, round(exposure_us * ratio))))
        else:
            return None
        return None if new == exposure_us else new

    async def read(
        self, spectro: Spectrocolorimeter, exposure_us: int
    ) -> tuple[SpectroReading, int]:
        """Read at ``exposure_us``, adapting it (see the module docstring); returns the
        reading kept and the exposure the next reading should start from."""
        reading = await spectro.measure()
        for _ in range(self.max_tries - 1):
            new = self.next_exposure_us(exposure_us, reading.peak_fraction)
            if new is None:
                break
            exposure_us = new
            await spectro.set_exposure_us(exposure_us)
            reading = await spectro.measure()
        return reading, exposure_us
