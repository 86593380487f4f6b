"""The store's failures, each one line naming the store (and the run when there is one).

:class:`StoreError` is the family; a runner answers :class:`StoreUnavailable` (transient) by
pausing with the arms parked, :class:`RunBusy` by refusing to measure, and
:class:`StoreDamaged` by naming the damaged run.
"""

from __future__ import annotations

__all__ = ["RunBusy", "StoreDamaged", "StoreError", "StoreUnavailable"]


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
