"""The scan runner's reading path: a spectro reading, its mirror reference and its colour.

:meth:`SpectroReadings._read_spectro` takes one reading (auto-exposure, the plausibility
check of :mod:`goniolab.scan.sanity`, retries through transient faults);
:meth:`SpectroReadings._referenced` refers a sample reading to the certified mirror
(:class:`~goniolab.scan.reference.SpectralReference`, docs/CALIBRATION.md) once the mirror's
readings are stored; :meth:`SpectroReadings._colour_of` computes its colour.

:class:`SpectroReadings` is a base of :class:`goniolab.scan.runner.ScanRunner`, which sets
the attributes declared here.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from drivers.base import DeviceFault, SpectroReading
from goniolab.scan.colour import PointColour
from goniolab.scan.events import InstrumentError
from goniolab.scan.exposure import EXCLUDED_QUALITY, AutoExposure, quality_of_raw
from goniolab.scan.moves import DeviceOps
from goniolab.scan.plans import MIRROR_INDEX, BrdfPlan, PlanPoint
from goniolab.scan.reference import SpectralReference
from goniolab.scan.sanity import check_reading
from goniolab.scan.standards import Standard
from goniolab.store import RunStore

__all__ = ["INLINE_COLOUR_S", "SpectroReadings", "timed"]

_T = TypeVar("_T")

#: A reading's colour computed in less than this (once colour-science is loaded, ~0.1 ms)
#: is computed on the event loop next time; longer ones go to a worker thread.
INLINE_COLOUR_S = 1e-3


def timed(fn: Callable[..., _T], *args: Any) -> tuple[_T, float]:
    """``fn(*args)`` and the seconds it took."""
    t0 = time.perf_counter()
    return fn(*args), time.perf_counter() - t0


class SpectroReadings(DeviceOps):
    """The reading path of a run (a base of :class:`~goniolab.scan.runner.ScanRunner`)."""

    plan: BrdfPlan
    store: RunStore
    reading_retries: int
    point_colour: PointColour
    mirror_standard: Standard | None
    _reference: SpectralReference | None
    _colour_inline: bool
    _mirror_pct: float | None
    _auto: AutoExposure

    async def _read_spectro(self, p: PlanPoint) -> SpectroReading:
        """One spectro reading, taken again after a transient fault (timeout, garbled reply,
        an implausible value (:mod:`goniolab.scan.sanity`), a lost link: then the port is
        reopened first) up to ``reading_retries`` times; each retry is reported, nothing is
        stored twice."""

        async def read() -> SpectroReading:
            if self.plan.auto_exposure:
                reading, self._exposure_us = await self._auto.read(self.spectro, self._exposure_us)
            else:
                reading = await self.spectro.measure()
            return check_reading(reading)  # an implausible Y is read again, never stored

        reading = await self._retry(
            f"point {p.index}, repeat {p.repeat}", read, self._reconnect_spectro,
            self.reading_retries, "spectro",
        )  # fmt: skip
        if reading.stale_lines:  # a late or repeated answer was dropped: say so
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="spectro",
                    message=f"point {p.index}, repeat {p.repeat}: dropped {reading.stale_lines} "
                    "reply line(s) of an earlier request (a late or repeated answer); the "
                    "reading kept is the answer to this point's own request",
                    fatal=False,
                )
            )
        return reading

    async def _colour_of(
        self, reading: SpectroReading, p: PlanPoint, absolute: Sequence[float] | None
    ) -> tuple[dict[str, float] | None, str]:
        """The reading's colour (computed in a worker thread), or why there is none.

        A spectrum colour cannot be computed from (wrong length, NaN, negative values, a grid
        short of 380-780 nm) is reported as a non-fatal instrument error; the reading is
        stored all the same, without colour.
        """
        from goniolab.colour.spectra import ColourError

        # referenced to the certified mirror: the absolute spectrum (no further scaling)
        spectrum = reading.values if absolute is None else tuple(absolute)
        args = (reading.wavelengths_nm, spectrum, p.theta_r_deg, None)
        measured = self.point_colour.measured
        try:
            if self._colour_inline:
                # a few hundred multiply-adds once colour-science is loaded: a worker
                # thread's hand-off would cost more than the work (issue 13: the sequencer's
                # overhead per reading); a spectrum that takes longer sends it back
                values, took_s = timed(measured, *args)
            else:
                values, took_s = await asyncio.to_thread(lambda: timed(measured, *args))
            self._colour_inline = took_s < INLINE_COLOUR_S
        except (ColourError, ValueError) as exc:
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="spectro",
                    message=f"point {p.index}, repeat {p.repeat}: no colour: {exc} "
                    "(reading stored without colour)",
                    fatal=False,
                )
            )
            return None, str(exc)
        return values.as_dict(), ""

    def _mirror_level(self) -> float | None:
        vals = [p.luminance_pct for p in self.store.points(self.run_id) if p.index == MIRROR_INDEX]
        if len(vals) < self.plan.repeats:
            return None
        return math.fsum(vals) / len(vals)

    def _load_reference(self) -> SpectralReference | None:
        """The mirror reference of the run (its repeats averaged as spectra) once all its
        readings are stored, else ``None``."""
        if not self.plan.mirror_reference or self.mirror_standard is None:
            return None
        rows = [p for p in self.store.points(self.run_id) if p.index == MIRROR_INDEX]
        if len(rows) < self.plan.repeats:
            return None
        usable = [p for p in rows if quality_of_raw(p.raw) not in EXCLUDED_QUALITY]
        if not usable:
            flags = sorted({quality_of_raw(p.raw) for p in rows})
            raise DeviceFault(
                f"every mirror reference reading is flagged ({', '.join(flags)}): the "
                "reference cannot be used"
                + ("" if self.plan.auto_exposure else "; --auto-exposure adapts the exposure"),
                device="spectro",
            )
        rows = usable
        readings = [
            (
                list(p.raw.get("wavelengths_nm") or ()),
                list(p.raw.get("values") or ()),
                float(p.raw.get("luminance_pct", p.luminance_pct)),
            )
            for p in rows
        ]
        return SpectralReference.from_readings(
            self.mirror_standard, self.plan.theta_i_deg, readings, self.point_colour.settings
        )

    def _referenced(
        self, reading: SpectroReading, p: PlanPoint
    ) -> tuple[float, tuple[float, ...] | None, dict[str, Any]]:
        """A sample reading referenced to the certified mirror (once the mirror's readings
        are all stored; :class:`~goniolab.scan.reference.SpectralReference`):
        ``(luminance %, absolute spectrum % or None, provenance)``; a mirror reading or a
        run without reference as read."""
        raw_pct = float(reading.luminance_pct)
        if p.index == MIRROR_INDEX or not self.plan.mirror_reference:
            return raw_pct, None, {}
        if self._reference is None:
            self._mirror_pct = self._mirror_level()
            self._reference = self._load_reference()
        if self._reference is None:
            return raw_pct, None, {}
        absolute, lum, info = self._reference.apply(reading.wavelengths_nm, reading.values, raw_pct)
        if info["method"] != "spectral":
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="spectro",
                    message=f"point {p.index}, repeat {p.repeat}: mirror reference applied "
                    f"as a scalar: {info['method']}",
                    fatal=False,
                )
            )
        return lum, absolute, info
