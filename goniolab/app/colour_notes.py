"""Where a colour number comes from, in the words every face shows (issue 25's provenance
rule): which model made each predicted colour and what it cannot predict
(``goniolab predict colour``, ``goniolab runs colour``, the TUI's colour table)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "PredictedColourModels",
    "averaging_notes",
    "calibration_note",
    "predicted_colour_models",
    "predicted_colour_notes",
    "surface_colour_notes",
]


def surface_colour_notes(
    model: Any,
    theta_i: float,
    rows: list[dict[str, Any]],
    source_deg: float,
    detector_deg: float,
) -> list[str]:
    """Name the model that computes each row's coat-surface part (``surface_model``,
    :func:`goniolab.optics.provenance.provenance_of`) and warn where it has no wavelength in
    it (:func:`goniolab.colour.spectral.surface_colour_note`)."""
    from goniolab.colour.spectral import surface_colour_note, wavelength_free
    from goniolab.optics.apertures import Cone
    from goniolab.optics.provenance import provenance_of

    src, det = Cone(source_deg), Cone(detector_deg)
    free: dict[str, list[float]] = {}
    for r in rows:
        t = float(r["theta_r_deg"])
        name = provenance_of(model, theta_i, t, src, det).model
        r["surface_model"] = name
        if wavelength_free(name):
            free.setdefault(name, []).append(t)
    return [surface_colour_note(name, angles) for name, angles in free.items()]


@dataclass(frozen=True, slots=True)
class PredictedColourModels:
    """Which model made each predicted colour of a stored run, and what the user must know
    about it (:func:`predicted_colour_models`): the one source of ``runs colour``'s
    ``predicted_model`` / ``predicted_colour_note`` and the TUI colour table's marks."""

    #: Per angle asked: the model that computed its prediction (``None``: the run does not say).
    model: list[str | None]
    #: Per angle asked: the note of a wavelength-free model (``None``: no note).
    note: list[str | None]
    #: One note per wavelength-free model, naming the angles it computed.
    notes: list[str]


def predicted_colour_models(run_model: Any, theta_r_deg: Sequence[float]) -> PredictedColourModels:
    """Name the model of each predicted colour at ``theta_r_deg`` from a stored run's
    model record (``run_model``: its ``computed_by``,
    :meth:`goniolab.scan.prediction.Predictor.provenance`, or ``model_name`` for a run that
    predates it) and, where that model has no wavelength in it (the facet model), the note
    that its colour from surface scattering is not predicted
    (:func:`goniolab.colour.spectral.surface_colour_note`)."""
    from goniolab.colour.spectral import surface_colour_note, wavelength_free

    model = run_model if isinstance(run_model, dict) else {}
    computed_by = model.get("computed_by")
    by_angle: dict[float, str] = {}
    if isinstance(computed_by, dict):
        for name, angles in computed_by.items():
            for t in angles if isinstance(angles, list) else []:
                by_angle[round(float(t), 6)] = str(name)
    elif isinstance(model.get("model_name"), str):  # a run that predates computed_by
        by_angle = {round(float(t), 6): model["model_name"] for t in theta_r_deg}
    names: list[str | None] = [by_angle.get(round(float(t), 6)) for t in theta_r_deg]
    row_notes: list[str | None] = [
        surface_colour_note(n) if n is not None and wavelength_free(n) else None for n in names
    ]
    free: dict[str, list[float]] = {}
    for t, n, note in zip(theta_r_deg, names, row_notes, strict=True):
        if n is not None and note is not None:
            free.setdefault(n, []).append(float(t))
    notes = [surface_colour_note(n, angles) for n, angles in free.items()]
    return PredictedColourModels(names, row_notes, notes)


def predicted_colour_notes(rec: Any, rows: list[dict[str, Any]]) -> list[str]:
    """Name the model of each row's predicted colour (``predicted_model``) and its note
    (``predicted_colour_note``) where it has no wavelength in it
    (:func:`predicted_colour_models`); return the notes per model."""
    with_pred = [r for r in rows if r.get("predicted_L") is not None]
    got = predicted_colour_models(rec.model, [float(r["theta_r_deg"]) for r in with_pred])
    for r, name, note in zip(with_pred, got.model, got.note, strict=True):
        if name is None:
            continue
        r["predicted_model"] = name
        if note is not None:
            r["predicted_colour_note"] = note
    return got.notes


def averaging_notes(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Say where a stored run's measured colour averaged its repeats as L*a*b* instead of
    as spectra (``averaged = "lab"``, :func:`goniolab.scan.colour.colour_rows`), and why
    (the row's ``averaged_reason``), one note per reason naming its angles. L*a*b* is not
    linear in the spectrum (CIE 15:2004 eq. 8.1's cube root): the mean of the repeats'
    L*a*b* is not the colour of their mean spectrum. A row of one reading averages
    nothing: it has no note (its ``averaged_reason`` stays on the row)."""
    by_reason: dict[str, list[float]] = {}
    for r in rows:
        if r.get("averaged") == "lab" and int(r.get("n", 0)) > 1:
            why = str(r.get("averaged_reason") or "the run does not say why")
            by_reason.setdefault(why, []).append(float(r["theta_r_deg"]))
    out = []
    for why, angles in by_reason.items():
        lo, hi = min(angles), max(angles)
        where = f"theta_r {lo:g} deg" if lo == hi else f"theta_r {lo:g}..{hi:g} deg"
        out.append(f"measured colour ({where}): repeats averaged as L*a*b*, not as spectra: {why}")
    return out


def calibration_note(run_model: Any) -> str:
    """The calibration a stored BRDF run's readings rest on, as its record cites it
    (``calibration``: the latest ``goniolab calibrate`` run when it started, its age then
    and its check standard's verdict, :func:`goniolab.scan.calibration.calibration_notices`)."""
    model = run_model if isinstance(run_model, dict) else {}
    cite = model.get("calibration")
    if not isinstance(cite, dict):
        return "calibration: not recorded with the run"
    if cite.get("run") is None:
        return "calibration: none (no goniolab calibrate record when the run started)"
    out = f"calibration: run {cite['run']}"
    if cite.get("time_iso"):
        out += f" of {cite['time_iso']}"
    age_h = cite.get("age_h")
    if isinstance(age_h, int | float):
        out += f", {float(age_h):.1f} h old when the run started"
    ok, residual = cite.get("check_ok"), cite.get("check_residual_pct")
    if ok is None:
        out += "; check standard not measured"
    else:
        out += "; check standard " + ("within" if ok else "MISSED") + " its certificate"
        if isinstance(residual, int | float):
            out += f" ({float(residual):+.3f} %)"
    return out
