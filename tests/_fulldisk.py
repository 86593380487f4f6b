"""A really full disk for tests: a small tmpfs mounted on a temp dir (root only; the test
skips, saying why, where mounting is not allowed)."""

from __future__ import annotations

import contextlib
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest


@contextlib.contextmanager
def small_tmpfs(where: Path, size_kb: int) -> Iterator[Path]:
    """Mount a ``size_kb`` tmpfs on ``where`` (created) for the block; unmount after."""
    where.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0:
        pytest.skip("a full-disk test mounts a small tmpfs, which needs root")
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(where)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def fill(where: Path) -> None:
    """Fill the file system of ``where`` to the last byte (writes fail with ENOSPC)."""
    for name, chunk in (("filler", b"\0" * 4096), ("filler-tail", b"\0")):
        with open(where / name, "wb", buffering=0) as f, contextlib.suppress(OSError):
            while True:
                f.write(chunk)
