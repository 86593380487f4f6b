"""The PostgreSQL backend (psycopg 3, the ``goniolab[postgres]`` extra): the same tables and
per-reading commits as SQLite, on a database a lab shares.

Credentials come from libpq's own sources (``PGPASSWORD``, ``~/.pgpass``, ``PGSSLMODE`` and
certificate files, or the URL); a password never appears in a message
(:func:`goniolab.redact.scrub_driver_message`). A server down, restarted, frozen or
unreachable never hangs a caller: a connect timeout (:data:`CONNECT_TIMEOUT_S`), a statement
timeout on the server (:data:`STATEMENT_TIMEOUT_S`), TCP keepalives and user timeout, and a
client watchdog that shuts the socket of a statement that does not return; the call is
:class:`~goniolab.store.exceptions.StoreUnavailable` and the next one reconnects, with
exponential backoff.
"""

from __future__ import annotations

import contextlib
import os
import socket
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

from goniolab.redact import scrub_driver_message
from goniolab.store.connection import Connection, Result
from goniolab.store.exceptions import StoreError, StoreUnavailable
from goniolab.store.schema import PG_SCHEMA, PG_SCHEMA_LOCK, upgrade_schema

__all__ = [
    "CONNECT_TIMEOUT_S",
    "STATEMENT_TIMEOUT_S",
    "PgConnection",
    "open_postgres",
    "pg_connect",
    "psycopg_module",
]

#: Connect timeout, and the longest one statement may take before the client gives the
#: connection up (a frozen or partitioned server) and the server cancels it.
CONNECT_TIMEOUT_S = 5
STATEMENT_TIMEOUT_S = 10.0
#: Reconnect backoff after a lost connection: first wait, factor, longest wait.
BACKOFF_FIRST_S, BACKOFF_FACTOR, BACKOFF_MAX_S = 0.5, 2.0, 10.0


def psycopg_module() -> Any:
    """The ``psycopg`` module, or :class:`StoreError` saying how to install it."""
    try:
        import psycopg
    except ImportError:
        raise StoreError(
            "a postgresql:// store needs psycopg: pip install 'goniolab[postgres]'"
        ) from None
    return psycopg


def pg_connect(conninfo: str, location: str, *, autocommit: bool = True) -> Any:
    """A new psycopg connection with the store's timeouts: connect, statement (server
    side) and TCP keepalives/user timeout (a dead peer is noticed in seconds).

    The session runs with ``jit=off``: the store's statements are short lookups, but the
    listing's per-run counts (:meth:`goniolab.store.RunStore.list_briefs`) exceed
    ``jit_above_cost`` on a store of a few hundred runs, and the JIT compile of a fresh
    session's first query (LLVM loaded, code emitted) cost more than the query itself:
    86 ms against 37 ms with ``jit=off`` on 520 runs / 213,200 readings
    (bench/bench_runs_list.py), and each CLI process is a fresh session."""
    psycopg = psycopg_module()
    try:
        return psycopg.connect(
            conninfo,
            autocommit=autocommit,
            connect_timeout=CONNECT_TIMEOUT_S,
            options=f"-c statement_timeout={int(STATEMENT_TIMEOUT_S * 1000)} -c jit=off",
            keepalives=1,
            keepalives_idle=5,
            keepalives_interval=2,
            keepalives_count=3,
            tcp_user_timeout=int((STATEMENT_TIMEOUT_S + 2) * 1000),
        )
    except psycopg.Error as exc:
        why = scrub_driver_message(str(exc) or type(exc).__name__, conninfo)
        raise StoreError(f"store {location}: cannot connect: {why}") from None


class PgConnection(Connection):
    """A PostgreSQL connection: ``%s`` placeholders, a statement timeout (server side), a
    client-side watchdog that gives a connection up when a statement does not return in
    time (the socket is shut down, the call fails with
    :class:`~goniolab.store.exceptions.StoreUnavailable`), and a reconnect with
    exponential backoff on the next call.

    Parameters
    ----------
    raw
        The open psycopg connection.
    location
        The store's name in messages (no password).
    conninfo
        The URL or keyword string to reconnect with (scrubbed from every message).
    """

    is_postgres: ClassVar[bool] = True

    def __init__(self, raw: Any, *, location: str, conninfo: str) -> None:
        super().__init__(raw, location=location)
        self.conninfo = conninfo
        self._broken = ""
        self._next_try = 0.0
        self._backoff_s = BACKOFF_FIRST_S

    def connect(self, *, autocommit: bool = True) -> Any:
        """Another connection to the same database (a claim holds its row lock on one)."""
        return pg_connect(self.conninfo, self.location, autocommit=autocommit)

    def why(self, exc: BaseException) -> str:
        """The driver's message, without the password."""
        return scrub_driver_message(str(exc) or type(exc).__name__, self.conninfo)

    # ------------------------------------------------------------------ statements
    @staticmethod
    def _pg_sql(sql: str) -> str:
        return "BEGIN" if sql == "BEGIN IMMEDIATE" else sql.replace("?", "%s")

    def execute(self, sql: str, params: Sequence[Any] = ()) -> Result:
        with self.lock:
            return self._run(lambda: self.raw.execute(self._pg_sql(sql), tuple(params)))

    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> Result:
        def many() -> Any:
            cur = self.raw.cursor()
            cur.executemany(self._pg_sql(sql), [tuple(r) for r in rows])
            return cur

        with self.lock:
            return self._run(many)

    def table_columns(self, table: str) -> list[str]:
        rows = self.execute(
            "SELECT column_name FROM information_schema.columns"
            " WHERE table_schema = current_schema() AND table_name = ?"
            " ORDER BY ordinal_position",
            (table,),
        ).fetchall()
        return [str(r[0]) for r in rows]

    def _run(self, run: Callable[[], Any]) -> Result:
        psycopg = psycopg_module()
        self._ensure_connected()
        timer = threading.Timer(STATEMENT_TIMEOUT_S + 2.0, self._give_up)
        timer.daemon = True
        timer.start()
        try:
            return Result.of(run())
        except psycopg.IntegrityError:
            raise
        except (psycopg.OperationalError, psycopg.InterfaceError) as exc:
            if self.raw.closed or self.raw.broken or isinstance(exc, psycopg.InterfaceError):
                self._mark_broken(exc)
            raise StoreUnavailable(
                f"store {self.location}: {self.why(exc)}"
                + (" (a write timed out)" if isinstance(exc, psycopg.errors.QueryCanceled) else "")
            ) from None
        except psycopg.Error as exc:
            raise StoreError(f"store {self.location}: {self.why(exc)}") from None
        finally:
            timer.cancel()

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
        self._broken = f"no answer within {STATEMENT_TIMEOUT_S + 2.0:g} s"

    def _mark_broken(self, exc: BaseException) -> None:
        if not self._broken:
            self._broken = self.why(exc)
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
        try:
            self.raw = self.connect()
        except StoreError as exc:
            self._next_try = time.monotonic() + self._backoff_s
            self._backoff_s = min(BACKOFF_MAX_S, self._backoff_s * BACKOFF_FACTOR)
            raise StoreUnavailable(str(exc)) from None
        self._broken = ""
        self._backoff_s = BACKOFF_FIRST_S


def open_postgres(conninfo: str, location: str, *, readonly: bool, create: bool) -> PgConnection:
    """Connect (libpq reads PGPASSWORD, ~/.pgpass, PGSSLMODE ... itself) and create the
    tables unless ``readonly``; every message is scrubbed of the password."""
    where = f"store {location}"
    db = PgConnection(pg_connect(conninfo, location), location=location, conninfo=conninfo)
    try:
        have = db.execute("SELECT to_regclass('runs') IS NOT NULL").fetchone()[0]
        if not have and (readonly or not create):
            raise StoreError(f"{where}: no goniolab run store in this database (no runs table)")
        if not readonly:
            with db.transaction():
                db.execute("SELECT pg_advisory_xact_lock(?)", (PG_SCHEMA_LOCK,))
                db.execute(PG_SCHEMA)
                upgrade_schema(db)
    except StoreError as exc:
        db.close()
        if str(exc).startswith(where):
            raise
        raise StoreError(f"{where}: cannot open: {exc}") from None
    return db
