"""Colour use cases: predict colour (``goniolab predict colour``), runs colour (``goniolab
runs colour``) and the paint and tolerance files they read (issue 24).

:func:`predict_colour` predicts the spectrum of a goniometer reading (coat surface model
with the coat's n(lambda) + the paint beneath, :mod:`goniolab.colour.spectral`) at the ASTM
E2194 aspecular angles (or given ones) and reports CIE L*a*b*, L*C*h, the flop index, the
sparkle of a paint with flakes and, against a measured file, the differences and tolerance
verdicts per angle. :func:`runs_colour` judges a stored scan's measured colour against its
prediction or another run (:func:`colour_report`). Each returns the document the CLI's
``--json`` prints.

Named ``colours``: a module name is used once in the tree (``goniolab/scan/colour.py``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from goniolab.errors import UserError

if TYPE_CHECKING:
    from goniolab.app.predictions import SurfaceRequest
    from goniolab.colour.spectra import ColourSettings
    from goniolab.store import RunRecord

__all__ = [
    "ColourOptions",
    "ColourPrediction",
    "RunsColour",
    "colour_report",
    "colour_settings",
    "load_paint_file",
    "load_tolerance",
    "predict_colour",
    "run_spectra",
    "runs_colour",
]


def load_paint_file(path: str) -> Any:
    """A :class:`goniolab.colour.paint.Paint` from a TOML file (``n,k`` tables beside it)."""
    from goniolab.colour.paint import PaintError, paint_from_dict
    from labtoml import TomlFileError, read_toml

    p = Path(path)
    try:
        data = read_toml(p, what="paint file")
    except TomlFileError as exc:
        raise UserError(str(exc)) from None
    tables: dict[str, str] = {}
    metallic = data.get("metallic")
    metal = metallic.get("metal") if isinstance(metallic, dict) else None
    for section in (data.get("coat"), metal):
        if isinstance(section, dict) and section.get("kind") == "table" and "file" in section:
            f = p.parent / str(section["file"])
            try:
                tables[str(section["file"])] = f.read_text(encoding="utf-8")
            except OSError as exc:
                raise UserError(f"{p}: n,k table {f}: cannot read: {exc.strerror}") from None
    try:
        return paint_from_dict(data, where=str(p), tables=tables)
    except PaintError as exc:
        raise UserError(" ".join(str(exc).split())) from None


def colour_settings(illuminant: str, observer: str) -> ColourSettings:
    """Checked CIE illuminant and observer (:class:`goniolab.colour.spectra.ColourSettings`)."""
    from goniolab.colour.spectra import ColourError, ColourSettings

    try:
        return ColourSettings(illuminant, observer).validated()
    except ColourError as exc:
        raise UserError(str(exc)) from None


@dataclass(frozen=True)
class ColourOptions:
    """How to predict colour: CIE settings, paint file (``None``: the sample's paint, or a
    clear coat of the surface's index over black), wavelength step, the cones, the
    geometry (``theta_r_deg`` ``None``: the E2194 aspecular angles), a measured
    ``compare`` file with its unit and tolerance set, the sparkle camera and lamp, a
    ``spectra_out`` file and the scale (``diffuser``: reflectance factors; ``mirror``: %
    of the mirror)."""

    illuminant: str = "D65"
    observer: str = "10"
    paint: str | None = None
    step_nm: float = 10.0
    source_deg: float = 6.0
    detector_deg: float = 6.0
    theta_i_deg: float = 45.0
    theta_r_deg: str | None = None
    compare: str | None = None
    compare_unit: Literal["factor", "percent"] = "factor"
    tolerance: str = "din6175-2"
    sparkle_pixel_um: float = 15.0
    sparkle_lamp_deg: float = 2.0
    spectra_out: str | None = None
    scale: str = "diffuser"


@dataclass(frozen=True)
class ColourPrediction:
    """The predicted colour: ``doc`` is the ``predict colour --json`` document (per
    geometry X, Y, Z, L*, a*, b*, C*, h, spectrum and reflectance factor; flop index,
    sparkle, the comparison with a measured file); ``notes`` what the user must know
    (e.g. the incidence taken from the measured file)."""

    doc: dict[str, Any]
    notes: list[str] = field(default_factory=list)


def _spectral(req: SurfaceRequest, opts: ColourOptions, progress: Any) -> tuple[Any, Any]:
    """The surface model of ``req`` and its spectral predictor (with the paint)."""
    from goniolab.app.predictions import surface_model
    from goniolab.colour.dispersion import DispersionError
    from goniolab.colour.spectra import ColourError
    from goniolab.model_cache import spectral_for

    model = surface_model(req, progress=progress)
    paint = load_paint_file(opts.paint) if opts.paint else None
    try:
        return model, spectral_for(
            model,
            source_cone_deg=opts.source_deg,
            detector_cone_deg=opts.detector_deg,
            step_nm=opts.step_nm,
            paint=paint,
        )
    except (ColourError, DispersionError) as exc:
        raise UserError(str(exc)) from None


def _compare_file(opts: ColourOptions) -> tuple[Any, int]:
    """``--compare FILE.csv`` (or a CxF3 file: ``.cxf``/``.cxf3``, or XML in the CxF3
    namespace): the measured multi-angle spectra (one incidence, one object), repeats
    averaged as spectra, and the rows read."""
    import numpy as np

    from goniolab.colour.cxf_files import is_cxf3, read_spectra_cxf
    from goniolab.colour.exchange import MultiAngleSpectra, read_spectra_csv
    from goniolab.colour.spectra import ColourError

    p = Path(str(opts.compare))
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise UserError(f"--compare {p}: cannot read: {exc.strerror}") from None
    cxf = p.suffix.lower() in (".cxf", ".cxf3") or is_cxf3(data)
    if cxf and opts.compare_unit != "factor":
        raise UserError(
            f"--compare {p}: CxF3 spectra are reflectance factors (100% = 1.0); "
            "--compare-unit percent does not apply"
        )
    try:
        text = "" if cxf else data.decode("utf-8")
    except UnicodeDecodeError as exc:  # a spreadsheet's "CSV" in its Windows code page
        line = data[: exc.start].count(b"\n") + 1
        raise UserError(
            f"--compare {p}: line {line}: byte 0x{data[exc.start]:02x} is not UTF-8 text "
            "(save the file as 'CSV UTF-8')"
        ) from None
    try:
        if cxf:
            table = read_spectra_cxf(data, where=str(p))
        else:
            table = read_spectra_csv(text, where=str(p), unit=opts.compare_unit,
                                     theta_i_deg=opts.theta_i_deg).select("measured")  # fmt: skip
    except ColourError as exc:
        raise UserError(str(exc)) from None
    if cxf and len(set(table.source)) != 1:
        raise UserError(
            f"--compare {p}: one object per file, found " + ", ".join(sorted(set(table.source)))
        )
    incidences = sorted({round(float(t), 6) for t in table.theta_i_deg})
    if len(incidences) != 1:
        raise UserError(
            f"--compare {p}: one incidence per file, found theta_i "
            + ", ".join(f"{t:g}" for t in incidences)
        )
    avg = table.averaged()
    order = np.argsort(-avg.theta_r_deg)
    averaged = MultiAngleSpectra(
        avg.wavelengths_nm,
        avg.theta_i_deg[order],
        avg.theta_r_deg[order],
        avg.factors[order],
        tuple(avg.source[k] for k in order),
        tuple(0 for _ in order),
        avg.notes,
    )
    return averaged, int(table.factors.shape[0])


def _percent_note(opts: ColourOptions, measured: Any) -> str:
    """A note when a file read as reflectance factors has every value above 1: a paint's
    factor is under 1 away from the specular direction (only near it, on a metallic, above),
    a percentage above 1 nearly everywhere. Said, not assumed: the values are used as
    given."""
    low = float(measured.factors.min())
    if opts.compare_unit != "factor" or low <= 1.0:
        return ""
    return (
        f"every value of {opts.compare} is above 1 (the lowest {low:.3g}): read as reflectance "
        "factors; if they are percentages, pass --compare-unit percent"
    )


def _compare_doc(opts: ColourOptions, measured: Any, rows_read: int, predicted_lab: Any,
                 settings: Any) -> dict[str, Any]:  # fmt: skip
    """Differences and tolerance verdicts of the prediction against the measured file."""
    from goniolab.colour.spectra import range_note
    from goniolab.colour.tolerance import evaluate, lab_under

    tolerance = load_tolerance(opts.tolerance)
    lab_m = lab_under(measured.wavelengths_nm, measured.factors, settings.illuminant,
                      settings.observer)  # fmt: skip
    verdicts, overall = evaluate(tolerance, measured.aspecular_deg, lab_m, predicted_lab)
    return {
        "file": str(opts.compare),
        "rows_read": rows_read,
        "wavelengths_nm": [float(w) for w in measured.wavelengths_nm],
        "measured_lab": [[float(v) for v in row] for row in lab_m],
        "pair": {"reference": f"measured {opts.compare}", "sample": "this prediction"},
        "spectra_notes": [
            n
            for n in (
                range_note(measured.wavelengths_nm),
                _percent_note(opts, measured),
                *measured.notes,
            )
            if n
        ],
        "tolerance": {
            **tolerance.describe(),
            "geometries": [v.as_dict() for v in verdicts],
            "overall": overall,
        },
    }


def predict_colour(
    req: SurfaceRequest, opts: ColourOptions, *, progress: Any = None
) -> ColourPrediction:
    """The predicted colour of ``req`` per geometry (ASTM E2194 angles by default), with
    the comparison against ``opts.compare`` and the spectra written to ``opts.spectra_out``
    when given."""
    import numpy as np

    from goniolab.app.predictions import parse_angle_list
    from goniolab.app.stored_runs import write_spectra
    from goniolab.colour.exchange import MultiAngleSpectra
    from goniolab.colour.multiangle import (
        E2194_ASPECULAR_DEG,
        aspecular_deg,
        flop_index_note,
        flop_of_rows,
        theta_r_for_aspecular,
    )
    from goniolab.colour.sparkle import sparkle_report
    from goniolab.colour.spectra import spectra_to_xyz, xyz_to_colour
    from goniolab.colour.spectral import reflectance_factor_scale

    settings = colour_settings(opts.illuminant, opts.observer)
    if opts.compare and opts.theta_r_deg:
        raise UserError("--compare takes the geometries from its file: leave out --theta-r")
    notes: list[str] = []
    theta_i = float(opts.theta_i_deg)
    measured, rows_read = _compare_file(opts) if opts.compare else (None, 0)
    if measured is not None:
        file_ti = float(measured.theta_i_deg[0])
        if abs(file_ti - theta_i) > 1e-9:
            notes.append(
                f"--compare {opts.compare} was measured at theta_i {file_ti:g} deg: predicting "
                f"there, not at --theta-i {theta_i:g}"
            )
        theta_i = file_ti
        tr = np.asarray(measured.theta_r_deg, dtype=np.float64)
    elif opts.theta_r_deg:
        tr = parse_angle_list(opts.theta_r_deg, "--theta-r")
    else:
        tr = np.array([theta_r_for_aspecular(a, theta_i) for a in E2194_ASPECULAR_DEG])
    if np.any(np.abs(tr) + 0.5 * opts.detector_deg >= 90.0):
        raise UserError("--theta-r: the detector cone must stay above the horizon (|theta_r| < 87)")
    model, sp = _spectral(req, opts, progress)
    try:
        spectra = sp.spectrum_pct(theta_i, tr)
        scale = reflectance_factor_scale(tr, opts.detector_deg, opts.scale)  # type: ignore[arg-type]
        factors = spectra / 100.0 * scale[:, None]
    except ValueError as exc:
        raise UserError(str(exc)) from None
    colours = xyz_to_colour(spectra_to_xyz(sp.wavelengths_nm, factors, settings), settings)
    rows: list[dict[str, Any]] = []
    for t, c, s, f in zip(tr, colours, spectra, factors, strict=True):
        rows.append(
            {
                "theta_r_deg": float(t),
                "aspecular_deg": aspecular_deg(float(t), theta_i),
                "X": float(c[0]),
                "Y": float(c[1]),
                "Z": float(c[2]),
                "L": float(c[3]),
                "a": float(c[4]),
                "b": float(c[5]),
                "C": float(c[6]),
                "h_deg": float(c[7]),
                "spectrum_pct": [float(v) for v in s],
                "reflectance_factor": [float(v) for v in f],
            }
        )
    from goniolab.app.colour_notes import surface_colour_notes

    colour_notes = surface_colour_notes(model, theta_i, rows, opts.source_deg, opts.detector_deg)
    notes.extend(colour_notes)
    try:
        sparkle = (
            sparkle_report(
                sp.paint,
                pixel_um=opts.sparkle_pixel_um,
                lamp_radius_deg=0.5 * opts.sparkle_lamp_deg,
            )
            if sp.paint.has_flakes
            else {}
        )
    except ValueError as exc:
        raise UserError(f"sparkle: {exc}") from None
    if opts.spectra_out:
        tables = [] if measured is None else [measured]
        tables.append(
            MultiAngleSpectra(
                np.asarray(sp.wavelengths_nm, dtype=np.float64),
                np.full(tr.size, theta_i),
                tr,
                factors,
                tuple("predicted" for _ in tr),
                tuple(0 for _ in tr),
            )
        )
        write_spectra(
            tables,
            opts.spectra_out,
            {"map": req.label, "scale": opts.scale, "detector_cone_deg": opts.detector_deg},
            mirror_scale=opts.scale == "mirror",
        )
    doc: dict[str, Any] = {
        "map": req.label,
        "theta_i_deg": theta_i,
        "illuminant": settings.illuminant,
        "observer": settings.observer,
        "scale": opts.scale,
        "wavelengths_nm": [float(w) for w in sp.wavelengths_nm],
        "model": sp.describe(),
        "geometries": rows,
        "flop_index": flop_of_rows(rows, theta_i),
        "flop_index_note": flop_index_note(theta_i),
        "predicted_colour_notes": colour_notes,
    }
    if sparkle:
        doc["sparkle"] = sparkle
    if measured is not None:
        lab = np.array([[r["L"], r["a"], r["b"]] for r in rows])
        doc["compare"] = _compare_doc(opts, measured, rows_read, lab, settings)
    if opts.spectra_out:
        doc["spectra_out"] = str(Path(opts.spectra_out).resolve())
    return ColourPrediction(doc, notes)


@dataclass(frozen=True)
class RunsColour:
    """``runs colour``: the run judged and the report (:func:`colour_report`)."""

    record: RunRecord
    doc: dict[str, Any]


def runs_colour(
    run_id: int,
    *,
    vs: int | None = None,
    tolerance: str = "din6175-2",
    illuminants: Sequence[str] = (),
    metamerism: bool = False,
    store: str | Path | None = None,
    config: str | Path | None = None,
) -> RunsColour:
    """A scan's measured colour per geometry judged against its prediction, or with ``vs``
    against another scan (the standard), under the tolerance set ``tolerance``
    (:func:`load_tolerance`), and under more ``illuminants`` / for ``metamerism``."""
    from goniolab.app.stored_runs import get_run, reading_store, scan_run

    tol = load_tolerance(tolerance)
    with reading_store(store, config) as s:
        rec = scan_run(s, run_id, "colour needs a scan (brdf) run")
        other = None
        if vs is not None:
            other = get_run(s, vs)
            if other.kind != "brdf":
                raise UserError(f"run {other.id} is a {other.kind} run: --vs needs a scan run")
        doc = colour_report(
            s, rec, other, tolerance=tol, illuminants=list(illuminants), metamerism=metamerism
        )
    return RunsColour(rec, doc)


def load_tolerance(arg: str) -> Any:
    """``--tolerance``: a built-in set's name or a TOML file (:mod:`goniolab.colour.tolerance`)."""
    from goniolab.colour.tolerance import BUILTIN_SETS, ToleranceError, load_tolerance_set

    try:
        if arg in BUILTIN_SETS:
            return load_tolerance_set(arg)
        p = Path(arg)
        if p.suffix.lower() != ".toml" and not p.exists():
            return load_tolerance_set(arg)  # names the built-in sets
        try:
            text = p.read_text(encoding="utf-8")
        except OSError as exc:
            raise UserError(f"--tolerance {p}: cannot read: {exc.strerror}") from None
        return load_tolerance_set(str(p), text)
    except ToleranceError as exc:
        raise UserError(f"--tolerance: {exc}") from None


def _mean_factors(measured: Any) -> Any:
    """Per geometry, the mean of the repeats' reflectance-factor spectra (NaN-aware)."""
    import warnings

    import numpy as np

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a geometry without readings: NaN
        return np.nanmean(measured, axis=1)


def run_spectra(store: Any, rec: Any) -> dict[str, Any]:
    """A run's spectra as reflectance factors: ``{"wavelengths_nm", "measured" (n, N) mean
    over repeats, "predicted_wavelengths_nm", "predicted" (n, M) or None}``."""
    from goniolab.datasets import predicted_grid_nm, run_reflectance_factors

    wl, measured, predicted = run_reflectance_factors(store, rec.id)
    return {
        "wavelengths_nm": wl,
        "measured": _mean_factors(measured) if wl.size else None,
        "predicted_wavelengths_nm": (
            None if predicted is None else predicted_grid_nm(predicted.shape[-1])
        ),
        "predicted": predicted,
    }


def _observer(rec: Any) -> str:
    cfg = rec.config if isinstance(rec.config, dict) else {}
    return str((cfg.get("colour") or {}).get("observer", "10"))


def _pairs_by_index(
    rows: list[dict[str, Any]], other_rows: list[dict[str, Any]] | None
) -> list[tuple[dict[str, Any], int, int | None]]:
    """(row, index in this run, index in the other run) of the geometries compared."""
    out: list[tuple[dict[str, Any], int, int | None]] = []
    for r in rows:
        if other_rows is None:
            out.append((r, int(r["index"]), None))
            continue
        match = next(
            (
                o
                for o in other_rows
                if abs(float(o["theta_r_deg"]) - float(r["theta_r_deg"])) < 0.01
            ),
            None,
        )
        if match is not None:
            out.append((r, int(r["index"]), int(match["index"])))
    return out


def colour_report(
    store: Any,
    rec: Any,
    other: Any | None,
    *,
    tolerance: Any,
    illuminants: list[str],
    metamerism: bool,
) -> dict[str, Any]:
    """Everything ``runs colour`` reports (its JSON document).

    The pair judged is (reference = the run's measured colour, sample = its prediction),
    or with ``other`` (``--vs``) (reference = the other run, the standard; sample = this
    run). Differences are sample - reference (:mod:`goniolab.colour.difference`); the
    tolerance set is applied per aspecular angle (:func:`goniolab.colour.tolerance.evaluate`).
    """
    import numpy as np

    from goniolab.app.stored_runs import run_colour
    from goniolab.colour.multiangle import flop_index_note, flop_of_rows
    from goniolab.colour.spectra import ColourError, range_note
    from goniolab.colour.tolerance import evaluate, lab_under, metamerism_table

    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    rows = run_colour(store, rec)
    if not any("L" in r for r in rows):
        raise UserError(f"run {rec.id} has no measured colour (no readings, or no usable spectra)")
    if other is not None:
        ti_other = float(other.plan.get("theta_i_deg", 45.0))
        if abs(ti_other - theta_i) > 1e-6:
            raise UserError(
                f"runs {rec.id} and {other.id} were lit at theta_i {theta_i:g} and "
                f"{ti_other:g} deg: their colours are not comparable geometry by geometry"
            )
    from goniolab.app.colour_notes import (
        averaging_notes,
        calibration_note,
        predicted_colour_notes,
    )

    colour_notes = predicted_colour_notes(rec, rows)
    other_rows = run_colour(store, other) if other is not None else None
    pairs = _pairs_by_index(rows, other_rows)
    if other is not None and not pairs:
        raise UserError(f"runs {rec.id} and {other.id} share no detector angle with colour")

    def lab_of(r: dict[str, Any], prefix: str = "") -> list[float]:
        keys = [f"{prefix}L", f"{prefix}a", f"{prefix}b"]
        return [float(r[k]) if r.get(k) is not None else float("nan") for k in keys]

    ref_lab: list[list[float]] = []
    smp_lab: list[list[float]] = []
    aspec: list[float] = []
    for r, _, j in pairs:
        aspec.append(float(r["aspecular_deg"]))
        if other_rows is None:
            ref_lab.append(lab_of(r))
            smp_lab.append(lab_of(r, "predicted_"))
        else:
            o = next(x for x in other_rows if int(x["index"]) == j)
            ref_lab.append(lab_of(o))
            smp_lab.append(lab_of(r))
    verdicts, overall = evaluate(tolerance, aspec, np.array(ref_lab), np.array(smp_lab))
    for (r, _, _), v in zip(pairs, verdicts, strict=True):
        if other_rows is None and all(np.isfinite(lab_of(r, "predicted_"))):
            r.update({k: v.values[k] for k in ("dL", "dC", "dH", "dE_CMC")})
    settings = rec.config.get("colour", {}) if isinstance(rec.config, dict) else {}
    note = ""
    if other is None and not any(r.get("predicted_L") is not None for r in rows):
        note = f"run {rec.id} has no predicted colours to judge against (compare runs: --vs RUN)"
    doc: dict[str, Any] = {
        "run": rec.id,
        "theta_i_deg": theta_i,
        "colour_settings": settings,
        # what the measured colours rest on: the calibration the run cites
        "calibration": rec.model.get("calibration") if isinstance(rec.model, dict) else None,
        "calibration_note": calibration_note(rec.model),
        "geometries": rows,
        "flop_index": flop_of_rows(rows, theta_i),
        "predicted_flop_index": flop_of_rows(rows, theta_i, "predicted_L"),
        "flop_index_note": flop_index_note(theta_i),
        "predicted_colour_notes": colour_notes,
        "averaging_notes": averaging_notes(rows),
        "pair": (
            {"reference": f"run {rec.id} measured", "sample": f"run {rec.id} predicted"}
            if other is None
            else {"reference": f"run {other.id} measured", "sample": f"run {rec.id} measured"}
        ),
        "differences": "sample - reference; dE_CMC with the set's l:c",
        "tolerance": {
            **tolerance.describe(),
            "geometries": [v.as_dict() for v in verdicts],
            "overall": overall,
            "note": note,
        },
    }
    if other is not None:
        cmp_ = [
            {"theta_r_deg": r["theta_r_deg"], **v.as_dict()}
            for (r, _, _), v in zip(pairs, verdicts, strict=True)
        ]
        de = [c["dE00"] for c in cmp_ if np.isfinite(c["dE00"])]
        doc["vs"] = {
            "run": other.id,
            "pairs": cmp_,
            "flop_index": flop_of_rows(other_rows or [], float(other.plan.get("theta_i_deg", 45))),
            "max_dE2000": max(de) if de else None,
            "mean_dE2000": sum(de) / len(de) if de else None,
        }
    # how the stored colours were integrated: a grid short of 380-780 nm is said
    grids = {
        tuple(p.raw.get("wavelengths_nm") or ())
        for p in store.points(rec.id)
        if p.index >= 0 and p.raw.get("wavelengths_nm")
    }
    doc["spectra_notes"] = sorted({n for g in grids if (n := range_note(np.asarray(g)))})
    if not (illuminants or metamerism):
        return doc
    # spectra of both sides, for colours under other illuminants
    mine = run_spectra(store, rec)
    observer = _observer(rec)
    if other is None:
        ref_wl, ref_r = mine["wavelengths_nm"], mine["measured"]
        smp_wl, smp_r = mine["predicted_wavelengths_nm"], mine["predicted"]
        missing = "predicted spectra" if smp_r is None else ""
    else:
        theirs = run_spectra(store, other)
        ref_wl, ref_r = theirs["wavelengths_nm"], theirs["measured"]
        smp_wl, smp_r = mine["wavelengths_nm"], mine["measured"]
        missing = ""
    if ref_r is None or smp_r is None:
        missing = missing or "measured spectra on one wavelength grid"
        raise UserError(
            f"--illuminant / --metamerism need the spectra of both sides: run {rec.id} has no "
            f"{missing}"
        )
    idx_ref = [i if other is None else j for _, i, j in pairs]
    idx_smp = [i for _, i, _ in pairs]
    ref_pair = (ref_wl, ref_r[idx_ref])
    smp_pair = (smp_wl, smp_r[idx_smp])
    notes = sorted({n for n in (range_note(ref_wl), range_note(smp_wl)) if n})
    doc["spectra_notes"] = sorted(set(doc["spectra_notes"]) | set(notes))
    try:
        per_ill: dict[str, Any] = {}
        for ill in illuminants:
            from goniolab.colour.spectra import ColourSettings

            name = ColourSettings(ill, observer).validated().illuminant
            lab_r = lab_under(ref_pair[0], ref_pair[1], name, observer)
            lab_s = lab_under(smp_pair[0], smp_pair[1], name, observer)
            v_ill, o_ill = evaluate(tolerance, aspec, lab_r, lab_s)
            per_ill[name] = {
                "geometries": [
                    {
                        "reference_lab": [float(x) for x in a],
                        "sample_lab": [float(x) for x in b],
                        **v.as_dict(),
                    }
                    for a, b, v in zip(lab_r, lab_s, v_ill, strict=True)
                ],
                "overall": o_ill,
            }
        if per_ill:
            doc["illuminants"] = per_ill
        if metamerism:
            doc["metamerism"] = metamerism_table(ref_pair, smp_pair, aspec, observer=observer)
    except ColourError as exc:
        raise UserError(str(exc)) from None
    return doc
