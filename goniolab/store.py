"""The run store: one SQLite file in WAL mode (default) or a shared PostgreSQL database,
every reading committed as it is measured.

``RunStore(path)`` opens an SQLite file; ``RunStore("postgresql://user@host/db")`` a
PostgreSQL database (psycopg 3, the ``goniolab[postgres]`` extra) with the same tables,
the same per-reading commit and the same claim semantics: a claim is a row lock on
``run_claims`` held by a connection of the claiming process, dropped by the server when
that process dies (also on ``kill -9``), as the file lock is by the kernel. Credentials come
from libpq's own sources (``PGPASSWORD``, ``~/.pgpass``, ``PGSSLMODE`` and certificate
files, or the URL); a password never appears in a message, a log line or a run's config
snapshot (:func:`goniolab.logs.redact`).

Tables
------
``runs``
    One row per scan or gloss session: kind, plan JSON, config snapshot JSON, sample,
    model parameters JSON, goniolab version, status (a :class:`~goniolab.scan.events.RunState`
    value), reason, created/started/finished timestamps.
``points``
    One row per reading: plan point ``idx`` and ``repeat``, nominal and measured angles,
    ``luminance_pct``, the raw reading as JSON and its timestamp.
    ``UNIQUE(run_id, idx, repeat)`` makes "every planned point stored exactly once" a
    property of the file, not of the code that writes it.
``predictions``
    The model's prediction for the geometry and aperture of each plan point.
``gloss_readings``
    Glossmeter readings (20/60/85 deg in GU) with their timestamp and the prediction
    beside them when the sample has a height map.

Crash safety: each insert is its own transaction, committed before the next point is
measured. WAL with ``synchronous=FULL`` keeps a committed row across a process kill and a
power loss; nothing is buffered in memory.
"""

from __future__ import annotations

import contextlib
import csv
import fcntl
import io
import json
import os
import sqlite3
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import platformdirs

from goniolab.logs import redact

__all__ = [
    "COLOUR_KEYS",
    "GlossRow",
    "PointRow",
    "PredictedColour",
    "RunBusy",
    "RunRecord",
    "RunStore",
    "StoreError",
    "default_store_path",
    "is_store_url",
    "resolve_store_path",
]

_SCHEMA_VERSION = 1

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    kind TEXT NOT NULL,
    plan_json TEXT NOT NULL,
    config_json TEXT NOT NULL,
    sample TEXT NOT NULL,
    model_json TEXT NOT NULL,
    version TEXT NOT NULL,
    status TEXT NOT NULL,
    reason TEXT NOT NULL DEFAULT '',
    created_at REAL NOT NULL,
    updated_at REAL NOT NULL,
    finished_at REAL
);
CREATE TABLE IF NOT EXISTS points (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    run_id INTEGER NOT NULL REFERENCES runs(id),
    idx INTEGER NOT NULL,
    repeat INTEGER NOT NULL,
    theta_i_deg REAL NOT NULL,
    theta_r_deg REAL NOT NULL,
    measured_theta_i_deg REAL NOT NULL,
    measured_theta_r_deg REAL NOT NULL,
    luminance_pct REAL NOT NULL,
    raw_json TEXT NOT NULL,
    timestamp REAL NOT NULL,
    UNIQUE (run_id, idx, repeat)
);
CREATE TABLE IF NOT EXISTS predictions (
    run_id INTEGER NOT NULL REFERENCES runs(id),
    idx INTEGER NOT NULL,
    theta_i_deg REAL NOT NULL,
    theta_r_deg REAL NOT NULL,
    predicted_pct REAL NOT NULL,
    PRIMARY KEY (run_id, idx)
);
CREATE TABLE IF NOT EXISTS gloss_readings (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    run_id INTEGER NOT NULL REFERENCES runs(id),
    seq INTEGER NOT NULL,
    g20_gu REAL,
    g60_gu REAL,
    g85_gu REAL,
    temperature_c REAL,
    predicted_json TEXT,
    raw TEXT NOT NULL,
    timestamp REAL NOT NULL,
    UNIQUE (run_id, seq)
);
CREATE INDEX IF NOT EXISTS points_run ON points(run_id, idx, repeat);
"""

#: Colour columns (issue 11), added to stores created before them by ``ALTER TABLE``:
#: measured CIE XYZ / L*a*b* / L*C*h per point, predicted L*a*b* and spectrum per geometry.
COLOUR_KEYS: tuple[str, ...] = ("X", "Y", "Z", "L", "a", "b", "C", "h_deg")
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
_COLOUR_COLUMNS = (("points", _POINT_COLOUR_COLUMNS), ("predictions", _PREDICTION_COLOUR_COLUMNS))

#: The same tables in PostgreSQL (``DOUBLE PRECISION`` where SQLite's REAL is 8 bytes),
#: plus ``run_claims``: one row per claimed run, row-locked while a runner holds it.
_PG_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS runs (
    id BIGSERIAL PRIMARY KEY,
    kind TEXT NOT NULL,
    plan_json TEXT NOT NULL,
    config_json TEXT NOT NULL,
    sample TEXT NOT NULL,
    model_json TEXT NOT NULL,
    version TEXT NOT NULL,
    status TEXT NOT NULL,
    reason TEXT NOT NULL DEFAULT '',
    created_at DOUBLE PRECISION NOT NULL,
    updated_at DOUBLE PRECISION NOT NULL,
    finished_at DOUBLE PRECISION
);
CREATE TABLE IF NOT EXISTS points (
    id BIGSERIAL PRIMARY KEY,
    run_id BIGINT NOT NULL REFERENCES runs(id),
    idx INTEGER NOT NULL,
    repeat INTEGER NOT NULL,
    theta_i_deg DOUBLE PRECISION NOT NULL,
    theta_r_deg DOUBLE PRECISION NOT NULL,
    measured_theta_i_deg DOUBLE PRECISION NOT NULL,
    measured_theta_r_deg DOUBLE PRECISION NOT NULL,
    luminance_pct DOUBLE PRECISION NOT NULL,
    raw_json TEXT NOT NULL,
    timestamp DOUBLE PRECISION NOT NULL,
    UNIQUE (run_id, idx, repeat)
);
CREATE TABLE IF NOT EXISTS predictions (
    run_id BIGINT NOT NULL REFERENCES runs(id),
    idx INTEGER NOT NULL,
    theta_i_deg DOUBLE PRECISION NOT NULL,
    theta_r_deg DOUBLE PRECISION NOT NULL,
    predicted_pct DOUBLE PRECISION NOT NULL,
    PRIMARY KEY (run_id, idx)
);
CREATE TABLE IF NOT EXISTS gloss_readings (
    id BIGSERIAL PRIMARY KEY,
    run_id BIGINT NOT NULL REFERENCES runs(id),
    seq INTEGER NOT NULL,
    g20_gu DOUBLE PRECISION,
    g60_gu DOUBLE PRECISION,
    g85_gu DOUBLE PRECISION,
    temperature_c DOUBLE PRECISION,
    predicted_json TEXT,
    raw TEXT NOT NULL,
    timestamp DOUBLE PRECISION NOT NULL,
    UNIQUE (run_id, seq)
);
CREATE TABLE IF NOT EXISTS run_claims (
    run_id BIGINT PRIMARY KEY REFERENCES runs(id)
);
"""
#: Advisory-lock key serialising schema creation by concurrent first users of a database.
_PG_SCHEMA_LOCK = 0x60_1010_AB


#: CSV columns of a scan export (one row per reading) and of a gloss export.
_POINT_FIELDS = (
    "run_id",
    "index",
    "repeat",
    "theta_i_deg",
    "theta_r_deg",
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
    # issue 21 (measure): the reading's quality flag and signal level, from its raw record
    "quality",
    "peak_fraction",
    "timestamp",
)
_GLOSS_FIELDS = (
    "run_id",
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


#: The columns of a :class:`RunRecord`, in the order :meth:`RunRecord.from_row` reads them.
_RUN_SELECT = (
    "SELECT id, kind, plan_json, config_json, sample, model_json, version, status,"
    " reason, created_at, updated_at, finished_at FROM runs"
)


class StoreError(Exception):
    """The store file cannot be opened, or a run id does not exist (message names both)."""


class RunBusy(StoreError):
    """Another runner (this process or another one) is measuring the run right now."""


class _ClaimFile:
    """One open lock file per store, shared by every claim of this process.

    POSIX record locks (``lockf``) belong to the process and closing *any* descriptor of
    the file drops all of them, so the file is opened once and closed only when the last
    claim is released. The kernel drops the locks when the process dies (also on
    ``kill -9``): a crashed run is never left claimed.
    """

    _open: ClassVar[dict[Path, tuple[int, set[int]]]] = {}

    @classmethod
    def acquire(cls, lock_path: Path, run_id: int) -> None:
        fd, held = cls._open.get(lock_path, (-1, set()))
        if run_id in held:
            raise RunBusy(f"run {run_id} is already being measured by this process")
        if fd < 0:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, run_id)
        except OSError as exc:
            if not held:
                os.close(fd)
            raise RunBusy(
                f"run {run_id} is being measured by another goniolab process; stop that one first"
            ) from exc
        held.add(run_id)
        cls._open[lock_path] = (fd, held)

    @classmethod
    def is_held(cls, lock_path: Path, run_id: int) -> bool | None:
        """Whether a runner (any process) holds ``run_id``; ``None`` when it cannot be told.

        The probe takes the lock for an instant: a runner claiming the run in exactly that
        instant is refused (and says so); it never breaks a held claim.
        """
        fd, held = cls._open.get(lock_path, (-1, set()))
        if run_id in held:
            return True
        if not lock_path.exists():
            return False
        own = fd < 0
        if own:
            try:
                fd = os.open(lock_path, os.O_RDWR)
            except OSError:  # a read-only store: no write lock can be tried
                return None
        try:
            fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, run_id)
        except OSError:
            return True
        else:
            fcntl.lockf(fd, fcntl.LOCK_UN, 1, run_id)
            return False
        finally:
            if own:  # this process holds no lock on the file: closing drops nothing
                os.close(fd)

    @classmethod
    def release(cls, lock_path: Path, run_id: int) -> None:
        fd, held = cls._open[lock_path]
        fcntl.lockf(fd, fcntl.LOCK_UN, 1, run_id)
        held.discard(run_id)
        if not held:
            os.close(fd)
            del cls._open[lock_path]


@dataclass(frozen=True, slots=True)
class RunRecord:
    """One row of ``runs`` with its JSON columns decoded."""

    id: int
    kind: str
    plan: dict[str, Any]
    config: dict[str, Any]
    sample: str
    model: dict[str, Any]
    version: str
    status: str
    reason: str
    created_at: float
    updated_at: float
    finished_at: float | None

    @classmethod
    def from_row(cls, row: Sequence[Any]) -> RunRecord:
        """From the columns of ``_RUN_SELECT``, in that order."""
        return cls(
            id=int(row[0]),
            kind=str(row[1]),
            plan=json.loads(row[2]),
            config=json.loads(row[3]),
            sample=str(row[4]),
            model=json.loads(row[5]),
            version=str(row[6]),
            status=str(row[7]),
            reason=str(row[8]),
            created_at=float(row[9]),
            updated_at=float(row[10]),
            finished_at=None if row[11] is None else float(row[11]),
        )

    def as_dict(self) -> dict[str, Any]:
        """Return the record as a JSON-serialisable dict."""
        return {
            "id": self.id,
            "kind": self.kind,
            "plan": self.plan,
            "config": self.config,
            "sample": self.sample,
            "model": self.model,
            "version": self.version,
            "status": self.status,
            "reason": self.reason,
            "created_at": self.created_at,
            "updated_at": self.updated_at,
            "finished_at": self.finished_at,
        }


@dataclass(frozen=True, slots=True)
class PointRow:
    """One stored reading (one row of ``points``)."""

    index: int
    repeat: int
    theta_i_deg: float
    theta_r_deg: float
    measured_theta_i_deg: float
    measured_theta_r_deg: float
    luminance_pct: float
    raw: dict[str, Any]
    timestamp: float
    #: Measured colour (keys of :data:`COLOUR_KEYS`), ``None`` when the spectrum could not
    #: be converted (then ``colour_error`` says why) or the store predates colour.
    colour: dict[str, float] | None = None
    colour_error: str = ""

    @classmethod
    def from_row(cls, r: Sequence[Any]) -> PointRow:
        """From the columns idx, repeat, theta_i_deg, theta_r_deg, measured_theta_i_deg,
        measured_theta_r_deg, luminance_pct, raw_json, timestamp and, when the store has
        them, the colour columns (:data:`COLOUR_KEYS` order, then colour_error)."""
        colour = None
        error = ""
        if len(r) > 9:
            if r[12] is not None:
                colour = {k: float(v) for k, v in zip(COLOUR_KEYS, r[9:17], strict=True)}
            error = str(r[17] or "")
        return cls(
            index=int(r[0]),
            repeat=int(r[1]),
            theta_i_deg=float(r[2]),
            theta_r_deg=float(r[3]),
            measured_theta_i_deg=float(r[4]),
            measured_theta_r_deg=float(r[5]),
            luminance_pct=float(r[6]),
            raw=json.loads(r[7]),
            timestamp=float(r[8]),
            colour=colour,
            colour_error=error,
        )


@dataclass(frozen=True, slots=True)
class PredictedColour:
    """The predicted colour of one plan geometry (L*a*b*) and its spectrum (% of mirror)."""

    L: float
    a: float
    b: float
    spectrum_pct: tuple[float, ...] | None = None


@dataclass(frozen=True, slots=True)
class GlossRow:
    """One stored glossmeter reading (one row of ``gloss_readings``)."""

    seq: int
    values_gu: dict[int, float | None]
    temperature_c: float | None
    predicted_gu: dict[int, float] | None
    raw: str
    timestamp: float

    @classmethod
    def from_row(cls, r: Sequence[Any]) -> GlossRow:
        """From the columns seq, g20_gu, g60_gu, g85_gu, temperature_c, predicted_json,
        raw, timestamp."""
        pred = None if r[5] is None else {int(k): float(v) for k, v in json.loads(r[5]).items()}
        return cls(
            seq=int(r[0]),
            values_gu={20: r[1], 60: r[2], 85: r[3]},
            temperature_c=r[4],
            predicted_gu=pred,
            raw=str(r[6]),
            timestamp=float(r[7]),
        )


def default_store_path() -> Path:
    """Return the default store file: ``<user data dir>/goniolab.sqlite`` (platformdirs)."""
    return Path(platformdirs.user_data_dir("goniolab", appauthor=False)) / "goniolab.sqlite"


def is_store_url(location: str | Path) -> bool:
    """Whether ``location`` names a PostgreSQL database (``postgresql://`` or ``postgres://``)."""
    return isinstance(location, str) and location.startswith(("postgresql://", "postgres://"))


def resolve_store_path(cli_store: str | None, config_store: str | None = None) -> Path | str:
    """Pick the store: ``--store`` first, then config ``[lab] store``, then the default file.

    A ``postgresql://`` URL is returned as it is (a string); a file as a :class:`Path`.
    """
    for choice in (cli_store, config_store):
        if choice:
            return choice if is_store_url(choice) else Path(choice).expanduser()
    return default_store_path()


def _pg_why(exc: BaseException) -> str:
    """psycopg's reason on one line (libpq's messages span lines)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def _why(exc: BaseException) -> str:
    """SQLite's reason, with the one a user meets most often made explicit."""
    text = str(exc)
    if "file is not a database" in text:
        return "not a goniolab run store (the file is not an SQLite database)"
    return text


def _dumps(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)


def _redacted(obj: Any) -> Any:
    """``obj`` with every string passed through :func:`goniolab.logs.redact` (a config
    snapshot keeps the store URL, never its password)."""
    if isinstance(obj, str):
        return redact(obj)
    if isinstance(obj, Mapping):
        return {k: _redacted(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_redacted(v) for v in obj]
    return obj


class _PgConnection:
    """A psycopg connection that speaks the SQLite store's SQL: ``?`` placeholders,
    ``BEGIN IMMEDIATE``; autocommit outside explicit transactions."""

    def __init__(self, conn: Any) -> None:
        self.conn = conn

    @staticmethod
    def _sql(sql: str) -> str:
        return "BEGIN" if sql == "BEGIN IMMEDIATE" else sql.replace("?", "%s")

    def execute(self, sql: str, params: Sequence[Any] = ()) -> Any:
        return self.conn.execute(self._sql(sql), tuple(params))

    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> Any:
        cur = self.conn.cursor()
        cur.executemany(self._sql(sql), [tuple(r) for r in rows])
        return cur

    def close(self) -> None:
        self.conn.close()


def _psycopg() -> Any:
    try:
        import psycopg
    except ImportError:
        raise StoreError(
            "a postgresql:// store needs psycopg: pip install 'goniolab[postgres]'"
        ) from None
    return psycopg


class RunStore:
    """The SQLite run store (one file, WAL mode).

    Parameters
    ----------
    path
        The database file; its directory is created if missing.
    readonly
        Open for reading only (``runs list/show/export``): the file must exist, nothing
        is created or written, and a store on read-only media can still be read.
    create
        Create the file when missing (``False``: a missing store is an error, e.g. for
        ``scan resume``).

    Raises
    ------
    StoreError
        The file cannot be opened or created; the message names the file and the reason
        (a directory, a read-only location, not an SQLite store, ...).

    Notes
    -----
    A :class:`RunStore` is used from one thread (the event loop's); numeric work goes to
    worker threads, store writes never do.
    """

    def __init__(self, path: str | Path, *, readonly: bool = False, create: bool = True) -> None:
        self.readonly = readonly
        self.is_postgres = is_store_url(path)
        self._claims: dict[int, Any] = {}
        self._colour_cols: bool | None = None
        if self.is_postgres:
            self._conninfo = str(path)
            #: How the store names itself (a URL without its password).
            self.location = redact(self._conninfo)
            self.path = Path(self.location.split("://", 1)[-1])
            self._db: Any = self._open_postgres(readonly=readonly, create=create)
            return
        self.path = Path(path)
        self.location = str(self.path)
        self._db = self._open_sqlite(readonly=readonly, create=create)

    def _open_sqlite(self, *, readonly: bool, create: bool) -> sqlite3.Connection:
        """Open the SQLite file: read-only, or for writing (created when missing and
        ``create``), after checks that say why a location cannot serve."""
        where = f"store {self.path}"
        if self.path.is_dir():
            raise StoreError(f"{where}: is a directory, not a store file")
        exists = self.path.exists()
        if not exists and (readonly or not create):
            raise StoreError(f"{where}: no such file (no run has been recorded there)")
        if readonly:
            return self._open_readonly(where)
        self._check_writable(where, exists)
        return self._open_writable(where)

    def _check_writable(self, where: str, exists: bool) -> None:
        """Create the store's directory; refuse, saying why, a location SQLite could only
        answer with "unable to open database file"."""
        blocker = next((d for d in self.path.parents if d.exists()), None)
        if blocker is not None and not blocker.is_dir():
            raise StoreError(f"{where}: {blocker} is a file, not a directory")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(
                f"{where}: cannot create the directory {self.path.parent}: {exc.strerror}"
            ) from exc
        # SQLite's own message for these is "unable to open database file": say why.
        # WAL writes <store>-wal and <store>-shm beside the file, so the directory must
        # be writable too (os.access also reports a read-only file system, even for root).
        if not os.access(self.path.parent, os.W_OK):
            raise StoreError(
                f"{where}: the directory {self.path.parent} is not writable "
                "(read-only file system or permissions); choose another --store"
            )
        if exists and not os.access(self.path, os.W_OK):
            raise StoreError(f"{where}: the file is read-only; choose another --store")

    def _open_writable(self, where: str) -> sqlite3.Connection:
        """Open (and create) the SQLite store: WAL, ``synchronous=FULL``, the schema."""
        try:
            db = sqlite3.connect(self.path, isolation_level=None, timeout=10.0)
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=FULL")
            db.execute("PRAGMA foreign_keys=ON")
            db.executescript(_SCHEMA)
            self._db = db  # _add_missing_columns reads the tables through self._db
            self._add_missing_columns()
            db.execute(
                "INSERT INTO meta(key, value) VALUES ('schema_version', ?)"
                " ON CONFLICT (key) DO NOTHING",
                (str(_SCHEMA_VERSION),),
            )
        except (OSError, sqlite3.Error) as exc:
            raise StoreError(f"{where}: cannot open: {_why(exc)}") from exc
        return db

    def _open_postgres(self, *, readonly: bool, create: bool) -> _PgConnection:
        """Connect (libpq reads PGPASSWORD, ~/.pgpass, PGSSLMODE ... itself) and create the
        tables unless ``readonly``; every message is passed through :func:`redact`."""
        psycopg = _psycopg()
        where = f"store {self.location}"
        try:
            conn = psycopg.connect(self._conninfo, autocommit=True, connect_timeout=10)
        except psycopg.Error as exc:
            raise StoreError(redact(f"{where}: cannot connect: {_pg_why(exc)}")) from None
        db = _PgConnection(conn)
        try:
            have = db.execute("SELECT to_regclass('runs') IS NOT NULL").fetchone()[0]
            if not have and (readonly or not create):
                raise StoreError(f"{where}: no goniolab run store in this database (no runs table)")
            if not readonly:
                with conn.transaction():
                    conn.execute("SELECT pg_advisory_xact_lock(%s)", (_PG_SCHEMA_LOCK,))
                    conn.execute(_PG_SCHEMA)
                    db.execute(
                        "INSERT INTO meta(key, value) VALUES ('schema_version', ?)"
                        " ON CONFLICT (key) DO NOTHING",
                        (str(_SCHEMA_VERSION),),
                    )
                    for table, cols in _COLOUR_COLUMNS:
                        for name, sql_type in cols:
                            pg_type = "DOUBLE PRECISION" if sql_type == "REAL" else sql_type
                            db.execute(
                                f"ALTER TABLE {table} ADD COLUMN IF NOT EXISTS {name} {pg_type}"
                            )
        except psycopg.Error as exc:
            conn.close()
            raise StoreError(redact(f"{where}: cannot open: {_pg_why(exc)}")) from None
        except StoreError:
            conn.close()
            raise
        return db

    def _add_missing_columns(self) -> None:
        """Bring an SQLite store written by an older goniolab up to the colour columns
        (additive: nothing stored is touched; the new columns are NULL for old rows)."""
        for table, cols in _COLOUR_COLUMNS:
            have = set(self.table_columns(table))
            for name, sql_type in cols:
                if name not in have:
                    self._db.execute(f"ALTER TABLE {table} ADD COLUMN {name} {sql_type}")

    @property
    def _has_colour(self) -> bool:
        """Whether this store has the colour columns (an old read-only store may not)."""
        if self._colour_cols is None:
            self._colour_cols = "colour_L" in self.table_columns("points")
        return self._colour_cols

    def _open_readonly(self, where: str) -> sqlite3.Connection:
        """Open for reading only: ``mode=ro``; on a read-only directory (no ``-shm`` can be
        created beside the file) ``immutable=1``, which reads the main file as it is."""
        uri = self.path.resolve().as_uri()
        query = "mode=ro" if os.access(self.path.parent, os.W_OK) else "immutable=1"
        try:
            db = sqlite3.connect(f"{uri}?{query}", uri=True, isolation_level=None, timeout=10.0)
            row = db.execute(
                "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'runs'"
            ).fetchone()
        except sqlite3.Error as exc:
            raise StoreError(f"{where}: cannot open: {_why(exc)}") from exc
        if not row[0]:
            db.close()
            raise StoreError(f"{where}: not a goniolab run store (no runs table)")
        return db

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Close the connection (committed data is already on disk)."""
        for conn in self._claims.values():
            conn.close()
        self._claims.clear()
        self._db.close()

    def __enter__(self) -> RunStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def _tx(self) -> Iterator[Any]:
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield self._db
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    @property
    def journal_mode(self) -> str:
        """The SQLite journal mode in use (``"wal"``; ``""`` for PostgreSQL)."""
        if self.is_postgres:
            return ""
        return str(self._db.execute("PRAGMA journal_mode").fetchone()[0])

    # ------------------------------------------------------------------ claims
    @contextmanager
    def claim_run(self, run_id: int) -> Iterator[None]:
        """Hold the run for measuring: a second runner of the same run (another process,
        e.g. ``scan resume`` while the scan still runs, or this one) gets :class:`RunBusy`.

        The claim is a POSIX record lock on byte ``run_id`` of ``<store>-lock`` beside the
        store file, released on exit and by the kernel when the process dies. In
        PostgreSQL it is a row lock (``SELECT ... FOR UPDATE NOWAIT`` on ``run_claims``) held
        by a connection of its own, released on exit and by the server when the process
        (and so its connection) dies.
        """
        claim = self._claim_postgres if self.is_postgres else self._claim_file
        with claim(run_id):
            yield

    def is_claimed(self, run_id: int) -> bool | None:
        """Whether a runner (this or another process) is measuring ``run_id`` right now;
        ``None`` when the store is read-only and it cannot be told. A run whose status
        says ``running`` but that nobody claims was interrupted (e.g. ``kill -9``)."""
        if self.is_postgres:
            return self._is_claimed_postgres(run_id)
        return _ClaimFile.is_held(self._lock_path, run_id)

    @contextmanager
    def _claim_file(self, run_id: int) -> Iterator[None]:
        """SQLite: the POSIX record lock on byte ``run_id`` of ``<store>-lock``."""
        lock_path = self._lock_path
        try:
            _ClaimFile.acquire(lock_path, run_id)
        except RunBusy as exc:
            raise RunBusy(f"store {self.path}: {exc}") from None
        except OSError as exc:
            raise StoreError(f"store {self.path}: cannot claim run {run_id}: {exc}") from exc
        try:
            yield
        finally:
            _ClaimFile.release(lock_path, run_id)

    def _is_claimed_postgres(self, run_id: int) -> bool:
        """PostgreSQL: the run's ``run_claims`` row is locked by some connection."""
        if run_id in self._claims:
            return True
        with self._tx() as db:
            free = db.execute(
                "SELECT run_id FROM run_claims WHERE run_id = ? FOR UPDATE SKIP LOCKED",
                (run_id,),
            ).fetchone()
            exists = db.execute(
                "SELECT COUNT(*) FROM run_claims WHERE run_id = ?", (run_id,)
            ).fetchone()[0]
        return bool(exists) and free is None

    @contextmanager
    def _claim_postgres(self, run_id: int) -> Iterator[None]:
        psycopg = _psycopg()
        where = f"store {self.location}"
        if run_id in self._claims:
            raise RunBusy(f"{where}: run {run_id} is already being measured by this process")
        self.get_run(run_id)
        self._db.execute(
            "INSERT INTO run_claims(run_id) VALUES (?) ON CONFLICT (run_id) DO NOTHING", (run_id,)
        )
        try:
            conn = psycopg.connect(self._conninfo, autocommit=False, connect_timeout=10)
        except psycopg.Error as exc:
            raise StoreError(
                redact(f"{where}: cannot claim run {run_id}: {_pg_why(exc)}")
            ) from None
        try:
            conn.execute(
                "SELECT run_id FROM run_claims WHERE run_id = %s FOR UPDATE NOWAIT", (run_id,)
            )
        except psycopg.errors.LockNotAvailable:
            conn.close()
            raise RunBusy(
                f"{where}: run {run_id} is being measured by another goniolab process; "
                "stop that one first"
            ) from None
        self._claims[run_id] = conn
        try:
            yield
        finally:
            self._claims.pop(run_id, None)
            # a round trip: the row lock is gone when it returns (close alone is async);
            # on a dead connection the server drops the lock with it
            with contextlib.suppress(psycopg.Error):
                conn.rollback()
            conn.close()

    @property
    def _lock_path(self) -> Path:
        return self.path.resolve().with_name(self.path.name + "-lock")

    # ------------------------------------------------------------------ runs
    def create_run(
        self,
        *,
        kind: str,
        plan: Mapping[str, Any],
        config: Mapping[str, Any],
        sample: str,
        model: Mapping[str, Any],
        version: str,
        status: str = "idle",
    ) -> int:
        """Insert a run and return its id."""
        now = time.time()
        with self._tx() as db:
            row = db.execute(
                "INSERT INTO runs(kind, plan_json, config_json, sample, model_json, version,"
                " status, reason, created_at, updated_at) VALUES (?,?,?,?,?,?,?,?,?,?)"
                " RETURNING id",
                (kind, _dumps(plan), _dumps(_redacted(config)), sample, _dumps(model), version,
                 status, "", now, now),
            ).fetchone()  # fmt: skip
        return int(row[0])

    def set_status(self, run_id: int, status: str, reason: str = "") -> None:
        """Record the run's state; terminal states (done, aborted, failed) set ``finished_at``."""
        now = time.time()
        finished = now if status in ("done", "aborted", "failed") else None
        with self._tx() as db:
            cur = db.execute(
                "UPDATE runs SET status = ?, reason = ?, updated_at = ?, finished_at = ?"
                " WHERE id = ?",
                (status, reason, now, finished, run_id),
            )
            if cur.rowcount != 1:
                raise StoreError(f"store {self.location}: no run {run_id}")

    def update_model(self, run_id: int, extra: Mapping[str, Any]) -> None:
        """Merge ``extra`` into the run's model parameters (e.g. an alignment's result)."""
        with self._tx() as db:
            row = db.execute("SELECT model_json FROM runs WHERE id = ?", (run_id,)).fetchone()
            if row is None:
                raise StoreError(f"store {self.path}: no run {run_id}")
            model = {**json.loads(row[0]), **extra}
            db.execute(
                "UPDATE runs SET model_json = ?, updated_at = ? WHERE id = ?",
                (_dumps(model), time.time(), run_id),
            )

    def get_run(self, run_id: int) -> RunRecord:
        """Return run ``run_id``; :class:`StoreError` naming the file when it does not exist."""
        row = self._db.execute(f"{_RUN_SELECT} WHERE id = ?", (run_id,)).fetchone()
        if row is None:
            raise StoreError(f"store {self.location}: no run {run_id}")
        return RunRecord.from_row(row)

    def list_runs(self, limit: int | None = None) -> list[RunRecord]:
        """Return runs, newest first."""
        sql = f"{_RUN_SELECT} ORDER BY id DESC"
        params: tuple[int, ...] = ()
        if limit is not None:
            sql += " LIMIT ?"
            params = (limit,)
        return [RunRecord.from_row(r) for r in self._db.execute(sql, params).fetchall()]

    # ------------------------------------------------------------------ points
    def add_point(
        self,
        run_id: int,
        *,
        index: int,
        repeat: int,
        theta_i_deg: float,
        theta_r_deg: float,
        measured_theta_i_deg: float,
        measured_theta_r_deg: float,
        luminance_pct: float,
        raw: Mapping[str, Any],
        timestamp: float,
        colour: Mapping[str, float] | None = None,
        colour_error: str = "",
    ) -> None:
        """Commit one reading. A second reading of the same (index, repeat) is refused.

        ``colour`` (keys of :data:`COLOUR_KEYS`) is the reading's measured colour, stored in
        the same row; ``colour_error`` says why there is none (a bad spectrum).

        Raises
        ------
        sqlite3.IntegrityError
            When (run_id, index, repeat) is already stored.
        """
        with self._tx() as db:
            db.execute(
                "INSERT INTO points(run_id, idx, repeat, theta_i_deg, theta_r_deg,"
                " measured_theta_i_deg, measured_theta_r_deg, luminance_pct, raw_json, timestamp)"
                " VALUES (?,?,?,?,?,?,?,?,?,?)",
                (run_id, index, repeat, theta_i_deg, theta_r_deg, measured_theta_i_deg,
                 measured_theta_r_deg, luminance_pct, _dumps(dict(raw)), timestamp),
            )  # fmt: skip
            if colour is not None or colour_error:
                values = [None if colour is None else float(colour[k]) for k in COLOUR_KEYS]
                db.execute(
                    "UPDATE points SET colour_X = ?, colour_Y = ?, colour_Z = ?, colour_L = ?,"
                    " colour_a = ?, colour_b = ?, colour_C = ?, colour_h_deg = ?,"
                    " colour_error = ? WHERE run_id = ? AND idx = ? AND repeat = ?",
                    (*values, colour_error or None, run_id, index, repeat),
                )

    def done_keys(self, run_id: int) -> set[tuple[int, int]]:
        """Return the (index, repeat) pairs already stored for ``run_id``."""
        rows = self._db.execute("SELECT idx, repeat FROM points WHERE run_id = ?", (run_id,))
        return {(int(i), int(r)) for i, r in rows.fetchall()}

    def points(self, run_id: int) -> list[PointRow]:
        """Return every stored reading of ``run_id`` ordered by (index, repeat)."""
        colour_sql = (
            ", colour_X, colour_Y, colour_Z, colour_L, colour_a, colour_b, colour_C,"
            " colour_h_deg, colour_error"
            if self._has_colour
            else ""
        )
        rows = self._db.execute(
            "SELECT idx, repeat, theta_i_deg, theta_r_deg, measured_theta_i_deg,"
            " measured_theta_r_deg, luminance_pct, raw_json, timestamp"
            + colour_sql
            + " FROM points WHERE run_id = ? ORDER BY idx, repeat",
            (run_id,),
        ).fetchall()
        return [PointRow.from_row(r) for r in rows]

    def count_points(self, run_id: int) -> int:
        """Return the number of stored readings of ``run_id``."""
        row = self._db.execute("SELECT COUNT(*) FROM points WHERE run_id = ?", (run_id,))
        return int(row.fetchone()[0])

    # ------------------------------------------------------------------ predictions
    def add_predictions(self, run_id: int, rows: Sequence[tuple[int, float, float, float]]) -> None:
        """Store predictions ``(index, theta_i_deg, theta_r_deg, predicted_pct)`` (upsert)."""
        with self._tx() as db:
            db.executemany(
                "INSERT INTO predictions(run_id, idx, theta_i_deg, theta_r_deg,"
                " predicted_pct) VALUES (?,?,?,?,?) ON CONFLICT (run_id, idx) DO UPDATE SET"
                " theta_i_deg = excluded.theta_i_deg, theta_r_deg = excluded.theta_r_deg,"
                " predicted_pct = excluded.predicted_pct",
                [(run_id, int(i), float(ti), float(tr), float(p)) for i, ti, tr, p in rows],
            )

    def add_predicted_colours(
        self, run_id: int, rows: Sequence[tuple[int, PredictedColour]]
    ) -> None:
        """Store the predicted colour (and spectrum) of geometries already predicted."""
        with self._tx() as db:
            db.executemany(
                "UPDATE predictions SET predicted_L = ?, predicted_a = ?, predicted_b = ?,"
                " predicted_spectrum_json = ? WHERE run_id = ? AND idx = ?",
                [
                    (
                        c.L,
                        c.a,
                        c.b,
                        None if c.spectrum_pct is None else json.dumps(list(c.spectrum_pct)),
                        run_id,
                        int(i),
                    )
                    for i, c in rows
                ],
            )

    def predicted_colours(self, run_id: int) -> dict[int, PredictedColour]:
        """Return ``{index: PredictedColour}`` for the geometries with a predicted colour."""
        if not self._has_colour:
            return {}
        rows = self._db.execute(
            "SELECT idx, predicted_L, predicted_a, predicted_b, predicted_spectrum_json"
            " FROM predictions WHERE run_id = ? AND predicted_L IS NOT NULL",
            (run_id,),
        ).fetchall()
        return {
            int(i): PredictedColour(
                float(lv), float(av), float(bv), None if sj is None else tuple(json.loads(sj))
            )
            for i, lv, av, bv, sj in rows
        }

    def predictions(self, run_id: int) -> dict[int, float]:
        """Return ``{index: predicted_pct}`` for ``run_id``."""
        rows = self._db.execute(
            "SELECT idx, predicted_pct FROM predictions WHERE run_id = ?", (run_id,)
        ).fetchall()
        return {int(i): float(p) for i, p in rows}

    # ------------------------------------------------------------------ gloss
    def add_gloss_reading(
        self,
        run_id: int,
        *,
        values_gu: Mapping[int, float | None],
        temperature_c: float | None,
        predicted_gu: Mapping[int, float] | None,
        raw: str,
        timestamp: float,
    ) -> int:
        """Commit one glossmeter reading; returns its sequence number within the run."""
        with self._tx() as db:
            seq = int(
                db.execute(
                    "SELECT COALESCE(MAX(seq), -1) + 1 FROM gloss_readings WHERE run_id = ?",
                    (run_id,),
                ).fetchone()[0]
            )
            pred = (
                None
                if predicted_gu is None
                else _dumps({str(k): v for k, v in predicted_gu.items()})
            )
            db.execute(
                "INSERT INTO gloss_readings(run_id, seq, g20_gu, g60_gu, g85_gu, temperature_c,"
                " predicted_json, raw, timestamp) VALUES (?,?,?,?,?,?,?,?,?)",
                (run_id, seq, values_gu.get(20), values_gu.get(60), values_gu.get(85),
                 temperature_c, pred, raw, timestamp),
            )  # fmt: skip
        return seq

    def gloss_readings(self, run_id: int) -> list[GlossRow]:
        """Return the glossmeter readings of ``run_id`` in the order they were read."""
        rows = self._db.execute(
            "SELECT seq, g20_gu, g60_gu, g85_gu, temperature_c, predicted_json, raw, timestamp"
            " FROM gloss_readings WHERE run_id = ? ORDER BY seq",
            (run_id,),
        ).fetchall()
        return [GlossRow.from_row(r) for r in rows]

    # ------------------------------------------------------------------ migration
    def table_columns(self, table: str) -> list[str]:
        """The column names of ``table`` in this store."""
        if self.is_postgres:
            rows = self._db.execute(
                "SELECT column_name FROM information_schema.columns"
                " WHERE table_schema = current_schema() AND table_name = ?"
                " ORDER BY ordinal_position",
                (table,),
            ).fetchall()
        else:
            rows = [(r[1],) for r in self._db.execute(f"PRAGMA table_info({table})").fetchall()]
        return [str(r[0]) for r in rows]

    def copy_run_from(self, src: RunStore, run_id: int) -> tuple[int, bool]:
        """Copy run ``run_id`` of ``src`` (with its readings, predictions and gloss readings)
        into this store in one transaction; returns ``(new id, copied)``.

        The source run is remembered (``meta``): copying it again returns the id of the
        first copy and ``copied = False``, so a migration can be re-run after a failure.
        Columns both stores have are copied (a newer source's extra columns are dropped).
        """
        key = f"migrated:{src.location}:{run_id}"
        done = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        if done is not None:
            return int(done[0]), False
        src_run = src._db.execute("SELECT * FROM runs WHERE id = ?", (run_id,))
        names = [d[0] for d in src_run.description]
        row = src_run.fetchone()
        if row is None:
            raise StoreError(f"store {src.location}: no run {run_id}")
        record = dict(zip(names, row, strict=True))
        record["config_json"] = _dumps(_redacted(json.loads(record["config_json"])))
        run_cols = [c for c in self.table_columns("runs") if c in record and c != "id"]
        with self._tx() as db:
            new_id = int(
                db.execute(
                    f"INSERT INTO runs({', '.join(run_cols)}) VALUES"
                    f" ({', '.join('?' for _ in run_cols)}) RETURNING id",
                    [record[c] for c in run_cols],
                ).fetchone()[0]
            )
            for table in ("points", "predictions", "gloss_readings"):
                theirs = src.table_columns(table)
                cols = [c for c in self.table_columns(table) if c in theirs and c != "id"]
                rows = src._db.execute(
                    f"SELECT {', '.join(cols)} FROM {table} WHERE run_id = ?", (run_id,)
                ).fetchall()
                if not rows:
                    continue
                at = cols.index("run_id")
                values = [[new_id if k == at else v for k, v in enumerate(r)] for r in rows]
                db.executemany(
                    f"INSERT INTO {table}({', '.join(cols)}) VALUES"
                    f" ({', '.join('?' for _ in cols)})",
                    values,
                )
            db.execute("INSERT INTO meta(key, value) VALUES (?, ?)", (key, str(new_id)))
        return new_id, True

    # ------------------------------------------------------------------ export
    def export_rows(self, run_id: int) -> list[dict[str, Any]]:
        """One flat dict per reading of ``run_id`` (points for scans, readings for gloss)."""
        run = self.get_run(run_id)
        if run.kind == "gloss":
            return [
                {
                    "run_id": run_id,
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
                for g in self.gloss_readings(run_id)
            ]
        preds = self.predictions(run_id)
        pcols = self.predicted_colours(run_id)

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

        return [
            {
                "run_id": run_id,
                "index": p.index,
                "repeat": p.repeat,
                "theta_i_deg": p.theta_i_deg,
                "theta_r_deg": p.theta_r_deg,
                "measured_theta_i_deg": p.measured_theta_i_deg,
                "measured_theta_r_deg": p.measured_theta_r_deg,
                "luminance_pct": p.luminance_pct,
                "predicted_pct": preds.get(p.index),
                **colour_cols(p),
                # issue 21 (measure): ok / saturated / under_noise_floor / unknown ("" = a
                # reading stored before the flags), the signal level it was judged by
                "quality": str(p.raw.get("quality", "")),
                "peak_fraction": p.raw.get("peak_fraction"),
                "timestamp": p.timestamp,
            }
            for p in self.points(run_id)
        ]

    def export(self, run_id: int, fmt: str) -> str:
        """Export run ``run_id`` as ``"csv"`` (one row per reading) or ``"json"``."""
        rows = self.export_rows(run_id)
        if fmt == "json":
            return json.dumps({"run": self.get_run(run_id).as_dict(), "readings": rows}, indent=2)
        if fmt == "csv":
            kind = self.get_run(run_id).kind
            buf = io.StringIO()
            fields = _GLOSS_FIELDS if kind == "gloss" else _POINT_FIELDS
            writer = csv.DictWriter(buf, fieldnames=list(fields), lineterminator="\n")
            writer.writeheader()  # also for a run without readings yet
            writer.writerows(rows)
            return buf.getvalue()
        raise StoreError(f"export format must be 'csv' or 'json', got {fmt!r}")
