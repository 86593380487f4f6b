"""A ``predict`` process's heap (goniolab.process_heap): what the kernel reports of it.

Each check runs in a fresh interpreter (the settings are per process) and reads the
kernel's own account, ``/proc/self/smaps`` (the ``hg`` flag of a mapping marked with
``MADV_HUGEPAGE``, proc(5)) and ``/proc/self/maps`` (where a block lies), not goniolab's.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from goniolab.process_heap import HEAP_RESERVE, thp_mode

ROOT = Path(__file__).resolve().parents[1]

#: The [heap] mappings of this process: (start, end, huge-page advised), as JSON.
_HEAP_MAPS = """
import json, re
def heap_maps():
    out, cur = [], None
    for line in open('/proc/self/smaps'):
        m = re.match(r'([0-9a-f]+)-([0-9a-f]+) \\S+ \\S+ \\S+ \\S+\\s*(.*)', line)
        if m:
            cur = (int(m.group(1), 16), int(m.group(2), 16), m.group(3).strip())
        elif line.startswith('VmFlags') and cur[2] == '[heap]':
            out.append((cur[0], cur[1], 'hg' in line.split()[1:]))
    return out
"""

linux_thp = pytest.mark.skipif(
    not sys.platform.startswith("linux") or thp_mode() not in ("always", "madvise"),
    reason="needs Linux with transparent huge pages (always or madvise)",
)


def probe(code: str, env: dict[str, str] | None = None) -> dict[str, object]:
    """Run ``code`` (which prints one JSON line last) in a fresh interpreter."""
    clean = {
        k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"
    }
    out = subprocess.run(
        [sys.executable, "-c", _HEAP_MAPS + code],
        cwd=ROOT,
        env={**clean, **(env or {})},
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    result: dict[str, object] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def test_thp_mode_is_the_bracketed_word(tmp_path: Path) -> None:
    f = tmp_path / "enabled"
    f.write_text("always [madvise] never\n")
    assert thp_mode(str(f)) == "madvise"
    f.write_text("[always] madvise never\n")
    assert thp_mode(str(f)) == "always"
    assert thp_mode(str(tmp_path / "missing")) is None


@linux_thp
def test_the_heap_grows_once_into_a_range_marked_for_huge_pages() -> None:
    got = probe(
        "from goniolab.process_heap import tune_predict_heap\n"
        "before = heap_maps()\n"
        "done = tune_predict_heap()\n"
        "print(json.dumps({'before': before, 'after': heap_maps(), 'done': done}))\n"
    )
    assert not any(hg for _, _, hg in got["before"])  # type: ignore[union-attr]
    marked = [(lo, hi) for lo, hi, hg in got["after"] if hg]  # type: ignore[union-attr]
    assert len(marked) == 1
    lo, hi = marked[0]
    assert lo % (2 << 20) == 0  # starts on a huge page
    assert HEAP_RESERVE - (2 << 20) <= hi - lo <= HEAP_RESERVE + (4 << 20)
    assert got["done"]["huge_pages"] == [lo, hi]  # type: ignore[index]


@linux_thp
def test_the_environment_wins_over_the_heap_settings() -> None:
    got = probe(
        "from goniolab.process_heap import tune_predict_heap\n"
        "done = tune_predict_heap()\n"
        "print(json.dumps({'after': heap_maps(), 'done': done}))\n",
        env={"MALLOC_TOP_PAD_": "131072", "MALLOC_ARENA_MAX": "2"},
    )
    assert not any(hg for _, _, hg in got["after"])  # type: ignore[union-attr]
    done = got["done"]
    assert done["why_not"] == "MALLOC_TOP_PAD_ set"  # type: ignore[index]
    assert "MALLOC_ARENA_MAX" not in done["mallopt"]  # type: ignore[index]


@linux_thp
def test_a_users_trim_threshold_or_tunables_win_over_the_heap_settings() -> None:
    code = (
        "from goniolab.process_heap import tune_predict_heap\n"
        "done = tune_predict_heap()\n"
        "print(json.dumps({'after': heap_maps(), 'done': done}))\n"
    )
    # a trim threshold under the reserve would hand the reserve back at the next free
    got = probe(code, env={"MALLOC_TRIM_THRESHOLD_": "131072"})
    assert not any(hg for _, _, hg in got["after"])  # type: ignore[union-attr]
    assert got["done"]["why_not"] == "MALLOC_TRIM_THRESHOLD_ set"  # type: ignore[index]
    got = probe(code, env={"GLIBC_TUNABLES": "glibc.malloc.arena_max=4:glibc.malloc.top_pad=0"})
    assert "MALLOC_ARENA_MAX" not in got["done"]["mallopt"]  # type: ignore[index]
    assert "MALLOC_MMAP_THRESHOLD_" in got["done"]["mallopt"]  # type: ignore[index]
    assert got["done"]["why_not"] == "MALLOC_TOP_PAD_ set"  # type: ignore[index]


#: A worker thread's 64 kB block (under glibc's default mmap threshold): in [heap] or not.
_THREAD_BLOCK = """
import ctypes, threading
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
where = []
threading.Thread(target=lambda: where.append(libc.malloc(64 * 1024))).start()
import time
while not where:
    time.sleep(0.01)
addr = where[0]
print(json.dumps({'in_heap': any(lo <= addr < hi for lo, hi, _ in heap_maps())}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's arenas: Linux")
def test_worker_threads_allocate_from_the_one_heap() -> None:
    # glibc's default: a thread's first block comes from an arena of its own, outside [heap]
    assert probe(_THREAD_BLOCK)["in_heap"] is False
    tuned = "from goniolab.process_heap import tune_predict_heap\ntune_predict_heap()\n"
    assert probe(tuned + _THREAD_BLOCK)["in_heap"] is True


@linux_thp
def test_only_a_predict_process_of_its_own_tunes_its_heap() -> None:
    run_cli = (
        "import contextlib, io, sys\n"
        "from goniolab.cli import main\n"
        "sys.argv = ['goniolab', *{argv!r}]\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    main({arg})\n"
        "print(json.dumps({{'marked': any(hg for _, _, hg in heap_maps())}}))\n"
    )
    stats = ["predict", "stats", "sample:wittmann-3", "--json"]
    assert probe(run_cli.format(argv=stats, arg=""))["marked"] is True
    # main(argv): called by a host process (a test, a notebook): its heap is left alone
    assert probe(run_cli.format(argv=stats, arg=repr(stats)))["marked"] is False
    assert probe(run_cli.format(argv=["samples"], arg=""))["marked"] is False


#: The CLI run as the console script runs it (``main()`` reading ``sys.argv``), with
#: ``predict stats`` replaced by a command that leaves an object with a finalizer in a
#: reference cycle: only the cyclic collector at exit can finalize it (the finalizer writes
#: by ``os`` calls bound beforehand, as module globals are gone by then).
_LEAKY_COMMAND = """
import gc, os, sys
import goniolab.commands.predict as predict
class Leaky:
    def __del__(self, _open=os.open, _write=os.write, _close=os.close,
                _flags=os.O_WRONLY | os.O_CREAT, _path={path!r}):
        fd = _open(_path, _flags, 0o644)
        _write(fd, b'finalized at exit')
        _close(fd)
def leaky(args):
    x = Leaky()
    x.cycle = x
    return 0
predict._cmd_stats = leaky
from goniolab.cli import main
sys.argv = ['goniolab', 'predict', 'stats', 'sample:wittmann-3']
code = main({arg})
print(json.dumps({{'frozen': gc.get_freeze_count()}}))
{at_exit}
sys.exit(code)
"""


def test_a_predict_process_freezes_its_imports_and_still_collects_the_commands_cycles(
    tmp_path: Path,
) -> None:
    out = tmp_path / "finalized.txt"

    def run(arg: str, at_exit: str = "") -> dict[str, object]:
        if out.exists():
            out.unlink()
        return probe(_LEAKY_COMMAND.format(path=str(out), arg=arg, at_exit=at_exit))

    assert int(run("")["frozen"]) > 10_000  # type: ignore[call-overload]  # numpy's among them
    # the command's own cycle was not frozen: collected at exit, its finalizer run
    assert out.read_text() == "finalized at exit"
    # (what a freeze of everything at exit would lose: the finalizer never runs)
    run("", at_exit="gc.freeze()")
    assert not out.exists()
    # a host process (main(argv)) keeps its collector as it was
    assert run(repr(["predict", "stats", "sample:wittmann-3"]))["frozen"] == 0
    assert out.read_text() == "finalized at exit"


#: Collections counted while nothing is frozen yet, from the CLI's start on.
_COLLECTIONS = """
import gc, sys
from goniolab.cli import main
early = []
gc.callbacks.append(lambda phase, info: early.append(1)
                    if phase == 'start' and not gc.get_freeze_count() else None)
sys.argv = ['goniolab', 'predict', 'stats', 'sample:wittmann-3', '--json']
import contextlib, io
with contextlib.redirect_stdout(io.StringIO()):
    main({arg})
print(json.dumps({{'early': len(early), 'enabled': gc.isenabled()}}))
"""


def test_a_predict_process_collects_nothing_while_it_imports() -> None:
    one_shot = probe(_COLLECTIONS.format(arg=""))
    assert one_shot == {"early": 0, "enabled": True}
    host = probe(_COLLECTIONS.format(arg=repr(["predict", "stats", "sample:wittmann-3"])))
    assert int(host["early"]) > 10  # type: ignore[call-overload]  # numpy's import collects
    assert host["enabled"] is True


def test_a_predict_that_ends_before_its_imports_leaves_the_collector_running() -> None:
    got = probe(
        "import gc, sys\n"
        "from goniolab.cli import main\n"
        "sys.argv = ['goniolab', 'predict', 'brdf', 'sample:wittmann-3', '--no-such-option']\n"
        "code = main()\n"
        "print(json.dumps({'code': code, 'enabled': gc.isenabled()}))\n"
    )
    assert got == {"code": 2, "enabled": True}
