"""The run store: one SQLite file in WAL mode, every reading committed as it is measured.

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

__all__ = [
    "GlossRow",
    "PointRow",
    "RunBusy",
    "RunRecord",
    "RunStore",
    "StoreError",
    "default_store_path",
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


@dataclass(frozen=True, slots=True)
class GlossRow:
    """One stored glossmeter reading (one row of ``gloss_readings``)."""

    seq: int
    values_gu: dict[int, float | None]
    temperature_c: float | None
    predicted_gu: dict[int, float] | None
    raw: str
    timestamp: float


def default_store_path() -> Path:
    """Return the default store file: ``<user data dir>/goniolab.sqlite`` (platformdirs)."""
    return Path(platformdirs.user_data_dir("goniolab", appauthor=False)) / "goniolab.sqlite"


def resolve_store_path(cli_store: str | None, config_store: str | None = None) -> Path:
    """Pick the store file: ``--store`` first, then config ``[lab] store``, then the default."""
    if cli_store:
        return Path(cli_store).expanduser()
    if config_store:
        return Path(config_store).expanduser()
    return default_store_path()


def _why(exc: BaseException) -> str:
    """SQLite's reason, with the one a user meets most often made explicit."""
    text = str(exc)
    if "file is not a database" in text:
        return "not a goniolab run store (the file is not an SQLite database)"
    return text


def _dumps(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)


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
        self.path = Path(path)
        self.readonly = readonly
        where = f"store {self.path}"
        if self.path.is_dir():
            raise StoreError(f"{where}: is a directory, not a store file")
        exists = self.path.exists()
        if not exists and (readonly or not create):
            raise StoreError(f"{where}: no such file (no run has been recorded there)")
        if readonly:
            self._db = self._open_readonly(where)
            return
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
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None, timeout=10.0)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute("PRAGMA foreign_keys=ON")
            self._db.executescript(_SCHEMA)
            self._db.execute(
                "INSERT OR IGNORE INTO meta(key, value) VALUES ('schema_version', ?)",
                (str(_SCHEMA_VERSION),),
            )
        except (OSError, sqlite3.Error) as exc:
            raise StoreError(f"{where}: cannot open: {_why(exc)}") from exc

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
        self._db.close()

    def __enter__(self) -> RunStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def _tx(self) -> Iterator[sqlite3.Connection]:
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield self._db
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    @property
    def journal_mode(self) -> str:
        """The SQLite journal mode in use (``"wal"``)."""
        return str(self._db.execute("PRAGMA journal_mode").fetchone()[0])

    # ------------------------------------------------------------------ claims
    @contextmanager
    def claim_run(self, run_id: int) -> Iterator[None]:
        """Hold the run for measuring: a second runner of the same run (another process,
        e.g. ``scan resume`` while the scan still runs, or this one) gets :class:`RunBusy`.

        The claim is a POSIX record lock on byte ``run_id`` of ``<store>-lock`` beside the
        store file, released on exit and by the kernel when the process dies.
        """
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

    def is_claimed(self, run_id: int) -> bool | None:
        """Whether a runner (this or another process) is measuring ``run_id`` right now;
        ``None`` when the store is read-only and it cannot be told. A run whose status
        says ``running`` but that nobody claims was interrupted (e.g. ``kill -9``)."""
        return _ClaimFile.is_held(self._lock_path, run_id)

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
            cur = db.execute(
                "INSERT INTO runs(kind, plan_json, config_json, sample, model_json, version,"
                " status, reason, created_at, updated_at) VALUES (?,?,?,?,?,?,?,?,?,?)",
                (kind, _dumps(plan), _dumps(config), sample, _dumps(model), version, status, "",
                 now, now),
            )  # fmt: skip
            run_id = cur.lastrowid
        assert run_id is not None
        return int(run_id)

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
                raise StoreError(f"store {self.path}: no run {run_id}")

    def get_run(self, run_id: int) -> RunRecord:
        """Return run ``run_id``; :class:`StoreError` naming the file when it does not exist."""
        row = self._db.execute(
            "SELECT id, kind, plan_json, config_json, sample, model_json, version, status,"
            " reason, created_at, updated_at, finished_at FROM runs WHERE id = ?",
            (run_id,),
        ).fetchone()
        if row is None:
            raise StoreError(f"store {self.path}: no run {run_id}")
        return self._record(row)

    def list_runs(self, limit: int | None = None) -> list[RunRecord]:
        """Return runs, newest first."""
        sql = (
            "SELECT id, kind, plan_json, config_json, sample, model_json, version, status,"
            " reason, created_at, updated_at, finished_at FROM runs ORDER BY id DESC"
        )
        params: tuple[int, ...] = ()
        if limit is not None:
            sql += " LIMIT ?"
            params = (limit,)
        return [self._record(r) for r in self._db.execute(sql, params).fetchall()]

    @staticmethod
    def _record(row: Sequence[Any]) -> RunRecord:
        return RunRecord(
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
    ) -> None:
        """Commit one reading. A second reading of the same (index, repeat) is refused.

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

    def done_keys(self, run_id: int) -> set[tuple[int, int]]:
        """Return the (index, repeat) pairs already stored for ``run_id``."""
        rows = self._db.execute("SELECT idx, repeat FROM points WHERE run_id = ?", (run_id,))
        return {(int(i), int(r)) for i, r in rows.fetchall()}

    def points(self, run_id: int) -> list[PointRow]:
        """Return every stored reading of ``run_id`` ordered by (index, repeat)."""
        rows = self._db.execute(
            "SELECT idx, repeat, theta_i_deg, theta_r_deg, measured_theta_i_deg,"
            " measured_theta_r_deg, luminance_pct, raw_json, timestamp FROM points"
            " WHERE run_id = ? ORDER BY idx, repeat",
            (run_id,),
        ).fetchall()
        return [
            PointRow(
                index=int(r[0]),
                repeat=int(r[1]),
                theta_i_deg=float(r[2]),
                theta_r_deg=float(r[3]),
                measured_theta_i_deg=float(r[4]),
                measured_theta_r_deg=float(r[5]),
                luminance_pct=float(r[6]),
                raw=json.loads(r[7]),
                timestamp=float(r[8]),
            )
            for r in rows
        ]

    def count_points(self, run_id: int) -> int:
        """Return the number of stored readings of ``run_id``."""
        row = self._db.execute("SELECT COUNT(*) FROM points WHERE run_id = ?", (run_id,))
        return int(row.fetchone()[0])

    # ------------------------------------------------------------------ predictions
    def add_predictions(self, run_id: int, rows: Sequence[tuple[int, float, float, float]]) -> None:
        """Store predictions ``(index, theta_i_deg, theta_r_deg, predicted_pct)`` (upsert)."""
        with self._tx() as db:
            db.executemany(
                "INSERT OR REPLACE INTO predictions(run_id, idx, theta_i_deg, theta_r_deg,"
                " predicted_pct) VALUES (?,?,?,?,?)",
                [(run_id, int(i), float(ti), float(tr), float(p)) for i, ti, tr, p in rows],
            )

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
        out = []
        for r in rows:
            pred = None if r[5] is None else {int(k): float(v) for k, v in json.loads(r[5]).items()}
            out.append(
                GlossRow(
                    seq=int(r[0]),
                    values_gu={20: r[1], 60: r[2], 85: r[3]},
                    temperature_c=r[4],
                    predicted_gu=pred,
                    raw=str(r[6]),
                    timestamp=float(r[7]),
                )
            )
        return out

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
