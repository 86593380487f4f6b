"""Alignment from the data: both arms' zero offsets and the sample's tilt.

Wittmann et al. (2021, secs. 5.2-5.3) blame the scatter of their glossy samples' peaks on
"lamp and sensor not perfectly aligned, sample tilted". With the arms at ``(L, D)``
(their own angles) the sample sees (:func:`sim.instruments.effective_angles`)::

    theta_i = L + dL + tau,        theta_r = D + dD - tau

(``dL``, ``dD``: the arms' zero offsets; ``tau``: the sample's tilt in the plane of
incidence). A reading depends on ``(theta_i, theta_r)`` only, so one specimen's data fix
only two combinations, ``dL + tau`` and ``dD - tau``: a tilt cannot be told from equal and
opposite arm offsets on the sample alone. The plan therefore uses two specimens:

1. **The ISO 2813 black-glass standard** (flat, n = 1.567, seated on the reference
   surface: by definition ``tau = 0``). At two or more incidences ``L_j`` the detector is
   swept through the specular peak, coarsely, then finely around the maximum. Its
   reading is known in closed form: ``k x 100 R(L + dL) x O(|D + dD - L - dL|)``, the
   Fresnel reflectance of the glass at the true incidence (Fresnel, unpolarised, PHYSICS.md)
   times the overlap of the source image with the detector cone
   (:func:`goniolab.optics.facet.cap_overlap_fraction`), with an unknown scale ``k``
   (lamp, detector calibration) and a stray-light floor. A least-squares fit over all
   readings gives ``dL - dD`` from where the peaks are and ``dL`` from how their heights
   change with incidence (R(theta) rises steeply: about 6 %/deg at 60 deg against 0.3 %/deg
   at 20 deg), hence ``dL`` and ``dD``.
2. **The sample** at the same incidences: the detector position of the peak (the midpoint
   of its half-maximum crossings on the fine sweep) minus that of the prediction at the
   nominal geometry is ``dL - dD + 2 tau`` (a tilt turns the mirror direction by twice
   itself); with ``dL - dD`` known, each incidence gives ``tau``. They are averaged with
   weights ``1 / (0.02 + |m_pred - theta_i|)^2``, ``m_pred`` the prediction's own
   midpoint: where the predicted peak is asymmetric (high incidence, wide lobes) the
   midpoint depends on the lobe's shape, hence on the model's error.

Each reading uses :class:`goniolab.scan.exposure.AutoExposure`; every target is approached
from below (the scans' direction), so the gears' backlash is the same as in a scan. The
alignment is measured in the arms' own frame (corrections of an earlier alignment are
switched off while it runs) and its result gives the corrections
(:meth:`AlignResult.corrections_deg`) that ``[alignment]`` applies to every later move
(:class:`drivers.goniometer.TwoArmGoniometer`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.base import DeviceError, Spectrocolorimeter
from drivers.goniometer import TwoArmGoniometer
from drivers.timing import Clock
from goniolab.scan.align_eta import eta_left, legs, move_size, nominal_parts, sweep
from goniolab.scan.black_glass_fit import (
    BLACK_GLASS_N,
    AlignGates,
    AlignRefused,
    StandardFit,
    check_standard,
    fit_standard,
    fit_standard_full,
    half_max_midpoint,
)
from goniolab.scan.dryrun import ArmMotion
from goniolab.scan.eta import EtaEstimator, WallTime
from goniolab.scan.events import (
    EventBus,
    InstrumentError,
    PointMeasured,
    Progress,
    RecordingBus,
    RunFinished,
    RunStarted,
    RunState,
    StateChanged,
    WarningLog,
)
from goniolab.scan.exposure import AutoExposure, reading_quality
from goniolab.scan.plans import PlanError
from goniolab.scan.prediction import Predictor
from goniolab.scan.standards import Standard
from goniolab.store import RunStore

__all__ = [
    "BLACK_GLASS_N",
    "AlignAborted",
    "AlignGates",
    "AlignPlan",
    "AlignRefused",
    "AlignResult",
    "AlignRunner",
    "StandardFit",
    "check_standard",
    "fit_standard",
    "fit_standard_full",
    "half_max_midpoint",
]


FloatArray = NDArray[np.float64]
SpecimenHook = Callable[[str], Awaitable[None]]


class AlignAborted(RuntimeError):
    """The alignment was aborted (:meth:`AlignRunner.abort`) before its result."""


@dataclass(frozen=True, slots=True)
class AlignPlan:
    """What the alignment measures (see the module docstring); angles in degrees."""

    theta_i_deg: tuple[float, ...] = (20.0, 40.0, 60.0)
    coarse_step_deg: float = 1.0
    coarse_span_deg: float = 5.0
    fine_step_deg: float = 0.25
    fine_span_deg: float = 4.5
    exposure_us: int = 10_000
    sample: str = ""

    def __post_init__(self) -> None:
        if len(set(self.theta_i_deg)) < 2:
            raise PlanError(
                f"align: needs two or more different incidence angles, got {list(self.theta_i_deg)}"
            )
        for name in ("coarse_step_deg", "coarse_span_deg", "fine_step_deg", "fine_span_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise PlanError(f"align: {name} must be > 0, got {v}")
        if self.fine_step_deg > self.coarse_step_deg:
            raise PlanError("align: the fine step must not exceed the coarse step")
        if not 500 <= self.exposure_us <= 250_000:
            raise PlanError(f"align: exposure_us must be in 500..250000, got {self.exposure_us}")

    def sweeps(self, theta_i_deg: float) -> tuple[FloatArray, float]:
        """The coarse detector angles around the nominal specular, and the fine span."""
        n = round(self.coarse_span_deg / self.coarse_step_deg)
        coarse = theta_i_deg + self.coarse_step_deg * np.arange(-n, n + 1)
        return np.asarray(coarse, dtype=np.float64), self.fine_span_deg

    def fine(self, centre_deg: float) -> FloatArray:
        """The fine detector angles around ``centre_deg``."""
        n = round(self.fine_span_deg / self.fine_step_deg)
        return np.asarray(centre_deg + self.fine_step_deg * np.arange(-n, n + 1))

    def to_dict(self) -> dict[str, Any]:
        """JSON form stored with the run."""
        return {
            "kind": "align",
            "theta_i_deg": list(self.theta_i_deg),
            "coarse_step_deg": self.coarse_step_deg,
            "coarse_span_deg": self.coarse_span_deg,
            "fine_step_deg": self.fine_step_deg,
            "fine_span_deg": self.fine_span_deg,
            "exposure_us": self.exposure_us,
            "sample": self.sample,
        }


@dataclass
class AlignResult:
    """The alignment found: ``theta_i = L + lamp_zero + tilt``, ``theta_r = D +
    detector_zero - tilt`` (degrees), with the per-specimen peaks and the standard's fit."""

    lamp_zero_deg: float
    detector_zero_deg: float
    sample_tilt_deg: float
    standard_rms_rel: float
    peaks: list[dict[str, Any]] = field(default_factory=list)
    readings: int = 0
    #: the black-glass fit and its gates' numbers (:class:`StandardFit`), the standard cited
    standard_fit: dict[str, float] = field(default_factory=dict)
    standard: dict[str, Any] = field(default_factory=dict)
    #: where the result was saved (the lab's alignment state file), "" = with the run only
    state_file: str = ""
    #: moves made without the approach from below (its point out of reach, or its move
    #: failed): each was reported when it happened
    approaches_skipped: int = 0
    #: the run's warnings, as they were published (:class:`~goniolab.scan.events.WarningLog`)
    warnings: list[str] = field(default_factory=list)

    def corrections_deg(self) -> tuple[float, float]:
        """Added to requested angles before the arms move (``[alignment]``): the sample
        then sees the requested geometry."""
        return (
            -(self.lamp_zero_deg + self.sample_tilt_deg),
            -(self.detector_zero_deg - self.sample_tilt_deg),
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON form (stored with the run, printed by ``scan --plan align --json``)."""
        c = self.corrections_deg()
        return {
            "lamp_zero_deg": self.lamp_zero_deg,
            "detector_zero_deg": self.detector_zero_deg,
            "sample_tilt_deg": self.sample_tilt_deg,
            "lamp_correction_deg": c[0],
            "detector_correction_deg": c[1],
            "standard_rms_rel": self.standard_rms_rel,
            "readings": self.readings,
            "peaks": self.peaks,
            "standard_fit": self.standard_fit,
            "standard": self.standard,
            "state_file": self.state_file,
            "approaches_skipped": self.approaches_skipped,
            "warnings": self.warnings,
        }


class AlignRunner:
    """Measure an :class:`AlignPlan` on a lab and compute the :class:`AlignResult`.

    Parameters
    ----------
    goniometer, spectro, clock
        The lab's instruments.
    plan
        What to measure.
    predictor
        The sample's prediction (its peak position at the nominal geometry).
    place_specimen
        Puts ``"standard"`` or ``"sample"`` under the instruments (the simulated lab's
        ``place_specimen``, or an operator prompt).
    store, run_id, bus
        Where readings, events and the result go.
    move_timeout_s
        Timeout of one move.
    motion, wall
        The arms' motion model and the clock of the ETA
        (:class:`goniolab.scan.eta.EtaEstimator`, the scans' estimator, over the plan's
        nominal sweeps: peaks at the nominal speculars). Without ``motion`` the moves are
        sized in degrees and timed from the first ones measured.
    """

    def __init__(
        self,
        *,
        goniometer: TwoArmGoniometer,
        spectro: Spectrocolorimeter,
        clock: Clock,
        plan: AlignPlan,
        predictor: Predictor,
        place_specimen: SpecimenHook,
        store: RunStore,
        run_id: int,
        bus: EventBus,
        move_timeout_s: float = 30.0,
        exposure: AutoExposure | None = None,
        standard: Standard | None = None,
        gates: AlignGates | None = None,
        motion: ArmMotion | None = None,
        wall: WallTime | None = None,
    ) -> None:
        self.goniometer = goniometer
        self.spectro = spectro
        self.clock = clock
        self.plan = plan
        self.predictor = predictor
        self.place_specimen = place_specimen
        self.store = store
        self.run_id = run_id
        #: the run's warnings as they are published (kept in the result)
        self.warnings = WarningLog(run_id)
        self.bus: EventBus = RecordingBus(bus, self.warnings)
        self.move_timeout_s = move_timeout_s
        self.exposure = exposure or AutoExposure()
        #: the certified black glass (``configs/standards.toml [black_glass]``)
        self.standard = standard
        self.gates = gates or AlignGates()
        self._saturated = {"standard": 0, "sample": 0}
        #: Saves a result before the run is marked done; returns where ("" = nowhere). A
        #: failure fails the run (the result stays stored with it).
        self.persist: Callable[[AlignResult], str] | None = None
        self._unknown_level = 0
        self._exposure_us = plan.exposure_us
        self._index = 0
        self._position: tuple[float, float] | None = None
        #: moves made without their approach from below (:meth:`_go`)
        self.approaches_skipped = 0
        self._abort = False
        #: :meth:`run` has published the run's end (done, aborted or failed)
        self.finished = False
        self.motion = motion
        self.wall = WallTime.of(clock) if wall is None else wall
        #: the readings' nominal geometries (each sweep's peak at its nominal specular)
        lim = goniometer.detector.limits_deg
        self._nominal = [g for ti in sorted(plan.theta_i_deg) for g in sweep(plan, lim, ti, ti)] * 2
        self._total = len(self._nominal)
        self._eta: EtaEstimator | None = None

    @property
    def aborted(self) -> bool:
        """:meth:`abort` was called."""
        return self._abort

    def abort(self) -> None:
        """Stop before the next reading: :meth:`run` stores the run as aborted (its
        readings kept, no result) and raises :class:`AlignAborted`."""
        self._abort = True

    async def _go(self, ti: float, tr: float) -> float | None:
        """Move to (ti, tr), approaching both arms from below (the scans' direction);
        returns the move's size for the ETA (``None``: no move)."""
        pos = self._position or await self.goniometer.positions_deg()
        moves = legs(pos, ti, tr)
        if len(moves) == 2:
            pre = moves[0][1]
            try:
                self.goniometer.check_geometry(*pre)
                await self.goniometer.move_to(pre[0], pre[1], self.move_timeout_s)
            except DeviceError as exc:
                # said and counted, not skipped silently: this sweep's backlash differs
                self.approaches_skipped += 1
                self.bus.publish(
                    InstrumentError(
                        run_id=self.run_id,
                        device="goniometer",
                        message=(
                            f"approach from below skipped: theta_i {pre[0]:g}, theta_r "
                            f"{pre[1]:g} deg: {exc}; moving to theta_i {ti:g}, theta_r "
                            f"{tr:g} deg directly (the arms' backlash is not taken out there)"
                        ),
                        fatal=False,
                    )
                )
        await self.goniometer.move_to(ti, tr, self.move_timeout_s)
        self._position = (ti, tr)
        return None if (ti, tr) == tuple(pos) else move_size(self.motion, moves)

    async def _place(self, specimen: str) -> None:
        """The operator (or the simulated lab) places ``specimen``: not the run's pace."""
        if self._eta is not None:
            self._eta.pause()
        try:
            await self.place_specimen(specimen)
        finally:
            if self._eta is not None:
                self._eta.resume()

    async def _read(self, specimen: str, phase: str, ti: float, tr: float) -> float:
        if self._abort:
            raise AlignAborted(f"aborted after {self._index} readings")
        eta = self._eta
        mark = None if eta is None else eta.start_part()
        move_x = await self._go(ti, tr)
        if eta is not None and mark is not None and move_x is not None:
            eta.finish_part("move", move_x, mark)
        mark = None if eta is None else eta.start_part()
        reading, self._exposure_us = await self.exposure.read(self.spectro, self._exposure_us)
        value = float(reading.luminance_pct)
        quality = reading_quality(reading)
        if quality == "saturated":
            self._saturated[specimen] = self._saturated.get(specimen, 0) + 1
        elif quality == "unknown":
            self._unknown_level += 1
        ts = time.time()
        self.store.add_point(
            self.run_id,
            index=self._index,
            repeat=0,
            theta_i_deg=ti,
            theta_r_deg=tr,
            measured_theta_i_deg=ti,
            measured_theta_r_deg=tr,
            luminance_pct=value,
            raw={
                "specimen": specimen,
                "phase": phase,
                "exposure_us": reading.exposure_us,
                "peak_fraction": reading.peak_fraction,
                "quality": quality,
                "clock_s": self.clock.now(),
            },
            timestamp=ts,
        )
        if eta is not None and mark is not None:
            eta.finish_part("reading", self.plan.exposure_us * 1e-6, mark)
        self._index += 1
        self.bus.publish(
            PointMeasured(
                run_id=self.run_id, timestamp=ts, index=self._index - 1, repeat=0,
                theta_i_deg=ti, theta_r_deg=tr, luminance_pct=value,
                measured_theta_i_deg=ti, measured_theta_r_deg=tr, predicted_pct=None,
            )
        )  # fmt: skip
        if eta is not None:
            eta.finish_point()
        self.bus.publish(
            Progress(run_id=self.run_id, done=self._index, total=self._total,
                     eta_s=eta_left(self._eta, self._total - self._index))
        )  # fmt: skip
        return value

    async def _peak_sweeps(
        self, specimen: str, ti: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Coarse sweep, then fine sweep around the coarse maximum, extended a fine step at
        a time (up to the coarse span) on a side whose half-maximum crossing it misses.

        Returns the coarse angles and values, then the fine ones sorted by angle.
        """
        coarse, _ = self.plan.sweeps(ti)
        lo, hi = self.goniometer.detector.limits_deg
        coarse = coarse[(coarse >= lo) & (coarse <= hi)]
        c_vals = [await self._read(specimen, "coarse", ti, float(t)) for t in coarse]
        centre = float(coarse[int(np.argmax(c_vals))])
        fine = self.plan.fine(centre)
        fine = fine[(fine >= lo) & (fine <= hi)]
        # centred on the measured maximum, the fine sweep may lose other readings than
        # the nominal one to a limit
        self._total += len(sweep(self.plan, (lo, hi), ti, centre)) - len(
            sweep(self.plan, (lo, hi), ti, ti)
        )
        readings = {float(t): await self._read(specimen, "fine", ti, float(t)) for t in fine}
        step = self.plan.fine_step_deg
        for _ in range(round(self.plan.coarse_span_deg / step)):
            xs = sorted(readings)
            ys = [readings[x] for x in xs]
            k = int(np.argmax(ys))
            half = 0.5 * ys[k]
            more = []
            if min(ys[: k + 1]) > half and xs[0] - step >= lo:
                more.append(round(xs[0] - step, 9))
            if min(ys[k:]) > half and xs[-1] + step <= hi:
                more.append(round(xs[-1] + step, 9))
            if not more:
                break
            self._total += len(more)
            for t in more:
                readings[t] = await self._read(specimen, "fine", ti, t)
        xs = sorted(readings)
        return (
            coarse,
            np.asarray(c_vals),
            np.asarray(xs, dtype=np.float64),
            np.asarray([readings[x] for x in xs]),
        )

    def _standard_index(self) -> tuple[float, dict[str, Any]]:
        """The black glass's certified index and its citation."""
        if self.standard is None:
            return BLACK_GLASS_N, {"standard": "black_glass", "certificate": "none (ISO 2813 n)",
                                   "n": BLACK_GLASS_N}  # fmt: skip
        if self.standard.model != "fresnel":
            raise AlignRefused(
                f"refused: the alignment needs the black glass as a Fresnel model (n), the "
                f"standard {self.standard.name!r} in {self.standard.source} is a "
                f"{self.standard.model!r}"
            )
        return self.standard.n, self.standard.cite()

    async def run(self) -> AlignResult:
        """Measure and fit; the corrections of an earlier alignment are off meanwhile."""
        saved = self.goniometer.corrections_deg
        self.goniometer.corrections_deg = (0.0, 0.0)
        self.bus.publish(
            RunStarted(run_id=self.run_id, kind="align", total_points=self._total,
                       plan=self.plan.to_dict(), sample=self.plan.sample)
        )  # fmt: skip
        self.store.set_status(self.run_id, RunState.RUNNING.value)
        self.bus.publish(StateChanged(run_id=self.run_id, state=RunState.RUNNING, reason=""))
        try:
            await self.spectro.set_exposure_us(self._exposure_us)
            start = await self.goniometer.positions_deg()
            parts = nominal_parts(self._nominal, (float(start[0]), float(start[1])),
                                  self.motion, self.plan.exposure_us * 1e-6)  # fmt: skip
            self._eta = EtaEstimator(parts, None, self.wall, move_known=self.motion is not None)
            self.bus.publish(
                Progress(run_id=self.run_id, done=0, total=self._total, eta_s=self._eta.total_s)
            )
            await self._place("standard")
            self._eta.begin_point()
            lamp: list[float] = []
            det: list[float] = []
            vals: list[float] = []
            peaks: list[dict[str, Any]] = []
            for ti in sorted(self.plan.theta_i_deg):
                ct, cv, ft, fv = await self._peak_sweeps("standard", ti)
                lamp.extend([ti] * (ct.size + ft.size))
                det.extend(ct.tolist() + ft.tolist())
                vals.extend(cv.tolist() + fv.tolist())
                peaks.append({"specimen": "standard", "theta_i_deg": ti,
                              "peak_deg": half_max_midpoint(ft, fv),
                              "amplitude_pct": float(max(cv.max(), fv.max()))})  # fmt: skip
            n, cite = self._standard_index()
            fit = fit_standard_full(
                lamp, det, vals, source=self.predictor.source,
                detector=self.predictor.detector, n=n,
            )  # fmt: skip
            check_standard(
                fit, [pk for pk in peaks if pk["specimen"] == "standard"], self.gates,
                n=n, certificate=str(cite.get("certificate", "none")),
                saturated=self._saturated.get("standard", 0),
            )  # fmt: skip
            if math.isnan(fit.s_weight_sigma):
                # said, not silently assumed (issue 21: a 2 % polarisation dependence moves
                # both zeros ~0.3 deg, and no gate sees it)
                self.bus.publish(
                    InstrumentError(
                        run_id=self.run_id,
                        device="spectro",
                        message=(
                            "the black-glass fit takes the spectro as insensitive to "
                            f"polarisation: {len(set(lamp))} incidences cannot tell it from the "
                            "lamp zero (a 2 % polarisation dependence moves both zeros ~0.3 "
                            "deg); align at three or more incidences to fit it"
                        ),
                        fatal=False,
                    )
                )
            d_l, d_d, rms = fit.lamp_zero_deg, fit.detector_zero_deg, fit.rms_rel
            await self._place("sample")
            self._position = None
            taus: list[tuple[float, float]] = []
            step = self.plan.fine_step_deg
            for ti in sorted(self.plan.theta_i_deg):
                _, _, ft, fv = await self._peak_sweeps("sample", ti)
                mid = half_max_midpoint(ft, fv)
                # the prediction at the nominal geometry, on the same grid phase as the
                # fine sweep (same interpolation bias), centred on the nominal specular:
                # the measured sweep is centred on the shifted peak and may not hold the
                # predicted one's crossings
                n = round((self.plan.fine_span_deg + self.plan.coarse_span_deg) / step)
                pt = np.asarray(ti + step * np.arange(-n, n + 1), dtype=np.float64)
                pmid = half_max_midpoint(pt, await self.predictor.predict(ti, pt.tolist()))
                delta = mid - pmid
                tau = 0.5 * (delta - (d_l - d_d))
                if math.isfinite(tau) and math.isfinite(pmid):
                    # trust the incidences where the model's own peak is symmetric: there
                    # the midpoint depends least on the lobe's shape (and its model error)
                    taus.append((tau, 1.0 / (0.02 + abs(pmid - ti)) ** 2))
                peaks.append({"specimen": "sample", "theta_i_deg": ti, "peak_deg": mid,
                              "predicted_peak_deg": pmid, "amplitude_pct": float(fv.max()),
                              "tilt_deg": tau})  # fmt: skip
            if not taus:
                raise RuntimeError("no sample peak was bracketed by the fine sweeps")
            result = AlignResult(
                lamp_zero_deg=d_l,
                detector_zero_deg=d_d,
                sample_tilt_deg=float(
                    np.average([t for t, _ in taus], weights=[w for _, w in taus])
                ),
                standard_rms_rel=rms,
                peaks=peaks,
                readings=self._index,
                standard_fit=fit.as_dict(),
                standard={**cite, "signal_level_unknown_readings": self._unknown_level},
                approaches_skipped=self.approaches_skipped,
                warnings=self.warnings.lines(),
            )
        except AlignAborted as exc:
            self.store.set_status(self.run_id, RunState.ABORTED.value, str(exc))
            self.bus.publish(
                StateChanged(run_id=self.run_id, state=RunState.ABORTED, reason=str(exc))
            )
            self.finished = True
            self.bus.publish(
                RunFinished(run_id=self.run_id, state=RunState.ABORTED, reason=str(exc), summary={})
            )
            raise
        except Exception as exc:
            # an instrument fault or a defect: the run is recorded as failed with the reason
            # and the failure published (a UI waiting for the run's end sees it), then raised
            reason = str(exc) if isinstance(exc, DeviceError | AlignRefused) else (
                f"internal error: {type(exc).__name__}: {exc}"
            )  # fmt: skip
            self.store.set_status(self.run_id, RunState.FAILED.value, reason)
            self.finished = True
            self.bus.publish(StateChanged(run_id=self.run_id, state=RunState.FAILED, reason=reason))
            self.bus.publish(
                RunFinished(run_id=self.run_id, state=RunState.FAILED, reason=reason, summary={})
            )
            raise
        finally:
            self.goniometer.corrections_deg = saved
        self.store.update_model(self.run_id, {"alignment": result.as_dict()})
        if self.persist is not None:
            try:
                result.state_file = self.persist(result)
            except Exception as exc:
                reason = f"the result could not be saved: {exc}"
                self.store.set_status(self.run_id, RunState.FAILED.value, reason)
                self.finished = True
                self.bus.publish(
                    StateChanged(run_id=self.run_id, state=RunState.FAILED, reason=reason)
                )
                self.bus.publish(
                    RunFinished(run_id=self.run_id, state=RunState.FAILED, reason=reason,
                                summary=result.as_dict())
                )  # fmt: skip
                raise
            self.store.update_model(self.run_id, {"alignment": result.as_dict()})
        self.store.set_status(self.run_id, RunState.DONE.value)
        self.bus.publish(StateChanged(run_id=self.run_id, state=RunState.DONE, reason=""))
        self.finished = True
        self.bus.publish(
            RunFinished(
                run_id=self.run_id, state=RunState.DONE, reason="", summary=result.as_dict()
            )
        )
        return result


def corrections_from(alignment: Mapping[str, float]) -> tuple[float, float]:
    """``(lamp, detector)`` corrections of an ``[alignment]`` table's three estimates."""
    d_l = float(alignment.get("lamp_zero_deg", 0.0))
    d_d = float(alignment.get("detector_zero_deg", 0.0))
    tau = float(alignment.get("sample_tilt_deg", 0.0))
    return -(d_l + tau), -(d_d - tau)
