"""``goniolab calibrate``: a calibration record later runs cite (docs/CALIBRATION.md).

At the specular geometry ``(theta, theta)`` the calibration reads

1. **the reference mirror** (``configs/standards.toml [mirror]``), ``repeats`` times with
   auto-exposure, averaged as spectra: ``m(lambda)``;
2. **the check standard** (the black glass, ``[black_glass]``), the same way: ``g(lambda)``,
   referenced to the certified mirror (docs/CALIBRATION.md, step 3)::

       R_check(lambda) = g(lambda) / m(lambda) x R_mirror,cert(lambda)

   and its luminance ``Y_check`` (the ``[colour]`` weights) is compared with the
   certificate's ``Y_cert`` as this detector reads it: the glass's Fresnel reflectances
   of its certified index weighted with the detector's share ``w`` of response to
   s-polarised light, ``R = w R_s + (1 - w) R_p`` (Born & Wolf sec. 1.5.2; ISO 2813:2014
   sec. 5.3: n = 1.567), the weighting the alignment fits (:func:`detector_polarisation`);
   ``residual = Y_check - Y_cert``, within the standard's ``tolerance`` or the record
   says it missed. The glass polarises (R_s 10.780 %, R_p 1.162 % at 45 deg), so a 51 % s
   detector reads it 0.096 points above the unpolarised certificate (0.198 at 60 deg,
   the whole 0.2 % tolerance).

The instrument's dark reference is its own (subtracted inside the spectro: the twin's
``SpectroChain``; a real Ruby's dark shutter); a saturated or under-noise-floor reading
refuses the calibration (nothing stored as a calibration). The record (time, exposures,
instrument identification, the mirror's and the check's certificates, the residual) is a
run of kind ``calibration`` with the readings; :func:`latest_calibration` finds it and
:func:`calibration_notices` says what a later run should warn about (age, a missed check).
"""

from __future__ import annotations

import math
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.base import Goniometer, Spectrocolorimeter, SpectroReading
from goniolab.colour.spectra import ColourSettings, xyz_weights
from goniolab.scan.exposure import EXCLUDED_QUALITY, AutoExposure, reading_quality
from goniolab.scan.plans import MIRROR_INDEX
from goniolab.scan.standards import Standard
from goniolab.store import RunRecord, RunStore

__all__ = [
    "UNPOLARISED",
    "CalibrationRefused",
    "DetectorPolarisation",
    "calibration_notices",
    "detector_polarisation",
    "latest_calibration",
    "run_calibration",
]

SpecimenHook = Callable[[str], Awaitable[None]]


class CalibrationRefused(RuntimeError):
    """A reading the calibration cannot use (saturated, under the noise floor)."""


@dataclass(frozen=True, slots=True)
class DetectorPolarisation:
    """The spectro's share ``s_weight`` of response to s-polarised light (0.5: it answers
    s and p alike) and where the number comes from (``source``: ``"fitted"`` by an
    alignment, ``"configured"`` for the simulated detector, ``"assumed"``), with one line
    for the user (``note``)."""

    s_weight: float
    source: str
    note: str
    s_weight_sigma: float = math.nan
    alignment_run: int | None = None

    def as_dict(self) -> dict[str, Any]:
        """What the calibration record stores (JSON: a NaN sigma is ``None``)."""
        return {
            "s_weight": self.s_weight,
            "s_weight_sigma": self.s_weight_sigma if math.isfinite(self.s_weight_sigma) else None,
            "source": self.source,
            "alignment_run": self.alignment_run,
            "note": self.note,
        }


#: A detector taken to answer s and p light alike (nothing fitted or configured).
UNPOLARISED = DetectorPolarisation(
    0.5,
    "assumed",
    "w = 0.5 assumed (unpolarised): no alignment has fitted the detector's s-weight "
    "(goniolab scan --plan align, three or more incidences)",
)


def detector_polarisation(
    store: RunStore, *, alignment_run: int, simulated_s_weight: float | None = None
) -> DetectorPolarisation:
    """The weighting the measurement chain uses for the detector: the ``s_weight`` the
    black-glass fit of the alignment the arms apply found (``alignment_run``, the config's
    ``[alignment] run``; fitted only with three or more incidences, else its ``w = 0.5``
    was assumed), else the simulated detector's ``[sim.twin] s_weight``
    (``simulated_s_weight``, a simulated lab), else :data:`UNPOLARISED`."""
    from goniolab.store import StoreError

    unfitted = ""
    if alignment_run > 0:
        try:
            rec = store.get_run(alignment_run)
        except StoreError:
            rec = None
        fit: dict[str, Any] = {}
        if rec is not None and rec.kind == "align" and rec.status == "done":
            fit = (rec.model.get("alignment") or {}).get("standard_fit") or {}
        w, sd = fit.get("s_weight"), fit.get("s_weight_sigma")
        if isinstance(w, int | float) and isinstance(sd, int | float) and math.isfinite(sd):
            return DetectorPolarisation(
                float(w),
                "fitted",
                f"w = {w:.4f} +/- {sd:.4f} fitted by the black-glass sweeps of alignment run "
                f"{alignment_run} (the alignment the arms apply)",
                float(sd),
                alignment_run,
            )
        unfitted = (
            f"alignment run {alignment_run} fitted no w (two incidences, or not in this store)"
        )
    if simulated_s_weight is not None:
        return DetectorPolarisation(
            float(simulated_s_weight),
            "configured",
            f"w = {simulated_s_weight:g}: the simulated detector's [sim.twin] s_weight "
            f"({unfitted or 'no alignment has fitted w'})",
        )
    if unfitted:
        return DetectorPolarisation(0.5, "assumed", f"w = 0.5 assumed (unpolarised): {unfitted}")
    return UNPOLARISED


@dataclass(frozen=True, slots=True)
class _Read:
    wavelengths_nm: tuple[float, ...]
    mean_pct: np.ndarray
    exposures_us: tuple[int, ...]


async def _read(
    spectro: Spectrocolorimeter,
    store: RunStore,
    run_id: int,
    index: int,
    specimen: str,
    theta_deg: float,
    repeats: int,
    exposure: AutoExposure,
    exposure_us: int,
) -> tuple[_Read, int]:
    readings: list[SpectroReading] = []
    for r in range(repeats):
        reading, exposure_us = await exposure.read(spectro, exposure_us)
        q = reading_quality(reading)
        store.add_point(
            run_id, index=index, repeat=r, theta_i_deg=theta_deg, theta_r_deg=theta_deg,
            measured_theta_i_deg=theta_deg, measured_theta_r_deg=theta_deg,
            luminance_pct=float(reading.luminance_pct),
            raw={"specimen": specimen, "quality": q, "exposure_us": reading.exposure_us,
                 "peak_fraction": reading.peak_fraction,
                 "wavelengths_nm": list(reading.wavelengths_nm), "values": list(reading.values)},
            timestamp=time.time(),
        )  # fmt: skip
        if q in EXCLUDED_QUALITY:
            raise CalibrationRefused(
                f"the {specimen} reading {r} is {q.replace('_', ' ')} at "
                f"{reading.exposure_us} us: no calibration from it"
            )
        readings.append(reading)
    wl = readings[0].wavelengths_nm
    mean = np.mean([np.asarray(x.values, dtype=np.float64) for x in readings], axis=0)
    return _Read(wl, mean, tuple(x.exposure_us for x in readings)), exposure_us


async def run_calibration(
    *,
    goniometer: Goniometer,
    spectro: Spectrocolorimeter,
    place: SpecimenHook,
    store: RunStore,
    run_id: int,
    mirror: Standard,
    check: Standard,
    settings: ColourSettings,
    theta_deg: float = 45.0,
    repeats: int = 3,
    exposure_us: int = 10_000,
    move_timeout_s: float = 30.0,
    polarisation: DetectorPolarisation = UNPOLARISED,
) -> dict[str, Any]:
    """Measure mirror and check standard (module docstring); return the record (also
    stored as the run's model and its status ``done``). ``polarisation``: the detector's
    s-weight the check standard's certificate is read with (:func:`detector_polarisation`).

    Raises
    ------
    CalibrationRefused
        A flagged reading; the run is marked failed by the caller.
    """
    exposure = AutoExposure()
    ident = await spectro.identify()
    await goniometer.move_to(theta_deg, theta_deg, move_timeout_s)
    await spectro.set_exposure_us(exposure_us)
    await place("mirror")
    m, exposure_us = await _read(spectro, store, run_id, MIRROR_INDEX, "mirror", theta_deg,
                                 repeats, exposure, exposure_us)  # fmt: skip
    await place("standard")
    g, exposure_us = await _read(spectro, store, run_id, 0, check.name, theta_deg, repeats,
                                 exposure, exposure_us)  # fmt: skip
    await place("sample")
    if g.wavelengths_nm != m.wavelengths_nm:
        raise CalibrationRefused("mirror and check readings on different wavelength grids")
    w_y = np.asarray(xyz_weights(m.wavelengths_nm, settings)[1])
    r_check = g.mean_pct / m.mean_pct * mirror.reflectance(m.wavelengths_nm, theta_deg)
    y_check = float(w_y @ r_check)
    w = polarisation.s_weight if check.splits_polarisation else 0.5
    y_cert = float(w_y @ check.reflectance(m.wavelengths_nm, theta_deg, s_weight=w))
    y_unpolarised = float(w_y @ check.reflectance(m.wavelengths_nm, theta_deg))
    if check.splits_polarisation:
        weighting = (
            f"R = w R_s + (1 - w) R_p of n = {check.n:g} (Fresnel) at {theta_deg:g} deg, "
            f"{polarisation.note}"
        )
    else:
        weighting = (
            "the certificate's table as it is (unpolarised: it gives no s and p parts; "
            f"the detector's {polarisation.note})"
        )
    residual = y_check - y_cert
    tol_pct = 100.0 * check.tolerance
    now = time.time()
    record: dict[str, Any] = {
        "time": now,
        "time_iso": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(now)),
        "instrument": ident,
        "theta_deg": theta_deg,
        "repeats": repeats,
        "exposure_us": {"mirror": list(m.exposures_us), "check": list(g.exposures_us)},
        "mirror": mirror.cite(),
        "mirror_reading_y_pct": float(w_y @ m.mean_pct) / 100.0,
        "check": {
            **check.cite(),
            "certified_y_pct": y_cert,
            "certified_unpolarised_y_pct": y_unpolarised,
            "s_weight": w,
            "weighting": weighting,
            "polarisation": polarisation.as_dict(),
            "measured_y_pct": y_check,
            "residual_pct": residual,
            "tolerance_pct": tol_pct,
            "ok": bool(abs(residual) <= tol_pct),
        },
        "dark": "the instrument's own dark reference (subtracted in the spectro)",
    }
    store.update_model(run_id, {"calibration": record})
    return record


def latest_calibration(store: RunStore) -> RunRecord | None:
    """The newest finished ``calibration`` run of the store, or None."""
    for rec in store.list_runs():
        if rec.kind == "calibration" and rec.status == "done":
            return rec
    return None


def calibration_notices(
    rec: RunRecord | None, *, max_age_h: float, now: float | None = None
) -> tuple[dict[str, Any], list[str]]:
    """What a run cites of the latest calibration, and the warnings: older than
    ``max_age_h``, or its check standard missed the certificate."""
    if rec is None:
        return {"run": None}, []
    record = rec.model.get("calibration") or {}
    t = float(record.get("time", rec.created_at))
    age_h = ((time.time() if now is None else now) - t) / 3600.0
    check = record.get("check") or {}
    cite = {"run": rec.id, "time_iso": record.get("time_iso", ""), "age_h": age_h,
            "check_ok": check.get("ok"), "check_residual_pct": check.get("residual_pct")}  # fmt: skip
    notes: list[str] = []
    if math.isfinite(max_age_h) and age_h > max_age_h:
        notes.append(
            f"the calibration (run {rec.id}) is {age_h:.1f} h old, older than "
            f"{max_age_h:g} h: run goniolab calibrate"
        )
    if check and not check.get("ok", True):
        notes.append(
            f"the calibration's check standard ({check.get('standard')}, certificate "
            f"{check.get('certificate')}) missed its certificate by "
            f"{float(check.get('residual_pct', math.nan)):+.3f} % (tolerance "
            f"{float(check.get('tolerance_pct', math.nan)):g} %)"
        )
    return cite, notes
