"""``goniolab`` commands run in the test's own process, returning what a subprocess would.

A ``goniolab`` subprocess pays 0.5-1.5 s of CPU importing numpy, colour-science (which
imports pandas), scipy and numba before it does anything; in the test process they are
imported once. Where a test's point is what a command does (its output, its exit status,
what it stores) and not the process boundary, :func:`run_cli` runs
:func:`goniolab.cli.main` with the command line, the environment changes and the working
directory the subprocess would get, and returns a :class:`subprocess.CompletedProcess`
with its exit status, stdout and stderr kept apart. The boundary itself (the console
script, signals, exit statuses seen by a shell, a killed process) stays tested by the real
subprocess tests: ``tests/test_cli_stop_signals.py``, ``tests/test_cli_pipes.py``,
``tests/test_cli_signals.py``, ``tests/test_store_pg.py`` (two scans at once through the
installed console script, kill -9), ``tests/scan/test_integration.py``, ``sim serve`` in
``tests/sim/test_wire.py`` and ``tests/wire/test_server_restart.py``.
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path


@contextlib.contextmanager
def _environ(changes: Mapping[str, str | None]) -> Iterator[None]:
    saved = {k: os.environ.get(k) for k in changes}
    try:
        for k, v in changes.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _text_stream() -> io.TextIOWrapper:
    # a real text stream over bytes (``sys.stdout.buffer`` exists, as in a process)
    return io.TextIOWrapper(io.BytesIO(), encoding="utf-8", newline="", write_through=True)


def run_cli(
    *args: str | Path,
    env: Mapping[str, str | None] | None = None,
    cwd: str | Path | None = None,
) -> subprocess.CompletedProcess[str]:
    """Run ``goniolab ARGS`` in process; ``env``: variables to set (``None``: unset) for
    the call only, on top of the test's environment; ``cwd``: the working directory for
    the call. Returns the exit status (``main``'s return value, or the ``SystemExit``
    code argparse raises), stdout and stderr as text."""
    from goniolab.cli import main

    argv = [str(a) for a in args]
    out, err = _text_stream(), _text_stream()
    here = os.getcwd()
    with _environ(env or {}), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            if cwd is not None:
                os.chdir(cwd)
            try:
                code = main(argv)
            except SystemExit as exc:
                # as the interpreter ends a process: None is 0, an int itself, anything
                # else printed to stderr and 1 (a sys.exit("message") must show its text)
                if exc.code is None:
                    code = 0
                elif isinstance(exc.code, int):
                    code = exc.code
                else:
                    print(exc.code, file=sys.stderr)
                    code = 1
        finally:
            os.chdir(here)
            out.flush()
            err.flush()
    text = [s.buffer.getvalue().decode("utf-8") for s in (out, err)]  # type: ignore[attr-defined]
    return subprocess.CompletedProcess(["goniolab", *argv], code, text[0], text[1])
