"""The facet model's walks on several threads (issue 26): :mod:`goniolab.optics.facet_threads`.

The walks are cut into the same tasks whatever the number of threads and their results
combined in a fixed order, so a map's numbers must be the same bits on one thread and on
two. The truths: the order of a task list, a barrier that only two threads running at
once can pass, the facets' own cell indices counted by ``np.unique``, and the Smith Lambda
table's definition summed facet by facet.
"""

from __future__ import annotations

import math
import os
import threading
from collections import deque
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from goniolab.optics import facet_threads as FT
from goniolab.optics._kernels_numpy import deposit_numpy
from goniolab.optics.apertures import Cone
from goniolab.optics.facet import FacetModel
from goniolab.optics.facet_backends import LEAN_SLOPE_BIN, SLOPES, slope_cells_indexed
from goniolab.optics.facet_threads import limit_threads, run_tasks, walk_threads
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.slope_statistics import SlopeStatistics
from goniolab.optics.surface import Surface


@pytest.fixture
def two_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(FT.THREADS_ENV, "2")


def test_results_come_in_task_order_whichever_thread_ran_them(two_threads: None) -> None:
    names: list[str] = []

    def task(k: int) -> int:
        names.append(threading.current_thread().name)
        return k * k

    assert run_tasks([lambda k=k: task(k) for k in range(40)]) == [k * k for k in range(40)]
    assert len(names) == 40


def test_two_tasks_run_at_once_on_two_threads(two_threads: None) -> None:
    """Each task waits at a barrier for the other: only two threads at once pass it."""
    barrier = threading.Barrier(2, timeout=10.0)
    idents = run_tasks([lambda: (barrier.wait(), threading.get_ident())[1]] * 2)
    assert idents[0] != idents[1]


def test_a_cap_of_one_thread_runs_the_tasks_in_the_caller(two_threads: None) -> None:
    me = threading.get_ident()
    with limit_threads(1):
        assert walk_threads() == 1
        assert run_tasks([threading.get_ident] * 4) == [me] * 4


def test_nested_calls_finish(two_threads: None) -> None:
    def inner(k: int) -> int:
        return sum(run_tasks([lambda j=j: j * k for j in range(5)]))

    assert run_tasks([lambda k=k: inner(k) for k in range(6)]) == [10 * k for k in range(6)]


def test_the_first_failing_task_in_order_is_raised(two_threads: None) -> None:
    def fail(k: int) -> int:
        raise ValueError(f"task {k}")

    tasks: list[Callable[[], int]] = [lambda: 1, lambda: fail(1), lambda: fail(2)]
    with pytest.raises(ValueError, match="task 1"):
        run_tasks(tasks)
    assert run_tasks([lambda: 3]) == [3]  # the pool still works


def test_an_interrupt_after_taking_a_task_fails_that_task_instead_of_losing_it(
    two_threads: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C lands on the main thread wherever it is; while it waits for its own batch it
    runs other threads' tasks. Raised between taking such a task and counting it, the task
    was never counted and that batch's caller waited for ever. Now the task counts as
    failed with the interrupt: its caller gets it once the started tasks end."""
    batch = FT._Batch([lambda: 1, lambda: 2, lambda: 3], 2)
    with FT._work:
        FT._open.append(batch)
    real_run = FT._run

    def interrupted(b: FT._Batch, i: int) -> None:
        raise KeyboardInterrupt  # after _take, before the task ran or was counted

    monkeypatch.setattr(FT, "_run", interrupted)
    with pytest.raises(KeyboardInterrupt):
        FT._step(batch)
    monkeypatch.setattr(FT, "_run", real_run)
    # the task and those never to start are counted: nothing is left to wait for, and
    # the batch's error is the interrupt, which its caller raises
    with FT._work:
        assert batch.left == 0
        assert batch not in FT._open
    assert batch.error is not None and batch.error[0] == 0
    assert isinstance(batch.error[1], KeyboardInterrupt)
    assert FT._step(batch) == (False, None)
    assert run_tasks([lambda: 4, lambda: 5]) == [4, 5]  # the pool still works


def test_an_interrupt_inside_taking_the_last_task_leaves_it_to_its_owner(
    two_threads: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """CPython raises a pending Ctrl-C right after a C call returns, such as the removal
    of a batch whose last task is being taken from the open batches: raised there, after
    the task was counted taken but before the taker knew which, it was never run nor
    counted. The task is now counted taken after the removal: still untaken, its owner
    (which takes its own tasks without the open list) runs it."""

    class InterruptAfterRemove(deque[FT._Batch]):
        def remove(self, value: FT._Batch) -> None:
            super().remove(value)
            raise KeyboardInterrupt  # the signal check after the C call

    batch = FT._Batch([lambda: 1, lambda: 2], 2)
    with FT._work:
        FT._open.append(batch)
    assert FT._step(batch) == (True, None)
    real, patched = FT._open, InterruptAfterRemove(FT._open)
    monkeypatch.setattr(FT, "_open", patched)
    with pytest.raises(KeyboardInterrupt):
        FT._step(batch)
    monkeypatch.undo()
    real.clear()
    real.extend(patched)  # the open batches as the interrupt left them
    with FT._work:
        assert batch not in FT._open and batch.left == 1 and batch.error is None
    assert FT._step(batch) == (True, None)  # the owner's own loop takes it
    assert batch.left == 0 and batch.results == [1, 2]


def test_an_interrupt_just_after_a_call_opened_its_batch_cancels_the_batch(
    two_threads: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C right after a call put its batch among the open ones (``deque.append``, a C
    call) left the batch there, untaken: the helpers later ran all its tasks, before any
    newer call's. Now the interrupted call cancels its tasks not yet started."""

    class InterruptAfterAppend(deque[FT._Batch]):
        def append(self, value: FT._Batch) -> None:
            super().append(value)
            raise KeyboardInterrupt

    ran: list[int] = []
    real, patched = FT._open, InterruptAfterAppend(FT._open)
    monkeypatch.setattr(FT, "_open", patched)
    with pytest.raises(KeyboardInterrupt):
        run_tasks([lambda k=k: ran.append(k) for k in range(4)])
    monkeypatch.undo()
    real.clear()
    real.extend(patched)
    assert len(FT._open) == 0
    assert run_tasks([lambda: 7, lambda: 8]) == [7, 8]
    assert ran == []  # none of the abandoned tasks ran, then or later


_SWALLOWED = """
import os, signal, threading, time
os.environ["GONIOLAB_THREADS"] = "2"
from goniolab.optics import facet_threads as FT
own1_running, w0_taken, release = threading.Event(), threading.Event(), threading.Event()
other = {}
def worker():  # another thread's call (a TUI worker, a notebook's thread)
    def w0():
        w0_taken.set()
        release.wait(10.0)
    def w1():  # run by the main thread while it waits: Ctrl-C lands here
        threading.Timer(0.1, os.kill, (os.getpid(), signal.SIGINT)).start()
        time.sleep(3.0)
    try:
        other["result"] = FT.run_tasks([w0, w1])
    except BaseException as exc:
        other["error"] = type(exc).__name__
def own0():  # the main thread's first task: the helper holds own1, the worker waits on w0
    assert own1_running.wait(10.0)
    threading.Thread(target=worker).start()
    assert w0_taken.wait(10.0)
def own1():
    own1_running.set()
    time.sleep(3.0)
t0 = time.monotonic()
try:
    FT.run_tasks([own0, own1])
    print("returned", round(time.monotonic() - t0, 1))
except KeyboardInterrupt:
    print("KeyboardInterrupt", round(time.monotonic() - t0, 1))
release.set()
"""


def test_ctrl_c_in_another_calls_task_reaches_the_main_threads_call() -> None:
    """Waiting for its own tasks, the main thread runs other threads' tasks; a Ctrl-C (a
    real SIGINT) during one failed only that other call, and the main thread's call went
    on and returned as if nothing had happened. Now both raise it, the main thread's at
    once (not after its own 3 s task on the helper)."""
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", _SWALLOWED], capture_output=True, text=True, timeout=60,
        cwd=str(Path(__file__).resolve().parents[2]),
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    word, seconds = out.stdout.split()
    assert word == "KeyboardInterrupt", out.stdout
    assert float(seconds) < 2.0


def test_a_task_is_counted_once_whatever_calls_finish_again(two_threads: None) -> None:
    batch = FT._Batch([lambda: 1, lambda: 2], 2)
    with FT._work:
        FT._open.append(batch)
    assert FT._step(batch) == (True, None)
    FT._finish(batch, 0, None, KeyboardInterrupt())  # a handler's call after the count
    with FT._work:
        assert batch.left == 1 and batch.error is None and batch.results[0] == 1
    assert FT._step(batch) == (True, None)
    assert batch.left == 0 and batch.results == [1, 2]


def test_thread_count_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(FT.THREADS_ENV, "3")
    monkeypatch.setenv("OMP_NUM_THREADS", "5")
    assert walk_threads() == 3
    with limit_threads(2):
        assert walk_threads() == 2
    monkeypatch.delenv(FT.THREADS_ENV)
    assert walk_threads() == 5
    monkeypatch.delenv("OMP_NUM_THREADS")
    cpus = len(os.sched_getaffinity(0))
    monkeypatch.setattr(os, "getloadavg", lambda: (0.0, 0.0, 0.0))
    assert walk_threads() == cpus
    if cpus > 1:  # a busy machine: one thread, unless the environment asks for more
        monkeypatch.setattr(os, "getloadavg", lambda: (cpus - 0.5, 0.0, 0.0))
        assert walk_threads() == 1
        monkeypatch.setenv(FT.THREADS_ENV, str(cpus))
        assert walk_threads() == cpus
        monkeypatch.delenv(FT.THREADS_ENV)
    for bad in ("0", "-2", "two", "4,2"):
        monkeypatch.setenv(FT.THREADS_ENV, bad)
        with pytest.raises(ValueError, match=f"GONIOLAB_THREADS={bad!r}"):
            walk_threads()
    monkeypatch.delenv(FT.THREADS_ENV)
    # OpenMP's list of nested levels (OpenMP 5.2 sec. 21.1.2): the outermost level counts
    monkeypatch.setenv("OMP_NUM_THREADS", "3,2")
    assert walk_threads() == 3
    monkeypatch.setenv("OMP_NUM_THREADS", "0,2")
    with pytest.raises(ValueError, match="OMP_NUM_THREADS='0,2'"):
        walk_threads()


def _on_threads(n: int, fn: Callable[[], object], monkeypatch: pytest.MonkeyPatch) -> object:
    monkeypatch.setenv(FT.THREADS_ENV, str(n))
    return fn()


def _rough_map(n: int = 700) -> HeightMap:
    """A rough map (rms slope about 0.08): many slope cells, several walk spans and count
    chunks (the thresholds are lowered by the tests that need more)."""
    rng = np.random.default_rng(7)
    k = np.fft.fftfreq(n)
    filt = np.exp(-0.5 * (2.0 * math.pi * 2.0) ** 2 * (k[:, None] ** 2 + k[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * filt))
    z *= 0.08 / float(np.std(np.diff(z, axis=1)))
    z += 0.01 * np.arange(n)[None, :]  # a tilt, levelled away
    return HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source="rough")


def test_slope_cells_are_the_facets_unique_cells_on_one_and_two_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import goniolab.optics.facet_backends as FB

    monkeypatch.setattr(FB, "_ONE_PASS_COUNT", 1 << 16)  # several count chunks
    monkeypatch.setattr(FB, "_ONE_PASS_CHUNK", 1 << 12)
    hm = _rough_map()
    got = {
        n: _on_threads(n, lambda: slope_cells_indexed(Surface.from_heightmap(hm)), monkeypatch)
        for n in (1, 2)
    }
    (cp1, cq1, c1), idx1 = got[1]  # type: ignore[misc]
    (cp2, cq2, c2), idx2 = got[2]  # type: ignore[misc]
    for a, b in ((cp1, cp2), (cq1, cq2), (c1, c2), (idx1[0], idx2[0]), (idx1[1], idx2[1])):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    # the truth: each facet's cell floor(slope / bin + 1/2), counted by np.unique
    s = Surface.from_heightmap(hm)
    ip = np.floor(s.p / LEAN_SLOPE_BIN + 0.5).astype(np.int64)
    iq = np.floor(s.q / LEAN_SLOPE_BIN + 0.5).astype(np.int64)
    cells, counts = np.unique(np.stack([ip, iq], axis=1), axis=0, return_counts=True)
    np.testing.assert_array_equal(np.rint(cp2 / LEAN_SLOPE_BIN), cells[:, 0])
    np.testing.assert_array_equal(np.rint(cq2 / LEAN_SLOPE_BIN), cells[:, 1])
    np.testing.assert_array_equal(c2, counts)
    assert int(c2.sum()) == s.n_facets


def test_slope_cells_asked_by_two_threads_at_once_are_counted_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Two gloss geometries handed to the facet model run as tasks on two threads; both
    ask for the slope cells. Without a lock each counted them (double the walk's time,
    twice its memory); the second now waits for the first's cells, the same object."""
    import goniolab.optics.facet as F

    model = FacetModel(Surface.from_heightmap(_rough_map(200)), backend="lean")
    walking, release = threading.Event(), threading.Event()
    walks: list[int] = []
    real = F.slope_cells_indexed

    def slow_walk(surface: Surface) -> object:
        walks.append(threading.get_ident())
        walking.set()
        release.wait(10.0)
        return real(surface)

    monkeypatch.setattr(F, "slope_cells_indexed", slow_walk)
    got: list[object] = []
    first = threading.Thread(target=lambda: got.append(model._cells(True)))
    first.start()
    assert walking.wait(10.0)
    second = threading.Thread(target=lambda: got.append(model._cells(True)))
    second.start()
    second.join(0.3)  # it waits for the first walk (without the lock it walks too)
    release.set()
    first.join(10.0)
    second.join(10.0)
    assert len(walks) == 1
    assert len(got) == 2 and got[0] is got[1]


def test_lambda_table_on_two_threads_is_its_definition_and_the_same_bits(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import goniolab.optics.slope_statistics as S

    monkeypatch.setattr(S, "_LAMBDA_GROUPS", 4)
    monkeypatch.setattr(S, "_NODE_GROUPS", 4)
    monkeypatch.setattr(S, "_NODE_GROUP_MIN", 1 << 10)
    s = Surface.from_heightmap(_rough_map(300))
    tables = {
        n: _on_threads(n, lambda: SlopeStatistics(s)._lambda_table, monkeypatch) for n in (1, 2)
    }
    t1, t2 = tables[1], tables[2]
    assert isinstance(t1, np.ndarray) and isinstance(t2, np.ndarray)
    assert np.array_equal(t1, t2)
    # T(theta, phi) = mean(max(0, cos t - sin t (p cos ph + q sin ph))), facet by facet
    for th_deg, ph_deg in ((0.0, 0.0), (30.0, 45.0), (60.0, 200.0), (80.0, 315.0), (89.5, 90.0)):
        t, ph = math.radians(th_deg), math.radians(ph_deg)
        x = s.p * math.cos(ph) + s.q * math.sin(ph)
        truth = float(np.mean(np.maximum(0.0, math.cos(t) - math.sin(t) * x)))
        got = float(t1[round(th_deg / 0.5), round(ph_deg / 5.0)])
        assert got == pytest.approx(truth, rel=1e-6, abs=1e-9)


def test_deposit_is_the_same_bits_on_one_and_two_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import goniolab.optics._kernels_numpy as KN

    monkeypatch.setattr(KN, "_DEPOSIT_PART_MIN", 1 << 10)  # four parts
    monkeypatch.setattr(KN, "_DEPOSIT_PARTS", 4)
    s = Surface.from_heightmap(_rough_map(300))
    wi = np.array([math.sin(math.radians(45.0)), 0.0, math.cos(math.radians(45.0))])
    h = math.radians(0.05)
    args = (wi, 1.55, 0.0, False, math.radians(-7.0), h, 1700, -130 * h, h, 261, True)
    out = {
        n: _on_threads(n, lambda: deposit_numpy(s.p, s.q, SLOPES, *args), monkeypatch)
        for n in (1, 2)
    }
    (g1, gg1, w1), (g2, gg2, w2) = out[1], out[2]  # type: ignore[misc]
    assert np.array_equal(g1, g2) and np.array_equal(gg1, gg2) and w1 == w2
    # every landed weight is on the grid: the cloud-in-cell corners sum to the weights
    assert float(g1.sum()) == pytest.approx(w1, rel=1e-12)


def test_masked_curve_is_the_same_bits_on_one_and_two_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import goniolab.optics._kernels_numpy as KN
    import goniolab.optics.facet_backends as FB
    import goniolab.optics.slope_statistics as S

    for mod, name, value in ((S, "_LAMBDA_GROUPS", 4), (S, "_NODE_GROUPS", 4),
                             (S, "_NODE_GROUP_MIN", 1 << 10), (KN, "_DEPOSIT_PARTS", 4),
                             (KN, "_DEPOSIT_PART_MIN", 1 << 10), (FB, "_ONE_PASS_COUNT", 1 << 15)):  # fmt: skip
        monkeypatch.setattr(mod, name, value)  # every walk cut into several tasks
    hm = _rough_map(400)
    curves = {}
    for n in (1, 2):
        monkeypatch.setenv(FT.THREADS_ENV, str(n))
        model = FacetModel(Surface.from_heightmap(hm), masking=True, backend="lean")
        curves[n] = model.luminance_pct(45.0, np.arange(0.0, 71.0), source=Cone(6.0))
    assert np.array_equal(curves[1], curves[2])
    assert abs(int(np.argmax(curves[1])) - 45) <= 1  # the specular peak
