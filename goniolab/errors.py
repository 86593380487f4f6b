"""Errors the ``goniolab`` application reports to a user as one clear line.

Library layers raise their own errors (``goniolab.optics.HeightMapError``,
``drivers.base.DeviceError``, ``goniolab.store.StoreError``, ``goniolab.scan.plans.PlanError``);
the application layer (:mod:`goniolab.app`, issue 24) turns those a user can act on into a
:class:`UserError`, where a use case calls the library: on a lab with the one context
manager :func:`goniolab.app.lab_setup.lab_errors` (a refused plan, an unreachable
instrument, a store that refuses a write, a run another process holds); a store opened with
:func:`goniolab.app.lab_setup.open_store`, a run read with
:func:`goniolab.app.stored_runs.get_run`, a netCDF file with
:mod:`goniolab.app.netcdf_files`, a height map or an option of a prediction in
:mod:`goniolab.app.predictions`. Each face then presents a :class:`UserError` at one point:
the CLI's ``goniolab.cli.main`` (``goniolab: error: ...`` and its ``exit_code``), the TUI's
key actions (a notification), the notebook API (the exception itself).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["ConfigError", "UserError", "a_run_of_kind"]

#: How a message names a run of each stored kind.
_RUN_KINDS = {"align": "an alignment run"}


def a_run_of_kind(kind: str) -> str:
    """``"an alignment run"`` for ``"align"``: a run kind with its article (issue 27:
    "a align run")."""
    return _RUN_KINDS.get(kind, f"{'an' if kind[:1] in 'aeiou' else 'a'} {kind} run")


class UserError(Exception):
    """An error caused by input the user can fix, or an instrument the user can check.

    Parameters
    ----------
    message
        One line naming the file/key/device and the reason.
    exit_code
        2 for bad input (file, config, option), 1 for instrument or run failures.
    """

    def __init__(self, message: str, *, exit_code: int = 2) -> None:
        self.exit_code = exit_code
        super().__init__(message)


class ConfigError(UserError):
    """A lab config file is unreadable or invalid; the message names file, key and reason.

    Raised by :mod:`goniolab.config` (and re-exported there) and by the twin's assembly
    (:mod:`sim.assembly`), which may import this module but not the config's.
    """

    def __init__(self, path: str | Path, key: str, reason: str) -> None:
        self.path = str(path)
        self.key = key
        self.reason = reason
        where = f"{self.path}: {key}: " if key else f"{self.path}: "
        super().__init__(where + reason, exit_code=2)
