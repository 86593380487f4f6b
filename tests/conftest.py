"""Shared test set-up: the log file of every in-process ``goniolab`` call goes to a
per-test directory, never to the user's log dir."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def _log_dir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    path = tmp_path_factory.mktemp("log")
    monkeypatch.setenv("GONIOLAB_LOG_DIR", str(path))
    return path
