"""Files others read: a stored run as CSV, JSON, netCDF or Parquet, one exporter per format.

The exporters are a registry (:data:`EXPORTERS`, :func:`register_exporter`), as height-map
formats are (:mod:`goniolab.surfaces.registry`): ``goniolab runs export --format`` takes its
choices and help from it, and a file suffix picks its exporter (:func:`resolve_format`); a
suffix or a format no exporter has is refused, naming the ones there are.

- **csv**: one row per reading (:func:`export_rows`: :data:`SCAN_COLUMNS` for a scan,
  :data:`GLOSS_COLUMNS` for a gloss log, colour columns included), ISO 8601 UTC timestamps.
  A scan with spectra adds :data:`SPECTRUM_COLUMNS`, then ``R_400 ... R_700`` (one column
  per wavelength of the readings' grid: the reading's spectrum as a reflectance factor,
  :mod:`goniolab.run_spectra`) and ``predicted_R_380 ...`` (the geometry's predicted
  spectrum on the predictions' grid); a cell is empty where there is no value.
- **json**: ``{"run": {...}, "readings": [...], "spectra": {...}}``, the run record with ISO
  times beside the Unix ones, readings as in the CSV, and for a scan with spectra what they
  are (quantity, units, relative to, referenced to, cone, standards, calibration, grids).
- **netcdf** (netCDF-4 through xarray + h5netcdf): the Dataset of
  :func:`goniolab.datasets.run_dataset`, CF-style ``units`` on every variable and the run's
  metadata (plan, model, config snapshot, status, version) as global attributes; the spectra
  as ``reflectance_factor`` and ``predicted_reflectance_factor`` with the same provenance as
  attributes.
- **parquet** (pyarrow): the CSV's table with typed columns (timestamps as
  ``timestamp[us, UTC]``), the run record as JSON in the schema metadata under the key
  ``goniolab.run``, the spectra's provenance under ``goniolab.spectra`` and ``units``,
  ``long_name``, ``wavelength_nm`` on each spectral column.

``spectra=False`` (``runs export --no-spectra``) leaves a scan's spectra out of every format:
the compact table. ``goniolab runs import`` reads a JSON export's spectra back
(:func:`goniolab.run_spectra.restore_from_export`).

Every file is built in memory and replaced whole (:mod:`goniolab._atomic`): a full disk
or a failed export leaves an existing file as it was. Each carries the run's UUID
(``run_uuid`` column, ``uuid`` in the run record, ``run_uuid`` attribute).

Importing this module is cheap (the CLI's parser reads the registry): numpy, pandas,
xarray and pyarrow are imported by the writers that use them.

Adding a format is one writer and its registration::

    def _tsv_text(store: RunStore, run_id: int) -> str: ...

    register_exporter(Exporter("tsv", (".tsv",), "tab-separated, one row per reading",
                               text=_tsv_text))
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from goniolab import jsonout
from goniolab._atomic import atomic_write_bytes

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd
    import pyarrow as pa

    from goniolab.run_spectra import RunSpectra
    from goniolab.store import PointRow, RunStore

__all__ = [
    "EXPORTERS",
    "FORMATS",
    "GLOSS_COLUMNS",
    "PARQUET_RUN_KEY",
    "PARQUET_SPECTRA_KEY",
    "SCAN_COLUMNS",
    "SPECTRUM_COLUMNS",
    "Exporter",
    "export_columns",
    "export_rows",
    "export_rows_iso",
    "export_run",
    "format_for_path",
    "read_parquet_export",
    "register_exporter",
    "resolve_format",
    "run_dataframe",
]

#: Columns of a scan export (one row per reading) and of a gloss export, in file order.
SCAN_COLUMNS: tuple[str, ...] = (
    "run_id",
    "run_uuid",
    "index",
    "repeat",
    "theta_i_deg",
    "theta_r_deg",
    # ASTM E2194 / DIN 6175-2: theta_i - theta_r (goniolab.colour.multiangle.aspecular_deg;
    # 15 = theta_r 30 at theta_i 45, < 0 beyond the specular direction)
    "aspecular_deg",
    "measured_theta_i_deg",
    "measured_theta_r_deg",
    "luminance_pct",
    "predicted_pct",
    "X",
    "Y",
    "Z",
    "L_star",
    "a_star",
    "b_star",
    "C_star",
    "h_deg",
    "predicted_L_star",
    "predicted_a_star",
    "predicted_b_star",
    "colour_error",
    # issue 21: the reading's quality flag and signal level, from its raw record
    "quality",
    "peak_fraction",
    "timestamp",
)
GLOSS_COLUMNS: tuple[str, ...] = (
    "run_id",
    "run_uuid",
    "seq",
    "timestamp",
    "g20_gu",
    "g60_gu",
    "g85_gu",
    "temperature_c",
    "predicted_g20_gu",
    "predicted_g60_gu",
    "predicted_g85_gu",
)
#: After :data:`SCAN_COLUMNS` in the export of a scan with spectra, before its ``R_<nm>``
#: and ``predicted_R_<nm>`` columns: what the spectra are relative to (``perfect diffuser``:
#: reflectance factors; ``perfect mirror``: fractions of the mirror, the ``[colour] scale =
#: "mirror"``) and what the reading was referenced to (a certified standard with its
#: certificate and method, or the spectro's own reference; empty without a spectrum).
SPECTRUM_COLUMNS: tuple[str, ...] = ("spectrum_relative_to", "spectrum_referenced_to")
#: The ``spectrum_relative_to`` cell by ``[colour] scale``.
SPECTRUM_RELATIVE_TO: dict[str, str] = {"diffuser": "perfect diffuser", "mirror": "perfect mirror"}
#: Schema-metadata key of the run record in a Parquet export.
PARQUET_RUN_KEY = b"goniolab.run"
#: Schema-metadata key of the spectra's provenance (JSON) in a Parquet export
#: (:meth:`goniolab.run_spectra.RunSpectra.provenance`).
PARQUET_SPECTRA_KEY = b"goniolab.spectra"

#: A text format's writer: the file's text (a writer of an exporter with ``no_spectra``
#: also takes ``spectra=False``).
TextWriter = Callable[..., str]
#: A binary format's writer: writes the file (replaced whole).
FileWriter = Callable[..., None]


@dataclass(frozen=True, slots=True)
class Exporter:
    """One export format.

    Attributes
    ----------
    name
        The ``--format`` name (lower case).
    suffixes
        The file suffixes that pick this format (lower case, with the dot); the first is
        the one it is written with.
    description
        One line for the CLI help and the docs.
    text
        A text format's writer (to stdout or to a file).
    to_file
        A binary format's writer (it needs a file).
    no_spectra
        The writer takes ``spectra=False`` (``runs export --no-spectra``): the compact
        table, without a scan's spectral columns and their provenance.
    """

    name: str
    suffixes: tuple[str, ...]
    description: str
    text: TextWriter | None = None
    to_file: FileWriter | None = None
    no_spectra: bool = False

    @property
    def suffix(self) -> str:
        """The suffix a file of this format is written with."""
        return self.suffixes[0]

    @property
    def binary(self) -> bool:
        """Whether the format needs a file (it cannot go to stdout)."""
        return self.text is None


#: The export formats by name, in the order the CLI lists them.
EXPORTERS: dict[str, Exporter] = {}
#: Each format's file suffix (``{"csv": ".csv", ..., "netcdf": ".nc"}``), kept by
#: :func:`register_exporter`.
FORMATS: dict[str, str] = {}


def register_exporter(exporter: Exporter) -> Exporter:
    """Add an export format; returns it.

    Raises
    ------
    ValueError
        The name or a suffix is taken, a suffix is not ``.lowercase``, or the exporter has
        not exactly one writer.
    """
    name = exporter.name
    if not name or name != name.lower() or name in EXPORTERS:
        raise ValueError(f"export format {name!r}: a new lower-case name is needed")
    if (exporter.text is None) == (exporter.to_file is None):
        raise ValueError(f"export format {name!r}: give exactly one of text= or to_file=")
    if not exporter.suffixes:
        raise ValueError(f"export format {name!r}: give at least one file suffix")
    for suffix in exporter.suffixes:
        if not suffix.startswith(".") or suffix != suffix.lower() or len(suffix) < 2:
            raise ValueError(f"export format {name!r}: suffix {suffix!r} is not like '.csv'")
        taken = format_for_path(f"x{suffix}")
        if taken is not None:
            raise ValueError(f"export format {name!r}: suffix {suffix} is {taken}'s")
    EXPORTERS[name] = exporter
    FORMATS[name] = exporter.suffix
    return exporter


def format_for_path(path: str | Path) -> str | None:
    """The export format a file suffix names (``.nc`` -> ``netcdf``), else ``None``."""
    suffix = Path(path).suffix.lower()
    return next((e.name for e in EXPORTERS.values() if suffix in e.suffixes), None)


def _known_suffixes() -> str:
    return ", ".join(f"{'/'.join(e.suffixes)} ({e.name})" for e in EXPORTERS.values())


def resolve_format(fmt: str | None, out: str | Path | None) -> str:
    """The format to export in: ``fmt`` when given, else the one ``out``'s suffix names,
    else ``csv`` (no file: text on stdout).

    Raises
    ------
    ValueError
        ``fmt`` is no export format; ``out`` has a suffix no exporter has (or none) and
        ``fmt`` is not given; or ``out``'s suffix is another format's than ``fmt`` (a
        Parquet file named ``.csv``). The message lists the known formats or suffixes.
    """
    if fmt is not None:
        if fmt not in EXPORTERS:
            raise ValueError(f"unknown export format {fmt!r} (known: {', '.join(EXPORTERS)})")
        named = None if out is None else format_for_path(out)
        if named is not None and named != fmt:
            raise ValueError(
                f"{out}: {Path(out or '').suffix} is the suffix of {named}, not of {fmt} "
                f"(write {fmt} as {'/'.join(EXPORTERS[fmt].suffixes)})"
            )
        return fmt
    if out is None:
        return "csv"
    named = format_for_path(out)
    if named is None:
        suffix = Path(out).suffix
        raise ValueError(
            f"{out}: {'the suffix ' + repr(suffix) if suffix else 'no suffix'} names no "
            f"export format (known: {_known_suffixes()}); pass --format csv|json|netcdf|parquet (format= in Python)"
        )
    return named


def export_run(
    store: RunStore, run_id: int, fmt: str, out: str | Path | None = None, *, spectra: bool = True
) -> str:
    """Export run ``run_id`` in ``fmt`` (a name of :data:`EXPORTERS`).

    Parameters
    ----------
    store
        An open store.
    run_id
        The run (``StoreError`` when it does not exist).
    fmt
        ``csv``, ``json``, ``netcdf``, ``parquet`` or a registered format.
    out
        The file to write; required for the binary formats (netCDF, Parquet). ``None``
        returns the text of a text format instead.
    spectra
        ``False``: leave a scan's spectra out (the ``R_<nm>``, ``predicted_R_<nm>`` and
        :data:`SPECTRUM_COLUMNS` columns, the JSON's ``spectra``, netCDF's spectral
        variables): the compact table (``runs export --no-spectra``).

    Returns
    -------
    str
        The text (a text format without ``out``) or ``""`` when a file was written.

    Raises
    ------
    ValueError
        Unknown format (the message lists the known ones), a binary format without
        ``out``, or ``spectra=False`` for a format that cannot leave them out.
    OSError
        The file cannot be written (an existing file is left as it was).
    """
    exporter = EXPORTERS.get(fmt)
    if exporter is None:
        raise ValueError(f"export format must be one of {', '.join(EXPORTERS)}, got {fmt!r}")
    options: dict[str, bool] = {}
    if not spectra:
        if not exporter.no_spectra:
            with_option = ", ".join(e.name for e in EXPORTERS.values() if e.no_spectra)
            raise ValueError(
                f"{fmt} cannot leave the spectra out (formats that can: {with_option})"
            )
        options["spectra"] = False
    if exporter.to_file is not None:
        if out is None:
            raise ValueError(
                f"{fmt} is a binary format: give an output file (-o run{exporter.suffix})"
            )
        exporter.to_file(store, run_id, Path(out), **options)
        return ""
    assert exporter.text is not None
    text = exporter.text(store, run_id, **options)
    if out is None:
        return text
    atomic_write_bytes(out, text.encode("utf-8"))
    return ""


# ---------------------------------------------------------------------- the rows


def export_rows(store: RunStore, run_id: int) -> list[dict[str, Any]]:
    """One flat dict per reading of ``run_id`` (points for scans, readings for gloss), with
    the columns of :func:`export_columns` (:data:`SCAN_COLUMNS` or :data:`GLOSS_COLUMNS`,
    then a scan's spectra); timestamps in Unix seconds."""
    return _table(store, run_id).rows


def export_columns(store: RunStore, run_id: int) -> tuple[str, ...]:
    """The columns of ``run_id``'s export, in file order: :data:`GLOSS_COLUMNS` for a gloss
    log; :data:`SCAN_COLUMNS` for a scan, followed, when it has spectra, by
    :data:`SPECTRUM_COLUMNS`, ``R_<nm>`` per wavelength of the readings' grid (the
    reading's spectrum on the run's scale) and ``predicted_R_<nm>`` per wavelength of
    the predictions' grid (the geometry's predicted spectrum)."""
    return _table(store, run_id).columns


@dataclass(frozen=True, slots=True)
class _Table:
    columns: tuple[str, ...]
    rows: list[dict[str, Any]]
    spectra: RunSpectra | None


def _table(store: RunStore, run_id: int, with_spectra: bool = True) -> _Table:
    run = store.get_run(run_id)
    if run.kind == "gloss":
        rows = [
            {
                "run_id": run_id,
                "run_uuid": run.uuid,
                "seq": g.seq,
                "timestamp": g.timestamp,
                "g20_gu": g.values_gu.get(20),
                "g60_gu": g.values_gu.get(60),
                "g85_gu": g.values_gu.get(85),
                "temperature_c": g.temperature_c,
                "predicted_g20_gu": None if g.predicted_gu is None else g.predicted_gu.get(20),
                "predicted_g60_gu": None if g.predicted_gu is None else g.predicted_gu.get(60),
                "predicted_g85_gu": None if g.predicted_gu is None else g.predicted_gu.get(85),
            }
            for g in store.gloss_readings(run_id)
        ]
        return _Table(GLOSS_COLUMNS, rows, None)
    preds = store.predictions(run_id)
    pcols = store.predicted_colours(run_id)
    points = store.points(run_id)

    def colour_cols(p: PointRow) -> dict[str, Any]:
        c = p.colour or {}
        pc = pcols.get(p.index)
        return {
            "X": c.get("X"),
            "Y": c.get("Y"),
            "Z": c.get("Z"),
            "L_star": c.get("L"),
            "a_star": c.get("a"),
            "b_star": c.get("b"),
            "C_star": c.get("C"),
            "h_deg": c.get("h_deg"),
            "predicted_L_star": None if pc is None else pc.L,
            "predicted_a_star": None if pc is None else pc.a,
            "predicted_b_star": None if pc is None else pc.b,
            "colour_error": p.colour_error,
        }

    rows = [
        {
            "run_id": run_id,
            "run_uuid": run.uuid,
            "index": p.index,
            "repeat": p.repeat,
            "theta_i_deg": p.theta_i_deg,
            "theta_r_deg": p.theta_r_deg,
            "aspecular_deg": p.theta_i_deg - p.theta_r_deg,  # the core's, inline (cheap import)
            "measured_theta_i_deg": p.measured_theta_i_deg,
            "measured_theta_r_deg": p.measured_theta_r_deg,
            "luminance_pct": p.luminance_pct,
            "predicted_pct": preds.get(p.index),
            **colour_cols(p),
            # ok / saturated / under_noise_floor / unknown ("" = a reading stored before
            # the flags), and the signal level it was judged by
            "quality": str(p.raw.get("quality", "")),
            "peak_fraction": p.raw.get("peak_fraction"),
            "timestamp": p.timestamp,
        }
        for p in points
    ]
    if run.kind != "brdf" or not with_spectra:  # an alignment or calibration run: no spectra
        return _Table(SCAN_COLUMNS, rows, None)
    if not any(p.raw.get("values") or p.raw.get("absolute_values") for p in points) and not any(
        pc.spectrum_pct for pc in pcols.values()
    ):  # nothing spectral stored (an imported run, a luminance-only instrument)
        return _Table(SCAN_COLUMNS, rows, None)
    from goniolab.run_spectra import run_spectra

    spectra = run_spectra(store, run_id, points)
    extra = _spectrum_columns(spectra)
    if not extra:
        return _Table(SCAN_COLUMNS, rows, None)
    for p, row in zip(points, rows, strict=True):
        row.update(_spectrum_cells(spectra, p.index, p.repeat))
    return _Table(SCAN_COLUMNS + extra, rows, spectra)


def _spectrum_columns(spectra: RunSpectra) -> tuple[str, ...]:
    from goniolab.run_spectra import PREDICTED_PREFIX, spectral_columns

    measured = spectral_columns(spectra.wavelengths_nm) if spectra.has_measured else []
    predicted = (
        []
        if spectra.predicted_wavelengths_nm is None
        else spectral_columns(spectra.predicted_wavelengths_nm, PREDICTED_PREFIX)
    )
    if not measured and not predicted:
        return ()
    return (*SPECTRUM_COLUMNS, *measured, *predicted)


def _cells(values: Any) -> list[float | None]:
    return [float(v) if math.isfinite(v) else None for v in values]


def _spectrum_cells(spectra: RunSpectra, index: int, repeat: int) -> dict[str, Any]:
    """A reading's spectrum columns: its own measured spectrum and its geometry's
    prediction (empty for the mirror reference and for a reading without a spectrum)."""
    from goniolab.run_spectra import PREDICTED_PREFIX, spectral_columns

    n, reps = spectra.measured.shape[:2]
    inside = 0 <= index < n and 0 <= repeat < reps
    referenced = spectra.referenced_by.get((index, repeat), "") if inside else ""
    out: dict[str, Any] = {
        "spectrum_relative_to": SPECTRUM_RELATIVE_TO.get(spectra.scale, spectra.scale),
        "spectrum_referenced_to": referenced,
    }
    if spectra.has_measured:
        names = spectral_columns(spectra.wavelengths_nm)
        values = _cells(spectra.measured[index, repeat]) if referenced else [None] * len(names)
        out.update(zip(names, values, strict=True))
    if spectra.predicted is not None and spectra.predicted_wavelengths_nm is not None:
        names = spectral_columns(spectra.predicted_wavelengths_nm, PREDICTED_PREFIX)
        at_geometry = 0 <= index < spectra.predicted.shape[0]
        values = _cells(spectra.predicted[index]) if at_geometry else [None] * len(names)
        out.update(zip(names, values, strict=True))
    return out


def export_rows_iso(store: RunStore, run_id: int) -> list[dict[str, Any]]:
    """:func:`export_rows` with each ``timestamp`` as ISO 8601 UTC text."""
    return _iso(export_rows(store, run_id))


def _iso(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    from goniolab.datasets import iso_utc

    for row in rows:
        if "timestamp" in row:
            row["timestamp"] = iso_utc(row["timestamp"])
    return rows


def run_dataframe(store: RunStore, run_id: int) -> pd.DataFrame:
    """One row per reading as a pandas DataFrame; ``timestamp`` is ``datetime64[us, UTC]``."""
    return _dataframe(_table(store, run_id))


def _dataframe(table: _Table) -> pd.DataFrame:
    import pandas as pd

    df = pd.DataFrame.from_records(table.rows, columns=list(table.columns))
    if "timestamp" in df:
        df["timestamp"] = pd.to_datetime(df["timestamp"], unit="s", utc=True).astype(
            "datetime64[us, UTC]"
        )
    for col in df.columns:
        if col != "timestamp" and df[col].dtype == object:
            converted = pd.to_numeric(df[col], errors="coerce")
            if converted.notna().sum() == df[col].notna().sum():
                df[col] = converted.astype("float64")
    return df


def _run_doc(store: RunStore, run_id: int) -> dict[str, Any]:
    from goniolab.datasets import iso_utc

    doc = store.get_run(run_id).as_dict()
    for key in ("created_at", "updated_at", "finished_at"):
        doc[f"{key}_iso"] = iso_utc(doc[key])
    return doc


# ---------------------------------------------------------------------- the writers


def _csv_text(store: RunStore, run_id: int, spectra: bool = True) -> str:
    table = _table(store, run_id, spectra)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(table.columns), lineterminator="\n")
    writer.writeheader()  # also for a run without readings yet
    writer.writerows(_iso(table.rows))
    return buf.getvalue()


def _json_text(store: RunStore, run_id: int, spectra: bool = True) -> str:
    table = _table(store, run_id, spectra)
    doc: dict[str, Any] = {"run": _run_doc(store, run_id), "readings": _iso(table.rows)}
    if table.spectra is not None:
        doc["spectra"] = table.spectra.provenance()
    return jsonout.dumps(doc, indent=2, default=str) + "\n"  # no NaN/Infinity


def _write_netcdf(store: RunStore, run_id: int, out: Path, spectra: bool = True) -> None:
    from goniolab.datasets import run_dataset, write_netcdf

    ds = run_dataset(store, run_id)
    if not spectra:  # the variables on a wavelength axis, and the axes
        ds = ds.drop_dims([d for d in ("wavelength_nm", "predicted_wavelength_nm") if d in ds.dims])
    write_netcdf(ds, out)


def _write_parquet(store: RunStore, run_id: int, out: Path, spectra: bool = True) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = _table(store, run_id, spectra)
    arrow = pa.Table.from_pandas(_dataframe(table), preserve_index=False)
    meta = dict(arrow.schema.metadata or {})
    meta[PARQUET_RUN_KEY] = json.dumps(_run_doc(store, run_id), sort_keys=True).encode()
    if table.spectra is not None:
        prov = table.spectra.provenance()
        meta[PARQUET_SPECTRA_KEY] = json.dumps(prov, sort_keys=True).encode()
        arrow = arrow.replace_schema_metadata(meta)
        arrow = arrow.cast(_spectrum_schema(arrow.schema, table.spectra))
    else:
        arrow = arrow.replace_schema_metadata(meta)
    sink = pa.BufferOutputStream()  # in memory, then replaced whole (goniolab._atomic)
    pq.write_table(arrow, sink)
    atomic_write_bytes(out, sink.getvalue().to_pybytes())


def _spectrum_schema(schema: pa.Schema, spectra: RunSpectra) -> pa.Schema:
    """``schema`` with field metadata on each spectral column: ``units`` "1", a
    ``long_name`` saying measured or predicted and relative to what, ``wavelength_nm``."""
    from goniolab.run_spectra import PREDICTED_PREFIX, spectral_columns

    labels: dict[str, tuple[str, float]] = {}
    if spectra.has_measured:
        for name, w in zip(spectral_columns(spectra.wavelengths_nm), spectra.wavelengths_nm,
                           strict=True):  # fmt: skip
            labels[name] = (f"measured {spectra.quantity}", float(w))
    if spectra.predicted_wavelengths_nm is not None:
        grid = spectra.predicted_wavelengths_nm
        for name, w in zip(spectral_columns(grid, PREDICTED_PREFIX), grid, strict=True):
            labels[name] = (f"predicted {spectra.quantity}", float(w))
    fields = []
    for f in schema:
        if f.name in labels:
            what, w = labels[f.name]
            f = f.with_metadata(
                {
                    b"units": b"1",
                    b"long_name": f"{what} at {w:g} nm, relative to the {spectra.relative_to}".encode(),
                    b"wavelength_nm": f"{w:g}".encode(),
                }
            )
        fields.append(f)
    import pyarrow as pa

    return pa.schema(fields, metadata=schema.metadata)


def read_parquet_export(path: str | Path) -> dict[str, Any]:
    """A Parquet export read back as the JSON export's document (``{"run", "readings",
    "spectra"}``, timestamps in Unix seconds, a NaN cell as ``None``), for ``runs import``.

    Raises
    ------
    ValueError
        The file cannot be read as Parquet, or carries no goniolab run record (the message
        names the file).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise ValueError(f"{path}: not a Parquet file: {exc}") from None
    meta = table.schema.metadata or {}
    if PARQUET_RUN_KEY not in meta:
        raise ValueError(
            f"{path}: no {PARQUET_RUN_KEY.decode()} schema metadata (not a goniolab run "
            "export: 'goniolab runs export RUN -o FILE.parquet' writes one)"
        )
    try:
        run = json.loads(meta[PARQUET_RUN_KEY])
        spectra = json.loads(meta[PARQUET_SPECTRA_KEY]) if PARQUET_SPECTRA_KEY in meta else None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: its goniolab schema metadata is not JSON: {exc}") from None

    def cell(v: Any) -> Any:
        if isinstance(v, float) and math.isnan(v):
            return None  # the DataFrame's missing value (an empty CSV cell, null in JSON)
        return v.timestamp() if hasattr(v, "timestamp") else v

    readings = [{k: cell(v) for k, v in row.items()} for row in table.to_pylist()]
    doc: dict[str, Any] = {"run": run, "readings": readings}
    if spectra is not None:
        doc["spectra"] = spectra
    return doc


register_exporter(
    Exporter(
        "csv",
        (".csv",),
        "one row per reading, ISO 8601 UTC timestamps, spectra as R_<nm> columns",
        text=_csv_text,
        no_spectra=True,
    )
)
register_exporter(
    Exporter(
        "json",
        (".json",),
        "the run record, its readings and their spectra's provenance",
        text=_json_text,
        no_spectra=True,
    )
)
register_exporter(
    Exporter(
        "netcdf",
        (".nc", ".nc4", ".netcdf"),
        "netCDF-4 (xarray + h5netcdf): CF-style units, the run's metadata as attributes",
        to_file=_write_netcdf,
        no_spectra=True,
    )
)
register_exporter(
    Exporter(
        "parquet",
        (".parquet", ".pq"),
        "Parquet (pyarrow): typed columns, the run record in the schema metadata",
        to_file=_write_parquet,
        no_spectra=True,
    )
)
