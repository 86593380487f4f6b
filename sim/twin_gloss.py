"""The simulated ISO 2813 glossmeter (ZGM1120-like), with its calibration drift and warm-up.

:class:`SimGlossmeter` implements :class:`drivers.base.Glossmeter`; its values come from the
model's ``gloss`` (ISO 2813 at 20/60/85 deg), rounded to 0.1 GU, with overflow above
:data:`GLOSS_OVERFLOW_GU`; the realistic twin adds :class:`GlossDrift`.

References
----------
.. [1] ISO 2813:2014 / ASTM D523: specular gloss at 20/60/85 deg.
.. [2] Zehntner ZGM1120 Technical Manual rev. 3.0 (2021), pp. 16-28: 0.1 GU resolution,
   -2 = overflow.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass

import numpy as np

from drivers.base import GLOSS_ANGLES_DEG, GlossReading
from drivers.timing import Clock
from goniolab.optics.models import ReflectanceModel
from sim.faults import FaultInjector
from sim.twin_link import SimLink

__all__ = ["GLOSS_OVERFLOW_GU", "GlossDrift", "SimGlossmeter"]

#: Readings above this are reported as overflow (ZGM1120 range 0..2000 GU).
GLOSS_OVERFLOW_GU = 2000.0


@dataclass(frozen=True)
class GlossDrift:
    """The glossmeter's calibration drift and temperature (ZGM1120-like).

    The instrument's temperature warms from ``ambient_c`` by ``warmup_c`` with time
    constant ``warmup_tau_s`` after power-on; its gain drifts by ``drift_pct_per_h`` per
    hour since the last calibration and by ``temp_coeff_pct_per_c`` per degree from the
    calibration temperature; each value gets ``noise_gu`` (1 sigma) before rounding to
    0.1 GU. ``calibrate`` (on the black standard) resets the time and temperature terms.
    """

    drift_pct_per_h: float = 0.5
    temp_coeff_pct_per_c: float = 0.05
    ambient_c: float = 23.0
    warmup_c: float = 4.0
    warmup_tau_s: float = 900.0
    noise_gu: float = 0.1

    def temperature_c(self, t_s: float) -> float:
        """Instrument temperature ``t_s`` seconds after power-on."""
        return self.ambient_c + self.warmup_c * (1.0 - math.exp(-max(t_s, 0.0) / self.warmup_tau_s))

    def gain(self, t_s: float, calibrated_at_s: float) -> float:
        """Reading / truth at time ``t_s`` for a calibration at ``calibrated_at_s``."""
        hours = max(t_s - calibrated_at_s, 0.0) / 3600.0
        dt_c = self.temperature_c(t_s) - self.temperature_c(calibrated_at_s)
        return 1.0 + 0.01 * (self.drift_pct_per_h * hours + self.temp_coeff_pct_per_c * dt_c)


class SimGlossmeter(SimLink):
    """A simulated ISO 2813 glossmeter (implements ``Glossmeter``), ZGM1120-like.

    Parameters
    ----------
    model
        The sample's reflectance model (``model.gloss`` gives the GU values).
    clock
        Lab clock (measurement time and auto-send interval).
    noise_pct
        Relative noise (1 sigma, % of the reading) before rounding to 0.1 GU.
    rng
        Seeded generator.
    measure_time_s
        Duration of one measurement.
    autosend_interval_s
        Interval of pushed readings in :meth:`readings` (an operator pressing the
        button); 0 disables the stream.
    temperature_c
        Reported instrument temperature (ideal twin; with ``drift`` it follows
        :meth:`GlossDrift.temperature_c`).
    faults
        Fault injector.
    name
        Device name in errors.
    drift
        The realistic twin's calibration drift and warm-up (:class:`GlossDrift`); with it,
        ``noise_pct`` is replaced by ``drift.noise_gu``. ``None``: the ideal twin.
    """

    def __init__(
        self,
        model: ReflectanceModel,
        clock: Clock,
        *,
        noise_pct: float = 0.0,
        rng: np.random.Generator | None = None,
        measure_time_s: float = 0.5,
        autosend_interval_s: float = 5.0,
        temperature_c: float = 23.0,
        faults: FaultInjector | None = None,
        name: str = "glossmeter",
        drift: GlossDrift | None = None,
    ) -> None:
        self.name = name
        self.drift = drift
        self._powered_at_s = clock.now()
        # per geometry: the ZGM1120 calibrates ONE angle per Calibrate (opcode 72)
        self._calibrated_at_s = {a: self._powered_at_s for a in GLOSS_ANGLES_DEG}
        self._gloss_cache: dict[int, float] = {}
        self.model = model
        self.clock = clock
        self.noise_pct = noise_pct
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self.measure_time_s = measure_time_s
        self.autosend_interval_s = autosend_interval_s
        self.temperature_c = temperature_c
        self.faults = faults or FaultInjector(name)
        self._connected = False

    @property
    def model(self) -> ReflectanceModel:
        """The sample under the meter; setting it (another sample) forgets the cached gloss."""
        return self._model

    @model.setter
    def model(self, model: ReflectanceModel) -> None:
        self._model = model
        self._gloss_cache.clear()

    async def predicted_gu(self, angles_deg: Sequence[int]) -> dict[int, float]:
        """Noise-free model gloss per geometry (cached until the sample changes)."""
        missing = [a for a in angles_deg if a not in self._gloss_cache]
        if missing:
            values = await asyncio.to_thread(self.model.gloss, tuple(missing))
            self._gloss_cache.update({int(k): float(v) for k, v in values.items()})
        return {a: self._gloss_cache[a] for a in angles_deg}

    async def warm_up(self) -> None:
        """Compute (and cache) the model gloss at 20/60/85 deg before the first request."""
        await self.predicted_gu(GLOSS_ANGLES_DEG)

    async def read_values_gu(
        self, angles_deg: Sequence[int]
    ) -> tuple[dict[int, float | None], tuple[int, ...]]:
        """Noisy values rounded to 0.1 GU, and the geometries that overflowed."""
        for a in angles_deg:
            if a not in GLOSS_ANGLES_DEG:
                raise ValueError(f"{self.name}: geometry {a} deg not one of {GLOSS_ANGLES_DEG}")
        await self.clock.sleep(self.measure_time_s)
        clean = await self.predicted_gu(angles_deg)
        values: dict[int, float | None] = {a: None for a in GLOSS_ANGLES_DEG}
        overflow: list[int] = []
        for a in angles_deg:
            v = clean[a] * self._gain(a)
            if self.drift is not None:
                v += self.drift.noise_gu * float(self._rng.standard_normal())
            elif self.noise_pct:
                v *= 1.0 + 0.01 * self.noise_pct * float(self._rng.standard_normal())
            if v > GLOSS_OVERFLOW_GU:
                overflow.append(a)
                values[a] = None
            else:
                values[a] = round(max(v, 0.0), 1)
        return values, tuple(overflow)

    async def measure(self, angles_deg: Sequence[int] = GLOSS_ANGLES_DEG) -> GlossReading:
        """One measurement at the requested geometries (others are ``None``)."""
        self._op("measure")
        values, overflow = await self.read_values_gu(angles_deg)
        return GlossReading(
            values_gu=values,
            overflow_deg=overflow,
            temperature_c=self.current_temperature_c(),
            timestamp=time.time(),
            raw="",
        )

    def current_temperature_c(self) -> float:
        """The instrument's temperature now (warming up after power-on with ``drift``)."""
        if self.drift is None:
            return self.temperature_c
        return round(self.drift.temperature_c(self.clock.now() - self._powered_at_s), 1)

    def _gain(self, angle_deg: int) -> float:
        """Reading / truth now at ``angle_deg`` (1 for the ideal twin)."""
        if self.drift is None:
            return 1.0
        return self.drift.gain(
            self.clock.now() - self._powered_at_s,
            self._calibrated_at_s[angle_deg] - self._powered_at_s,
        )

    def calibrate_ppm(self, angle_deg: int | None = None) -> int:
        """Calibrate on the standard: the drift of ``angle_deg`` (``None``: every geometry)
        starts again from here. Returns the deviation found (gain - 1, in ppm), as the
        ZGM1120's Calibrate (opcode 72) does; with ``None`` that of the first geometry."""
        angles = GLOSS_ANGLES_DEG if angle_deg is None else (angle_deg,)
        for a in angles:
            if a not in GLOSS_ANGLES_DEG:
                raise ValueError(f"{self.name}: geometry {a} deg not one of {GLOSS_ANGLES_DEG}")
        now = self.clock.now()
        ppm = round((self._gain(angles[0]) - 1.0) * 1e6)
        for a in angles:
            self._calibrated_at_s[a] = now
        return ppm

    async def calibrate(
        self,
        angle_deg: int,
        *,
        second_standard_dgu: int | None = None,
        timeout_s: float = 10.0,
    ) -> int:
        """Calibrate ONE geometry, as :meth:`drivers.glossmeter.Zgm1120.calibrate` does;
        the deviation from the last calibration in ppm. The twin resets its drift on any
        standard: ``second_standard_dgu`` is checked as the meter checks it, not used."""
        self._op("calibrate")
        if second_standard_dgu is not None and not 0 < second_standard_dgu <= 99999:
            raise ValueError(f"second_standard_dgu {second_standard_dgu} out of 1..99999")
        await self.clock.sleep(self.measure_time_s)
        return self.calibrate_ppm(angle_deg)

    def readings(self) -> AsyncIterator[GlossReading]:
        """Readings pushed every ``autosend_interval_s`` clock seconds (auto-send)."""
        return self._stream()

    async def _stream(self) -> AsyncIterator[GlossReading]:
        if self.autosend_interval_s <= 0:
            return
        while True:
            await self.clock.sleep(self.autosend_interval_s)
            yield await self.measure()
