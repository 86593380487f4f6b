"""The run store: one SQLite file in WAL mode (default) or a shared PostgreSQL database,
every reading committed as it is measured.

``RunStore(path)`` opens an SQLite file; ``RunStore("postgresql://user@host/db")`` a
PostgreSQL database (psycopg 3, the ``goniolab[postgres]`` extra) with the same tables,
the same per-reading commit and the same claim semantics: a claim is a row lock on
``run_claims`` held by a connection of the claiming process, dropped by the server when
that process dies (also on ``kill -9``), as the file lock is by the kernel. Credentials come
from libpq's own sources (``PGPASSWORD``, ``~/.pgpass``, ``PGSSLMODE`` and certificate
files, or the URL); a password never appears in a message, a log line or a run's config
snapshot (:func:`goniolab.redact.redact`, by parsing the URL or keyword string). A libpq
keyword string (``host=... dbname=...``) names a database as well as a URL does.

Identity: every run has a UUID (``runs.uuid``, unique), kept by ``runs migrate`` and written
into every export, and the operator's ``operator``, ``sample_id``, ``notes`` and ``tags``.
A store from an older goniolab gets the columns on open and a UUID 5 per run
(:func:`legacy_uuid`); the store itself has a UUID (``meta.store_uuid``).

Failures: every error is one line (:class:`StoreError`); a write the store cannot take now
is :class:`StoreUnavailable` (a full disk, an SQLite lock held past the 10 s busy timeout, a
PostgreSQL server down, restarted, frozen or unreachable: connect, statement and TCP
timeouts, a client watchdog, reconnect with backoff), which a runner answers by pausing
with the arms parked; a page or row that cannot be read is :class:`StoreDamaged`, naming
the run. Claims on an SQLite store are filelock locks (no ``fcntl``: Windows works).

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
import io
import json
import os
import socket
import sqlite3
import threading
import time
import uuid as uuidlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import platformdirs

from goniolab.redact import is_conninfo, redact, redact_obj, scrub_driver_message

__all__ = [
    "COLOUR_KEYS",
    "GlossRow",
    "PointRow",
    "PredictedColour",
    "RunBusy",
    "RunMeta",
    "RunRecord",
    "RunStore",
    "StoreDamaged",
    "StoreError",
    "StoreUnavailable",
    "default_store_path",
    "is_store_url",
    "legacy_uuid",
    "resolve_store_path",
]

#: 2: run identity (uuid, operator, notes, tags, sample_id), added to older stores on open.
_SCHEMA_VERSION = 2

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
#: Run identity (issue 22): a UUID that travels with the run (exports, migrations, bluesky
#: documents) and what the operator says about it. Older stores get them by ``ALTER TABLE``
#: and a UUID per existing run (:func:`legacy_uuid`).
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
    "run_uuid",
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


#: The columns of a :class:`RunRecord`, in the order :meth:`RunRecord.from_row` reads them
#: (``{identity}``: the identity columns, or NULLs in an old read-only store).
_RUN_SELECT = (
    "SELECT id, kind, plan_json, config_json, sample, model_json, version, status,"
    " reason, created_at, updated_at, finished_at, {identity} FROM runs"
)
_IDENTITY_SELECT = "uuid, operator, notes, tags_json, sample_id"
_NO_IDENTITY_SELECT = "NULL, NULL, NULL, NULL, NULL"
#: The namespace of the UUIDs given to runs stored before runs had one.
_LEGACY_NAMESPACE = uuidlib.UUID("6f1c2a7e-3b1d-5c4e-9a8b-0d2e4f6a8c10")


class StoreError(Exception):
    """The store file cannot be opened, or a run id does not exist (message names both)."""


class RunBusy(StoreError):
    """Another runner (this process or another one) is measuring the run right now."""


class StoreUnavailable(StoreError):
    """The store cannot take a write right now (a database down, frozen or unreachable, a
    full disk, an SQLite file locked by another program for more than its busy timeout).
    Transient: the same call may succeed later (:meth:`RunStore.wait_writable`)."""


class StoreDamaged(StoreError):
    """A page of the store file, or one run's row, cannot be read (the message says which)."""


def _lock_class() -> Any:
    """filelock's lock for this platform (``fcntl.flock`` on POSIX, ``msvcrt`` on Windows)."""
    import warnings

    with warnings.catch_warnings():
        # without fcntl (and not Windows) filelock falls back to its soft lock and warns
        warnings.simplefilter("ignore")
        import filelock

    return filelock.FileLock, filelock.Timeout


class _RunLocks:
    """Per-run claim locks of this process: ``<store>-locks/run-<id>.lock`` beside the store.

    The locks are filelock's (``flock`` on POSIX, ``LockFileEx``/``msvcrt`` on Windows):
    held by an open file the OS closes when the process dies (also on ``kill -9``), so a
    crashed run is never left claimed. No ``fcntl`` import here: the store opens on
    Windows (tests/test_store_locking.py imports it with ``fcntl`` unavailable).
    """

    _held: ClassVar[dict[tuple[Path, int], Any]] = {}
    _guard: ClassVar[threading.Lock] = threading.Lock()

    @staticmethod
    def path(lock_dir: Path, run_id: int) -> Path:
        return lock_dir / f"run-{run_id}.lock"

    @classmethod
    def _new(cls, lock_dir: Path, run_id: int) -> Any:
        file_lock, _ = _lock_class()
        return file_lock(
            str(cls.path(lock_dir, run_id)), timeout=0, thread_local=False, is_singleton=False
        )

    @classmethod
    def acquire(cls, lock_dir: Path, run_id: int) -> None:
        _, timeout_error = _lock_class()
        with cls._guard:
            if (lock_dir, run_id) in cls._held:
                raise RunBusy(f"run {run_id} is already being measured by this process")
            lock_dir.mkdir(exist_ok=True)
            lock = cls._new(lock_dir, run_id)
            try:
                lock.acquire(blocking=False)
            except timeout_error:
                raise RunBusy(
                    f"run {run_id} is being measured by another goniolab process; "
                    "stop that one first"
                ) from None
            cls._held[(lock_dir, run_id)] = lock

    @classmethod
    def is_held(cls, lock_dir: Path, run_id: int) -> bool | None:
        """Whether a runner (any process) holds ``run_id``; ``None`` when it cannot be told.

        The probe takes the lock for an instant: a runner claiming the run in exactly that
        instant is refused (and says so); it never breaks a held claim.
        """
        if (lock_dir, run_id) in cls._held:
            return True
        if not cls.path(lock_dir, run_id).exists():
            return False
        if not os.access(lock_dir, os.W_OK):  # a read-only store: no lock can be tried
            return None
        _, timeout_error = _lock_class()
        lock = cls._new(lock_dir, run_id)
        try:
            lock.acquire(blocking=False)
        except timeout_error:
            return True
        except OSError:
            return None
        lock.release()
        return False

    @classmethod
    def release(cls, lock_dir: Path, run_id: int) -> None:
        with cls._guard:
            lock = cls._held.pop((lock_dir, run_id), None)
        if lock is not None:
            lock.release()


def legacy_uuid(location: str, run_id: int, created_at: float) -> str:
    """The UUID of a run stored before runs had one: a UUID 5 of the store's location, the
    run id and its creation time (the same whether the store is upgraded or read as it is,
    distinct for two PCs' stores at the same path: their creation times differ)."""
    return str(uuidlib.uuid5(_LEGACY_NAMESPACE, f"{location}\n{run_id}\n{created_at!r}"))


def _haystack(rec: RunRecord) -> str:
    """What ``runs list --search`` looks in, lower-case."""
    return "\n".join([rec.sample, rec.sample_id, rec.operator, rec.notes, *rec.tags]).lower()


def _json_column(run_id: int, column: str, text: Any) -> Any:
    """Decode one JSON column; :class:`StoreDamaged` naming the run and column if it is not."""
    try:
        return json.loads(text)
    except (TypeError, ValueError) as exc:
        raise StoreDamaged(f"run {run_id}: {column} is not valid JSON ({exc})") from None


@dataclass(frozen=True, slots=True)
class RunRecord:
    """One row of ``runs`` with its JSON columns decoded.

    ``damage`` is empty for a sound row; for a row whose JSON cannot be decoded it says
    which column and why (``plan``/``config``/``model`` are then empty): :meth:`RunStore.
    list_runs` lists such a run, :meth:`RunStore.get_run` refuses it in one line.
    """

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
    uuid: str = ""
    operator: str = ""
    notes: str = ""
    tags: tuple[str, ...] = ()
    sample_id: str = ""
    damage: str = ""

    @classmethod
    def from_row(cls, row: Sequence[Any], location: str = "") -> RunRecord:
        """From the columns of ``_RUN_SELECT``, in that order (a row without the identity
        columns gets :func:`legacy_uuid` and empty metadata)."""
        run_id = int(row[0])
        damage: list[str] = []
        decoded: list[Any] = []
        for k, column in ((2, "plan_json"), (3, "config_json"), (5, "model_json")):
            try:
                value = _json_column(run_id, column, row[k])
                if not isinstance(value, dict):
                    raise StoreDamaged(f"run {run_id}: {column} is not a JSON object")
            except StoreDamaged as exc:
                damage.append(str(exc).split(": ", 1)[1])
                value = {}
            decoded.append(value)
        ident = list(row[12:17]) if len(row) > 12 else [None] * 5
        tags: tuple[str, ...] = ()
        if ident[3]:
            try:
                tags = tuple(str(t) for t in json.loads(ident[3]))
            except (TypeError, ValueError):
                damage.append("tags_json is not valid JSON")
        created = float(row[9])
        return cls(
            id=run_id,
            kind=str(row[1]),
            plan=decoded[0],
            config=decoded[1],
            sample=str(row[4]),
            model=decoded[2],
            version=str(row[6]),
            status=str(row[7]),
            reason=str(row[8]),
            created_at=created,
            updated_at=float(row[10]),
            finished_at=None if row[11] is None else float(row[11]),
            uuid=str(ident[0]) if ident[0] else legacy_uuid(location, run_id, created),
            operator=str(ident[1] or ""),
            notes=str(ident[2] or ""),
            tags=tags,
            sample_id=str(ident[4] or ""),
            damage="; ".join(damage),
        )

    def as_dict(self) -> dict[str, Any]:
        """Return the record as a JSON-serialisable dict."""
        doc = {
            "id": self.id,
            "uuid": self.uuid,
            "kind": self.kind,
            "plan": self.plan,
            "config": self.config,
            "sample": self.sample,
            "sample_id": self.sample_id,
            "operator": self.operator,
            "notes": self.notes,
            "tags": list(self.tags),
            "model": self.model,
            "version": self.version,
            "status": self.status,
            "reason": self.reason,
            "created_at": self.created_at,
            "updated_at": self.updated_at,
            "finished_at": self.finished_at,
        }
        if self.damage:
            doc["damage"] = self.damage
        return doc


@dataclass(frozen=True, slots=True)
class RunMeta:
    """What the operator says about a run: who, which physical sample, notes, tags.

    Set from ``goniolab scan --operator/--sample-id/--note/--tag``, the config's ``[run]``
    table, the TUI and the API; changed later with ``goniolab runs annotate``.
    """

    operator: str = ""
    sample_id: str = ""
    notes: str = ""
    tags: tuple[str, ...] = field(default_factory=tuple)

    def merged(self, other: RunMeta) -> RunMeta:
        """``other``'s non-empty fields over this one's (tags: both, in order, once each)."""
        return RunMeta(
            operator=other.operator or self.operator,
            sample_id=other.sample_id or self.sample_id,
            notes=other.notes or self.notes,
            tags=tuple(dict.fromkeys((*self.tags, *other.tags))),
        )


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
    """Whether ``location`` names a PostgreSQL database: a ``postgresql://`` (or
    ``postgres://``) URL, or a libpq keyword/value string (``host=... dbname=...``)."""
    if not isinstance(location, str):
        return False
    return location.startswith(("postgresql://", "postgres://")) or is_conninfo(location)


def resolve_store_path(cli_store: str | None, config_store: str | None = None) -> Path | str:
    """Pick the store: ``--store`` first, then config ``[lab] store``, then the default file.

    A ``postgresql://`` URL is returned as it is (a string); a file as a :class:`Path`.
    """
    for choice in (cli_store, config_store):
        if choice:
            return choice if is_store_url(choice) else Path(choice).expanduser()
    return default_store_path()


def _why(exc: BaseException) -> str:
    """SQLite's reason, with the ones a user meets most often made explicit."""
    text = str(exc) or type(exc).__name__
    if "file is not a database" in text:
        return "not a goniolab run store (the file is not an SQLite database)"
    if "disk is full" in text or getattr(exc, "sqlite_errorname", "") == "SQLITE_FULL":
        return "the disk is full (free some space; every reading taken so far is stored)"
    if "database is locked" in text or "database table is locked" in text:
        return (
            f"locked by another program for more than {_SQLITE_BUSY_S:g} s "
            "(a database browser holding a write transaction?)"
        )
    if "malformed" in text:
        return "the file is damaged (database disk image is malformed)"
    return text


def _dumps(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)


def _redacted(obj: Any) -> Any:
    """``obj`` with the password of every connection string in it blanked
    (:func:`goniolab.redact.redact`, by parsing: other text is kept as it is)."""
    return redact_obj(obj)


#: SQLite's busy timeout: a writer waits this long for another program's lock.
_SQLITE_BUSY_S = 10.0
#: PostgreSQL: connect timeout, and the longest one statement may take before the client
#: gives the connection up (a frozen or partitioned server) and the server cancels it.
_PG_CONNECT_TIMEOUT_S = 5
_PG_STATEMENT_TIMEOUT_S = 10.0
#: Reconnect backoff after a lost PostgreSQL connection: first wait, factor, longest wait.
_BACKOFF_FIRST_S, _BACKOFF_FACTOR, _BACKOFF_MAX_S = 0.5, 2.0, 10.0


class _Result:
    """The rows of one statement, fetched while the connection was held (thread-safe)."""

    __slots__ = ("description", "rowcount", "rows")

    def __init__(self, rows: list[Any], description: Any, rowcount: int) -> None:
        self.rows = rows
        self.description = description
        self.rowcount = rowcount

    def fetchone(self) -> Any:
        return self.rows[0] if self.rows else None

    def fetchall(self) -> list[Any]:
        return self.rows

    def __iter__(self) -> Iterator[Any]:
        return iter(self.rows)


class _Conn:
    """One database connection shared by the threads of a process: every statement runs
    under a lock and returns its rows already fetched, so the scan's event loop, a worker
    thread (``goniolab.api.run_scan`` in Jupyter) and the TUI may share one store.

    SQLite statements speak as written; PostgreSQL ones get ``%s`` placeholders, a
    statement timeout (server side), a client-side watchdog that gives a connection up
    when a statement does not return in time (a frozen or partitioned server: the socket
    is shut down, the call fails with :class:`StoreUnavailable`), and a reconnect with
    exponential backoff on the next call.
    """

    def __init__(
        self,
        raw: Any,
        *,
        location: str,
        connect: Callable[[], Any] | None = None,
        conninfo: str = "",
    ) -> None:
        self.raw = raw
        self.location = location
        self.is_postgres = connect is not None
        self._connect = connect
        self._conninfo = conninfo
        self.lock = threading.RLock()
        self._broken = ""
        self._next_try = 0.0
        self._backoff_s = _BACKOFF_FIRST_S
        self.in_tx = False

    # ------------------------------------------------------------------ statements
    @staticmethod
    def _pg_sql(sql: str) -> str:
        return "BEGIN" if sql == "BEGIN IMMEDIATE" else sql.replace("?", "%s")

    def execute(self, sql: str, params: Sequence[Any] = ()) -> _Result:
        with self.lock:
            if not self.is_postgres:
                return self._sqlite(lambda: self.raw.execute(sql, tuple(params)))
            return self._pg(lambda: self.raw.execute(self._pg_sql(sql), tuple(params)))

    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> _Result:
        with self.lock:
            if not self.is_postgres:
                return self._sqlite(lambda: self.raw.executemany(sql, [tuple(r) for r in rows]))

            def many() -> Any:
                cur = self.raw.cursor()
                cur.executemany(self._pg_sql(sql), [tuple(r) for r in rows])
                return cur

            return self._pg(many)

    def _sqlite(self, run: Callable[[], Any]) -> _Result:
        try:
            cur = run()
            rows = cur.fetchall() if cur.description is not None else []
            return _Result(rows, cur.description, cur.rowcount)
        except sqlite3.IntegrityError:
            raise
        except sqlite3.OperationalError as exc:
            why = _why(exc)
            if "disk is full" in why or "locked" in why or "disk I/O" in str(exc):
                raise StoreUnavailable(f"store {self.location}: {why}") from exc
            raise StoreError(f"store {self.location}: {why}") from exc
        except sqlite3.DatabaseError as exc:
            raise StoreDamaged(f"store {self.location}: {_why(exc)}") from exc

    def _pg(self, run: Callable[[], Any]) -> _Result:
        psycopg = _psycopg()
        self._ensure_connected()
        timer = threading.Timer(_PG_STATEMENT_TIMEOUT_S + 2.0, self._give_up)
        timer.daemon = True
        timer.start()
        try:
            cur = run()
            rows = cur.fetchall() if cur.description is not None else []
            return _Result(rows, cur.description, cur.rowcount)
        except psycopg.IntegrityError:
            raise
        except (psycopg.OperationalError, psycopg.InterfaceError) as exc:
            if self.raw.closed or self.raw.broken or isinstance(exc, psycopg.InterfaceError):
                self._mark_broken(exc)
            raise StoreUnavailable(
                f"store {self.location}: {self._pg_why(exc)}"
                + (" (a write timed out)" if isinstance(exc, psycopg.errors.QueryCanceled) else "")
            ) from None
        except psycopg.Error as exc:
            raise StoreError(f"store {self.location}: {self._pg_why(exc)}") from None
        finally:
            timer.cancel()

    def _pg_why(self, exc: BaseException) -> str:
        return scrub_driver_message(str(exc) or type(exc).__name__, self._conninfo)

    # ------------------------------------------------------------------ reconnect
    def _give_up(self) -> None:
        """The watchdog: a statement has run past its time (the server is frozen or the
        network partitioned; a TCP connection to a stopped server never errs by itself).
        Shut the socket down so that the blocked call returns with an error."""
        with contextlib.suppress(Exception):
            fd = self.raw.pgconn.socket
            s = socket.socket(fileno=os.dup(fd))
            try:
                s.shutdown(socket.SHUT_RDWR)
            finally:
                s.close()
        self._broken = f"no answer within {_PG_STATEMENT_TIMEOUT_S + 2.0:g} s"

    def _mark_broken(self, exc: BaseException) -> None:
        if not self._broken:
            self._broken = self._pg_why(exc)
        self._next_try = time.monotonic() + self._backoff_s

    def _ensure_connected(self) -> None:
        """Reconnect a lost connection, no sooner than the backoff allows."""
        if not (self._broken or self.raw.closed or self.raw.broken):
            return
        if not self._broken:
            self._broken = "the connection was closed"
        now = time.monotonic()
        if now < self._next_try:
            raise StoreUnavailable(
                f"store {self.location}: unreachable ({self._broken}); "
                f"next reconnect in {self._next_try - now:.1f} s"
            )
        with contextlib.suppress(Exception):
            self.raw.close()
        assert self._connect is not None
        try:
            self.raw = self._connect()
        except StoreError as exc:
            self._next_try = time.monotonic() + self._backoff_s
            self._backoff_s = min(_BACKOFF_MAX_S, self._backoff_s * _BACKOFF_FACTOR)
            raise StoreUnavailable(str(exc)) from None
        self._broken = ""
        self._backoff_s = _BACKOFF_FIRST_S

    def close(self) -> None:
        with self.lock, contextlib.suppress(Exception):
            self.raw.close()


def _psycopg() -> Any:
    try:
        import psycopg
    except ImportError:
        raise StoreError(
            "a postgresql:// store needs psycopg: pip install 'goniolab[postgres]'"
        ) from None
    return psycopg


class RunStore:
    """The run store: an SQLite file (WAL mode) or a PostgreSQL database.

    Parameters
    ----------
    path
        The database file (its directory is created if missing), or a PostgreSQL
        ``postgresql://`` URL or libpq ``host=... dbname=...`` string.
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
    One store may be used from several threads (each statement holds the connection's
    lock; a transaction holds it throughout). A write that cannot be made raises
    :class:`StoreUnavailable` (transient: a database down, a full disk, a lock held by
    another program) or :class:`StoreError`, always in one line; a read of a damaged
    page or row raises :class:`StoreDamaged`.
    """

    def __init__(self, path: str | Path, *, readonly: bool = False, create: bool = True) -> None:
        self.readonly = readonly
        self.is_postgres = is_store_url(path)
        self._claims: dict[int, Any] = {}
        self._columns: dict[str, list[str]] = {}
        if self.is_postgres:
            self._conninfo = str(path)
            #: How the store names itself (its URL or keyword string without the password).
            self.location = redact(self._conninfo)
            self.path = Path(self.location.split("://", 1)[-1])
            self._db: _Conn = self._open_postgres(readonly=readonly, create=create)
            return
        self._conninfo = ""
        self.path = Path(path)
        self.location = str(self.path)
        self._db = self._open_sqlite(readonly=readonly, create=create)

    def __repr__(self) -> str:
        return f"RunStore({self.location!r}{', readonly=True' if self.readonly else ''})"

    def _open_sqlite(self, *, readonly: bool, create: bool) -> _Conn:
        """Open the SQLite file: read-only, or for writing (created when missing and
        ``create``), after checks that say why a location cannot serve."""
        where = f"store {self.path}"
        if self.path.is_dir():
            raise StoreError(f"{where}: is a directory, not a store file")
        exists = self.path.exists()
        if not exists and (readonly or not create):
            raise StoreError(f"{where}: no such file (no run has been recorded there)")
        if exists and not self.path.is_file():
            # a FIFO or a device would block SQLite's open or read for ever
            raise StoreError(f"{where}: not a regular file, not a store")
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

    def _open_writable(self, where: str) -> _Conn:
        """Open (and create) the SQLite store: WAL, ``synchronous=FULL``, the schema, the
        columns and run UUIDs an older store lacks."""
        try:
            raw = sqlite3.connect(
                self.path, isolation_level=None, timeout=_SQLITE_BUSY_S, check_same_thread=False
            )
            raw.execute("PRAGMA journal_mode=WAL")
            raw.execute("PRAGMA synchronous=FULL")
            raw.execute("PRAGMA foreign_keys=ON")
            raw.executescript(_SCHEMA)
        except (OSError, sqlite3.Error) as exc:
            raise StoreError(f"{where}: cannot open: {_why(exc)}") from exc
        self._db = _Conn(raw, location=self.location)
        try:
            self._upgrade()
        except StoreError as exc:
            raw.close()
            raise StoreError(f"{where}: cannot open: {str(exc).split(': ', 1)[-1]}") from exc
        return self._db

    def _pg_connect(self, *, autocommit: bool = True) -> Any:
        """A new psycopg connection with the store's timeouts: connect, statement (server
        side) and TCP keepalives/user timeout (a dead peer is noticed in seconds)."""
        psycopg = _psycopg()
        try:
            return psycopg.connect(
                self._conninfo,
                autocommit=autocommit,
                connect_timeout=_PG_CONNECT_TIMEOUT_S,
                options=f"-c statement_timeout={int(_PG_STATEMENT_TIMEOUT_S * 1000)}",
                keepalives=1,
                keepalives_idle=5,
                keepalives_interval=2,
                keepalives_count=3,
                tcp_user_timeout=int((_PG_STATEMENT_TIMEOUT_S + 2) * 1000),
            )
        except psycopg.Error as exc:
            why = scrub_driver_message(str(exc) or type(exc).__name__, self._conninfo)
            raise StoreError(f"store {self.location}: cannot connect: {why}") from None

    def _open_postgres(self, *, readonly: bool, create: bool) -> _Conn:
        """Connect (libpq reads PGPASSWORD, ~/.pgpass, PGSSLMODE ... itself) and create the
        tables unless ``readonly``; every message is scrubbed of the password."""
        where = f"store {self.location}"
        conn = self._pg_connect()
        self._db = db = _Conn(
            conn, location=self.location, connect=self._pg_connect, conninfo=self._conninfo
        )
        try:
            have = db.execute("SELECT to_regclass('runs') IS NOT NULL").fetchone()[0]
            if not have and (readonly or not create):
                raise StoreError(f"{where}: no goniolab run store in this database (no runs table)")
            if not readonly:
                with self._tx():
                    db.execute("SELECT pg_advisory_xact_lock(?)", (_PG_SCHEMA_LOCK,))
                    db.execute(_PG_SCHEMA)
                    self._upgrade()
        except StoreError as exc:
            db.close()
            if str(exc).startswith(where):
                raise
            raise StoreError(f"{where}: cannot open: {exc}") from None
        return db

    def _upgrade(self) -> None:
        """Bring a store written by an older goniolab up to this schema (additive: nothing
        stored is changed; new columns are NULL for old rows, and each old run gets its
        :func:`legacy_uuid`); record the schema version and give the store its own UUID."""
        pg = self.is_postgres
        for table, cols in _ADDED_COLUMNS:
            have = {c.lower() for c in self.table_columns(table)}  # PostgreSQL folds case
            for name, sql_type in cols:
                if name.lower() not in have:
                    kind = "DOUBLE PRECISION" if pg and sql_type == "REAL" else sql_type
                    self._db.execute(f"ALTER TABLE {table} ADD COLUMN {name} {kind}")
        self._columns.clear()
        missing = self._db.execute(
            "SELECT id, created_at FROM runs WHERE uuid IS NULL OR uuid = ''"
        ).fetchall()
        for run_id, created in missing:
            self._db.execute(
                "UPDATE runs SET uuid = ? WHERE id = ?",
                (legacy_uuid(self.location, int(run_id), float(created)), int(run_id)),
            )
        have_meta = dict(self._db.execute("SELECT key, value FROM meta").fetchall())
        if have_meta.get("schema_version") == str(_SCHEMA_VERSION) and "store_uuid" in have_meta:
            return  # up to date: opening writes nothing (another program may hold the lock)
        for sql in _ADDED_INDEXES:
            self._db.execute(sql)
        self._db.execute(
            "INSERT INTO meta(key, value) VALUES ('schema_version', ?) ON CONFLICT (key)"
            " DO UPDATE SET value = excluded.value",
            (str(_SCHEMA_VERSION),),
        )
        self._db.execute(
            "INSERT INTO meta(key, value) VALUES ('store_uuid', ?) ON CONFLICT (key) DO NOTHING",
            (str(uuidlib.uuid4()),),
        )

    @property
    def store_uuid(self) -> str | None:
        """The store's own UUID (``None`` for an old store opened read-only): two handles
        on one store (a symlink, a relative path, another spelling of a URL) share it."""
        row = self._db.execute("SELECT value FROM meta WHERE key = 'store_uuid'").fetchone()
        return None if row is None else str(row[0])

    def _has_column(self, table: str, column: str) -> bool:
        """Whether ``table`` has ``column`` (case-insensitive: PostgreSQL folds names)."""
        if table not in self._columns:
            self._columns[table] = [c.lower() for c in self.table_columns(table)]
        return column.lower() in self._columns[table]

    @property
    def _has_colour(self) -> bool:
        """Whether this store has the colour columns (an old read-only store may not)."""
        return self._has_column("points", "colour_L")

    @property
    def _run_select(self) -> str:
        ident = _IDENTITY_SELECT if self._has_column("runs", "uuid") else _NO_IDENTITY_SELECT
        return _RUN_SELECT.format(identity=ident)

    def _open_readonly(self, where: str) -> _Conn:
        """Open for reading only: ``mode=ro``; on a read-only directory (no ``-shm`` can be
        created beside the file) ``immutable=1``, which reads the main file as it is."""
        uri = self.path.resolve().as_uri()
        query = "mode=ro" if os.access(self.path.parent, os.W_OK) else "immutable=1"
        try:
            raw = sqlite3.connect(
                f"{uri}?{query}",
                uri=True,
                isolation_level=None,
                timeout=_SQLITE_BUSY_S,
                check_same_thread=False,
            )
            row = raw.execute(
                "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'runs'"
            ).fetchone()
        except sqlite3.Error as exc:
            raise StoreError(f"{where}: cannot open: {_why(exc)}") from exc
        if not row[0]:
            raw.close()
            raise StoreError(f"{where}: not a goniolab run store (no runs table)")
        return _Conn(raw, location=self.location)

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Close the connection (committed data is already on disk)."""
        for conn in self._claims.values():
            with contextlib.suppress(Exception):
                conn.close()
        self._claims.clear()
        self._db.close()

    def __enter__(self) -> RunStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def _tx(self) -> Iterator[_Conn]:
        """One transaction, holding the connection's lock throughout (a nested call joins
        the outer transaction)."""
        db = self._db
        with db.lock:
            if db.in_tx:
                yield db
                return
            db.execute("BEGIN IMMEDIATE")
            db.in_tx = True
            try:
                yield db
            except BaseException:
                db.in_tx = False
                with contextlib.suppress(Exception):  # a lost connection has nothing to undo
                    db.execute("ROLLBACK")
                raise
            db.in_tx = False
            db.execute("COMMIT")

    def wait_writable(self) -> None:
        """Return when the store takes writes again; :class:`StoreUnavailable` (one line,
        why) while it does not. Used by a runner that paused on a failed write."""
        with self._tx() as db:
            db.execute("UPDATE meta SET value = value WHERE key = 'schema_version'")

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

        For SQLite the claim is a lock on ``<store>-locks/run-<id>.lock`` beside the store
        file (filelock: ``flock`` on POSIX, ``msvcrt`` on Windows), released on exit and by
        the OS when the process dies. In PostgreSQL it is a row lock (``SELECT ... FOR
        UPDATE NOWAIT`` on ``run_claims``) held by a connection of its own, released on exit
        and by the server when the process (and so its connection) dies.
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
        return _RunLocks.is_held(self._lock_dir, run_id)

    @contextmanager
    def _claim_file(self, run_id: int) -> Iterator[None]:
        """SQLite: the file lock of the run (:class:`_RunLocks`)."""
        lock_dir = self._lock_dir
        try:
            _RunLocks.acquire(lock_dir, run_id)
        except RunBusy as exc:
            raise RunBusy(f"store {self.path}: {exc}") from None
        except OSError as exc:
            raise StoreError(f"store {self.path}: cannot claim run {run_id}: {exc}") from exc
        try:
            yield
        finally:
            _RunLocks.release(lock_dir, run_id)

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
            conn = self._pg_connect(autocommit=False)
        except StoreError as exc:
            raise StoreError(
                f"{where}: cannot claim run {run_id}: {str(exc).split('cannot connect: ', 1)[-1]}"
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

    def ensure_claim(self, run_id: int) -> None:
        """After a lost PostgreSQL connection: take this process's claim of ``run_id``
        again if the server dropped it with the connection (a restart); :class:`RunBusy`
        if another runner took the run meanwhile. A no-op for SQLite (the OS keeps a file
        lock as long as the process lives)."""
        conn = self._claims.get(run_id)
        if conn is None:
            return
        psycopg = _psycopg()
        with contextlib.suppress(psycopg.Error):
            if not (conn.closed or conn.broken):
                conn.execute("SELECT 1")
                return
        with contextlib.suppress(Exception):
            conn.close()
        new = self._pg_connect(autocommit=False)
        try:
            new.execute(
                "SELECT run_id FROM run_claims WHERE run_id = %s FOR UPDATE NOWAIT", (run_id,)
            )
        except psycopg.errors.LockNotAvailable:
            new.close()
            raise RunBusy(
                f"store {self.location}: run {run_id} was taken by another goniolab process "
                "while the database was away"
            ) from None
        except psycopg.Error as exc:
            new.close()
            why = scrub_driver_message(str(exc), self._conninfo)
            raise StoreUnavailable(f"store {self.location}: {why}") from None
        self._claims[run_id] = new

    @property
    def _lock_dir(self) -> Path:
        return self.path.resolve().with_name(self.path.name + "-locks")

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
        meta: RunMeta | None = None,
    ) -> int:
        """Insert a run (with a new UUID and ``meta``) and return its id."""
        now = time.time()
        m = meta or RunMeta()
        with self._tx() as db:
            row = db.execute(
                "INSERT INTO runs(kind, plan_json, config_json, sample, model_json, version,"
                " status, reason, created_at, updated_at, uuid, operator, notes, tags_json,"
                " sample_id) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?) RETURNING id",
                (kind, _dumps(plan), _dumps(_redacted(config)), sample, _dumps(model), version,
                 status, "", now, now, str(uuidlib.uuid4()), m.operator, m.notes,
                 json.dumps(list(m.tags)), m.sample_id),
            ).fetchone()  # fmt: skip
        return int(row[0])

    def set_meta(
        self,
        run_id: int,
        *,
        operator: str | None = None,
        sample_id: str | None = None,
        notes: str | None = None,
        tags: Sequence[str] | None = None,
    ) -> RunRecord:
        """Change what is said about a run (``None`` keeps a field); returns the record."""
        sets: list[str] = []
        values: list[Any] = []
        for column, value in (("operator", operator), ("sample_id", sample_id), ("notes", notes)):
            if value is not None:
                sets.append(f"{column} = ?")
                values.append(value)
        if tags is not None:
            sets.append("tags_json = ?")
            values.append(json.dumps(list(dict.fromkeys(tags))))
        if sets:
            with self._tx() as db:
                cur = db.execute(
                    f"UPDATE runs SET {', '.join(sets)}, updated_at = ? WHERE id = ?",
                    (*values, time.time(), run_id),
                )
                if cur.rowcount != 1:
                    raise StoreError(f"store {self.location}: no run {run_id}")
        return self.get_run(run_id)

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
                raise StoreError(f"store {self.location}: no run {run_id}")
            model = {**_json_column(run_id, "model_json", row[0]), **extra}
            db.execute(
                "UPDATE runs SET model_json = ?, updated_at = ? WHERE id = ?",
                (_dumps(model), time.time(), run_id),
            )

    def get_run(self, run_id: int, *, allow_damaged: bool = False) -> RunRecord:
        """Return run ``run_id``.

        Raises
        ------
        StoreError
            No such run (the message names the store).
        StoreDamaged
            The run's row cannot be decoded (unless ``allow_damaged``: then the record
            says so in ``damage``).
        """
        row = self._db.execute(f"{self._run_select} WHERE id = ?", (run_id,)).fetchone()
        if row is None:
            raise StoreError(f"store {self.location}: no run {run_id}")
        rec = RunRecord.from_row(row, self.location)
        if rec.damage and not allow_damaged:
            raise StoreDamaged(f"store {self.location}: run {run_id} is damaged: {rec.damage}")
        return rec

    def find_uuid(self, run_uuid: str) -> int | None:
        """The id of the run with UUID ``run_uuid`` in this store, else ``None``."""
        if not self._has_column("runs", "uuid"):
            return next((r.id for r in self.list_runs() if r.uuid == run_uuid), None)
        row = self._db.execute("SELECT id FROM runs WHERE uuid = ?", (run_uuid,)).fetchone()
        return None if row is None else int(row[0])

    def list_runs(self, limit: int | None = None) -> list[RunRecord]:
        """Return runs, newest first (a damaged row is listed with its ``damage``)."""
        sql = f"{self._run_select} ORDER BY id DESC"
        params: tuple[int, ...] = ()
        if limit is not None:
            sql += " LIMIT ?"
            params = (limit,)
        return [RunRecord.from_row(r, self.location) for r in self._db.execute(sql, params)]

    def list_briefs(
        self,
        limit: int | None = None,
        *,
        operator: str | None = None,
        tag: str | None = None,
        sample_id: str | None = None,
        text: str | None = None,
    ) -> list[tuple[RunRecord, int | None]]:
        """Runs newest first with their number of readings (points of a scan, readings of
        a gloss log), in one query (no reading is loaded: the counts come from the
        ``(run_id, ...)`` indexes). Filters: ``operator``, ``sample_id`` (exact), ``tag``
        (one of the run's tags), ``text`` (a case-insensitive substring of the sample,
        sample id, operator, notes or tags).

        A store whose readings cannot be counted (a damaged page) gets each run's count
        on its own; a run whose count fails has ``None`` (and :meth:`count_readings`
        says why).
        """
        where: list[str] = []
        params: list[Any] = []
        has_ident = self._has_column("runs", "uuid")
        if has_ident:
            if operator is not None:
                where.append("operator = ?")
                params.append(operator)
            if sample_id is not None:
                where.append("sample_id = ?")
                params.append(sample_id)
            if tag is not None:
                where.append("tags_json LIKE ?")
                params.append(f"%{json.dumps(tag)}%")  # narrowed; the exact test is below
            if text is not None:
                like = f"%{text.lower()}%"
                where.append(
                    "(LOWER(sample) LIKE ? OR LOWER(COALESCE(sample_id, '')) LIKE ?"
                    " OR LOWER(COALESCE(operator, '')) LIKE ? OR LOWER(COALESCE(notes, '')) LIKE ?"
                    " OR LOWER(COALESCE(tags_json, '')) LIKE ?)"
                )
                params += [like] * 5
        sql = self._run_select.replace(
            " FROM runs",
            ", (SELECT COUNT(*) FROM points p WHERE p.run_id = runs.id),"
            " (SELECT COUNT(*) FROM gloss_readings g WHERE g.run_id = runs.id) FROM runs",
        )
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY id DESC"
        if limit is not None and has_ident and tag is None:
            sql += " LIMIT ?"
            params.append(limit)
        out: list[tuple[RunRecord, int | None]] = []
        try:
            rows = self._db.execute(sql, params).fetchall()
        except StoreDamaged:
            rows = None
        if rows is not None:
            for r in rows:
                rec = RunRecord.from_row(r[:-2], self.location)
                out.append((rec, int(r[-1] if rec.kind == "gloss" else r[-2])))
        else:
            for rec in self.list_runs():
                try:
                    out.append((rec, self.count_readings(rec)))
                except StoreDamaged:
                    out.append((rec, None))
        if not has_ident or rows is None or tag is not None:  # the exact filter
            out = [
                (rec, n)
                for rec, n in out
                if (operator is None or rec.operator == operator)
                and (sample_id is None or rec.sample_id == sample_id)
                and (tag is None or tag in rec.tags)
                and (text is None or text.lower() in _haystack(rec))
            ]
            out = out[:limit] if limit is not None else out
        return out

    def count_readings(self, rec: RunRecord) -> int:
        """The number of readings of ``rec``: points of a scan, readings of a gloss log."""
        table = "gloss_readings" if rec.kind == "gloss" else "points"
        row = self._db.execute(f"SELECT COUNT(*) FROM {table} WHERE run_id = ?", (rec.id,))
        return int(row.fetchone()[0])

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
        return [self._decoded(PointRow.from_row, run_id, "reading", r) for r in rows]

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
        return [self._decoded(GlossRow.from_row, run_id, "gloss reading", r) for r in rows]

    def _decoded(self, build: Callable[[Any], Any], run_id: int, what: str, row: Any) -> Any:
        """``build(row)``, or :class:`StoreDamaged` naming the store, run and row."""
        try:
            return build(row)
        except (TypeError, ValueError, IndexError) as exc:
            raise StoreDamaged(
                f"store {self.location}: run {run_id} is damaged: {what} {row[0]}: {exc}"
            ) from None

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

    def copy_run_from(self, src: RunStore, run_id: int) -> tuple[int, str]:
        """Copy run ``run_id`` of ``src`` (with its readings, predictions and gloss readings)
        into this store in one transaction; returns ``(id here, action)``.

        A run is matched by its UUID: a run not here yet is ``"copied"`` (a new id); a copy
        that is behind its source (copied while it was aborted or still running, finished
        later) is ``"updated"``: its row takes the source's status, reason and metadata and
        the readings it lacks are added; an up-to-date copy is ``"unchanged"``. A copy made
        by an older goniolab (remembered in ``meta`` by the source's path and id) is matched
        only when its creation time is the source run's too (another PC's store at the same
        path holds other runs). Columns both stores have are copied.

        Raises
        ------
        StoreDamaged
            The source run's row cannot be read (nothing is written).
        """
        rec = src.get_run(run_id)
        src_run = src._db.execute("SELECT * FROM runs WHERE id = ?", (run_id,))
        names = [d[0] for d in src_run.description]
        record = dict(zip(names, src_run.fetchone(), strict=True))
        record["uuid"] = rec.uuid
        record["config_json"] = _dumps(_redacted(rec.config))
        existing = self.find_uuid(rec.uuid)
        if existing is None:
            legacy = self._db.execute(
                "SELECT value FROM meta WHERE key = ?", (f"migrated:{src.location}:{run_id}",)
            ).fetchone()
            if legacy is not None:
                row = self._db.execute(
                    "SELECT created_at FROM runs WHERE id = ?", (int(legacy[0]),)
                ).fetchone()
                if row is not None and float(row[0]) == rec.created_at:
                    existing = int(legacy[0])
        run_cols = [c for c in self.table_columns("runs") if c in record and c != "id"]
        with self._tx() as db:
            if existing is None:
                here = int(
                    db.execute(
                        f"INSERT INTO runs({', '.join(run_cols)}) VALUES"
                        f" ({', '.join('?' for _ in run_cols)}) RETURNING id",
                        [record[c] for c in run_cols],
                    ).fetchone()[0]
                )
                action = "copied"
            else:
                here = existing
                mine = db.execute(
                    f"SELECT {', '.join(run_cols)} FROM runs WHERE id = ?", (here,)
                ).fetchone()
                theirs = [record[c] for c in run_cols]
                changed = list(mine) != theirs
                if changed:
                    upd = [c for c in run_cols if c not in ("created_at",)]
                    db.execute(
                        f"UPDATE runs SET {', '.join(f'{c} = ?' for c in upd)} WHERE id = ?",
                        [*(record[c] for c in upd), here],
                    )
                action = "updated" if changed else "unchanged"
            added = self._copy_children(src, run_id, here)
            if action == "unchanged" and added:
                action = "updated"
        return here, action

    #: The conflict target of each child table (what makes a row "already there").
    _CHILD_KEYS: ClassVar[dict[str, str]] = {
        "points": "run_id, idx, repeat",
        "predictions": "run_id, idx",
        "gloss_readings": "run_id, seq",
    }

    def _copy_children(self, src: RunStore, run_id: int, here: int) -> int:
        """Add the readings, predictions and gloss readings of ``src``'s run ``run_id`` that
        run ``here`` lacks (inside the caller's transaction); return how many were added."""
        added = 0
        for table, key in self._CHILD_KEYS.items():
            theirs = {c.lower() for c in src.table_columns(table)}
            cols = [c for c in self.table_columns(table) if c.lower() in theirs and c != "id"]
            rows = src._db.execute(
                f"SELECT {', '.join(cols)} FROM {table} WHERE run_id = ?", (run_id,)
            ).fetchall()
            if not rows:
                continue
            before = self._db.execute(
                f"SELECT COUNT(*) FROM {table} WHERE run_id = ?", (here,)
            ).fetchone()[0]
            at = cols.index("run_id")
            values = [[here if k == at else v for k, v in enumerate(r)] for r in rows]
            self._db.executemany(
                f"INSERT INTO {table}({', '.join(cols)}) VALUES"
                f" ({', '.join('?' for _ in cols)}) ON CONFLICT ({key}) DO NOTHING",
                values,
            )
            after = self._db.execute(
                f"SELECT COUNT(*) FROM {table} WHERE run_id = ?", (here,)
            ).fetchone()[0]
            added += int(after) - int(before)
        return added

    # ------------------------------------------------------------------ export
    def export_rows(self, run_id: int) -> list[dict[str, Any]]:
        """One flat dict per reading of ``run_id`` (points for scans, readings for gloss)."""
        run = self.get_run(run_id)
        if run.kind == "gloss":
            return [
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
                "run_uuid": run.uuid,
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
