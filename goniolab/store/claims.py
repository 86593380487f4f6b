"""Claims: one runner measures a run at a time, and a crashed runner never leaves it claimed.

- SQLite (:class:`FileClaims`): a filelock lock on ``<store>-locks/run-<id>.lock`` beside
  the store file (``flock`` on POSIX, ``LockFileEx``/``msvcrt`` on Windows), held by an open
  file the OS closes when the process dies (also on ``kill -9``). No ``fcntl`` import: the
  store opens on Windows (tests/test_store_locking.py imports it with ``fcntl`` unavailable).
- PostgreSQL (:class:`PgClaims`): a row lock (``SELECT ... FOR UPDATE NOWAIT`` on
  ``run_claims``) held by a connection of its own, which the server drops when that
  connection (and so the process) dies.

A second claim of a held run, from this process or another one, is
:class:`~goniolab.store.exceptions.RunBusy`.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Any, ClassVar, Protocol

from goniolab.store.exceptions import RunBusy, StoreError, StoreUnavailable
from goniolab.store.postgres import PgConnection, psycopg_module

__all__ = ["Claims", "FileClaims", "PgClaims", "RunLocks"]


class Claims(Protocol):
    """What a store does with claims, whatever its backend."""

    def claim(self, run_id: int) -> AbstractContextManager[None]:
        """Hold ``run_id`` for the ``with`` block (:class:`RunBusy` when it is held)."""
        ...

    def is_claimed(self, run_id: int) -> bool | None:
        """Whether a runner holds ``run_id``; ``None`` when it cannot be told."""
        ...

    def ensure(self, run_id: int) -> None:
        """Take this process's claim of ``run_id`` again if the backend dropped it."""
        ...

    def close(self) -> None:
        """Release every claim this object holds."""
        ...


def _lock_class() -> Any:
    """filelock's lock for this platform (``fcntl.flock`` on POSIX, ``msvcrt`` on Windows)."""
    import warnings

    with warnings.catch_warnings():
        # without fcntl (and not Windows) filelock falls back to its soft lock and warns
        warnings.simplefilter("ignore")
        import filelock

    return filelock.FileLock, filelock.Timeout


class RunLocks:
    """Per-run claim locks of this process: ``<lock dir>/run-<id>.lock``, one filelock lock
    per claimed run, shared by every store handle of the process."""

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


class FileClaims:
    """The claims of an SQLite store file: :class:`RunLocks` in ``<store>-locks/``."""

    def __init__(self, path: Path) -> None:
        self.path = path

    @property
    def lock_dir(self) -> Path:
        return self.path.resolve().with_name(self.path.name + "-locks")

    @contextmanager
    def claim(self, run_id: int) -> Iterator[None]:
        lock_dir = self.lock_dir
        try:
            RunLocks.acquire(lock_dir, run_id)
        except RunBusy as exc:
            raise RunBusy(f"store {self.path}: {exc}") from None
        except OSError as exc:
            raise StoreError(f"store {self.path}: cannot claim run {run_id}: {exc}") from exc
        try:
            yield
        finally:
            RunLocks.release(lock_dir, run_id)

    def is_claimed(self, run_id: int) -> bool | None:
        return RunLocks.is_held(self.lock_dir, run_id)

    def ensure(self, run_id: int) -> None:
        """Nothing to do: the OS keeps a file lock as long as the process lives."""

    def close(self) -> None:
        """Nothing to do: each claim is released by the end of its ``with`` block."""


def _lock_row(conn: Any, run_id: int, busy: str) -> None:
    """Lock the run's ``run_claims`` row on ``conn`` (a connection of the claim's own);
    :class:`RunBusy` saying ``busy`` when another connection holds it. ``conn`` is closed
    when the lock is not taken."""
    psycopg = psycopg_module()
    try:
        conn.execute("SELECT run_id FROM run_claims WHERE run_id = %s FOR UPDATE NOWAIT", (run_id,))
    except psycopg.errors.LockNotAvailable:
        conn.close()
        raise RunBusy(busy) from None
    except BaseException:
        conn.close()
        raise


class PgClaims:
    """The claims of a PostgreSQL store: row locks on ``run_claims``, one connection each.

    Parameters
    ----------
    db
        The store's connection (it inserts the ``run_claims`` rows and probes them).
    check_run
        Raises when the run does not exist (or cannot be read): a claim names a real run.
    """

    def __init__(self, db: PgConnection, check_run: Callable[[int], object]) -> None:
        self.db = db
        self._check_run = check_run
        self._held: dict[int, Any] = {}

    def is_claimed(self, run_id: int) -> bool:
        """The run's ``run_claims`` row is locked by some connection."""
        if run_id in self._held:
            return True
        with self.db.transaction() as db:
            free = db.execute(
                "SELECT run_id FROM run_claims WHERE run_id = ? FOR UPDATE SKIP LOCKED",
                (run_id,),
            ).fetchone()
            exists = db.execute(
                "SELECT COUNT(*) FROM run_claims WHERE run_id = ?", (run_id,)
            ).fetchone()[0]
        return bool(exists) and free is None

    @contextmanager
    def claim(self, run_id: int) -> Iterator[None]:
        psycopg = psycopg_module()
        where = f"store {self.db.location}"
        if run_id in self._held:
            raise RunBusy(f"{where}: run {run_id} is already being measured by this process")
        self._check_run(run_id)
        self.db.execute(
            "INSERT INTO run_claims(run_id) VALUES (?) ON CONFLICT (run_id) DO NOTHING", (run_id,)
        )
        try:
            conn = self.db.connect(autocommit=False)
        except StoreError as exc:
            raise StoreError(
                f"{where}: cannot claim run {run_id}: {str(exc).split('cannot connect: ', 1)[-1]}"
            ) from None
        busy = f"{where}: run {run_id} is being measured by another goniolab process"
        _lock_row(conn, run_id, busy + "; stop that one first")
        self._held[run_id] = conn
        try:
            yield
        finally:
            self._held.pop(run_id, None)
            # a round trip: the row lock is gone when it returns (close alone is async);
            # on a dead connection the server drops the lock with it
            with contextlib.suppress(psycopg.Error):
                conn.rollback()
            conn.close()

    def ensure(self, run_id: int) -> None:
        """After a lost connection: take the claim of ``run_id`` again if the server dropped
        it with the connection (a restart); :class:`RunBusy` if another runner took the run
        meanwhile."""
        conn = self._held.get(run_id)
        if conn is None:
            return
        psycopg = psycopg_module()
        with contextlib.suppress(psycopg.Error):
            if not (conn.closed or conn.broken):
                conn.execute("SELECT 1")
                return
        with contextlib.suppress(Exception):
            conn.close()
        new = self.db.connect(autocommit=False)
        try:
            busy = f"store {self.db.location}: run {run_id} was taken by another goniolab"
            _lock_row(new, run_id, busy + " process while the database was away")
        except psycopg.Error as exc:
            raise StoreUnavailable(f"store {self.db.location}: {self.db.why(exc)}") from None
        self._held[run_id] = new

    def close(self) -> None:
        for conn in self._held.values():
            with contextlib.suppress(Exception):
                conn.close()
        self._held.clear()
