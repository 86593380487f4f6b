"""What a one-shot ``predict`` process pays besides computing: fresh pages and its exit.

Run:  .venv/bin/python bench/bench_process.py [--repeats 8] [--before DIR] [--json]

Two measurements (issue 26, bench/README.md "A one-shot process"):

- ``pages``: 64 MB of anonymous memory touched once (a write per 4 kB page) after
  ``madvise(MADV_HUGEPAGE)`` (2 MB transparent huge pages) and after ``MADV_NOHUGEPAGE``
  (4 kB pages), each in a fresh mapping: wall ms and minor page faults, medians of
  ``--repeats``. What goniolab.process_heap's huge-page heap changes for the temporaries.
- ``exit``: on bench/bench_lean.py's rough 2048^2 map, ``predict brdf MAP --theta-i 45
  --theta-r 0:70:1`` as ``goniolab`` runs it (``console()``: the one-shot end) and as
  ``sys.exit(main())`` (the interpreter's own exit), and with ``--before DIR`` the same
  from another checkout: the time from the command's return (a timestamp written to
  stderr after ``main()``) to the parent's ``wait`` returning, medians of ``--repeats``
  fresh processes.
- ``collections``: the same command as ``goniolab`` runs it: the cyclic collections the
  whole process makes and their time (``gc.callbacks``), medians of ``--repeats``; with
  ``--before DIR`` also from that checkout.
"""

from __future__ import annotations

import argparse
import json
import mmap
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

_MB64 = 64 << 20


def touch_pages(huge: bool) -> tuple[float, int]:
    """(ms, minor faults) to touch a fresh 64 MB mapping once, page by page."""
    m = mmap.mmap(-1, _MB64, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    try:
        m.madvise(mmap.MADV_HUGEPAGE if huge else mmap.MADV_NOHUGEPAGE)
        view = memoryview(m)
        f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        t0 = time.perf_counter()
        for at in range(0, _MB64, 4096):
            view[at] = 1
        ms = 1e3 * (time.perf_counter() - t0)
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0
        view.release()
    finally:
        m.close()
    return ms, faults


#: The command in a fresh process: ``{run}`` is ``console()`` or ``sys.exit(main())``; the
#: timestamp is written when the command has returned (console() then ends the process).
_EXIT_CODE = """import sys, time
from goniolab import cli
sys.argv = ['goniolab', 'predict', 'brdf', {map!r}, '--theta-i', '45', '--theta-r', '0:70:1']
main = cli.main
def timed():
    code = main()
    sys.stderr.write('RETURNED %.6f\\n' % time.time())
    sys.stderr.flush()
    return code
cli.main = timed
{run}
"""


#: The command with every cyclic collection counted and timed (``{run}``: as above).
_GC_CODE = """import gc, sys, time
got = [0, 0.0, 0.0]
def watch(phase, info):
    if phase == 'start':
        got[2] = time.perf_counter()
    else:
        got[0] += 1
        got[1] += time.perf_counter() - got[2]
gc.callbacks.append(watch)
from goniolab import cli
sys.argv = ['goniolab', 'predict', 'brdf', {map!r}, '--theta-i', '45', '--theta-r', '0:70:1']
main = cli.main
def counted():
    code = main()
    sys.stderr.write('COLLECTIONS %d %.6f\\n' % (got[0], got[1]))
    sys.stderr.flush()
    return code
cli.main = counted
{run}
"""


def collections(code: str, env: dict[str, str]) -> tuple[int, float]:
    """(collections, their ms) of one process running ``code``."""
    proc = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        cwd=tempfile.gettempdir(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        check=True,
    )
    line = [ln for ln in proc.stderr.splitlines() if ln.startswith("COLLECTIONS ")][-1]
    n, secs = line.split()[1:]
    return int(n), 1e3 * float(secs)


def exit_ms(code: str, env: dict[str, str]) -> float:
    proc = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        cwd=tempfile.gettempdir(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        check=True,
    )
    end = time.time()
    stamp = [ln for ln in proc.stderr.splitlines() if ln.startswith("RETURNED ")]
    return 1e3 * (end - float(stamp[-1].split()[1]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=8)
    ap.add_argument("--before", help="another checkout (its goniolab on PYTHONPATH)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    out: dict[str, object] = {"load_before": os.getloadavg()[0]}
    pages: dict[str, dict[str, float]] = {}
    for name, huge in (("2 MB huge pages", True), ("4 kB pages", False)):
        runs = [touch_pages(huge) for _ in range(args.repeats)]
        pages[name] = {"ms": statistics.median(r[0] for r in runs),
                       "faults": statistics.median(r[1] for r in runs)}  # fmt: skip
    out["pages_64mb"] = pages
    from bench_lean import gaussian_map

    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    exits: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="goniolab-process-") as tmp:
        mp = Path(tmp) / "rough.npy"
        gaussian_map(mp, 2048, 2.5, 30.0, 1.0, seed=2)
        variants = {
            "console() (goniolab)": ("cli.console()", str(ROOT)),
            "sys.exit(main())": ("sys.exit(cli.main())", str(ROOT)),
        }
        if args.before:
            variants["sys.exit(main()), --before"] = ("sys.exit(cli.main())", args.before)
        codes = {k: (_EXIT_CODE.format(map=str(mp), run=run), {**env, "PYTHONPATH": path})
                 for k, (run, path) in variants.items()}  # fmt: skip
        for code, e in codes.values():
            exit_ms(code, e)  # untimed: bytecode written, page cache warm
        rows: dict[str, list[float]] = {k: [] for k in codes}
        for r in range(args.repeats):
            for k in list(codes) if r % 2 == 0 else list(codes)[::-1]:
                rows[k].append(exit_ms(*codes[k]))
        exits = {k: statistics.median(v) for k, v in rows.items()}
        gc_runs = {"console() (goniolab)": str(ROOT)}
        if args.before:
            gc_runs["sys.exit(main()), --before"] = args.before
        gcs: dict[str, tuple[float, float]] = {}
        for k, path in gc_runs.items():
            run = "cli.console()" if path == str(ROOT) else "sys.exit(cli.main())"
            code = _GC_CODE.format(map=str(mp), run=run)
            got = [collections(code, {**env, "PYTHONPATH": path}) for _ in range(args.repeats)]
            gcs[k] = (statistics.median(g[0] for g in got), statistics.median(g[1] for g in got))
    out["exit_ms"] = exits
    out["collections"] = {k: {"count": n, "ms": ms} for k, (n, ms) in gcs.items()}
    out["load_after"] = os.getloadavg()[0]
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"load average {out['load_before']:.1f} before / {out['load_after']:.1f} after, "
          f"medians of {args.repeats}")  # fmt: skip
    for name, r in pages.items():
        print(f"64 MB touched, {name:16} {r['ms']:7.1f} ms  {r['faults']:7.0f} faults")
    for name, ms in exits.items():
        print(f"exit of predict brdf (rough 2048^2), {name:28} {ms:6.1f} ms")
    for name, (n, ms) in gcs.items():
        print(f"cyclic collections of predict brdf, {name:29} {n:4.0f}, {ms:5.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
