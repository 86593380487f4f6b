"""The SQLite backend: one file in WAL mode, every reading its own committed transaction.

WAL with ``synchronous=FULL`` keeps a committed row across a process kill and a power loss;
nothing is buffered in memory. A writer waits :data:`BUSY_TIMEOUT_S` for a lock another
program holds, then the write is :class:`~goniolab.store.exceptions.StoreUnavailable`. A
store is opened read-only (``runs list/show/export``) without creating or writing anything,
also on read-only media; a location that cannot serve (a directory, a FIFO, a read-only
directory, a file that is not a store) is refused saying why.
"""

from __future__ import annotations

import os
import sqlite3
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from goniolab.store.connection import Connection, Result
from goniolab.store.exceptions import StoreDamaged, StoreError, StoreUnavailable
from goniolab.store.schema import SQLITE_SCHEMA, upgrade_schema

__all__ = ["BUSY_TIMEOUT_S", "SqliteConnection", "open_sqlite", "sqlite_why"]

#: SQLite's busy timeout: a writer waits this long for another program's lock.
BUSY_TIMEOUT_S = 10.0


def sqlite_why(exc: BaseException) -> str:
    """SQLite's reason, with the ones a user meets most often made explicit."""
    text = str(exc) or type(exc).__name__
    if "file is not a database" in text:
        return "not a goniolab run store (the file is not an SQLite database)"
    if "disk is full" in text or getattr(exc, "sqlite_errorname", "") == "SQLITE_FULL":
        return "the disk is full (free some space; every reading taken so far is stored)"
    if "database is locked" in text or "database table is locked" in text:
        return (
            f"locked by another program for more than {BUSY_TIMEOUT_S:g} s "
            "(a database browser holding a write transaction?)"
        )
    if "malformed" in text:
        return "the file is damaged (database disk image is malformed)"
    return text


class SqliteConnection(Connection):
    """An SQLite connection (``check_same_thread=False``: the lock serialises threads)."""

    def execute(self, sql: str, params: Sequence[Any] = ()) -> Result:
        with self.lock:
            return self._run(lambda: self.raw.execute(sql, tuple(params)))

    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> Result:
        with self.lock:
            return self._run(lambda: self.raw.executemany(sql, [tuple(r) for r in rows]))

    def table_columns(self, table: str) -> list[str]:
        return [str(r[1]) for r in self.execute(f"PRAGMA table_info({table})").fetchall()]

    def _run(self, run: Callable[[], Any]) -> Result:
        try:
            return Result.of(run())
        except sqlite3.IntegrityError:
            raise
        except sqlite3.OperationalError as exc:
            why = sqlite_why(exc)
            if "disk is full" in why or "locked" in why or "disk I/O" in str(exc):
                raise StoreUnavailable(f"store {self.location}: {why}") from exc
            raise StoreError(f"store {self.location}: {why}") from exc
        except sqlite3.DatabaseError as exc:
            raise StoreDamaged(f"store {self.location}: {sqlite_why(exc)}") from exc


def open_sqlite(path: Path, *, readonly: bool, create: bool) -> SqliteConnection:
    """Open the SQLite file: read-only, or for writing (created when missing and
    ``create``), after checks that say why a location cannot serve."""
    where = f"store {path}"
    if path.is_dir():
        raise StoreError(f"{where}: is a directory, not a store file")
    exists = path.exists()
    if not exists and (readonly or not create):
        raise StoreError(f"{where}: no such file (no run has been recorded there)")
    if exists and not path.is_file():
        # a FIFO or a device would block SQLite's open or read for ever
        raise StoreError(f"{where}: not a regular file, not a store")
    if readonly:
        return _open_readonly(path, where)
    _check_writable(path, where, exists)
    return _open_writable(path, where)


def _check_writable(path: Path, where: str, exists: bool) -> None:
    """Create the store's directory; refuse, saying why, a location SQLite could only
    answer with "unable to open database file"."""
    blocker = next((d for d in path.parents if d.exists()), None)
    if blocker is not None and not blocker.is_dir():
        raise StoreError(f"{where}: {blocker} is a file, not a directory")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StoreError(
            f"{where}: cannot create the directory {path.parent}: {exc.strerror}"
        ) from exc
    # SQLite's own message for these is "unable to open database file": say why.
    # WAL writes <store>-wal and <store>-shm beside the file, so the directory must
    # be writable too (os.access also reports a read-only file system, even for root).
    if not os.access(path.parent, os.W_OK):
        raise StoreError(
            f"{where}: the directory {path.parent} is not writable "
            "(read-only file system or permissions); choose another --store"
        )
    if exists and not os.access(path, os.W_OK):
        raise StoreError(f"{where}: the file is read-only; choose another --store")


def _open_writable(path: Path, where: str) -> SqliteConnection:
    """Open (and create) the SQLite store: WAL, ``synchronous=FULL``, the schema, the
    columns and run UUIDs an older store lacks."""
    try:
        raw = sqlite3.connect(
            path, isolation_level=None, timeout=BUSY_TIMEOUT_S, check_same_thread=False
        )
        raw.execute("PRAGMA journal_mode=WAL")
        raw.execute("PRAGMA synchronous=FULL")
        raw.execute("PRAGMA foreign_keys=ON")
        raw.executescript(SQLITE_SCHEMA)
    except (OSError, sqlite3.Error) as exc:
        raise StoreError(f"{where}: cannot open: {sqlite_why(exc)}") from exc
    db = SqliteConnection(raw, location=str(path))
    try:
        upgrade_schema(db)
    except StoreError as exc:
        raw.close()
        raise StoreError(f"{where}: cannot open: {str(exc).split(': ', 1)[-1]}") from exc
    return db


def _open_readonly(path: Path, where: str) -> SqliteConnection:
    """Open for reading only: ``mode=ro``; on a read-only directory (no ``-shm`` can be
    created beside the file) ``immutable=1``, which reads the main file as it is."""
    uri = path.resolve().as_uri()
    query = "mode=ro" if os.access(path.parent, os.W_OK) else "immutable=1"
    try:
        raw = sqlite3.connect(
            f"{uri}?{query}",
            uri=True,
            isolation_level=None,
            timeout=BUSY_TIMEOUT_S,
            check_same_thread=False,
        )
        row = raw.execute(
            "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'runs'"
        ).fetchone()
    except sqlite3.Error as exc:
        raise StoreError(f"{where}: cannot open: {sqlite_why(exc)}") from exc
    if not row[0]:
        raw.close()
        raise StoreError(f"{where}: not a goniolab run store (no runs table)")
    return SqliteConnection(raw, location=str(path))
