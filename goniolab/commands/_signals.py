"""Termination signals of the long-running commands (``scan``, ``gloss log``).

Every way a lab process is told to end is an abort, never a kill in mid-move (issue 23,
item 3): Ctrl-C (SIGINT), ``systemctl stop`` / ``docker stop`` / ``timeout`` (SIGTERM) and a
dropped ssh session (SIGHUP). The first signal asks the run to stop (the arms stop, park,
and the run is stored ``aborted`` with the signal's name as its reason); a second one asks
to quit at once, which still stops the arms and records the run (the runner's cancellation
path), only without waiting for the current reading.
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Callable

__all__ = ["STOP_SIGNALS", "describe", "install_stop_signals"]

#: The signals that end a run, by name (SIGHUP does not exist on Windows).
STOP_SIGNALS: tuple[str, ...] = ("SIGINT", "SIGTERM", "SIGHUP")

_DESCRIPTIONS = {
    "SIGINT": "Ctrl-C (SIGINT)",
    "SIGTERM": "SIGTERM (the process was asked to stop)",
    "SIGHUP": "SIGHUP (the terminal went away)",
}


def describe(name: str) -> str:
    """How a signal is named in messages and stored reasons."""
    return _DESCRIPTIONS.get(name, name)


def install_stop_signals(
    loop: asyncio.AbstractEventLoop,
    first: Callable[[str], None],
    again: Callable[[str], None],
) -> Callable[[], None]:
    """Call ``first(name)`` on the first stop signal and ``again(name)`` on every later one;
    return a function that removes the handlers. Signals the platform lacks, or that the
    loop cannot handle (Windows' selector loop), are left alone."""
    installed: list[int] = []
    count = 0

    def handler(name: str) -> None:
        nonlocal count
        count += 1
        (first if count == 1 else again)(name)

    for name in STOP_SIGNALS:
        signum = getattr(signal, name, None)
        if signum is None:
            continue
        try:
            loop.add_signal_handler(signum, handler, name)
        except (NotImplementedError, RuntimeError, ValueError):
            continue
        installed.append(signum)

    def remove() -> None:
        for signum in installed:
            loop.remove_signal_handler(signum)

    return remove
