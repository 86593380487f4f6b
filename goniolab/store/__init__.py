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

Crash safety: each insert is its own transaction, committed before the next point is
measured. WAL with ``synchronous=FULL`` keeps a committed row across a process kill and a
power loss; nothing is buffered in memory.

The rooms of the package, one job each:

=========================  ==============================================================
``runstore``               :class:`RunStore` (runs) and where a store is
``readings``               points, predictions, gloss readings of a run
``records``                the decoded rows (:class:`RunRecord`, :class:`PointRow` ...)
``schema``                 the tables (described there) and the upgrade of older stores
``connection``             one connection shared by threads, transactions
``sqlite`` / ``postgres``  the two backends (timeouts, watchdog, reconnect)
``claims``                 one runner per run (filelock, PostgreSQL row locks)
``migrate``                ``runs migrate``: copy runs between stores by UUID
``json_import``            ``runs import``: a JSON export read back (through migrate)
``exceptions``             :class:`StoreError` and its kinds
=========================  ==============================================================

Exports (CSV, JSON, netCDF, Parquet) live with the exporters: :mod:`goniolab.export`.
"""

from __future__ import annotations

from goniolab.store.exceptions import RunBusy, StoreDamaged, StoreError, StoreUnavailable
from goniolab.store.json_import import import_export_doc, import_json_export
from goniolab.store.records import (
    COLOUR_KEYS,
    GlossRow,
    PointRow,
    PredictedColour,
    RunMeta,
    RunRecord,
    legacy_uuid,
)
from goniolab.store.runstore import RunStore, default_store_path, is_store_url, resolve_store_path

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
    "import_export_doc",
    "import_json_export",
    "is_store_url",
    "legacy_uuid",
    "resolve_store_path",
]
