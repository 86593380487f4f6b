"""One database connection shared by the threads of a process, whatever the backend.

Every statement runs under the connection's lock and returns its rows already fetched
(:class:`Result`), so the scan's event loop, a worker thread (``goniolab.api.run_scan`` in
Jupyter) and the TUI may share one store. Statements are written with ``?`` placeholders;
each backend (:mod:`goniolab.store.sqlite`, :mod:`goniolab.store.postgres`) runs them its way
and turns its driver's failures into the store's one-line errors
(:mod:`goniolab.store.exceptions`).
"""

from __future__ import annotations

import contextlib
import threading
from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any, ClassVar

__all__ = ["Connection", "Result"]


class Result:
    """The rows of one statement, fetched while the connection was held (thread-safe)."""

    __slots__ = ("description", "rowcount", "rows")

    def __init__(self, rows: list[Any], description: Any, rowcount: int) -> None:
        self.rows = rows
        self.description = description
        self.rowcount = rowcount

    @classmethod
    def of(cls, cursor: Any) -> Result:
        """The rows of a DB-API cursor that has just run a statement."""
        rows = cursor.fetchall() if cursor.description is not None else []
        return cls(rows, cursor.description, cursor.rowcount)

    def fetchone(self) -> Any:
        return self.rows[0] if self.rows else None

    def fetchall(self) -> list[Any]:
        return self.rows

    def __iter__(self) -> Iterator[Any]:
        return iter(self.rows)


class Connection(ABC):
    """A store's connection: statements under one lock, transactions, the tables' columns.

    Parameters
    ----------
    raw
        The driver's connection (``sqlite3.Connection`` or ``psycopg.Connection``).
    location
        How the store names itself in messages (a path, or a URL without its password).
    """

    #: Whether the backend is PostgreSQL (SQL that differs asks this).
    is_postgres: ClassVar[bool] = False

    def __init__(self, raw: Any, *, location: str) -> None:
        self.raw = raw
        self.location = location
        self.lock = threading.RLock()
        self.in_tx = False
        self._columns: dict[str, list[str]] = {}

    @abstractmethod
    def execute(self, sql: str, params: Sequence[Any] = ()) -> Result:
        """Run one statement and fetch its rows."""

    @abstractmethod
    def executemany(self, sql: str, rows: Sequence[Sequence[Any]]) -> Result:
        """Run one statement once per row of ``rows``."""

    @abstractmethod
    def table_columns(self, table: str) -> list[str]:
        """The column names of ``table`` in this store, in their order."""

    def has_column(self, table: str, column: str) -> bool:
        """Whether ``table`` has ``column`` (case-insensitive: PostgreSQL folds names);
        remembered per table until :meth:`forget_columns`."""
        if table not in self._columns:
            self._columns[table] = [c.lower() for c in self.table_columns(table)]
        return column.lower() in self._columns[table]

    def forget_columns(self) -> None:
        """Forget the columns :meth:`has_column` remembered (after an ``ALTER TABLE``)."""
        self._columns.clear()

    @contextmanager
    def transaction(self) -> Iterator[Connection]:
        """One transaction, holding the connection's lock throughout (a nested call joins
        the outer transaction); rolled back when the block raises."""
        with self.lock:
            if self.in_tx:
                yield self
                return
            self.execute("BEGIN IMMEDIATE")
            self.in_tx = True
            try:
                yield self
            except BaseException:
                self.in_tx = False
                with contextlib.suppress(Exception):  # a lost connection has nothing to undo
                    self.execute("ROLLBACK")
                raise
            self.in_tx = False
            self.execute("COMMIT")

    def close(self) -> None:
        with self.lock, contextlib.suppress(Exception):
            self.raw.close()
