"""A stored scan's spectra as reflectance factors, and what they are relative to.

The one place that turns a run's stored readings (and stored predictions) into the
spectra every export writes (:mod:`goniolab.export`: CSV/JSON ``R_<nm>`` columns, Parquet,
netCDF through :func:`goniolab.datasets.run_dataset`; ``runs spectra``). A reading's
spectrum becomes a reflectance factor as the runner turned it into its colour
(:meth:`goniolab.scan.colour.PointColour.measured`, docs/CALIBRATION.md steps 3-4):

- referenced to a certified standard (``--mirror-reference``): the stored absolute spectrum
  ``raw.absolute_values`` (% of a perfect mirror, ``v / m x R_cert``), with the standard
  and method in ``raw.reference``;
- otherwise the reading as the spectro reports it (% of the instrument's own reference,
  taken as a perfect mirror; the run's scalar mirror level is not divided out, as the
  runner does not: it counted the mirror as 100 %, docs/CALIBRATION.md step 3);

then ``/ 100`` and, on the ``[colour] scale = "diffuser"`` (the default), divided by the
perfect diffuser's reading through the detector cone, ``sin^2(a_d) cos(theta_r)``
(:func:`goniolab.colour.spectral.reflectance_factor_scale`): 1 = the perfect reflecting
diffuser (CIE 15:2004 sec. 3.3). On ``scale = "mirror"`` the numbers stay fractions of the
perfect mirror and every label says so (not a reflectance factor).

Predicted spectra (% of a perfect mirror, on the 380-780 nm grid the spectral predictor
uses) get the same cone scale.

numpy only at import; the store and the plan are read, nothing is written.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:  # pragma: no cover - typing only
    from goniolab.colour.exchange import MultiAngleSpectra
    from goniolab.store import PointRow, RunRecord, RunStore

__all__ = [
    "PREDICTED_PREFIX",
    "RestoredSpectra",
    "RunSpectra",
    "percent_of_mirror",
    "predicted_grid_nm",
    "restore_from_export",
    "run_reflectance_factors",
    "run_spectra",
    "spectra_tables",
    "spectral_columns",
]

FloatArray = NDArray[np.float64]

#: Prefix of a predicted spectrum's columns (``predicted_R_400``); the measured ones are
#: ``R_400`` (:func:`goniolab.colour.exchange.spectral_column`).
PREDICTED_PREFIX = "predicted_"

#: What the numbers are relative to, by ``[colour] scale``.
RELATIVE_TO: dict[str, str] = {
    "diffuser": "perfect reflecting diffuser (CIE 15:2004 sec. 3.3), through the detector cone",
    "mirror": "perfect mirror ([colour] scale = mirror): not a reflectance factor",
}
#: The quantity, by ``[colour] scale``.
QUANTITY: dict[str, str] = {
    "diffuser": "spectral reflectance factor",
    "mirror": "spectral reflectance as a fraction of the perfect mirror",
}
#: A reading referenced by nothing but the spectro's own calibration.
INSTRUMENT_REFERENCE = (
    "the spectro's own reference taken as a perfect mirror (no certified standard)"
)


def spectral_columns(wavelengths_nm: Sequence[float] | FloatArray, prefix: str = "") -> list[str]:
    """``["R_400", "R_410", ...]`` (``prefix`` before each: ``predicted_R_400``)."""
    from goniolab.colour.exchange import spectral_column

    return [prefix + spectral_column(float(w)) for w in wavelengths_nm]


def predicted_grid_nm(n_wavelengths: int) -> FloatArray:
    """The grid of stored predicted spectra: the standard 380-780 nm in ``n`` steps
    (:func:`goniolab.colour.spectra.standard_grid_nm`, what the spectral predictor uses)."""
    return np.linspace(380.0, 780.0, int(n_wavelengths))


@dataclass(frozen=True)
class RunSpectra:
    """A scan run's measured and predicted spectra on its ``[colour] scale``.

    Attributes
    ----------
    wavelengths_nm
        The readings' common grid (empty when they share none).
    measured
        ``(n_geometries, repeats, n_wl)``, NaN where no reading (or no spectrum) is stored.
    predicted_wavelengths_nm, predicted
        The predictions' grid and ``(n_geometries, n_wl_pred)``; ``None`` without any.
    scale
        ``"diffuser"`` (reflectance factors) or ``"mirror"`` (fractions of the mirror).
    detector_cone_deg
        The detector cone's full angle (its half angle ``a_d`` sets the diffuser scale).
    referenced_by
        Per ``(index, repeat)``, what the reading was referenced to (the certified standard
        and method, or :data:`INSTRUMENT_REFERENCE`).
    standards
        The certified standards cited by the readings (``raw.reference`` without the
        per-reading method), deduplicated.
    calibration
        The calibration record the run cites (its model's ``calibration``), ``{}`` if none.
    """

    wavelengths_nm: FloatArray
    measured: FloatArray
    predicted_wavelengths_nm: FloatArray | None
    predicted: FloatArray | None
    scale: str
    detector_cone_deg: float
    referenced_by: Mapping[tuple[int, int], str] = field(default_factory=dict)
    standards: tuple[Mapping[str, Any], ...] = ()
    calibration: Mapping[str, Any] = field(default_factory=dict)

    @property
    def has_measured(self) -> bool:
        return bool(self.wavelengths_nm.size) and bool(np.isfinite(self.measured).any())

    @property
    def quantity(self) -> str:
        return QUANTITY.get(self.scale, f"spectral reading on an unknown scale {self.scale!r}")

    @property
    def relative_to(self) -> str:
        unknown = f"nothing: [colour] scale {self.scale!r} is unknown, the values are NaN"
        return RELATIVE_TO.get(self.scale, unknown)

    def referenced_to(self) -> str:
        """One line: what the measured spectra were referenced to (all readings)."""
        labels = sorted(set(self.referenced_by.values()))
        return "; ".join(labels) if labels else "no measured spectra"

    def provenance(self) -> dict[str, Any]:
        """What every export says about the spectra (JSON, Parquet metadata, netCDF
        attributes): quantity, units, reference, scale, cone, standards, calibration."""
        return {
            "quantity": self.quantity,
            "units": "1",
            "relative_to": self.relative_to,
            "referenced_to": self.referenced_to(),
            "colour_scale": self.scale,
            "detector_cone_deg": self.detector_cone_deg,
            "standards": [dict(s) for s in self.standards],
            "calibration": dict(self.calibration),
            "wavelengths_nm": [float(w) for w in self.wavelengths_nm],
            "columns": spectral_columns(self.wavelengths_nm) if self.has_measured else [],
            "predicted_wavelengths_nm": (
                None
                if self.predicted_wavelengths_nm is None
                else [float(w) for w in self.predicted_wavelengths_nm]
            ),
            "predicted_columns": (
                []
                if self.predicted_wavelengths_nm is None
                else spectral_columns(self.predicted_wavelengths_nm, PREDICTED_PREFIX)
            ),
            "predicted": "model prediction (% of a perfect mirror) on the same scale and cone",
        }


def _config_of(rec: RunRecord) -> dict[str, Any]:
    return rec.config if isinstance(rec.config, dict) else {}


def scale_name(rec: RunRecord) -> str:
    """The run's ``[colour] scale`` (``diffuser`` unless its config snapshot says)."""
    return str((_config_of(rec).get("colour") or {}).get("scale", "diffuser"))


def detector_cone_deg(rec: RunRecord) -> float:
    """The run's ``[spectro] detector_cone_deg`` (6 deg unless its config snapshot says)."""
    return float((_config_of(rec).get("spectro") or {}).get("detector_cone_deg", 6.0))


def factor_scale(rec: RunRecord, theta_r_deg: FloatArray) -> FloatArray:
    """Per geometry, what turns a fraction of the mirror into the run's scale: the
    ``[colour] scale`` through the detector cone
    (:func:`goniolab.colour.spectral.reflectance_factor_scale`, as the runner does)."""
    from goniolab.colour.spectral import reflectance_factor_scale

    try:
        out = np.asarray(
            reflectance_factor_scale(theta_r_deg, detector_cone_deg(rec), scale_name(rec)),  # type: ignore[arg-type]
            dtype=np.float64,
        )
    except ValueError:  # a point detector or a grazing angle: no factor (NaN, not a guess)
        return np.full(theta_r_deg.shape, np.nan)
    return np.broadcast_to(out, theta_r_deg.shape).astype(np.float64)


def _reference_label(raw: Mapping[str, Any]) -> str:
    """What a reading was referenced to, in one CSV cell without commas (a naive
    ``awk -F,`` of the export keeps its columns): ``certified mirror (certificate X;
    spectral)`` or :data:`INSTRUMENT_REFERENCE`."""
    imported = raw.get("referenced_to")  # a reading read back from an export says it
    if isinstance(imported, str) and imported:
        return imported
    ref = raw.get("reference")
    if isinstance(ref, Mapping) and ref.get("standard"):
        parts = [f"certificate {ref['certificate']}"] if ref.get("certificate") else []
        parts.append(str(ref.get("method", "method not recorded")))
        return f"certified {ref['standard']} ({'; '.join(parts)})".replace(",", ";")
    return INSTRUMENT_REFERENCE


def _standard_cite(raw: Mapping[str, Any]) -> dict[str, Any] | None:
    ref = raw.get("reference")
    if not isinstance(ref, Mapping) or not ref.get("standard"):
        return None
    keep = ("standard", "certificate", "certified_on", "model", "file", "n")
    return {k: ref[k] for k in keep if k in ref}


def _measured_fraction(raw: Mapping[str, Any], n_wl: int) -> FloatArray | None:
    """A reading's spectrum as a fraction of a perfect mirror, or None (none stored): the
    referenced spectrum when there is one, else the reading as reported -- the spectrum
    the runner took the reading's colour from (:meth:`goniolab.scan.colour.PointColour.measured`,
    :func:`goniolab.scan.colour.colour_rows`)."""
    values = raw.get("absolute_values") or raw.get("values")
    if values is None or len(values) != n_wl:
        return None
    return np.asarray(values, dtype=np.float64) / 100.0


def run_spectra(
    store: RunStore, run_id: int, points: Sequence[PointRow] | None = None
) -> RunSpectra:
    """Run ``run_id``'s spectra (:class:`RunSpectra`); ``points`` when the caller has them.

    Raises
    ------
    ValueError
        The run is not a scan (its plan is no BRDF plan).
    """
    from goniolab.scan.plans import MIRROR_INDEX, BrdfPlan

    rec = store.get_run(run_id)
    plan = BrdfPlan.from_dict(rec.plan)
    tr = np.asarray(plan.theta_r_deg, dtype=np.float64)
    n, reps = tr.size, plan.repeats
    rows = [p for p in (store.points(rec.id) if points is None else points)
            if p.index != MIRROR_INDEX]  # fmt: skip
    grids = {tuple(p.raw.get("wavelengths_nm") or ()) for p in rows if p.index >= 0}
    grid = next(iter(grids)) if len(grids) == 1 else ()
    wl = np.asarray(grid, dtype=np.float64)
    measured = np.full((n, reps, wl.size), np.nan)
    scale = factor_scale(rec, tr)
    referenced: dict[tuple[int, int], str] = {}
    standards: list[dict[str, Any]] = []
    for p in rows:
        if not (0 <= p.index < n and 0 <= p.repeat < reps) or not grid:
            continue
        r = _measured_fraction(p.raw, wl.size)
        if r is None:
            continue
        measured[p.index, p.repeat, :] = r * scale[p.index]
        referenced[(p.index, p.repeat)] = _reference_label(p.raw)
        cite = _standard_cite(p.raw)
        if cite is not None and cite not in standards:
            standards.append(cite)
    predicted: FloatArray | None = None
    getter = getattr(store, "predicted_colours", None)
    stored = getter(rec.id) if getter is not None else {}
    spectra = {int(k): pc.spectrum_pct for k, pc in stored.items() if pc.spectrum_pct}
    if spectra:
        m = len(next(iter(spectra.values())))
        predicted = np.full((n, m), np.nan)
        for k, sp in spectra.items():
            if 0 <= k < n and len(sp) == m:
                predicted[k] = np.asarray(sp, dtype=np.float64) / 100.0 * scale[k]
    calibration = rec.model.get("calibration") if isinstance(rec.model, dict) else None
    return RunSpectra(
        wavelengths_nm=wl,
        measured=measured,
        predicted_wavelengths_nm=None
        if predicted is None
        else predicted_grid_nm(predicted.shape[-1]),
        predicted=predicted,
        scale=scale_name(rec),
        detector_cone_deg=detector_cone_deg(rec),
        referenced_by=referenced,
        standards=tuple(standards),
        calibration=calibration if isinstance(calibration, dict) else {},
    )


def run_reflectance_factors(
    store: RunStore, run_id: int
) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """Measured and predicted spectra of a scan run on its scale (reflectance factors).

    Returns ``(wavelengths_nm, measured (n_geometries, repeats, n_wl), predicted
    (n_geometries, n_wl_pred) or None)`` (:func:`run_spectra` without its provenance).
    """
    sp = run_spectra(store, run_id)
    return sp.wavelengths_nm, sp.measured, sp.predicted


def spectra_tables(
    store: RunStore, run_id: int, which: str = "both"
) -> tuple[list[MultiAngleSpectra], dict[str, Any]]:
    """A scan run's spectra as exchange tables and what a file of them says about itself.

    Returns ``(tables, attrs)``: ``tables`` the ``measured`` spectra, one row per reading
    with a complete spectrum, and/or (``which``: ``measured``, ``predicted``, ``both``) the
    ``predicted`` ones, one row per geometry (:class:`goniolab.colour.exchange.MultiAngleSpectra`,
    for :func:`goniolab.spectra_files.write_spectra_file`); ``attrs`` the run, its sample,
    its ``[colour] scale``, the detector cone, what the spectra are relative to and
    referenced to, the certified standards and the calibration it cites.

    Raises
    ------
    ValueError
        ``which`` is none of the three, or the run is not a scan.
    """
    from goniolab.colour.exchange import MultiAngleSpectra

    if which not in ("measured", "predicted", "both"):
        raise ValueError(f"which must be measured, predicted or both, got {which!r}")
    rec = store.get_run(run_id)
    sp = run_spectra(store, run_id)
    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    tr = np.asarray(rec.plan.get("theta_r_deg", []), dtype=np.float64)
    out: list[MultiAngleSpectra] = []
    measured = sp.measured
    if which in ("measured", "both") and sp.wavelengths_nm.size:
        n, reps, _ = measured.shape
        keep = [
            (k, r) for k in range(n) for r in range(reps) if np.all(np.isfinite(measured[k, r]))
        ]
        if keep:
            out.append(
                MultiAngleSpectra(
                    sp.wavelengths_nm,
                    np.full(len(keep), theta_i),
                    np.array([tr[k] for k, _ in keep]),
                    np.array([measured[k, r] for k, r in keep]),
                    tuple("measured" for _ in keep),
                    tuple(r for _, r in keep),
                )
            )
    predicted, grid = sp.predicted, sp.predicted_wavelengths_nm
    if which in ("predicted", "both") and predicted is not None and grid is not None:
        keep_p = [k for k in range(predicted.shape[0]) if np.all(np.isfinite(predicted[k]))]
        if keep_p:
            out.append(
                MultiAngleSpectra(
                    grid,
                    np.full(len(keep_p), theta_i),
                    tr[keep_p],
                    predicted[keep_p],
                    tuple("predicted" for _ in keep_p),
                    tuple(0 for _ in keep_p),
                )
            )
    prov = sp.provenance()
    attrs: dict[str, Any] = {
        "run_id": rec.id,
        "sample": rec.sample,
        "colour_scale": sp.scale,
        "detector_cone_deg": sp.detector_cone_deg,
        "relative_to": prov["relative_to"],
        "referenced_to": prov["referenced_to"],
        "reference_standards": prov["standards"],
        "calibration": prov["calibration"],
    }
    return out, attrs


# ------------------------------------------------------------------ an export read back
@dataclass(frozen=True)
class RestoredSpectra:
    """A scan export's spectra turned back into what the store keeps (``runs import``).

    Attributes
    ----------
    raw
        Per ``(index, repeat)``, the fields to put into the reading's raw record:
        ``wavelengths_nm`` and ``values`` (% of the mirror, what the spectro reports) or,
        for a reading referenced to a certified standard, ``absolute_values`` (its
        referenced spectrum), and ``referenced_to`` (the export's
        ``spectrum_referenced_to``).
    predicted_pct
        Per geometry index, its predicted spectrum in % of the mirror on
        :func:`predicted_grid_nm`.
    """

    raw: dict[tuple[int, int], dict[str, Any]]
    predicted_pct: dict[int, tuple[float, ...]]


def percent_of_mirror(factors: FloatArray, scale: float) -> FloatArray:
    """The % of the mirror that :func:`run_spectra` turns into ``factors``: the inverse of
    ``values / 100 * scale``, exact in floating point.

    ``factors / scale * 100`` can be an ulp or two off the value the forward step maps to
    ``factors``; each element is stepped (``numpy.nextafter``) until the forward step gives
    back its factor bit for bit, so an export read back exports the same numbers. A factor
    no value reaches (a file edited by hand) keeps the nearest value found.
    """
    x = factors / scale * 100.0
    for _ in range(16):
        f = x / 100.0 * scale
        off = f != factors
        if not off.any():
            break
        x = np.where(off, np.nextafter(x, np.where(f < factors, np.inf, -np.inf)), x)
    return x


def _grid_of(columns: Sequence[str], prefix: str, where: str) -> tuple[list[str], FloatArray]:
    """The spectral columns with ``prefix`` (``R_400`` or ``predicted_R_400``) of an export's
    readings and their wavelengths, in file order."""
    names = [c for c in columns if c.startswith(prefix + "R_")]
    try:
        wl = np.array([float(c[len(prefix) + 2 :]) for c in names], dtype=np.float64)
    except ValueError:
        bad = next(c for c in names if not c[len(prefix) + 2 :].replace(".", "", 1).isdigit())
        raise ValueError(f"{where}: column {bad!r}: not a wavelength in nm") from None
    return names, wl


def _row_spectrum(row: Mapping[str, Any], names: Sequence[str], where: str) -> FloatArray | None:
    """The cells ``names`` of one reading: None when all are empty, else every one a
    finite number (a reading's spectrum is whole or absent in an export)."""
    cells = [row.get(c) for c in names]
    if all(v is None for v in cells):
        return None
    out = np.empty(len(names))
    for k, (name, v) in enumerate(zip(names, cells, strict=True)):
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
            raise ValueError(
                f"{where}, column {name}: {v!r} is not a finite number (a spectrum is whole "
                "or absent)"
            )
        out[k] = float(v)
    return out


def _standard_for(label: str, standards: Sequence[Any]) -> dict[str, Any] | None:
    """The export's certified standard a reading's ``spectrum_referenced_to`` names (the
    label :func:`_reference_label` wrote: standard, then its certificate), else None."""
    for st in standards:
        if not (isinstance(st, Mapping) and st.get("standard")):
            continue
        head = f"certified {st['standard']} (".replace(",", ";")
        cert = f"certificate {st['certificate']}".replace(",", ";") if st.get("certificate") else ""
        if label.startswith(head) and cert in label:
            return dict(st)
    return None


def restore_from_export(
    rec: RunRecord,
    readings: Sequence[Mapping[str, Any]],
    where: str,
    *,
    provenance: Mapping[str, Any] | None = None,
) -> RestoredSpectra:
    """The measured and predicted spectra of a JSON export's readings (``R_<nm>``,
    ``predicted_R_<nm>``: reflectance factors on the run's ``[colour] scale``,
    :func:`run_spectra`) as the store keeps them, for the run ``rec`` (its plan and config
    snapshot give each geometry's scale). Exported again, the run gives the same numbers
    (:func:`percent_of_mirror`). ``provenance``, the export's ``spectra``, gives a
    referenced reading its certified standard back (matched by the reading's label).

    Raises
    ------
    ValueError
        ``where: readings[N], column C: why`` -- a cell that is not a number, a spectrum
        given where the run's scale has no factor (a point detector), a predicted grid other
        than the stored one, two readings of one geometry with different predictions.
    """
    from goniolab.scan.plans import BrdfPlan

    if not readings:
        return RestoredSpectra({}, {})
    columns = list(dict.fromkeys(c for r in readings for c in r))
    names, wl = _grid_of(columns, "", where)
    p_names, p_wl = _grid_of(columns, PREDICTED_PREFIX, where)
    if p_names and not np.array_equal(p_wl, predicted_grid_nm(p_wl.size)):
        raise ValueError(
            f"{where}: columns {p_names[0]}..{p_names[-1]}: predicted spectra are stored on "
            f"{p_wl.size} steps of 380-780 nm, not on this grid"
        )
    exact = (provenance or {}).get("wavelengths_nm")  # the grid unrounded (names: %g)
    if isinstance(exact, list) and len(exact) == wl.size and spectral_columns(exact) == names:
        wl = np.asarray(exact, dtype=np.float64)
    tr = np.asarray(BrdfPlan.from_dict(rec.plan).theta_r_deg, dtype=np.float64)
    scale = factor_scale(rec, tr)
    raw: dict[tuple[int, int], dict[str, Any]] = {}
    predicted: dict[int, tuple[float, ...]] = {}
    for n, row in enumerate(readings):
        at = f"{where}: readings[{n}]"
        k, rep = int(row["index"]), int(row["repeat"])
        inside = 0 <= k < tr.size
        measured = _row_spectrum(row, names, at) if names else None
        if measured is not None:
            if not (inside and np.isfinite(scale[k]) and scale[k] != 0.0):
                raise ValueError(
                    f"{at}, column {names[0]}: a spectrum at a geometry whose scale has no "
                    f"factor (index {k}: no reflectance factor there)"
                )
            label = str(row.get("spectrum_referenced_to") or "")
            pct = [float(v) for v in percent_of_mirror(measured, float(scale[k]))]
            key = "values" if label in ("", INSTRUMENT_REFERENCE) else "absolute_values"
            raw[(k, rep)] = {
                "wavelengths_nm": [float(w) for w in wl],
                key: pct,
                "referenced_to": label or INSTRUMENT_REFERENCE,
            }
            standard = _standard_for(label, (provenance or {}).get("standards") or ())
            if key == "absolute_values" and standard is not None:
                raw[(k, rep)]["reference"] = standard
        pred = _row_spectrum(row, p_names, at) if p_names else None
        if pred is not None and inside and np.isfinite(scale[k]) and scale[k] != 0.0:
            pct_p = tuple(float(v) for v in percent_of_mirror(pred, float(scale[k])))
            if predicted.setdefault(k, pct_p) != pct_p:
                raise ValueError(
                    f"{at}, column {p_names[0]}: geometry {k}'s predicted spectrum differs "
                    "from the one of its other readings"
                )
    return RestoredSpectra(raw, predicted)
