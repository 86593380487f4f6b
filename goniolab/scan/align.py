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
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.base import DeviceError, Spectrocolorimeter
from drivers.goniometer import TwoArmGoniometer
from drivers.timing import Clock
from goniolab.optics.apertures import Cone, cap_overlap_fraction
from goniolab.optics.fresnel import fresnel, fresnel_dielectric_sp
from goniolab.scan.events import (
    EventBus,
    InstrumentError,
    PointMeasured,
    Progress,
    RunFinished,
    RunStarted,
    RunState,
    StateChanged,
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

#: Refractive index of the ISO 2813 black-glass standard.
BLACK_GLASS_N = 1.567

FloatArray = NDArray[np.float64]
SpecimenHook = Callable[[str], Awaitable[None]]


class AlignAborted(RuntimeError):
    """The alignment was aborted (:meth:`AlignRunner.abort`) before its result."""


class AlignRefused(RuntimeError):
    """The standard's readings fail a quality gate (:class:`AlignGates`): a missing, wrong
    or saturated standard, a fit that does not describe the data. Nothing is written."""


@dataclass(frozen=True, slots=True)
class AlignGates:
    """What the black-glass readings must pass before their zeros are believed.

    ``scale_tolerance``: the fitted scale ``k`` (reading / certified reading) within
    ``1 +/- scale_tolerance`` (the instrument reports % of a perfect mirror, the standard's
    certificate says what it reflects); ``max_rms_rel``: the fit's relative rms over the
    readings above 10 % of the peak; ``max_sigma_deg``: the 1-sigma uncertainty of each
    zero from the fit's covariance; ``max_geometric_gap_deg``: the fit's ``dL - dD`` against
    the peaks' own half-maximum midpoints (a check that does not rest on the Fresnel shape).
    """

    scale_tolerance: float = 0.15
    max_rms_rel: float = 0.02
    max_sigma_deg: float = 0.05
    max_geometric_gap_deg: float = 0.1
    #: the fitted detector polarisation weight ``w`` (share of its response to s light)
    #: within ``0.5 +/- max_s_weight_dev``: a polarisation dependence ``2w - 1`` beyond
    #: 20 % is no fibre-fed spectrometer's, it is a misfit
    max_s_weight_dev: float = 0.1


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
        }


def half_max_midpoint(
    theta_deg: Sequence[float] | FloatArray, values: Sequence[float] | FloatArray
) -> float:
    """Midpoint of the half-maximum crossings around the largest value (linear
    interpolation); NaN when a crossing lies outside the sweep."""
    x = np.asarray(theta_deg, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    k = int(np.argmax(y))
    half = 0.5 * float(y[k])
    left = right = math.nan
    for j in range(k, 0, -1):
        if y[j - 1] <= half < y[j]:
            left = x[j - 1] + (half - y[j - 1]) * (x[j] - x[j - 1]) / (y[j] - y[j - 1])
            break
    for j in range(k, x.size - 1):
        if y[j + 1] <= half < y[j]:
            right = x[j] + (half - y[j]) * (x[j + 1] - x[j]) / (y[j + 1] - y[j])
            break
    return 0.5 * (left + right)


def _standard_model(
    params: FloatArray,
    lamp: FloatArray,
    det: FloatArray,
    source: Cone,
    detector: Cone,
    n: float = BLACK_GLASS_N,
) -> FloatArray:
    """The black glass's reading; ``params = (dL, dD, k, floor[, w])``: with ``w`` the
    detector's share of response to s-polarised light, ``R = w R_s + (1 - w) R_p``
    (Fresnel, Born & Wolf sec. 1.5.2), without it the unpolarised mean."""
    d_l, d_d, k, floor = params[:4]
    if len(params) > 4:
        w = float(params[4])
        r_s, r_p = fresnel_dielectric_sp(np.cos(np.radians(lamp + d_l)), n)
        r = w * np.asarray(r_s) + (1.0 - w) * np.asarray(r_p)
    else:
        r = fresnel(np.cos(np.radians(lamp + d_l)), n)
    gamma = np.radians(np.abs(det + d_d - lamp - d_l))
    o = cap_overlap_fraction(
        gamma, math.radians(source.half_angle_deg), math.radians(detector.half_angle_deg)
    )
    return np.asarray(k * 100.0 * r * o + floor)


@dataclass(frozen=True, slots=True)
class StandardFit:
    """The black-glass fit: zeros (deg), scale ``k`` and stray floor (%), the relative rms
    of the readings above 10 % of the peak, the zeros' 1-sigma uncertainties (deg) from
    the covariance ``s^2 (J^T J)^-1`` (``s^2`` the reduced chi-square), and ``dL - dD``
    from the peaks' half-maximum midpoints alone (the geometric check)."""

    lamp_zero_deg: float
    detector_zero_deg: float
    scale: float
    floor_pct: float
    rms_rel: float
    lamp_zero_sigma_deg: float
    detector_zero_sigma_deg: float
    geometric_difference_deg: float
    #: the detector's share of response to s-polarised light, fitted with its 1-sigma
    #: (three or more incidences), else 0.5 assumed (sigma NaN)
    s_weight: float = 0.5
    s_weight_sigma: float = math.nan

    def as_dict(self) -> dict[str, float]:
        """JSON form."""
        return {
            "s_weight": self.s_weight,
            "s_weight_sigma": self.s_weight_sigma,
            "lamp_zero_deg": self.lamp_zero_deg,
            "detector_zero_deg": self.detector_zero_deg,
            "scale": self.scale,
            "floor_pct": self.floor_pct,
            "rms_rel": self.rms_rel,
            "lamp_zero_sigma_deg": self.lamp_zero_sigma_deg,
            "detector_zero_sigma_deg": self.detector_zero_sigma_deg,
            "fit_difference_deg": self.lamp_zero_deg - self.detector_zero_deg,
            "geometric_difference_deg": self.geometric_difference_deg,
        }


def fit_standard(
    lamp_deg: Sequence[float],
    det_deg: Sequence[float],
    values_pct: Sequence[float],
    *,
    source: Cone,
    detector: Cone,
) -> tuple[float, float, float]:
    """Fit the black-glass readings: ``(lamp_zero_deg, detector_zero_deg, rms_rel)``
    (:func:`fit_standard_full`)."""
    f = fit_standard_full(lamp_deg, det_deg, values_pct, source=source, detector=detector)
    return f.lamp_zero_deg, f.detector_zero_deg, f.rms_rel


def fit_standard_full(
    lamp_deg: Sequence[float],
    det_deg: Sequence[float],
    values_pct: Sequence[float],
    *,
    source: Cone,
    detector: Cone,
    n: float = BLACK_GLASS_N,
    fit_polarisation: bool | None = None,
) -> StandardFit:
    """Fit the black-glass readings (certified index ``n``).

    Weighted least squares (``scipy.optimize.least_squares``) of the closed-form reading
    (module docstring) over all readings, 0.3 % relative plus 5e-4 % absolute sigma; the
    parameter covariance is ``s^2 (J^T J)^-1`` at the solution (Press et al., *Numerical
    Recipes*, 3rd ed., sec. 15.5), ``s^2`` the reduced chi-square.

    ``fit_polarisation`` (default: with three or more incidences) also fits the detector's
    polarisation weight ``w`` (:func:`_standard_model`). A fibre-fed grating spectrometer
    answers s and p light unequally by a few % and the glass polarises strongly
    (R_s 18 %, R_p 0.4 % at 60 deg): an unpolarised fit of a detector with ``w = 0.51``
    (2 % polarisation dependence) puts both zeros 0.27 deg off with an rms of 0.4 %, which
    no gate sees (issue 21: "the absolute zeros rest on the shape of the Fresnel curve").
    The peaks' heights at three incidences fix ``k``, ``dL`` and ``w`` together (R_s and
    R_p change differently with incidence); with two, ``w`` is taken as 0.5 and said so
    (``s_weight_sigma`` NaN).
    """
    from scipy.optimize import least_squares

    lamp = np.asarray(lamp_deg, dtype=np.float64)
    det = np.asarray(det_deg, dtype=np.float64)
    y = np.asarray(values_pct, dtype=np.float64)
    sigma = 0.003 * np.abs(y) + 5e-4
    # start: the peaks' shift gives dL - dD; dL = 0
    shifts = []
    for t in np.unique(lamp):
        sel = lamp == t
        order = np.argsort(det[sel])
        mid = half_max_midpoint(det[sel][order], y[sel][order])
        if math.isfinite(mid):
            shifts.append(mid - t)
    s0 = float(np.mean(shifts)) if shifts else 0.0

    def resid(p: FloatArray) -> FloatArray:
        return np.asarray((_standard_model(p, lamp, det, source, detector, n) - y) / sigma)

    with_w = np.unique(lamp).size >= 3 if fit_polarisation is None else fit_polarisation
    x0 = [0.0, -s0, 1.0, 0.0] + ([0.5] if with_w else [])
    scale = [0.1, 0.1, 0.1, 1e-3] + ([0.01] if with_w else [])
    fit = least_squares(resid, x0=np.array(x0), x_scale=np.array(scale))
    d_l, d_d = float(fit.x[0]), float(fit.x[1])
    model = _standard_model(fit.x, lamp, det, source, detector, n)
    big = y > 0.1 * y.max()
    rms = float(np.sqrt(np.mean(((model - y)[big] / y[big]) ** 2)))
    dof = max(y.size - fit.x.size, 1)
    s2 = float(np.sum(fit.fun**2)) / dof
    try:
        cov = np.linalg.inv(fit.jac.T @ fit.jac) * s2
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        sd = np.full(fit.x.size, math.inf)
    return StandardFit(
        lamp_zero_deg=d_l,
        detector_zero_deg=d_d,
        scale=float(fit.x[2]),
        floor_pct=float(fit.x[3]),
        rms_rel=rms,
        lamp_zero_sigma_deg=float(sd[0]),
        detector_zero_sigma_deg=float(sd[1]),
        geometric_difference_deg=float(np.mean(shifts)) if shifts else math.nan,
        s_weight=float(fit.x[4]) if with_w else 0.5,
        s_weight_sigma=float(sd[4]) if with_w else math.nan,
    )


def check_standard(
    fit: StandardFit,
    peaks: Sequence[Mapping[str, Any]],
    gates: AlignGates,
    *,
    n: float,
    certificate: str,
    saturated: int,
) -> None:
    """Refuse (:class:`AlignRefused`, saying which) a standard that is saturated, missing
    (a sample or nothing), wrong (the mirror reads ~20x black glass), or a fit that does not
    describe the readings; the message quotes the numbers against the certificate."""
    if saturated:
        raise AlignRefused(
            f"refused: {saturated} black-glass readings saturated the spectro even at the "
            "shortest exposure (the instrument reports a clipped channel): reduce the lamp "
            "or check the spectro"
        )
    ratios = []
    for pk in peaks:
        want = 100.0 * float(fresnel(math.cos(math.radians(float(pk["theta_i_deg"]))), n))
        ratios.append((float(pk["amplitude_pct"]) / want, pk, want))
    worst = max(ratios, key=lambda r: abs(math.log(max(r[0], 1e-9))))
    ratio, pk, want = worst
    quote = (
        f"peak {pk['amplitude_pct']:.3g} % at theta_i {pk['theta_i_deg']:g} deg where black "
        f"glass n = {n:g} (certificate {certificate}) reads {want:.3g} %"
    )
    if ratio > 5.0:
        raise AlignRefused(
            f"refused: not the black-glass standard: {quote}; this reads like a mirror. "
            "Place the black-glass standard"
        )
    if not (1.0 - gates.scale_tolerance <= ratio <= 1.0 + gates.scale_tolerance) or not (
        1.0 - gates.scale_tolerance <= fit.scale <= 1.0 + gates.scale_tolerance
    ):
        raise AlignRefused(
            f"refused: the black-glass standard is missing or misplaced: {quote} "
            f"(fitted scale {fit.scale:.3g}, allowed 1 +/- {gates.scale_tolerance:g}). "
            "Place the black-glass standard on the reference seat"
        )
    if fit.rms_rel > gates.max_rms_rel:
        raise AlignRefused(
            f"refused: the black-glass fit misses its readings by {100 * fit.rms_rel:.2f} % "
            f"rms (allowed {100 * gates.max_rms_rel:g} %): not a clean flat standard?"
        )
    sig = max(fit.lamp_zero_sigma_deg, fit.detector_zero_sigma_deg)
    if not sig <= gates.max_sigma_deg:
        raise AlignRefused(
            f"refused: the zeros are uncertain to {sig:.3g} deg (1 sigma; allowed "
            f"{gates.max_sigma_deg:g} deg): add incidences or finer sweeps"
        )
    if not abs(fit.s_weight - 0.5) <= gates.max_s_weight_dev:
        raise AlignRefused(
            f"refused: the black-glass fit needs a detector answering {100 * fit.s_weight:.1f} % "
            f"to s-polarised light (allowed 50 +/- {100 * gates.max_s_weight_dev:g} %): "
            "the readings do not follow the glass's Fresnel curve"
        )
    gap = abs(fit.lamp_zero_deg - fit.detector_zero_deg - fit.geometric_difference_deg)
    if not gap <= gates.max_geometric_gap_deg:
        raise AlignRefused(
            f"refused: the fit puts dL - dD at "
            f"{fit.lamp_zero_deg - fit.detector_zero_deg:+.3f} deg, the peaks' own midpoints "
            f"at {fit.geometric_difference_deg:+.3f} deg (allowed gap "
            f"{gates.max_geometric_gap_deg:g} deg)"
        )


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
    ) -> None:
        self.goniometer = goniometer
        self.spectro = spectro
        self.clock = clock
        self.plan = plan
        self.predictor = predictor
        self.place_specimen = place_specimen
        self.store = store
        self.run_id = run_id
        self.bus = bus
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
        self._abort = False
        #: :meth:`run` has published the run's end (done, aborted or failed)
        self.finished = False
        n_coarse = len(plan.sweeps(plan.theta_i_deg[0])[0])
        n_fine = len(plan.fine(0.0))
        self._total = 2 * len(plan.theta_i_deg) * (n_coarse + n_fine)

    @property
    def aborted(self) -> bool:
        """:meth:`abort` was called."""
        return self._abort

    def abort(self) -> None:
        """Stop before the next reading: :meth:`run` stores the run as aborted (its
        readings kept, no result) and raises :class:`AlignAborted`."""
        self._abort = True

    async def _go(self, ti: float, tr: float) -> None:
        """Move to (ti, tr), approaching both arms from below (the scans' direction)."""
        pos = self._position or await self.goniometer.positions_deg()
        if ti < pos[0] - 1e-9 or tr < pos[1] - 1e-9:
            pre = (min(ti, pos[0]) - 0.5, min(tr, pos[1]) - 0.5)
            try:
                self.goniometer.check_geometry(*pre)
                await self.goniometer.move_to(pre[0], pre[1], self.move_timeout_s)
            except Exception:
                pass
        await self.goniometer.move_to(ti, tr, self.move_timeout_s)
        self._position = (ti, tr)

    async def _read(self, specimen: str, phase: str, ti: float, tr: float) -> float:
        if self._abort:
            raise AlignAborted(f"aborted after {self._index} readings")
        await self._go(ti, tr)
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
        self._index += 1
        self.bus.publish(
            PointMeasured(
                run_id=self.run_id, timestamp=ts, index=self._index - 1, repeat=0,
                theta_i_deg=ti, theta_r_deg=tr, luminance_pct=value,
                measured_theta_i_deg=ti, measured_theta_r_deg=tr, predicted_pct=None,
            )
        )  # fmt: skip
        self.bus.publish(
            Progress(run_id=self.run_id, done=self._index, total=self._total, eta_s=0.0)
        )
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
            await self.place_specimen("standard")
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
            await self.place_specimen("sample")
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
