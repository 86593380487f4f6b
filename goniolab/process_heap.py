"""glibc's heap for a one-shot ``predict`` process: freed blocks kept, huge pages, one arena.

A ``goniolab predict`` process reads a map, forms a few dozen temporaries of 0.1-4 MB
(a rough 2048^2 map's 394,000 slope cells: 3 MB an array) and ends. With glibc's defaults
each of them costs fresh pages: blocks above 128 kB come from ``mmap`` and go back on
``free``, and the heap's top is given back once 128 kB are free there. Every first touch
of a 4 kB page is a page fault, and in a virtual machine a costly one (on the 2-core bench
machine 64 MB touched in 4 kB pages took 22.4 ms, in 2 MB transparent huge pages 3.1 ms:
``bench/bench_process.py``). :func:`tune_predict_heap` therefore

- keeps freed blocks below 64 MB for reuse (``M_MMAP_THRESHOLD``, ``M_TRIM_THRESHOLD``):
  a walk that frees its temporaries between blocks reuses their pages;
- grows the heap once by :data:`HEAP_RESERVE` bytes of address space (``M_TOP_PAD``, no
  memory touched) and marks that range for transparent huge pages (``madvise(...,
  MADV_HUGEPAGE)``, Linux's "madvise" THP mode): the temporaries below numpy's own 4 MB
  huge-page threshold then fault in 2 MB at a time;
- serves every thread from that heap (``M_ARENA_MAX`` = 1): a worker thread's arena
  would be a separate mapping in 4 kB pages. The threads allocate under Python's lock
  anyway, so one arena costs them no waiting.

On the rough 2048^2 ``predict brdf`` of ``bench/bench_lean.py`` (its ``faults`` column) the
whole process's page faults fell from 16,555 to 4,276 with this and the collector settings
of :mod:`goniolab.cli` (bench/README.md, issue 26, "A one-shot process"). A setting given
in the environment (``MALLOC_TRIM_THRESHOLD_``, ``MALLOC_MMAP_THRESHOLD_``,
``MALLOC_TOP_PAD_``, ``MALLOC_ARENA_MAX``, or the same ``glibc.malloc.*`` tunables in
``GLIBC_TUNABLES``, which glibc reads itself) wins over the one here (a trim threshold of
the user's also leaves the heap's reserve out); other C libraries than glibc, other
systems, and a kernel without transparent huge pages are left as they are.

Only for a process of its own (the CLI calls it before any work): a long-lived process (the
TUI, a notebook) keeps glibc's defaults.

References
----------
.. [1] mallopt(3), Linux man-pages (M_ARENA_MAX, M_MMAP_THRESHOLD, M_TOP_PAD,
   M_TRIM_THRESHOLD; the ``MALLOC_*_`` environment variables).
.. [2] madvise(2) (MADV_HUGEPAGE) and the kernel's admin guide, "Transparent Hugepage
   Support" (``/sys/kernel/mm/transparent_hugepage/enabled``).
"""

from __future__ import annotations

import ctypes
import os
import sys
from typing import Any

__all__ = ["HEAP_RESERVE", "thp_mode", "tune_predict_heap"]

#: mallopt parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_THRESHOLD = -3
M_ARENA_MAX = -8
#: madvise advice (Linux's mman.h).
MADV_HUGEPAGE = 14
#: glibc's default top pad (mallopt(3)), restored once the heap has grown.
_DEFAULT_TOP_PAD = 128 * 1024
#: Address space the heap grows by once, marked for huge pages (a rough 2048^2 ``predict
#: brdf`` used 92 MB of heap; a larger map's arrays exceed 64 MB and are mapped by numpy,
#: which marks those itself).
HEAP_RESERVE = 128 << 20
_HUGE_PAGE = 2 << 20
#: (mallopt parameter, the environment variable and the glibc tunable that override it,
#: value).
_KEEP_FREED = (
    (M_TRIM_THRESHOLD, "MALLOC_TRIM_THRESHOLD_", "glibc.malloc.trim_threshold", 256 << 20),
    (M_MMAP_THRESHOLD, "MALLOC_MMAP_THRESHOLD_", "glibc.malloc.mmap_threshold", 64 << 20),
    (M_ARENA_MAX, "MALLOC_ARENA_MAX", "glibc.malloc.arena_max", 1),
)
_THP_ENABLED = "/sys/kernel/mm/transparent_hugepage/enabled"


def thp_mode(path: str = _THP_ENABLED) -> str | None:
    """The kernel's transparent huge page mode (``always``, ``madvise`` or ``never``, the
    bracketed word of ``path``), or None when the kernel has none."""
    try:
        with open(path, encoding="ascii") as f:
            text = f.read()
    except OSError:
        return None
    start, end = text.find("["), text.find("]")
    return text[start + 1 : end] if 0 <= start < end else None


def tune_predict_heap() -> dict[str, Any]:
    """Set glibc's heap up for a one-shot ``predict`` process (see the module's text).

    Returns what was done, for a test or a benchmark to read: ``{"mallopt": [names],
    "huge_pages": (start, end) or None, "why_not": reason or None}``.
    """
    done: dict[str, Any] = {"mallopt": [], "huge_pages": None, "why_not": None}
    if not sys.platform.startswith("linux"):
        done["why_not"] = "not Linux"
        return done
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # no mallopt in this C library
        done["why_not"] = "no mallopt (not glibc)"
        return done
    for param, env, tunable, value in _KEEP_FREED:
        if not _user_set(env, tunable) and mallopt(param, value) == 1:
            done["mallopt"].append(env)
    if _user_set("MALLOC_TOP_PAD_", "glibc.malloc.top_pad"):
        done["why_not"] = "MALLOC_TOP_PAD_ set"
    elif _user_set("MALLOC_TRIM_THRESHOLD_", "glibc.malloc.trim_threshold"):
        # a threshold of the user's below the reserve would give it back at the next free
        done["why_not"] = "MALLOC_TRIM_THRESHOLD_ set"
    elif thp_mode() not in ("always", "madvise"):
        done["why_not"] = "no transparent huge pages"
    else:
        done["huge_pages"], done["why_not"] = _reserve_huge_heap(libc, mallopt)
    return done


def _user_set(env: str, tunable: str) -> bool:
    """Whether the user chose this malloc setting: its ``MALLOC_*_`` variable, or its
    tunable in ``GLIBC_TUNABLES`` (``glibc.malloc.arena_max=4:...``)."""
    if env in os.environ:
        return True
    tunables = os.environ.get("GLIBC_TUNABLES", "")
    return any(item.split("=", 1)[0] == tunable for item in tunables.split(":"))


class _MallInfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2`` (glibc 2.33): every field a ``size_t``."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena", "ordblks", "smblks", "hblks", "hblkhd",
            "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost",
        )
    ]  # fmt: skip


def _reserve_huge_heap(libc: Any, mallopt: Any) -> tuple[tuple[int, int] | None, str | None]:
    """Grow the heap once by :data:`HEAP_RESERVE` and mark it for huge pages: the range
    marked, or None and why not."""
    try:
        sbrk, malloc, free, madvise = libc.sbrk, libc.malloc, libc.free, libc.madvise
        mallinfo2 = libc.mallinfo2
    except AttributeError:
        return None, "no sbrk, madvise or mallinfo2 (glibc before 2.33)"
    sbrk.restype, sbrk.argtypes = ctypes.c_void_p, [ctypes.c_ssize_t]
    malloc.restype, malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    free.argtypes = [ctypes.c_void_p]
    madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    mallinfo2.restype = _MallInfo2
    top_free = int(mallinfo2().keepcost)  # what the heap's top chunk holds now
    if top_free > HEAP_RESERVE // 4:
        return None, "the heap's top already holds free memory"
    start = sbrk(0)
    if mallopt(M_TOP_PAD, HEAP_RESERVE) != 1:
        return None, "mallopt(M_TOP_PAD) refused"
    try:
        # a block just larger than the top chunk: the heap grows by it plus the pad
        block = malloc(top_free + 64 * 1024)
        free(block)
    finally:
        mallopt(M_TOP_PAD, _DEFAULT_TOP_PAD)
    end = sbrk(0)
    if start is None or end is None or start == ctypes.c_void_p(-1).value:
        return None, "sbrk failed"
    lo = -(-start // _HUGE_PAGE) * _HUGE_PAGE
    if end - lo < _HUGE_PAGE:
        return None, "the heap did not grow (its memory came from mmap)"
    if madvise(lo, end - lo, MADV_HUGEPAGE) != 0:
        return None, f"madvise failed (errno {ctypes.get_errno()})"
    return (lo, end), None
