"""Files others read: a stored run as CSV, JSON, netCDF or Parquet.

- **CSV**: one row per reading, ISO 8601 UTC timestamps, the columns of
  :meth:`goniolab.store.RunStore.export_rows` (colour columns included when the store has
  them).
- **JSON**: ``{"run": {...}, "readings": [...]}``, the run record with ISO times beside
  the Unix ones, readings as in the CSV.
- **netCDF** (netCDF-4 through xarray + h5netcdf): the Dataset of
  :func:`goniolab.datasets.run_dataset`, CF-style ``units`` on every variable and the run's
  metadata (plan, model, config snapshot, status, version) as global attributes.
- **Parquet** (pyarrow): the CSV's table with typed columns (timestamps as
  ``timestamp[us, UTC]``) and the run record as JSON in the schema metadata under the key
  ``goniolab.run``.

Every file is built in memory and replaced whole (:mod:`goniolab._atomic`): a full disk
or a failed export leaves an existing file as it was. Each carries the run's UUID
(``run_uuid`` column, ``uuid`` in the run record, ``run_uuid`` attribute).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from goniolab import jsonout
from goniolab._atomic import atomic_write_bytes
from goniolab.datasets import iso_utc

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd

    from goniolab.store import RunStore

__all__ = [
    "FORMATS",
    "PARQUET_RUN_KEY",
    "export_rows_iso",
    "export_run",
    "format_for_path",
    "run_dataframe",
]

#: Export formats and the file suffix each writes.
FORMATS: dict[str, str] = {"csv": ".csv", "json": ".json", "netcdf": ".nc", "parquet": ".parquet"}
#: Binary formats: they need ``-o FILE``.
_BINARY = ("netcdf", "parquet")
#: Schema-metadata key of the run record in a Parquet export.
PARQUET_RUN_KEY = b"goniolab.run"


def format_for_path(path: str | Path) -> str | None:
    """The export format a file suffix names (``.nc`` -> ``netcdf``), else ``None``."""
    suffix = Path(path).suffix.lower()
    if suffix in (".nc", ".nc4", ".netcdf"):
        return "netcdf"
    if suffix in (".parquet", ".pq"):
        return "parquet"
    if suffix in (".csv", ".json"):
        return suffix[1:]
    return None


def _run_doc(store: RunStore, run_id: int) -> dict[str, Any]:
    rec = store.get_run(run_id)
    doc = rec.as_dict()
    for key in ("created_at", "updated_at", "finished_at"):
        doc[f"{key}_iso"] = iso_utc(doc[key])
    return doc


def export_rows_iso(store: RunStore, run_id: int) -> list[dict[str, Any]]:
    """:meth:`RunStore.export_rows` with each ``timestamp`` as ISO 8601 UTC text."""
    rows = store.export_rows(run_id)
    for row in rows:
        if "timestamp" in row:
            row["timestamp"] = iso_utc(row["timestamp"])
    return rows


def _fields(store: RunStore, run_id: int, rows: list[dict[str, Any]]) -> list[str]:
    if rows:
        return list(rows[0])
    # no readings yet: the header alone (the store's own CSV knows the columns)
    header = store.export(run_id, "csv").splitlines()
    return header[0].split(",") if header else []


def run_dataframe(store: RunStore, run_id: int) -> pd.DataFrame:
    """One row per reading as a pandas DataFrame; ``timestamp`` is ``datetime64[us, UTC]``."""
    import pandas as pd

    rows = store.export_rows(run_id)
    fields = _fields(store, run_id, rows)
    df = pd.DataFrame.from_records(rows, columns=fields)
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


def _csv_text(store: RunStore, run_id: int) -> str:
    rows = export_rows_iso(store, run_id)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=_fields(store, run_id, rows), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def _json_text(store: RunStore, run_id: int) -> str:
    doc = {"run": _run_doc(store, run_id), "readings": export_rows_iso(store, run_id)}
    return jsonout.dumps(doc, indent=2, default=str) + "\n"  # no NaN/Infinity


def export_run(store: RunStore, run_id: int, fmt: str, out: str | Path | None = None) -> str:
    """Export run ``run_id`` in ``fmt`` (one of :data:`FORMATS`).

    Parameters
    ----------
    store
        An open store.
    run_id
        The run (``StoreError`` when it does not exist).
    fmt
        ``csv``, ``json``, ``netcdf`` or ``parquet``.
    out
        The file to write; required for the binary formats (netCDF, Parquet). ``None``
        returns the CSV/JSON text instead.

    Returns
    -------
    str
        The text (CSV/JSON without ``out``) or ``""`` when a file was written.

    Raises
    ------
    ValueError
        Unknown format, or a binary format without ``out``.
    OSError
        The file cannot be written.
    """
    if fmt not in FORMATS:
        raise ValueError(f"export format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt in _BINARY and out is None:
        raise ValueError(f"{fmt} is a binary format: give an output file (-o run{FORMATS[fmt]})")
    if fmt == "csv":
        text = _csv_text(store, run_id)
    elif fmt == "json":
        text = _json_text(store, run_id)
    elif fmt == "netcdf":
        from goniolab.datasets import run_dataset, write_netcdf

        assert out is not None
        write_netcdf(run_dataset(store, run_id), out)
        return ""
    else:
        assert out is not None
        _write_parquet(store, run_id, Path(out))
        return ""
    if out is None:
        return text
    atomic_write_bytes(out, text.encode("utf-8"))
    return ""


def _write_parquet(store: RunStore, run_id: int, out: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    df = run_dataframe(store, run_id)
    table = pa.Table.from_pandas(df, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[PARQUET_RUN_KEY] = json.dumps(_run_doc(store, run_id), sort_keys=True).encode()
    sink = pa.BufferOutputStream()  # in memory, then replaced whole (goniolab._atomic)
    pq.write_table(table.replace_schema_metadata(meta), sink)
    atomic_write_bytes(out, sink.getvalue().to_pybytes())
