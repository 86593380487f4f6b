"""The store's tables: the SQLite and PostgreSQL schemas, and the additive upgrade of a store
written by an older goniolab (:func:`upgrade_schema`).

Tables
------
``meta``
    ``schema_version`` and the store's own ``store_uuid``; ``migrated:<source>:<id>`` rows
    written by an older ``runs migrate``.
``runs``
    One row per scan or gloss session: kind, plan JSON, config snapshot JSON, sample,
    model parameters JSON, goniolab version, status (a :class:`~goniolab.scan.events.RunState`
    value), reason, created/started/finished timestamps, and the run's identity (UUID,
    operator, notes, tags, physical sample id).
``points``
    One row per reading: plan point ``idx`` and ``repeat``, nominal and measured angles,
    ``luminance_pct``, the raw reading as JSON, its timestamp and measured colour.
    ``UNIQUE(run_id, idx, repeat)`` makes "every planned point stored exactly once" a
    property of the file, not of the code that writes it.
``predictions``
    The model's prediction for the geometry and aperture of each plan point (and its
    predicted colour and spectrum).
``gloss_readings``
    Glossmeter readings (20/60/85 deg in GU) with their timestamp and the prediction
    beside them when the sample has a height map.
``run_claims`` (PostgreSQL only)
    One row per claimed run, row-locked while a runner holds it (:mod:`goniolab.store.claims`).
"""

from __future__ import annotations

import uuid as uuidlib

from goniolab.store.connection import Connection
from goniolab.store.records import legacy_uuid

__all__ = ["PG_SCHEMA", "PG_SCHEMA_LOCK", "SCHEMA_VERSION", "SQLITE_SCHEMA", "upgrade_schema"]

#: 2: run identity (uuid, operator, notes, tags, sample_id), added to older stores on open.
SCHEMA_VERSION = 2

#: The tables, written once for both backends (``{serial}``: an auto-incremented id,
#: ``{run_ref}``: a run id column, ``{real}``: an 8-byte float).
_TABLES = """
CREATE TABLE IF NOT EXISTS meta (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS runs (
    id {serial},
    kind TEXT NOT NULL,
    plan_json TEXT NOT NULL,
    config_json TEXT NOT NULL,
    sample TEXT NOT NULL,
    model_json TEXT NOT NULL,
    version TEXT NOT NULL,
    status TEXT NOT NULL,
    reason TEXT NOT NULL DEFAULT '',
    created_at {real} NOT NULL,
    updated_at {real} NOT NULL,
    finished_at {real}
);
CREATE TABLE IF NOT EXISTS points (
    id {serial},
    run_id {run_ref} NOT NULL REFERENCES runs(id),
    idx INTEGER NOT NULL,
    repeat INTEGER NOT NULL,
    theta_i_deg {real} NOT NULL,
    theta_r_deg {real} NOT NULL,
    measured_theta_i_deg {real} NOT NULL,
    measured_theta_r_deg {real} NOT NULL,
    luminance_pct {real} NOT NULL,
    raw_json TEXT NOT NULL,
    timestamp {real} NOT NULL,
    UNIQUE (run_id, idx, repeat)
);
CREATE TABLE IF NOT EXISTS predictions (
    run_id {run_ref} NOT NULL REFERENCES runs(id),
    idx INTEGER NOT NULL,
    theta_i_deg {real} NOT NULL,
    theta_r_deg {real} NOT NULL,
    predicted_pct {real} NOT NULL,
    PRIMARY KEY (run_id, idx)
);
CREATE TABLE IF NOT EXISTS gloss_readings (
    id {serial},
    run_id {run_ref} NOT NULL REFERENCES runs(id),
    seq INTEGER NOT NULL,
    g20_gu {real},
    g60_gu {real},
    g85_gu {real},
    temperature_c {real},
    predicted_json TEXT,
    raw TEXT NOT NULL,
    timestamp {real} NOT NULL,
    UNIQUE (run_id, seq)
);
"""
#: The SQLite tables (REAL is an 8-byte float there) and the index of the readings.
SQLITE_SCHEMA = (
    _TABLES.format(serial="INTEGER PRIMARY KEY AUTOINCREMENT", run_ref="INTEGER", real="REAL")
    + "CREATE INDEX IF NOT EXISTS points_run ON points(run_id, idx, repeat);\n"
)

#: Colour columns (issue 11), added to stores created before them by ``ALTER TABLE``:
#: measured CIE XYZ / L*a*b* / L*C*h per point (:data:`~goniolab.store.records.COLOUR_KEYS`
#: order), predicted L*a*b* and spectrum per geometry.
_POINT_COLOUR_COLUMNS: tuple[tuple[str, str], ...] = (
    ("colour_X", "REAL"),
    ("colour_Y", "REAL"),
    ("colour_Z", "REAL"),
    ("colour_L", "REAL"),
    ("colour_a", "REAL"),
    ("colour_b", "REAL"),
    ("colour_C", "REAL"),
    ("colour_h_deg", "REAL"),
    ("colour_error", "TEXT"),
)
_PREDICTION_COLOUR_COLUMNS: tuple[tuple[str, str], ...] = (
    ("predicted_L", "REAL"),
    ("predicted_a", "REAL"),
    ("predicted_b", "REAL"),
    ("predicted_spectrum_json", "TEXT"),
)
#: Run identity (issue 22): a UUID that travels with the run (exports, migrations, bluesky
#: documents) and what the operator says about it. Older stores get them by ``ALTER TABLE``
#: and a UUID per existing run (:func:`~goniolab.store.records.legacy_uuid`).
_RUN_IDENTITY_COLUMNS: tuple[tuple[str, str], ...] = (
    ("uuid", "TEXT"),
    ("operator", "TEXT"),
    ("notes", "TEXT"),
    ("tags_json", "TEXT"),
    ("sample_id", "TEXT"),
)
_COLOUR_COLUMNS = (("points", _POINT_COLOUR_COLUMNS), ("predictions", _PREDICTION_COLOUR_COLUMNS))
#: Every column added after the first schema, by table.
_ADDED_COLUMNS = (*_COLOUR_COLUMNS, ("runs", _RUN_IDENTITY_COLUMNS))
#: Indexes that need the added columns (``runs list`` filters and ``migrate`` by UUID).
_ADDED_INDEXES = (
    "CREATE UNIQUE INDEX IF NOT EXISTS runs_uuid ON runs(uuid)",
    "CREATE INDEX IF NOT EXISTS runs_operator ON runs(operator)",
)

#: The same tables in PostgreSQL (``DOUBLE PRECISION`` where SQLite's REAL is 8 bytes),
#: plus ``run_claims``: one row per claimed run, row-locked while a runner holds it.
PG_SCHEMA = (
    _TABLES.format(serial="BIGSERIAL PRIMARY KEY", run_ref="BIGINT", real="DOUBLE PRECISION")
    + """CREATE TABLE IF NOT EXISTS run_claims (
    run_id BIGINT PRIMARY KEY REFERENCES runs(id)
);
"""
)
#: Advisory-lock key serialising schema creation by concurrent first users of a database.
PG_SCHEMA_LOCK = 0x60_1010_AB


def upgrade_schema(db: Connection) -> None:
    """Bring a store written by an older goniolab up to this schema (additive: nothing
    stored is changed; new columns are NULL for old rows, and each old run gets its
    :func:`~goniolab.store.records.legacy_uuid`); record the schema version and give the
    store its own UUID."""
    for table, cols in _ADDED_COLUMNS:
        have = {c.lower() for c in db.table_columns(table)}  # PostgreSQL folds case
        for name, sql_type in cols:
            if name.lower() not in have:
                kind = "DOUBLE PRECISION" if db.is_postgres and sql_type == "REAL" else sql_type
                db.execute(f"ALTER TABLE {table} ADD COLUMN {name} {kind}")
    db.forget_columns()
    missing = db.execute(
        "SELECT id, created_at FROM runs WHERE uuid IS NULL OR uuid = ''"
    ).fetchall()
    for run_id, created in missing:
        db.execute(
            "UPDATE runs SET uuid = ? WHERE id = ?",
            (legacy_uuid(db.location, int(run_id), float(created)), int(run_id)),
        )
    have_meta = dict(db.execute("SELECT key, value FROM meta").fetchall())
    if have_meta.get("schema_version") == str(SCHEMA_VERSION) and "store_uuid" in have_meta:
        return  # up to date: opening writes nothing (another program may hold the lock)
    for sql in _ADDED_INDEXES:
        db.execute(sql)
    db.execute(
        "INSERT INTO meta(key, value) VALUES ('schema_version', ?) ON CONFLICT (key)"
        " DO UPDATE SET value = excluded.value",
        (str(SCHEMA_VERSION),),
    )
    db.execute(
        "INSERT INTO meta(key, value) VALUES ('store_uuid', ?) ON CONFLICT (key) DO NOTHING",
        (str(uuidlib.uuid4()),),
    )
