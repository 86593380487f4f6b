"""The wave models' gloss on two threads (issue 26, the 16-wavelength gloss).

The ISO 2813 geometries of a gloss, the Kirchhoff readings beside the energy check, and the
energy checks' Horner sums, per-cell weights and Rayleigh-Rice terms run as tasks of
:func:`goniolab.optics.facet_threads.run_tasks`; every cell is formed by the same
operations whichever thread forms it and every sum is taken in one thread, so a gloss must
be the same bits on one thread and on two. The truths: the one-thread numbers themselves,
a barrier only two threads running at once can pass (so the two-thread run really ran two),
and the progress sums worked by hand.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable
from typing import Any

import pytest

from goniolab.optics import facet_threads as FT
from goniolab.optics.kirchhoff import KirchhoffModel
from goniolab.optics.rayleigh_rice import RayleighRiceModel
from goniolab.optics.wave_tasks import run_reporting
from tests.optics.conftest import gaussian_acf_map


def _meet_once(cls: type, name: str, barrier: threading.Barrier, mp: pytest.MonkeyPatch) -> None:
    """The first call of ``cls.name`` waits at ``barrier`` (then runs as before)."""
    original = getattr(cls, name)
    first = threading.Event()

    def wrapped(self: Any, *args: Any, **kwargs: Any) -> Any:
        if not first.is_set():
            first.set()
            barrier.wait()
        return original(self, *args, **kwargs)

    mp.setattr(cls, name, wrapped)


def _gloss_on(
    n_threads: int, make: Callable[[], Any], mp: pytest.MonkeyPatch
) -> tuple[dict[int, float], list[float]]:
    mp.setenv(FT.THREADS_ENV, str(n_threads))
    assert FT.walk_threads() == n_threads
    model = make()
    gloss = model.gloss((20, 60, 85))
    model._shared.cache.clear()
    scales = model._energy_scales(85.0, [0.4, 0.55, 0.7])
    return gloss, scales


@pytest.mark.parametrize("seed", [3, 5])
def test_kirchhoff_gloss_is_the_same_bits_on_one_thread_and_two(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A smooth coat on 4 tiles; the rough one (seed 5: Sq 0.12 um) plans several Taylor
    bands in the energy check (its per-band cell masks)."""
    sq = 0.05 if seed == 3 else 0.12
    hm = gaussian_acf_map(256, sq, 2.0, 0.5, seed)

    def make() -> KirchhoffModel:
        return KirchhoffModel(hm, tile=128, n=1.55)

    one = _gloss_on(1, make, monkeypatch)
    with monkeypatch.context() as mp:
        # the energy check (85 deg) and the 60 deg readings must run at the same time
        barrier = threading.Barrier(2, timeout=30.0)
        _meet_once(KirchhoffModel, "_energy_d1", barrier, mp)
        _meet_once(KirchhoffModel, "_raw_power", barrier, mp)
        two = _gloss_on(2, make, mp)
    assert two == one
    assert all(0.0 < s <= 1.0 for s in one[1])
    assert all(v > 0.0 for v in one[0].values())


def test_rayleigh_rice_gloss_is_the_same_bits_on_one_thread_and_two(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Rayleigh-Rice answers 85 deg (its energy check's terms in blocks of rows on two
    threads) and hands 20 and 60 deg to its Kirchhoff sibling (g > RR_VALID_G there)."""
    hm = gaussian_acf_map(256, 0.05, 2.0, 0.5, 3)

    def make() -> RayleighRiceModel:
        return RayleighRiceModel(hm, tile=128, n=1.55)

    one = _gloss_on(1, make, monkeypatch)
    assert {t: p.model for t, p in make().gloss_provenance().items()} == {
        20: "kirchhoff",
        60: "kirchhoff",
        85: "rayleigh-rice",
    }
    with monkeypatch.context() as mp:
        barrier = threading.Barrier(2, timeout=30.0)
        _meet_once(RayleighRiceModel, "_energy_scales_at", barrier, mp)
        _meet_once(KirchhoffModel, "_raw_power", barrier, mp)
        two = _gloss_on(2, make, mp)
    assert two == one


def test_progress_of_tasks_at_once_adds_up_and_closes_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Two tasks' reports on one thread (a fixed order), summed by hand: task 0 reports
    1/2 and 2/2, task 1 1/3 and 3/3. The sum stays below its total until both have ended;
    then one (5, 5)."""
    monkeypatch.setenv(FT.THREADS_ENV, "1")
    calls: list[tuple[int, int, str]] = []
    model = KirchhoffModel(
        gaussian_acf_map(64, 0.05, 2.0, 0.5, 1), progress=lambda *c: calls.append(c)
    )

    def task(what: str, steps: list[tuple[int, int]]) -> str:
        for done, total in steps:
            fn = model.progress
            assert fn is not None
            fn(done, total, what)
        return what

    out = run_reporting(
        [lambda: task("a", [(1, 2), (2, 2)]), lambda: task("b", [(1, 3), (3, 3)])],
        model.progress,
    )
    assert out == ["a", "b"]
    assert calls == [(1, 2, "a"), (1, 2, "a"), (3, 5, "b"), (4, 5, "b"), (5, 5, "b")]


def test_a_gloss_on_two_threads_reports_one_rising_bar(monkeypatch: pytest.MonkeyPatch) -> None:
    """The readings of 20/60/85 deg and the energy check report at once from two threads:
    one sequence, done and total never falling, done reaching the total only at the end
    (the terminal bar closes at done >= total)."""
    monkeypatch.setenv(FT.THREADS_ENV, "2")
    calls: list[tuple[int, int, str]] = []
    hm = gaussian_acf_map(256, 0.05, 2.0, 0.5, 3)
    model = KirchhoffModel(hm, tile=128, progress=lambda *c: calls.append(c))
    model.gloss((20, 60, 85))
    done = [d for d, _, _ in calls]
    totals = [t for _, t, _ in calls]
    assert len(calls) > 10
    assert done == sorted(done) and totals == sorted(totals)
    assert all(d < t for d, t, _ in calls[:-1])
    assert calls[-1][0] == calls[-1][1] == totals[-1]
    assert {w for *_, w in calls} == {"kirchhoff FFT", "kirchhoff energy check"}


@pytest.mark.parametrize(
    ("r0", "r1", "step", "parts"),
    [(0, 1024, 21, 4), (0, 1024, 16, 2), (5, 30, 16, 4), (0, 10, 16, 4)],
)
def test_row_parts_cover_the_rows_in_whole_blocks(r0: int, r1: int, step: int, parts: int) -> None:
    """The parts of a pass over blocks of ``step`` rows: consecutive, covering ``r0:r1``,
    each cut on a block boundary (so each block is the one pass's), at most ``parts``."""
    from goniolab.optics.wave_tasks import row_parts

    got = row_parts(r0, r1, step, parts)
    assert got[0][0] == r0 and got[-1][1] == r1
    assert all(a < b for a, b in got) and all(p[1] == q[0] for p, q in itertools.pairwise(got))
    assert all((a - r0) % step == 0 for a, _ in got)
    n_blocks = -(-(r1 - r0) // step)
    assert len(got) == min(parts, n_blocks)
