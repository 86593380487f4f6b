"""Shared test set-up: the log file of every in-process ``goniolab`` call goes to a
per-test directory, never to the user's log dir; hypothesis draws the same examples on
every run (``derandomize``), so ``make test`` passes or fails the same way each time. To
search further: ``HYPOTHESIS_PROFILE=explore .venv/bin/python -m pytest tests/...``."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

settings.register_profile("goniolab", derandomize=True, database=None)
settings.register_profile("explore", max_examples=1000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "goniolab"))


@pytest.fixture(autouse=True)
def _log_dir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    path = tmp_path_factory.mktemp("log")
    monkeypatch.setenv("GONIOLAB_LOG_DIR", str(path))
    return path


def pytest_configure(config: pytest.Config) -> None:
    """Under xdist, the controller fills the shared numba and twin caches once before the
    workers start (tests/_warm.py); a worker or a plain run does not."""
    if hasattr(config, "workerinput") or not config.getoption("numprocesses", default=None):
        return
    from tests._warm import warm_caches

    warm_caches()
