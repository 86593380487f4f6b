"""Fixtures of the lab contract suite: the same lab in-process and on the wire
(see contract_support.py)."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from goniolab.lab_wiring import Lab
from tests.contract.contract_support import MODEL, lab_toml


@pytest.fixture(params=["inproc", "wire", "wire-rtu"])
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def make_lab(tmp_path: Path, backend: str) -> Callable[..., Lab]:
    def make(**kw: object) -> Lab:
        return Lab.from_config(lab_toml(tmp_path, backend, **kw), model=MODEL)  # type: ignore[arg-type]

    return make


@pytest.fixture
async def lab(make_lab: Callable[..., Lab]) -> AsyncIterator[Lab]:
    async with make_lab() as opened:
        yield opened
