"""Measured-beside-predicted bookkeeping for the TUI (no Textual here, so it is testable alone).

A :class:`Comparison` accumulates the scan events of one run (every repeat of every plan
point, and the model's prediction for each point) and derives what the screens show:
mean and min/max of the repeats, the residuals, and the seed's comparison metrics.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 4.2, fig. 8: measured
   and computed in-plane curves are compared by peak amplitude and FWHM
   (:func:`goniolab.optics.metrics.peak_metrics`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.metrics import PeakMetrics, peak_metrics
from goniolab.scan.events import ColourPredicted, GlossRead, PointMeasured, PointPredicted

__all__ = ["ColourArrays", "Comparison", "ComparisonMetrics", "CurveArrays"]

FloatArray = NDArray[np.float64]


def _peak_or_nan(theta_deg: FloatArray, values: FloatArray) -> PeakMetrics:
    """:func:`goniolab.optics.metrics.peak_metrics` of the finite samples, NaN when too few.

    A live scan has gaps (points not yet measured or predicted); the metrics of the
    samples received so far are shown, and NaN (a ``-`` cell) until three are in.
    """
    ok = np.isfinite(theta_deg) & np.isfinite(values)
    theta, vals = theta_deg[ok], values[ok]
    # Repeats of one geometry share theta: arrays() already averages them, so theta is
    # strictly increasing unless the plan itself repeats an angle.
    if theta.size < 3 or np.any(np.diff(theta) <= 0):
        return PeakMetrics(math.nan, math.nan, math.nan)
    return peak_metrics(theta, vals)


def _is_a_peak(theta_deg: FloatArray, values: FloatArray, predicted_deg: float) -> bool:
    """The measured maximum is a peak: not at either end of the measured range and, when
    the predicted peak is known, the measured range contains the predicted peak position.

    :mod:`goniolab.scan.summary` applies the same rule to a finished run (no peak
    comparison unless the measured range contains the specular direction; the peak
    metrics are those of Wittmann et al. 2021, sec. 4.2).
    """
    ok = np.isfinite(theta_deg) & np.isfinite(values)
    theta, vals = theta_deg[ok], values[ok]
    if theta.size < 3:
        return False
    k = int(np.argmax(vals))
    if k in (0, theta.size - 1):
        return False
    return not math.isfinite(predicted_deg) or bool(theta[0] <= predicted_deg <= theta[-1])


@dataclass(frozen=True, slots=True)
class CurveArrays:
    """The per-point arrays the plots draw, sorted by ``theta_r_deg``.

    ``mean_pct``/``min_pct``/``max_pct`` are NaN where the point has no reading yet,
    ``predicted_pct`` is NaN where the model's prediction has not arrived.
    """

    theta_r_deg: FloatArray
    mean_pct: FloatArray
    min_pct: FloatArray
    max_pct: FloatArray
    predicted_pct: FloatArray
    n_readings: NDArray[np.int64]

    @property
    def residual_pct(self) -> FloatArray:
        """Measured mean minus predicted, in % of a mirror (NaN where either is missing)."""
        return self.mean_pct - self.predicted_pct


@dataclass(frozen=True, slots=True)
class ColourArrays:
    """Per point, sorted by ``theta_r_deg``: measured L*a*b* (the repeats with colour
    averaged as spectra, :meth:`Comparison.mean_lab`) and predicted L*a*b*, shape ``(n, 3)``, NaN where not (yet) known."""

    theta_r_deg: FloatArray
    measured_lab: FloatArray
    predicted_lab: FloatArray
    #: Incidence of the run (the aspecular angles are ``theta_i - theta_r``, ASTM E2194).
    theta_i_deg: float = 45.0
    #: Per point: the model that computed its predicted colour (``None``: no prediction, or
    #: the run does not say) and the note of a wavelength-free model (``None``: no note),
    #: as the app layer says them (:func:`goniolab.app.colour_notes.predicted_colour_models`,
    #: the same as ``goniolab runs colour``).
    predicted_model: tuple[str | None, ...] = ()
    predicted_colour_note: tuple[str | None, ...] = ()
    #: One note per wavelength-free model, naming its angles (the table's legend).
    predicted_colour_notes: tuple[str, ...] = ()
    #: Where repeats were averaged as L*a*b* instead of as spectra, and why
    #: (:func:`goniolab.app.colour_notes.averaging_notes`, as ``runs colour`` says it).
    averaging_notes: tuple[str, ...] = ()

    @property
    def aspecular_deg(self) -> FloatArray:
        """ASTM E2194 aspecular angle of each point, ``theta_i - theta_r``."""
        out: FloatArray = self.theta_i_deg - self.theta_r_deg
        return out

    def differences(self) -> dict[str, FloatArray]:
        """dL*, dC*, dH*, dE76/94/00, CMC of predicted vs measured (measured = reference;
        :func:`goniolab.colour.difference.differences`), NaN where either is missing."""
        from goniolab.colour.difference import differences

        return differences(self.measured_lab, self.predicted_lab)

    @property
    def delta_e_ab(self) -> FloatArray:
        """CIE 1976 dE*ab between measured and predicted (NaN where either is missing)."""
        out: FloatArray = np.sqrt(np.sum((self.measured_lab - self.predicted_lab) ** 2, axis=1))
        return out


@dataclass(frozen=True, slots=True)
class ComparisonMetrics:
    """What the metrics table shows: peaks of both curves, RMSE and the last gloss reading."""

    measured: PeakMetrics
    predicted: PeakMetrics
    rmse_pct: float
    n_compared: int
    gloss_measured_gu: dict[int, float | None]
    gloss_predicted_gu: dict[int, float]


@dataclass
class Comparison:
    """Accumulates the readings and predictions of one run.

    Points are keyed by the plan index; repeats of a point are kept individually so
    their scatter can be drawn as min/max bars.
    """

    run_id: int = 0
    sample: str = ""
    readings: dict[int, list[float]] = field(default_factory=dict)
    theta_r_deg: dict[int, float] = field(default_factory=dict)
    predicted: dict[int, float] = field(default_factory=dict)
    gloss: list[GlossRead] = field(default_factory=list)
    #: Measured L*a*b* of each repeat with a colour, per plan point.
    lab: dict[int, list[tuple[float, float, float]]] = field(default_factory=dict)
    #: Measured (XYZ, white) of each repeat with a colour, per plan point (``None`` where
    #: the event carried none: the point's repeats are then averaged as L*a*b*).
    xyz: dict[int, list[tuple[tuple[float, float, float], tuple[float, float, float]] | None]] = (
        field(default_factory=dict)
    )
    #: Predicted L*a*b* per plan point.
    predicted_lab: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    #: The plan point of the last reading with a colour (the swatch shows it).
    last_colour_index: int | None = None
    #: The run's incidence (for the aspecular angles of the colour table).
    theta_i_deg: float = 45.0
    #: readings flagged saturated / under the noise floor (kept off the curve), by flag
    flagged: dict[str, int] = field(default_factory=dict)
    #: The run's stored prediction record (its ``computed_by``: which model computed each
    #: angle, :meth:`goniolab.scan.prediction.Predictor.provenance`); empty until read.
    prediction_record: dict[str, Any] = field(default_factory=dict)

    def clear(self, *, run_id: int = 0, sample: str = "", theta_i_deg: float = 45.0) -> None:
        """Forget the curve and start collecting for ``run_id``.

        Glossmeter readings are a log of the session, not of one scan: they are kept.
        """
        self.run_id = run_id
        self.sample = sample
        self.theta_i_deg = float(theta_i_deg)
        self.readings.clear()
        self.theta_r_deg.clear()
        self.predicted.clear()
        self.lab.clear()
        self.xyz.clear()
        self.predicted_lab.clear()
        self.last_colour_index = None
        self.flagged.clear()
        self.prediction_record = {}

    def add_measured(self, ev: PointMeasured) -> None:
        """Record one reading (one repeat of plan point ``ev.index``).

        Mirror-reference readings (negative plan index, the 100 % level) are not points
        of the curve and are skipped.
        """
        if ev.index < 0:
            return
        if ev.quality in ("saturated", "under_noise_floor"):
            # shown (the runner's warning toast), counted, never averaged into the curve
            self.flagged[ev.quality] = self.flagged.get(ev.quality, 0) + 1
            return
        self.readings.setdefault(ev.index, []).append(ev.luminance_pct)
        self.theta_r_deg.setdefault(ev.index, ev.theta_r_deg)
        if ev.lab is not None:
            self.lab.setdefault(ev.index, []).append(ev.lab)
            xyz, white = ev.xyz, ev.white_xyz
            pair = None if xyz is None or white is None else (xyz, white)
            self.xyz.setdefault(ev.index, []).append(pair)
            self.last_colour_index = ev.index

    def add_colour(self, ev: ColourPredicted) -> None:
        """Record the predicted colour of plan point ``ev.index``."""
        self.predicted_lab[ev.index] = ev.lab
        self.theta_r_deg.setdefault(ev.index, ev.theta_r_deg)

    def current_lab(self) -> tuple[float, float, float] | None:
        """Mean L*a*b* of the point read last (``None`` before the first colour)."""
        i = self.last_colour_index
        if i is None or i not in self.lab:
            return None
        m = self.mean_lab(i)
        return (float(m[0]), float(m[1]), float(m[2]))

    def mean_lab(self, index: int) -> FloatArray:
        """L*a*b* of point ``index``'s repeats averaged *as spectra*: the colour of their
        mean XYZ, which is the XYZ of their mean spectrum (XYZ is linear in the spectrum,
        CIE 15:2004 eq. 7.1; as ``runs show`` and ``runs colour`` average). Readings that
        came without XYZ, or with different whites, are averaged as L*a*b*."""
        pairs = self.xyz.get(index) or []
        whites = {p[1] for p in pairs if p is not None}
        if pairs and all(p is not None for p in pairs) and len(whites) == 1:
            from goniolab.colour.spectra import xyz_to_colour_of_white

            mean_xyz = np.mean(np.array([p[0] for p in pairs if p is not None]), axis=0)
            out: FloatArray = xyz_to_colour_of_white(mean_xyz, next(iter(whites)))[3:6]
            return out
        lab_mean: FloatArray = np.mean(np.array(self.lab[index]), axis=0)
        return lab_mean

    def lab_average_reason(self, index: int) -> str | None:
        """Why :meth:`mean_lab` averages point ``index``'s repeats as L*a*b* (``None``:
        it averages them as spectra, or there is nothing to average)."""
        pairs = self.xyz.get(index) or []
        if len(self.lab.get(index) or []) < 2:
            return None
        missing = sum(p is None for p in pairs)
        if missing:
            return f"{missing} of its readings came without XYZ (their white unknown)"
        if len({p[1] for p in pairs if p is not None}) > 1:
            return "its readings' L*a*b* are relative to different whites"
        return None

    def colour_arrays(self) -> ColourArrays:
        """Measured and predicted L*a*b* per point, sorted by theta_r."""
        idx = sorted(self.theta_r_deg, key=lambda i: (self.theta_r_deg[i], i))
        theta = np.array([self.theta_r_deg[i] for i in idx], dtype=np.float64)
        meas = np.full((theta.size, 3), np.nan)
        pred = np.full((theta.size, 3), np.nan)
        for k, i in enumerate(idx):
            if self.lab.get(i):
                meas[k] = self.mean_lab(i)
            if i in self.predicted_lab:
                pred[k] = self.predicted_lab[i]
        from goniolab.app.colour_notes import predicted_colour_models

        has = [k for k, i in enumerate(idx) if i in self.predicted_lab]
        got = predicted_colour_models(self.prediction_record, [float(theta[k]) for k in has])
        model: list[str | None] = [None] * len(idx)
        note: list[str | None] = [None] * len(idx)
        for k, m, n in zip(has, got.model, got.note, strict=True):
            model[k], note[k] = m, n
        from goniolab.app.colour_notes import averaging_notes

        rows = [
            {"theta_r_deg": float(theta[k]), "averaged": "lab", "n": len(self.lab[i]),
             "averaged_reason": why}
            for k, i in enumerate(idx)
            if (why := self.lab_average_reason(i)) is not None
        ]  # fmt: skip
        return ColourArrays(
            theta, meas, pred, self.theta_i_deg, tuple(model), tuple(note), tuple(got.notes),
            tuple(averaging_notes(rows)),
        )  # fmt: skip

    def add_predicted(self, ev: PointPredicted) -> None:
        """Record the model's prediction for plan point ``ev.index``."""
        self.predicted[ev.index] = ev.predicted_pct
        self.theta_r_deg.setdefault(ev.index, ev.theta_r_deg)

    def add_gloss(self, ev: GlossRead) -> None:
        """Record one glossmeter reading (with its prediction, if any)."""
        self.gloss.append(ev)

    @property
    def n_readings(self) -> int:
        """Number of readings (all repeats of all points) received so far."""
        return sum(len(v) for v in self.readings.values())

    def arrays(self) -> CurveArrays:
        """Per-point arrays sorted by theta_r (NaN where data has not arrived)."""
        idx = sorted(self.theta_r_deg, key=lambda i: (self.theta_r_deg[i], i))
        theta = np.array([self.theta_r_deg[i] for i in idx], dtype=np.float64)
        mean = np.full(theta.size, np.nan)
        lo = np.full(theta.size, np.nan)
        hi = np.full(theta.size, np.nan)
        pred = np.full(theta.size, np.nan)
        count = np.zeros(theta.size, dtype=np.int64)
        for k, i in enumerate(idx):
            reps = self.readings.get(i)
            if reps:
                mean[k] = float(np.mean(reps))
                lo[k] = min(reps)
                hi[k] = max(reps)
                count[k] = len(reps)
            if i in self.predicted:
                pred[k] = self.predicted[i]
        return CurveArrays(theta, mean, lo, hi, pred, count)

    def metrics(self) -> ComparisonMetrics:
        """Peak metrics of measured mean and predicted curve, their RMSE, last gloss.

        RMSE is ``sqrt(mean((measured_mean - predicted)^2))`` over the points that have
        both a reading and a prediction (NaN when there are none).
        """
        a = self.arrays()
        measured = _peak_or_nan(a.theta_r_deg, a.mean_pct)
        predicted = _peak_or_nan(a.theta_r_deg, a.predicted_pct)
        # A curve still climbing towards the specular direction (a scan in progress, or
        # one that stops short of it) has its maximum at an end: a flank, not a peak, and
        # its "amplitude" and "position" would mislead.
        if not _is_a_peak(a.theta_r_deg, a.predicted_pct, math.nan):
            predicted = PeakMetrics(math.nan, math.nan, math.nan)
        if not _is_a_peak(a.theta_r_deg, a.mean_pct, predicted.position_deg):
            measured = PeakMetrics(math.nan, math.nan, math.nan)
        res = a.residual_pct
        res = res[np.isfinite(res)]
        rmse = float(np.sqrt(np.mean(res**2))) if res.size else math.nan
        last = self.gloss[-1] if self.gloss else None
        return ComparisonMetrics(
            measured=measured,
            predicted=predicted,
            rmse_pct=rmse,
            n_compared=int(res.size),
            gloss_measured_gu=dict(last.values_gu) if last else {},
            gloss_predicted_gu=dict(last.predicted_gu or {}) if last else {},
        )
