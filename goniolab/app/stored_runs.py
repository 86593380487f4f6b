"""The stored runs: list, show, export, import, annotate, migrate, spectra and plot (issue 24).

Every face that reads or writes the run store (``goniolab runs``, ``goniolab plot``,
``goniolab fit colour``, the notebook's :class:`goniolab.api.Run`) calls these use cases:
the store is chosen here (``--store``, else the config's ``[lab] store``, else the default
file: :func:`goniolab.app.lab_setup.store_location`, the one place for every face), opened here, and a run that is not there is one
:class:`~goniolab.errors.UserError` (:func:`get_run`). Each use case returns a typed result
the face presents (text, JSON, a DataFrame).

The module is named ``stored_runs`` (not ``runs``): a module name is used once in the tree
(tests/test_layers.py), and ``goniolab/commands/runs.py`` is the CLI's face of it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from goniolab.app.lab_setup import open_store, resume_command, store_location
from goniolab.errors import UserError, a_run_of_kind

if TYPE_CHECKING:  # sqlite3 and the plans load when a use case runs, not at --help
    import pandas as pd
    import xarray as xr
    from matplotlib.figure import Figure

    from goniolab.store import RunRecord, RunStore

__all__ = [
    "ExportResult",
    "Migration",
    "RunBrief",
    "RunList",
    "RunPlot",
    "RunView",
    "SpectraWritten",
    "annotate_run",
    "export_run",
    "get_run",
    "import_runs",
    "interrupted",
    "list_runs",
    "migrate_runs",
    "plot_run",
    "reading_store",
    "run_colour",
    "run_dataframe",
    "run_summary",
    "run_xarray",
    "scan_run",
    "show_run",
    "summarize_run",
    "writable_store",
    "write_run_spectra",
    "write_spectra",
]

Location = Path | str


# ----------------------------------------------------------------------- the store, a run
@contextmanager
def _held(opened: Callable[[], RunStore]) -> Iterator[RunStore]:
    """The store ``opened()`` returns, closed at the end; any
    :class:`~goniolab.store.StoreError` while it is open is a :class:`UserError` (the
    store's message names the store and the run)."""
    from goniolab.store import StoreError

    try:
        with opened() as s:
            yield s
    except StoreError as exc:
        raise UserError(str(exc)) from exc


def reading_store(
    store: str | Path | None, config: str | Path | None
) -> AbstractContextManager[RunStore]:
    """The chosen store (:func:`goniolab.app.lab_setup.open_store`) opened for reading
    (nothing is created or written; it must exist), its errors :class:`UserError`."""
    return _held(lambda: open_store(store, config=config, readonly=True))


def writable_store(
    store: str | Path | None = None, config: str | Path | None = None, *, create: bool = True
) -> AbstractContextManager[RunStore]:
    """The chosen store opened for writing (``create=False``: it must exist), its errors
    :class:`UserError`."""
    return _held(lambda: open_store(store, config=config, create=create))


def get_run(store: RunStore, run_id: int, *, allow_damaged: bool = False) -> RunRecord:
    """Run ``run_id`` of ``store``; a run that is not there is one :class:`UserError`
    (the store's message: ``store X: no run 9``)."""
    from goniolab.store import StoreError

    try:
        return store.get_run(run_id, allow_damaged=allow_damaged)
    except StoreError as exc:
        raise UserError(str(exc)) from exc


def scan_run(store: RunStore, run_id: int, needs: str) -> RunRecord:
    """Run ``run_id`` of ``store``, which must be a scan (brdf) run: ``needs`` says what
    for (``"colour needs a scan (brdf) run"``)."""
    rec = get_run(store, run_id)
    if rec.kind != "brdf":
        raise UserError(f"run {rec.id} is {a_run_of_kind(rec.kind)}: {needs}")
    return rec


def interrupted(store: RunStore, r: RunRecord) -> bool:
    """A run stored as running/paused that no runner holds (its process died)."""
    return r.status in ("running", "paused") and store.is_claimed(r.id) is False


def run_summary(store: RunStore, rec: RunRecord) -> dict[str, Any]:
    """The summary of a stored run, recomputed from its stored readings and predictions."""
    from goniolab.store import StoreError

    if rec.kind == "brdf":
        from goniolab.scan.plans import BrdfPlan, PlanError
        from goniolab.scan.summary import summarize_brdf  # numpy: only when a run is shown

        try:
            plan = BrdfPlan.from_dict(rec.plan)
        except (PlanError, KeyError, TypeError, ValueError) as exc:
            raise UserError(
                f"store {store.location}: run {rec.id}: its stored plan cannot be read: {exc}"
            ) from exc
        try:
            return summarize_brdf(plan, store.points(rec.id), store.predictions(rec.id))
        except StoreError as exc:
            raise UserError(str(exc)) from exc
    if rec.kind == "glosscal":  # a glossmeter calibration: its record (gloss calibrate)
        return {"readings": 0, "gloss_calibration": rec.model.get("gloss_calibration")}
    if rec.kind in ("align", "calibration"):
        # the result is the run's record (what the alignment found, the calibration's check)
        key = "alignment" if rec.kind == "align" else "calibration"
        return {"readings": store.count_points(rec.id), key: rec.model.get(key)}
    from goniolab.scan.plans import gloss_statistics

    rows = store.gloss_readings(rec.id)
    return {
        "readings": len(rows),
        "statistics": gloss_statistics([r.values_gu for r in rows]).as_dict(),
    }


def run_colour(store: RunStore, rec: RunRecord) -> list[dict[str, Any]]:
    """Per-geometry measured and predicted colour of a BRDF run ([] for gloss runs)."""
    if rec.kind != "brdf":
        return []
    from goniolab.scan.colour import PointColour, colour_rows

    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    try:
        pc: PointColour | None = PointColour.from_snapshot(rec.config)
    except (TypeError, ValueError, AttributeError):
        pc = None  # a damaged snapshot: repeats averaged as L*a*b*
    return colour_rows(store.points(rec.id), store.predicted_colours(rec.id), theta_i, pc)


# ----------------------------------------------------------------------- list, show
@dataclass(frozen=True)
class RunBrief:
    """One run of a listing: its record, its readings (``None``: a damaged page) and
    whether it was interrupted."""

    record: RunRecord
    readings: int | None
    interrupted: bool

    def as_dict(self) -> dict[str, Any]:
        """The run as ``runs list --json`` prints it."""
        r = self.record
        doc: dict[str, Any] = {
            "id": r.id,
            "uuid": r.uuid,
            "kind": r.kind,
            "status": r.status,
            "interrupted": self.interrupted,
            "reason": r.reason,
            "sample": r.sample,
            "sample_id": r.sample_id,
            "operator": r.operator,
            "tags": list(r.tags),
            "notes": r.notes,
            "readings": self.readings,
            "created_at": r.created_at,
            "finished_at": r.finished_at,
        }
        if r.damage:
            doc["damage"] = r.damage
        return doc


@dataclass(frozen=True)
class RunList:
    """The runs of a store, newest first: ``exists`` False for a store file not made yet
    (nothing is created); ``filtered`` when a filter was given."""

    location: str
    exists: bool
    runs: list[RunBrief] = field(default_factory=list)
    filtered: bool = False


def list_runs(
    store: str | Path | None = None,
    config: str | Path | None = None,
    *,
    limit: int | None = None,
    operator: str | None = None,
    tag: str | None = None,
    sample_id: str | None = None,
    text: str | None = None,
    missing_ok: bool = True,
) -> RunList:
    """The runs of the chosen store, newest first, filtered by operator, tag, sample id or
    a text in sample, sample id, operator, notes or tags. A store file not made yet is an
    empty list (``missing_ok``; nothing is created), else the store's error."""
    path = store_location(store, config=config)
    if missing_ok and isinstance(path, Path) and not path.exists():
        # a fresh installation (or a mistyped --store): nothing to list, nothing created
        return RunList(str(path), exists=False)
    filtered = any(v is not None for v in (operator, tag, sample_id, text))
    with reading_store(path, None) as s:  # a missing store: its own message
        briefs = s.list_briefs(
            limit=limit, operator=operator, tag=tag, sample_id=sample_id, text=text
        )
        runs = [RunBrief(r, n, interrupted(s, r)) for r, n in briefs]
        return RunList(s.location, True, runs, filtered)


@dataclass(frozen=True)
class RunView:
    """One run as ``runs show`` shows it: record, summary, per-geometry colour and, for a
    scan not done, the command that continues it."""

    record: RunRecord
    interrupted: bool
    summary: dict[str, Any]
    colour: list[dict[str, Any]]
    resume: str | None

    def as_dict(self) -> dict[str, Any]:
        """``runs show --json``."""
        return {
            "run": self.record.as_dict(),
            "interrupted": self.interrupted,
            "summary": self.summary,
            "colour": self.colour,
        }


def show_run(
    run_id: int, store: str | Path | None = None, config: str | Path | None = None
) -> RunView:
    """Run ``run_id`` with its summary recomputed from its stored readings."""
    with reading_store(store, config) as s:
        rec = get_run(s, run_id)
        resume = resume_command(rec.id, s) if rec.status != "done" and rec.kind == "brdf" else None
        return RunView(rec, interrupted(s, rec), run_summary(s, rec), run_colour(s, rec), resume)


def summarize_run(
    run_id: int, store: str | Path | None = None, config: str | Path | None = None
) -> dict[str, Any]:
    """The summary ``runs show`` prints (RMSE, peaks, counts) of run ``run_id``."""
    with reading_store(store, config) as s:
        return run_summary(s, get_run(s, run_id))


def run_xarray(
    run_id: int, store: str | Path | None = None, config: str | Path | None = None
) -> xr.Dataset:
    """Measured, predicted, residual (and colour) per point of run ``run_id``
    (:func:`goniolab.datasets.run_dataset`)."""
    from goniolab.datasets import run_dataset

    with reading_store(store, config) as s:
        get_run(s, run_id)
        return run_dataset(s, run_id)


def run_dataframe(
    run_id: int, store: str | Path | None = None, config: str | Path | None = None
) -> pd.DataFrame:
    """One row per reading of run ``run_id`` (the CSV export's columns,
    :func:`goniolab.export.run_dataframe`)."""
    from goniolab.export import run_dataframe as frame

    with reading_store(store, config) as s:
        get_run(s, run_id)
        return frame(s, run_id)


# ----------------------------------------------------------------------- export, plot
@dataclass(frozen=True)
class ExportResult:
    """An exported run: its format, the file written (``None``: ``text`` is the export)."""

    run_id: int
    format: str
    output: Path | None
    text: str


def export_run(
    run_id: int,
    fmt: str | None = None,
    output: str | Path | None = None,
    *,
    store: str | Path | None = None,
    config: str | Path | None = None,
    spectra: bool = True,
) -> ExportResult:
    """Export run ``run_id`` in ``fmt`` (default: from ``output``'s suffix, else CSV) to
    ``output`` or as text (:mod:`goniolab.export`); ``spectra=False``: without a scan's
    spectra (the compact table)."""
    from goniolab.export import EXPORTERS, resolve_format
    from goniolab.export import export_run as export

    try:
        fmt = resolve_format(fmt, output)
    except ValueError as exc:  # issue 27: `-o run.xlsx` wrote CSV silently
        raise UserError(f"runs export: {exc}") from None
    if EXPORTERS[fmt].binary and not output:
        raise UserError(
            f"runs export --format {fmt}: a binary format needs -o FILE "
            f"(e.g. -o run{EXPORTERS[fmt].suffix})"
        )
    if not spectra and not EXPORTERS[fmt].no_spectra:
        raise UserError(f"runs export --no-spectra: the {fmt} format cannot leave spectra out")
    with reading_store(store, config) as s:
        get_run(s, run_id)
        try:
            text = export(s, run_id, fmt, output, spectra=spectra)
        except OSError as exc:
            raise UserError(
                f"cannot write {output}: {exc.strerror or exc}"
                + (f" ({output} is left as it was)" if output and Path(output).exists() else "")
            ) from exc
    return ExportResult(run_id, fmt, None if output is None else Path(output), text)


@dataclass(frozen=True)
class RunPlot:
    """A drawn run: the figure and the file it was written to (``None``: not written)."""

    record: RunRecord
    figure: Figure
    output: Path | None


def plot_run(
    run_id: int,
    out: str | Path | None = None,
    *,
    log: bool = False,
    store: str | Path | None = None,
    config: str | Path | None = None,
) -> RunPlot:
    """Draw run ``run_id`` (:mod:`goniolab.run_plots`) and write it to ``out`` when given
    (the suffix picks the format: PNG, SVG or PDF)."""
    from goniolab.run_plots import PLOT_FORMATS
    from goniolab.run_plots import plot_run as draw

    path = None if out is None else Path(out)
    if path is not None:
        if path.suffix.lower() not in PLOT_FORMATS:
            raise UserError(f"--out {path}: the suffix picks the format: {', '.join(PLOT_FORMATS)}")
        if path.parent and not path.parent.is_dir():
            raise UserError(f"--out {path}: no such directory {path.parent}")
    with reading_store(store, config) as s:
        rec = get_run(s, run_id)
        try:
            fig = draw(s, run_id, out=path, log=log)
        except OSError as exc:
            raise UserError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return RunPlot(rec, fig, path)


@dataclass(frozen=True)
class SpectraWritten:
    """``runs spectra``: how many spectra of which kind went to which file and format."""

    run_id: int
    rows: int
    which: str
    format: str
    output: Path


def write_run_spectra(
    run_id: int,
    output: str | Path,
    which: str = "both",
    *,
    store: str | Path | None = None,
    config: str | Path | None = None,
) -> SpectraWritten:
    """Write a scan's ``measured``/``predicted``/``both`` spectra as reflectance factors
    (:func:`goniolab.run_spectra.spectra_tables`, written by
    :func:`goniolab.spectra_files.write_spectra_file`: CSV ``R_400..``, Parquet, netCDF)."""
    from goniolab.run_spectra import spectra_tables

    with reading_store(store, config) as s:
        rec = scan_run(s, run_id, "spectra need a scan (brdf) run")
        tables, attrs = spectra_tables(s, rec.id, which)
    if not tables:
        raise UserError(f"run {rec.id} has no {which} spectra on one wavelength grid")
    fmt = write_spectra(tables, output, attrs, mirror_scale=attrs["colour_scale"] == "mirror")
    rows = sum(t.factors.shape[0] for t in tables)
    return SpectraWritten(rec.id, rows, which, fmt, Path(output))


def write_spectra(
    tables: Sequence[Any], output: str | Path, attrs: dict[str, Any], *, mirror_scale: bool
) -> str:
    """:func:`goniolab.spectra_files.write_spectra_file`, its errors as :class:`UserError`
    (a suffix no format has, a file that cannot be written); returns the format."""
    from goniolab.spectra_files import write_spectra_file

    try:
        return write_spectra_file(tables, output, attrs, mirror_scale=mirror_scale)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"{output}: cannot write: {exc.strerror or exc}") from None


# ----------------------------------------------------------------------- write: meta, import
def annotate_run(
    run_id: int,
    *,
    store: str | Path | None = None,
    config: str | Path | None = None,
    operator: str | None = None,
    sample_id: str | None = None,
    notes: str | None = None,
    tags: Sequence[str] | None = None,
    add_tags: Sequence[str] = (),
    remove_tags: Sequence[str] = (),
) -> RunRecord:
    """Set a run's operator, physical sample id, notes or tags (``None``: kept).

    ``tags`` replaces the tags; ``add_tags`` / ``remove_tags`` edit the stored ones. The
    store must exist (nothing is created); a damaged run can still be annotated.
    """
    with writable_store(store, config, create=False) as s:
        rec = s.get_run(run_id, allow_damaged=True)
        new_tags = None if tags is None else list(tags)
        if add_tags or remove_tags:
            drop = set(remove_tags)
            new_tags = [t for t in (*(rec.tags if tags is None else tags), *add_tags)
                        if t not in drop]  # fmt: skip
        return s.set_meta(
            run_id, operator=operator, sample_id=sample_id, notes=notes, tags=new_tags
        )


def import_runs(
    files: Sequence[str], store: str | Path | None = None, config: str | Path | None = None
) -> list[dict[str, Any]]:
    """Read JSON (or Parquet) exports back into the chosen store, matched by run UUID: per file
    ``{"file", "run_id", "uuid", "action"}``, or ``{"file", "error"}`` for one that failed
    (the others are still imported). A scan's exported spectra are stored back
    (:func:`goniolab.run_spectra.restore_from_export`): exported again, it gives the same
    spectra."""
    from goniolab.export import read_parquet_export
    from goniolab.store import StoreError, import_export_doc, import_json_export

    done: list[dict[str, Any]] = []
    with writable_store(store, config) as dst:
        for name in files:
            try:
                counted: list[int] = []
                restore = functools.partial(_restore, counted=counted)
                if Path(name).suffix.lower() in (".parquet", ".pq"):
                    try:
                        doc = read_parquet_export(name)
                    except ValueError as exc:
                        raise StoreError(str(exc)) from None
                    here, action, uuid = import_export_doc(dst, doc, name, restore_spectra=restore)
                else:
                    here, action, uuid = import_json_export(dst, name, restore_spectra=restore)
            except StoreError as exc:
                done.append({"file": name, "error": str(exc)})
                continue
            done.append({"file": name, "run_id": here, "uuid": uuid, "action": action,
                         "spectra": counted[0] if counted else 0,
                         "predicted_spectra": counted[1] if counted else 0})  # fmt: skip
    return done


def _restore(
    rec: RunRecord,
    readings: Sequence[Mapping[str, Any]],
    provenance: Mapping[str, Any],
    where: str,
    *,
    counted: list[int],
) -> tuple[Mapping[tuple[int, int], Mapping[str, Any]], Mapping[int, Sequence[float]]]:
    """:func:`goniolab.run_spectra.restore_from_export` in the store's terms; ``counted``
    gets the numbers of measured and predicted spectra restored."""
    from goniolab.run_spectra import restore_from_export

    restored = restore_from_export(rec, readings, where, provenance=provenance)
    counted[:] = [len(restored.raw), len(restored.predicted_pct)]
    return restored.raw, restored.predicted_pct


@dataclass(frozen=True)
class Migration:
    """``runs migrate``: the source, the target and one entry per run (``action``:
    copied, updated, unchanged, skipped or error)."""

    source: str
    target: str
    runs: list[dict[str, Any]]

    @property
    def errors(self) -> int:
        """Runs that could not be read from the source."""
        return sum(1 for m in self.runs if m["action"] == "error")


def _same_store(src: RunStore, dst: RunStore) -> bool:
    """Whether two open stores are one (a symlink, a relative path, another spelling of
    the URL): the same store UUID, or for files the same file."""
    a, b = src.store_uuid, dst.store_uuid
    if a is not None and b is not None:
        return a == b
    if not (src.is_postgres or dst.is_postgres):
        try:
            return src.path.resolve().samefile(dst.path.resolve())
        except OSError:
            return False
    return False


def migrate_runs(
    source: str,
    store: str | Path | None = None,
    config: str | Path | None = None,
    *,
    on_run: Callable[[dict[str, Any], RunRecord], None] | None = None,
) -> Migration:
    """Copy every run of ``source`` (an SQLite file or another store) into the chosen
    store, matched by run UUID: new runs copied, partial copies brought up to date, a run
    being measured right now skipped. ``on_run(entry, record)`` is told of each run as it
    is done."""
    from goniolab.store import StoreError, is_store_url

    src_loc: Location = source if is_store_url(source) else Path(source).expanduser()
    target = store_location(store, config=config)
    if isinstance(src_loc, Path) and isinstance(target, Path):
        same = src_loc.resolve() == target.resolve() or (
            src_loc.exists() and target.exists() and src_loc.samefile(target)
        )
        if same:
            raise UserError(f"runs migrate: --from {source} is the target store itself")
    moved: list[dict[str, Any]] = []
    with reading_store(src_loc, None) as src, writable_store(target, None) as dst:
        if _same_store(src, dst):
            raise UserError(
                f"runs migrate: --from {src.location} is the target store {dst.location} "
                "itself (the same store UUID)"
            )
        runs = sorted(src.list_runs(), key=lambda r: r.id)
        for rec in runs:
            entry: dict[str, Any] = {"from": rec.id, "uuid": rec.uuid}
            if rec.status in ("running", "paused") and src.is_claimed(rec.id):
                why = "being measured right now; run migrate again when it has finished"
                entry.update(to=None, copied=False, action="skipped", reason=why)
            else:
                try:
                    new_id, action = dst.copy_run_from(src, rec.id)
                except StoreError as exc:
                    entry.update(to=None, copied=False, action="error", error=str(exc))
                else:
                    entry.update(to=new_id, copied=action == "copied", action=action)
            moved.append(entry)
            if on_run is not None:
                on_run(entry, rec)
        where = dst.location
    return Migration(src.location, where, moved)
