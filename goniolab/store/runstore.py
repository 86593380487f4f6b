"""The run store object: :class:`RunStore` on an SQLite file or a PostgreSQL database, and
where a store is (:func:`resolve_store_path`).

The backend is chosen by the location (:func:`is_store_url`); everything above this module
speaks to :class:`RunStore` alone. Runs (:meth:`RunStore.create_run`, :meth:`~RunStore.
get_run`, :meth:`~RunStore.list_briefs` ...) are here; the readings are
:class:`~goniolab.store.readings.ReadingTables`, the claims :mod:`goniolab.store.claims`,
the copy between stores :mod:`goniolab.store.migrate`, the exports :mod:`goniolab.export`.
"""

from __future__ import annotations

import json
import time
import uuid as uuidlib
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import platformdirs

from goniolab.redact import is_conninfo, redact, redact_obj
from goniolab.store.claims import Claims, FileClaims, PgClaims
from goniolab.store.connection import Connection
from goniolab.store.exceptions import StoreDamaged, StoreError
from goniolab.store.migrate import copy_run
from goniolab.store.postgres import open_postgres
from goniolab.store.readings import ReadingTables
from goniolab.store.records import (
    RunMeta,
    RunRecord,
    json_column,
    json_text,
    run_select,
    search_text,
)
from goniolab.store.sqlite import open_sqlite

__all__ = ["RunStore", "default_store_path", "is_store_url", "resolve_store_path"]


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


class RunStore(ReadingTables):
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

    Attributes
    ----------
    location
        How the store names itself in messages (a path, or the URL without its password).
    is_postgres
        Whether the store is a PostgreSQL database.
    db
        The connection (:class:`~goniolab.store.connection.Connection`: ``execute``,
        ``transaction()``), for SQL the methods do not cover (``runs migrate``, benches).

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
        self.db: Connection
        self._claims: Claims
        if self.is_postgres:
            conninfo = str(path)
            #: How the store names itself (its URL or keyword string without the password).
            self.location = redact(conninfo)
            self.path = Path(self.location.split("://", 1)[-1])
            pg = open_postgres(conninfo, self.location, readonly=readonly, create=create)
            self.db = pg
            self._claims = PgClaims(pg, self.get_run)
            return
        self.path = Path(path)
        self.location = str(self.path)
        self.db = open_sqlite(self.path, readonly=readonly, create=create)
        self._claims = FileClaims(self.path)

    def __repr__(self) -> str:
        return f"RunStore({self.location!r}{', readonly=True' if self.readonly else ''})"

    @property
    def store_uuid(self) -> str | None:
        """The store's own UUID (``None`` for an old store opened read-only): two handles
        on one store (a symlink, a relative path, another spelling of a URL) share it."""
        row = self.db.execute("SELECT value FROM meta WHERE key = 'store_uuid'").fetchone()
        return None if row is None else str(row[0])

    @property
    def _run_select(self) -> str:
        return run_select(has_identity=self.db.has_column("runs", "uuid"))

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """Close the connection (committed data is already on disk)."""
        self._claims.close()
        self.db.close()

    def __enter__(self) -> RunStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def wait_writable(self) -> None:
        """Return when the store takes writes again; :class:`StoreUnavailable` (one line,
        why) while it does not. Used by a runner that paused on a failed write."""
        with self.db.transaction() as db:
            db.execute("UPDATE meta SET value = value WHERE key = 'schema_version'")

    @property
    def journal_mode(self) -> str:
        """The SQLite journal mode in use (``"wal"``; ``""`` for PostgreSQL)."""
        if self.is_postgres:
            return ""
        return str(self.db.execute("PRAGMA journal_mode").fetchone()[0])

    # ------------------------------------------------------------------ claims
    @contextmanager
    def claim_run(self, run_id: int) -> Iterator[None]:
        """Hold the run for measuring: a second runner of the same run (another process,
        e.g. ``scan resume`` while the scan still runs, or this one) gets :class:`RunBusy`.

        For SQLite the claim is a lock on ``<store>-locks/run-<id>.lock`` beside the store
        file (filelock: ``flock`` on POSIX, ``msvcrt`` on Windows), released on exit and by
        the OS when the process dies. In PostgreSQL it is a row lock (``SELECT ... FOR
        UPDATE NOWAIT`` on ``run_claims``) held by a connection of its own, released on exit
        and by the server when the process (and so its connection) dies
        (:mod:`goniolab.store.claims`).
        """
        with self._claims.claim(run_id):
            yield

    def is_claimed(self, run_id: int) -> bool | None:
        """Whether a runner (this or another process) is measuring ``run_id`` right now;
        ``None`` when the store is read-only and it cannot be told. A run whose status
        says ``running`` but that nobody claims was interrupted (e.g. ``kill -9``)."""
        return self._claims.is_claimed(run_id)

    def ensure_claim(self, run_id: int) -> None:
        """After a lost PostgreSQL connection: take this process's claim of ``run_id``
        again if the server dropped it with the connection (a restart); :class:`RunBusy`
        if another runner took the run meanwhile. A no-op for SQLite (the OS keeps a file
        lock as long as the process lives)."""
        self._claims.ensure(run_id)

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
        with self.db.transaction() as db:
            row = db.execute(
                "INSERT INTO runs(kind, plan_json, config_json, sample, model_json, version,"
                " status, reason, created_at, updated_at, uuid, operator, notes, tags_json,"
                " sample_id) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?) RETURNING id",
                (kind, json_text(plan), json_text(redact_obj(config)), sample, json_text(model), version,
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
            with self.db.transaction() as db:
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
        with self.db.transaction() as db:
            cur = db.execute(
                "UPDATE runs SET status = ?, reason = ?, updated_at = ?, finished_at = ?"
                " WHERE id = ?",
                (status, reason, now, finished, run_id),
            )
            if cur.rowcount != 1:
                raise StoreError(f"store {self.location}: no run {run_id}")

    def update_model(self, run_id: int, extra: Mapping[str, Any]) -> None:
        """Merge ``extra`` into the run's model parameters (e.g. an alignment's result)."""
        with self.db.transaction() as db:
            row = db.execute("SELECT model_json FROM runs WHERE id = ?", (run_id,)).fetchone()
            if row is None:
                raise StoreError(f"store {self.location}: no run {run_id}")
            model = {**json_column(run_id, "model_json", row[0]), **extra}
            db.execute(
                "UPDATE runs SET model_json = ?, updated_at = ? WHERE id = ?",
                (json_text(model), time.time(), run_id),
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
        row = self.db.execute(f"{self._run_select} WHERE id = ?", (run_id,)).fetchone()
        if row is None:
            raise StoreError(f"store {self.location}: no run {run_id}")
        rec = RunRecord.from_row(row, self.location)
        if rec.damage and not allow_damaged:
            raise StoreDamaged(f"store {self.location}: run {run_id} is damaged: {rec.damage}")
        return rec

    def find_uuid(self, run_uuid: str) -> int | None:
        """The id of the run with UUID ``run_uuid`` in this store, else ``None``."""
        if not self.db.has_column("runs", "uuid"):
            return next((r.id for r in self.list_runs() if r.uuid == run_uuid), None)
        row = self.db.execute("SELECT id FROM runs WHERE uuid = ?", (run_uuid,)).fetchone()
        return None if row is None else int(row[0])

    def list_runs(self, limit: int | None = None, *, kind: str | None = None) -> list[RunRecord]:
        """Return runs, newest first (a damaged row is listed with its ``damage``); only
        those of ``kind`` when given (selected in the query: no other run is decoded)."""
        sql = self._run_select
        params: tuple[int | str, ...] = ()
        if kind is not None:
            sql += " WHERE kind = ?"
            params = (kind,)
        sql += " ORDER BY id DESC"
        if limit is not None:
            sql += " LIMIT ?"
            params = (*params, limit)
        return [RunRecord.from_row(r, self.location) for r in self.db.execute(sql, params)]

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

        The records are brief (:attr:`RunRecord.brief`): a listing shows neither the config
        snapshot nor the model, and decoding them was most of its time (a real scan's
        snapshot is 3 kB of JSON: 107 against 45 ms for 520 runs, bench/bench_runs_list.py).
        The server still checks that they are JSON objects where it can (SQLite's
        ``json_valid``, PostgreSQL 16's ``pg_input_is_valid``); a run failing the check is
        read whole, so its ``damage`` says why, as :meth:`list_runs` does. On PostgreSQL
        before 16 a config or model column garbled by hand shows when the run is opened.

        A store whose readings cannot be counted (a damaged page) gets each run's count
        on its own; a run whose count fails has ``None`` (and :meth:`count_readings`
        says why).
        """
        where: list[str] = []
        params: list[Any] = []
        has_ident = self.db.has_column("runs", "uuid")
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
        sql = (
            self._run_select.replace("config_json,", "NULL,")
            .replace("model_json,", "NULL,")
            .replace(
                " FROM runs",
                f", {self._objects_check()},"
                " (SELECT COUNT(*) FROM points p WHERE p.run_id = runs.id),"
                " (SELECT COUNT(*) FROM gloss_readings g WHERE g.run_id = runs.id) FROM runs",
            )
        )
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY id DESC"
        if limit is not None and has_ident and tag is None:
            sql += " LIMIT ?"
            params.append(limit)
        out: list[tuple[RunRecord, int | None]] = []
        try:
            rows = self.db.execute(sql, params).fetchall()
        except StoreDamaged:
            rows = None
        if rows is not None:
            for r in rows:
                rec = RunRecord.from_row(r[:-3], self.location, brief=True)
                if not r[-3]:  # config or model is no JSON object: read whole, say why
                    rec = self.get_run(rec.id, allow_damaged=True)
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
                and (text is None or text.lower() in search_text(rec))
            ]
            out = out[:limit] if limit is not None else out
        return out

    def _objects_check(self) -> str:
        """SQL true when a run's config_json and model_json are JSON objects, without
        raising on a garbled one (see :meth:`list_briefs`)."""
        cols = ("config_json", "model_json")
        if not self.db.is_postgres:
            valid = " AND ".join(f"json_valid({c})" for c in cols)
            objects = " AND ".join(f"json_type({c}) = 'object'" for c in cols)
            return f"CASE WHEN {valid} THEN {objects} ELSE 0 END"
        version = int(getattr(getattr(self.db.raw, "info", None), "server_version", 0) or 0)
        if version < 160000:
            return "TRUE"
        valid = " AND ".join(f"pg_input_is_valid({c}, 'json')" for c in cols)
        objects = " AND ".join(f"json_typeof({c}::json) = 'object'" for c in cols)
        return f"CASE WHEN {valid} THEN {objects} ELSE FALSE END"

    def count_readings(self, rec: RunRecord) -> int:
        """The number of readings of ``rec``: points of a scan, readings of a gloss log."""
        table = "gloss_readings" if rec.kind == "gloss" else "points"
        row = self.db.execute(f"SELECT COUNT(*) FROM {table} WHERE run_id = ?", (rec.id,))
        return int(row.fetchone()[0])

    # ------------------------------------------------------------------ migration
    def table_columns(self, table: str) -> list[str]:
        """The column names of ``table`` in this store."""
        return self.db.table_columns(table)

    def copy_run_from(self, src: RunStore, run_id: int) -> tuple[int, str]:
        """Copy run ``run_id`` of ``src`` (with its readings, predictions and gloss readings)
        into this store in one transaction; returns ``(id here, action)``: ``"copied"``,
        ``"updated"`` or ``"unchanged"`` (:func:`goniolab.store.migrate.copy_run`).

        Raises
        ------
        StoreDamaged
            The source run's row cannot be read (nothing is written).
        """
        return copy_run(self, src, run_id)
