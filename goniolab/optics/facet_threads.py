"""The cores the facet model's walks may use, and the one way they share them.

numpy releases the GIL inside its array loops, so the lean facet model's walks over a map
(the slope cells, the Smith Lambda table, the nodes' Lambda, the deposit) run on several
threads of one process when they are cut into independent tasks. :func:`run_tasks` runs a
fixed list of tasks on up to :func:`walk_threads` threads, the caller's among them, and
returns their results in the order of the list. The callers cut the work into the same
tasks whatever the number of threads and combine the results in the list's order (or as
exact integer counts), so a map's numbers are the same bits on one thread or on many: the
threads change when a task runs, never what it computes.

How many threads: ``GONIOLAB_THREADS`` (a positive integer) when set, else
``OMP_NUM_THREADS`` when set (the usual cap of a batch or cluster job), else the CPUs this
process may run on (:func:`os.sched_getaffinity`), or one when the load average says the
others are busy (:func:`_spare`); :func:`limit_threads` caps the calling thread further
(``goniolab.batch`` runs each of its worker processes on one thread).
"""

from __future__ import annotations

import os
import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar

__all__ = ["THREADS_ENV", "limit_threads", "run_tasks", "thread_limit", "walk_threads"]

T = TypeVar("T")

#: Environment variable capping the threads of the facet model's walks.
THREADS_ENV = "GONIOLAB_THREADS"

_limits = threading.local()


@contextmanager
def limit_threads(n: int) -> Iterator[None]:
    """Within the block, this thread runs the facet kernels and walks on at most ``n``
    threads.

    A batch that spreads maps over worker processes (:mod:`goniolab.batch`) runs each map on
    one thread: the cores are busy with other maps.
    """
    if n < 1:
        raise ValueError(f"limit_threads needs n >= 1, got {n}")
    old = getattr(_limits, "n", None)
    _limits.n = n
    try:
        yield
    finally:
        _limits.n = old


def thread_limit() -> int | None:
    """The :func:`limit_threads` bound of this thread (None: no bound)."""
    n: int | None = getattr(_limits, "n", None)
    return n


def _env_threads(name: str) -> int | None:
    """The positive integer of environment variable ``name`` (None when unset or empty).
    ``OMP_NUM_THREADS`` may be OpenMP's list of nested levels (``4,2``, OpenMP 5.2 sec.
    21.1.2): its first entry, the outermost level, counts."""
    raw = os.environ.get(name, "").strip()
    if not raw:
        return None
    first = raw.split(",", 1)[0].strip() if name == "OMP_NUM_THREADS" else raw
    try:
        value = int(first)
    except ValueError:
        value = 0
    if value < 1:
        raise ValueError(f"{name}={raw!r}: the number of threads must be a positive integer")
    return value


def walk_threads() -> int:
    """Threads the facet model's walks may use in the calling thread: ``GONIOLAB_THREADS``,
    else ``OMP_NUM_THREADS``, else the CPUs of this process's affinity mask (one when the
    load average leaves less than half a CPU free), and at most the :func:`limit_threads`
    bound.

    Raises
    ------
    ValueError
        ``GONIOLAB_THREADS`` or ``OMP_NUM_THREADS`` is set but not a positive integer.
    """
    n = _env_threads(THREADS_ENV) or _env_threads("OMP_NUM_THREADS")
    if n is None:
        try:
            n = len(os.sched_getaffinity(0))
        except (AttributeError, OSError):  # not Linux
            n = os.cpu_count() or 1
        n = _spare(n)
    cap = thread_limit()
    return max(1, min(n, cap) if cap is not None else n)


def _spare(n: int) -> int:
    """``n``, or one thread when the machine's 1-minute load average leaves less than
    half a CPU of the ``n`` free: a second thread then waits for a core more than it
    works (on the 2-core machine at load 2, a rough 2048^2 ``predict brdf`` took 0.40 s
    on two threads, its one-thread base 0.32 s; bench/README.md, issue 26, roughwall). The
    numbers are the same either way; ``GONIOLAB_THREADS`` is taken as given."""
    if n <= 1:
        return 1
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):  # no load average here
        return n
    return n if load < n - 0.5 else 1


class _Batch:
    """One :func:`run_tasks` call: its tasks, handed out in order, and their results.

    ``finished[i]`` is set once task ``i`` is accounted for (run, failed, or never to be
    started), by one store: a task is never counted twice, and :func:`_finish` may be
    called again for it (by a thread's handler of an exception that came between taking
    a task and counting it, :func:`_step`) without harm."""

    __slots__ = ("error", "finished", "limit", "results", "taken", "tasks")

    def __init__(self, tasks: Sequence[Callable[[], Any]], limit: int) -> None:
        self.tasks = tasks
        #: the caller's thread bound, which its tasks keep on whichever thread they run
        self.limit = limit
        self.results: list[Any] = [None] * len(tasks)
        self.error: tuple[int, BaseException] | None = None
        self.taken = 0
        self.finished = [False] * len(tasks)

    @property
    def left(self) -> int:
        """Tasks not yet accounted for (read with the lock held)."""
        return self.finished.count(False)


_lock = threading.Lock()
_work = threading.Condition(_lock)
_open: deque[_Batch] = deque()  # batches with tasks not yet handed out
_helpers: list[threading.Thread] = []
#: a waiter looks again this often even without a notification, so that a notification
#: lost to an exception between counting a task and notifying cannot keep it waiting
_RECHECK_S = 0.25


def _reset_after_fork() -> None:
    """A forked child has none of the parent's helper threads (and maybe a held lock)."""
    global _lock, _work
    _lock = threading.Lock()
    _work = threading.Condition(_lock)
    _open.clear()
    _helpers.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_reset_after_fork)


def _take(batch: _Batch) -> int | None:
    """The next task of ``batch`` to run (call with the lock held); None: none left."""
    if batch.taken >= len(batch.tasks):
        return None
    i = batch.taken
    if i + 1 == len(batch.tasks) and batch in _open:
        # before counting it taken: CPython runs a pending signal's handler right after a
        # C call such as remove(); raised here, the task is still untaken, and its owner,
        # which takes its own tasks without _open, runs it (the other order lost it)
        _open.remove(batch)
    batch.taken = i + 1  # (no signal check between this store and _step's `i = ...`)
    return i


def _finish(batch: _Batch, i: int, result: Any, failed: BaseException | None) -> None:
    """Account for task ``i`` of ``batch`` (once: again is a no-op); a failure also
    accounts for the tasks not yet started, which never will be."""
    with _work:
        if batch.finished[i]:
            return
        if failed is None:
            batch.results[i] = result
        else:
            if batch.error is None or i < batch.error[0]:
                batch.error = (i, failed)
            _cancel(batch)
        batch.finished[i] = True  # the one store that counts it
        if not batch.left:
            _work.notify_all()  # its caller waits (perhaps among others)


def _cancel(batch: _Batch) -> None:
    """Account for the tasks of ``batch`` not yet started, which never will be (call with
    the lock held; again is a no-op)."""
    for j in range(batch.taken, len(batch.tasks)):
        batch.finished[j] = True
    batch.taken = len(batch.tasks)
    if batch in _open:
        _open.remove(batch)


def _run(batch: _Batch, i: int) -> BaseException | None:
    """Run task ``i`` of ``batch`` and account for it; its exception, if it raised one."""
    old = getattr(_limits, "n", None)
    _limits.n = batch.limit
    try:
        result = batch.tasks[i]()
        failed: BaseException | None = None
    except BaseException as exc:  # re-raised in the caller, after the started tasks end
        result, failed = None, exc
    finally:
        _limits.n = old
    _finish(batch, i, result, failed)
    return failed


def _step(batch: _Batch) -> tuple[bool, BaseException | None]:
    """Take the next task of ``batch`` and run it: whether there was one, and the
    exception it raised.

    An exception outside the task (a KeyboardInterrupt lands on the main thread wherever
    it is, here between taking the task and counting it) accounts for the task as failed
    with it before it propagates: otherwise a batch of another thread (whose tasks the
    main thread takes while it waits) would wait for that task for ever."""
    i: int | None = None
    try:
        with _work:
            i = _take(batch)
        if i is None:
            return False, None
        return True, _run(batch, i)
    except BaseException as exc:
        if i is not None:
            _finish(batch, i, None, exc)
        raise


def _helper() -> None:
    while True:
        with _work:
            while not _open:
                _work.wait()
            batch = _open[0]
        _step(batch)


def run_tasks(tasks: Sequence[Callable[[], T]]) -> list[T]:
    """The results of ``tasks`` (callables without arguments), in their order, computed on
    up to :func:`walk_threads` threads (the calling thread takes tasks too; a task may call
    :func:`run_tasks` again). The first failing task's exception (in the list's order) is
    raised once the tasks already started have ended; the tasks not yet started are not.

    A task must not wait for anything its caller holds (a lock, a ``cached_property``
    being computed by the caller): it may run on another thread while the caller waits.
    """
    n = min(walk_threads(), len(tasks))
    if n <= 1:
        return [task() for task in tasks]
    batch = _Batch(tasks, walk_threads())
    try:
        with _work:
            while len(_helpers) < n - 1:
                helper = threading.Thread(target=_helper, name="goniolab-walk", daemon=True)
                helper.start()
                _helpers.append(helper)
            _open.append(batch)
            _work.notify_all()
        while _step(batch)[0]:
            pass
        # the last tasks run elsewhere: meanwhile, this thread takes other calls' tasks (a
        # nested call's, or another thread's), so that no core idles while there is work
        while True:
            with _work:
                while batch.left and not _open:
                    _work.wait(_RECHECK_S)
                if not batch.left:
                    break
                other = _open[0]
            _, failed = _step(other)
            if isinstance(failed, KeyboardInterrupt | SystemExit):
                # Ctrl-C meant for this (main) thread landed in another call's task: that
                # call fails with it, and so does this one, now (not after its own tasks;
                # its own instance: the other call's thread raises the first)
                raise type(failed)(*failed.args)
    except BaseException:
        with _work:  # this call is left (an interrupt): its tasks not yet started never
            _cancel(batch)  # will be, and no helper is to take them later
        raise
    if batch.error is not None:
        raise batch.error[1]
    results: list[T] = batch.results
    return results
