"""Opt-in pytest plugin: the CPU time each test costs, its child processes included.

Not active in ``make test``. Run it on a serial run (no ``-n``; under xdist each worker
would write its own share)::

    env -u PYTHONDONTWRITEBYTECODE PYTHONPATH=$PWD .venv/bin/python -m pytest tests -q \\
        -p no:cacheprovider -p tests._cpu_report

and it writes ``GONIOLAB_CPU_REPORT`` (default ``cpu_report.csv`` in the current
directory), one row per test, most expensive first: ``nodeid, cpu_s, self_s, children_s,
wall_s``. ``self_s`` is this process's ``time.process_time()`` over the test's setup, call
and teardown; ``children_s`` is the user+sys time of the child processes that ended
meanwhile (``resource.getrusage(RUSAGE_CHILDREN)``: ``goniolab`` subprocesses, servers,
kernels). A module- or session-scoped fixture's cost lands on the first test that uses it;
the fixtures' own setup costs go to ``<report>.fixtures.csv`` (name, scope, calls, total
and max CPU seconds, children included).
"""

from __future__ import annotations

import csv
import os
import resource
import time
from collections.abc import Generator
from pathlib import Path
from typing import Any

import pytest

_ROWS: dict[str, list[float]] = {}
_FIX: dict[tuple[str, str], list[float]] = {}


def _cpu() -> tuple[float, float]:
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time(), ch.ru_utime + ch.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None]:
    s0, c0 = _cpu()
    w0 = time.perf_counter()
    yield
    s1, c1 = _cpu()
    _ROWS[item.nodeid] = [s1 - s0 + c1 - c0, s1 - s0, c1 - c0, time.perf_counter() - w0]


@pytest.hookimpl(hookwrapper=True)
def pytest_fixture_setup(fixturedef: pytest.FixtureDef[Any], request: Any) -> Generator[None]:
    s0, c0 = _cpu()
    yield
    s1, c1 = _cpu()
    row = _FIX.setdefault((fixturedef.argname, fixturedef.scope), [0, 0.0, 0.0])
    cost = s1 - s0 + c1 - c0
    row[0] += 1
    row[1] += cost
    row[2] = max(row[2], cost)


def pytest_sessionfinish(session: pytest.Session) -> None:
    if hasattr(session.config, "workerinput"):
        return
    out = Path(os.environ.get("GONIOLAB_CPU_REPORT", "cpu_report.csv"))
    with out.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["nodeid", "cpu_s", "self_s", "children_s", "wall_s"])
        for nodeid, vals in sorted(_ROWS.items(), key=lambda kv: -kv[1][0]):
            w.writerow([nodeid, *(f"{v:.3f}" for v in vals)])
    with out.with_suffix(".fixtures.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["fixture", "scope", "calls", "total_cpu_s", "max_cpu_s"])
        for (name, scope), (n, tot, mx) in sorted(_FIX.items(), key=lambda kv: -kv[1][1]):
            w.writerow([name, scope, int(n), f"{tot:.3f}", f"{mx:.3f}"])
    total = sum(v[0] for v in _ROWS.values())
    print(f"\ncpu report: {len(_ROWS)} tests, {total:.1f} s CPU (children incl.) -> {out}")
