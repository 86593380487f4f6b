"""tests/_cli.py's in-process runner ends a command as the interpreter ends a process:
its exit status and stderr for ``sys.exit(None)``, ``sys.exit(3)`` and
``sys.exit("message")`` are a real process's (review of 2026-11-26: None read as 1, a
message was dropped)."""

from __future__ import annotations

import subprocess
import sys
from unittest import mock

import pytest

from tests._cli import run_cli


@pytest.mark.parametrize("code", [None, 0, 3, "the lab is closed"])
def test_run_cli_exits_as_a_process_does(code: object) -> None:
    real = subprocess.run(
        [sys.executable, "-c", f"import sys; sys.exit({code!r})"],
        capture_output=True,
        text=True,
        check=False,
    )
    with mock.patch("goniolab.cli.main", side_effect=SystemExit(code)):
        got = run_cli(["--version"])
    assert (got.returncode, got.stdout, got.stderr) == (real.returncode, real.stdout, real.stderr)


@pytest.mark.parametrize("name", ["GONIOLAB_THREADS", "OMP_NUM_THREADS"])
def test_a_bad_thread_count_is_an_error_before_any_work(name: str) -> None:
    """A thread count that is not a positive integer is a one-line error naming the
    variable (it had surfaced as a ValueError traceback from inside the slope walks)."""
    other = "OMP_NUM_THREADS" if name == "GONIOLAB_THREADS" else "GONIOLAB_THREADS"
    out = run_cli("predict", "gloss", "sample:gauss-sq177-l5", env={name: "two", other: None})
    assert out.returncode == 2, out.stderr
    assert out.stderr == (
        f"goniolab: error: {name}='two': the number of threads must be a positive integer\n"
    )
    assert out.stdout == ""
