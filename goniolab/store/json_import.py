"""``goniolab runs import FILE.json``: a run exported by ``runs export --format json`` read
back into a store (issue 22: goniolab reads its own exports back).

The export is loaded into a scratch SQLite store (the run with its own UUID, creation
time and identity, its readings and the predictions they carry), then copied into the
target with :func:`goniolab.store.migrate.copy_run`, the same path as ``runs migrate``: a
run the target already holds (same UUID) is brought up to date, never duplicated.

Spectra (issue 25): a scan's export carries each reading's spectrum and its geometry's
predicted spectrum as reflectance factors (``R_<nm>``, ``predicted_R_<nm>``). Given the
``restore_spectra`` step of the caller (:func:`goniolab.run_spectra.restore_from_export`:
the store does not know the colour scales), they are stored back as the runner stores them
(% of the mirror, the referenced spectrum for a reading referenced to a standard), and the
predicted L*a*b* with them: exported again, the run gives the same spectra. What an export
does not carry is not invented: the spectro's raw reading beside a referenced spectrum, the
mirror reference's spectrum, the exposure; the import says so.
"""

from __future__ import annotations

import json
import math
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from goniolab.store.exceptions import StoreError
from goniolab.store.records import COLOUR_KEYS, PredictedColour, RunMeta, RunRecord
from goniolab.store.runstore import RunStore

__all__ = ["RestoreSpectra", "import_export_doc", "import_json_export"]

#: ``(run, readings, the export's "spectra", file) -> (raw fields per (index, repeat),
#: predicted spectrum in % of the mirror per index)``; raises ValueError naming the file,
#: the reading and the column.
RestoreSpectra = Callable[
    [RunRecord, Sequence[Mapping[str, Any]], Mapping[str, Any], str],
    tuple[Mapping[tuple[int, int], Mapping[str, Any]], Mapping[int, Sequence[float]]],
]

#: Export column -> stored colour key (the export names L*, a*... with a _star suffix).
_COLOUR_COLUMNS = {
    "X": "X",
    "Y": "Y",
    "Z": "Z",
    "L_star": "L",
    "a_star": "a",
    "b_star": "b",
    "C_star": "C",
    "h_deg": "h_deg",
}


def _number(v: Any) -> float | None:
    return None if v is None else float(v)


def _time(v: Any) -> float:
    """Unix seconds from a number or an ISO 8601 time (how the JSON export writes them)."""
    if isinstance(v, str):
        from datetime import datetime

        return datetime.fromisoformat(v).timestamp()
    return float(v)


def _load(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise StoreError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise StoreError(f"{path}: not a JSON file: {exc}") from None
    return _checked(doc, path)


def _checked(doc: Any, path: Path) -> dict[str, Any]:
    """``doc`` when it is a run export's document (``run``, ``readings``), else why not."""
    if not (isinstance(doc, dict) and isinstance(doc.get("run"), dict)):
        raise StoreError(
            f"{path}: not a goniolab run export (expected 'run' and 'readings' from "
            "'goniolab runs export --format json')"
        )
    run = doc["run"]
    for key in ("uuid", "kind", "plan", "config", "sample", "model", "version", "status"):
        if key not in run:
            raise StoreError(f"{path}: run.{key}: missing (not a goniolab run export)")
    if run["kind"] not in ("brdf", "gloss"):
        raise StoreError(
            f"{path}: run.kind: {run['kind']!r} runs are not imported from JSON (their "
            "result lives in the store's record: use 'runs migrate' from the store)"
        )
    if not isinstance(doc.get("readings", []), list):
        raise StoreError(f"{path}: readings: expected a list")
    return doc


def _fill(
    scratch: RunStore, doc: dict[str, Any], path: Path, restore: RestoreSpectra | None
) -> int:
    """Write the export's run and readings into ``scratch``; return the run's id there."""
    run = doc["run"]
    meta = RunMeta.given(
        str(run.get("operator") or ""),
        str(run.get("sample_id") or ""),
        str(run.get("notes") or ""),
        run.get("tags") or (),
    )
    run_id = scratch.create_run(
        kind=run["kind"],
        plan=run["plan"],
        config=run["config"],
        sample=str(run["sample"]),
        model=run["model"],
        version=str(run["version"]),
        status=str(run["status"]),
        meta=meta,
    )
    created = float(run.get("created_at") or 0.0)
    updated = float(run.get("updated_at") or created)
    scratch.db.execute(
        "UPDATE runs SET uuid = ?, reason = ?, created_at = ?, updated_at = ? WHERE id = ?",
        (str(run["uuid"]), str(run.get("reason") or ""), created, updated, run_id),
    )
    try:
        if run["kind"] == "gloss":
            for r in doc.get("readings", []):
                pred = {a: r.get(f"predicted_g{a}_gu") for a in (20, 60, 85)}
                scratch.add_gloss_reading(
                    run_id,
                    values_gu={a: _number(r.get(f"g{a}_gu")) for a in (20, 60, 85)},
                    temperature_c=_number(r.get("temperature_c")),
                    predicted_gu={a: float(v) for a, v in pred.items() if v is not None} or None,
                    raw="",
                    timestamp=_time(r["timestamp"]),
                )
            return run_id
        readings = doc.get("readings", [])
        spectra: Mapping[tuple[int, int], Mapping[str, Any]] = {}
        predicted_pct: Mapping[int, Sequence[float]] = {}
        if restore is not None:
            try:
                spectra, predicted_pct = restore(
                    scratch.get_run(run_id), readings, doc.get("spectra") or {}, str(path)
                )
            except ValueError as exc:
                raise StoreError(str(exc)) from None
        predictions: dict[int, tuple[int, float, float, float]] = {}
        predicted_lab: dict[int, tuple[float, float, float]] = {}
        for r in readings:
            colour = {
                key: float(r[col]) for col, key in _COLOUR_COLUMNS.items() if r.get(col) is not None
            }
            scratch.add_point(
                run_id,
                index=int(r["index"]),
                repeat=int(r["repeat"]),
                theta_i_deg=float(r["theta_i_deg"]),
                theta_r_deg=float(r["theta_r_deg"]),
                measured_theta_i_deg=float(r["measured_theta_i_deg"]),
                measured_theta_r_deg=float(r["measured_theta_r_deg"]),
                luminance_pct=float(r["luminance_pct"]),
                raw={
                    "imported_from": path.name,
                    "quality": r.get("quality") or "",
                    **(
                        {}
                        if r.get("peak_fraction") is None
                        else {"peak_fraction": float(r["peak_fraction"])}
                    ),
                    **spectra.get((int(r["index"]), int(r["repeat"])), {}),
                },
                timestamp=_time(r["timestamp"]),
                colour=colour if len(colour) == len(COLOUR_KEYS) else None,
                colour_error=str(r.get("colour_error") or ""),
            )
            pred = r.get("predicted_pct")
            if pred is not None and math.isfinite(float(pred)):
                i = int(r["index"])
                predictions[i] = (i, float(r["theta_i_deg"]), float(r["theta_r_deg"]), float(pred))
                lab = [r.get(f"predicted_{c}_star") for c in ("L", "a", "b")]
                if all(v is not None for v in lab):
                    predicted_lab[i] = (float(lab[0]), float(lab[1]), float(lab[2]))
        if predictions:
            scratch.add_predictions(run_id, sorted(predictions.values()))
        colours = [
            (i, PredictedColour(*lab, _spectrum(predicted_pct.get(i))))
            for i, lab in sorted(predicted_lab.items())
        ]
        if colours:
            scratch.add_predicted_colours(run_id, colours)
    except (KeyError, TypeError, ValueError) as exc:
        raise StoreError(f"{path}: readings: a reading lacks or garbles {exc}") from None
    return run_id


def _spectrum(values: Sequence[float] | None) -> tuple[float, ...] | None:
    return None if values is None else tuple(float(v) for v in values)


def import_json_export(
    target: RunStore, path: str | Path, *, restore_spectra: RestoreSpectra | None = None
) -> tuple[int, str, str]:
    """Import the run of the JSON export ``path`` into ``target``; ``restore_spectra``
    stores a scan's exported spectra back (without it, they are left out).

    Returns
    -------
    (run id in the target, action, uuid)
        ``action`` is ``"copied"`` (new here), ``"updated"`` (the target held a partial
        copy of the same run, now brought up to date) or ``"unchanged"``.

    Raises
    ------
    StoreError
        The file cannot be read, is not a goniolab run export, or the target refuses it;
        the message names the file and the key.
    """
    p = Path(path)
    return import_export_doc(target, _load(p), p, restore_spectra=restore_spectra)


def import_export_doc(
    target: RunStore,
    doc: Mapping[str, Any],
    path: str | Path,
    *,
    restore_spectra: RestoreSpectra | None = None,
) -> tuple[int, str, str]:
    """Import a run export's document (``{"run", "readings", "spectra"}``, as the JSON
    export writes it: read from another format, e.g. a Parquet export by
    :func:`goniolab.export.read_parquet_export`) into ``target``; as
    :func:`import_json_export`, ``path`` naming the file in messages."""
    p = Path(path)
    doc = _checked(dict(doc), p)
    with (
        tempfile.TemporaryDirectory(prefix="goniolab-import-") as tmp,
        RunStore(Path(tmp) / "scratch.sqlite") as scratch,
    ):
        run_id = _fill(scratch, doc, p, restore_spectra)
        here, action = target.copy_run_from(scratch, run_id)
    return here, action, str(doc["run"]["uuid"])
