"""``runs list`` on a big store: the one-query listing (counts from the indexes,
:meth:`RunStore.list_briefs`) against the per-run way it replaced (a record query, then a
count or a load of the gloss readings per run), in SQLite and in PostgreSQL, in process and
as whole ``goniolab runs list`` / ``open_runs(limit=20)`` processes (issue 26: 4.4 s / 3.8 s
on a PostgreSQL store of 520 runs, target <= 0.2 s).

    PYTHONPATH=$PWD python bench/bench_runs_list.py [RUNS] [POINTS_PER_RUN] [--backend sqlite|postgres|both] [--repeats 5] [--before DIR]

PostgreSQL: a throw-away server is started the way the tests start theirs
(``tests/pg_server.py``: initdb + pg_ctl on a temp dir, a free port, scram-sha-256; as root
the server runs as the ``postgres`` user); the backend is skipped, with the reason, when the
server binaries or psycopg are missing. Each figure is the median of ``--repeats`` runs
after one warm-up. Every run carries JSON columns of a real scan's size (the config snapshot
of configs/lab-sim.toml, a 71-angle plan, a 1 kB model): the listing decodes them. A fresh
PostgreSQL store is listed before and after ``VACUUM ANALYZE`` (autovacuum's work, within a
minute of the writes: the counts then come from index-only scans).

Whole processes run twice: with goniolab's bytecode cached (``PYTHONPYCACHEPREFIX`` in the
temp dir, written by the warm-up: what any installation where Python may write
``__pycache__`` sees from the second run on) and without (``PYTHONDONTWRITEBYTECODE=1``:
every goniolab module compiled at each start, as in a read-only checkout or this
sandbox's environment). Beside them the floors no listing can go under: ``python -c pass``
and ``python -c "import pandas"`` (``open_runs`` returns a DataFrame, so pandas is part of
its contract). The load average is printed before and after.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from goniolab.store import RunStore  # noqa: E402 -- after the sys.path line


def _records() -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """A run's JSON columns as a real scan stores them: the config snapshot of
    configs/lab-sim.toml (3.0 kB), a 71-angle plan (0.6 kB), a model of about 1 kB."""
    from goniolab.config import load_lab_config
    from goniolab.scan.plans import BrdfPlan
    from goniolab.session import config_snapshot

    config = config_snapshot(load_lab_config(ROOT / "configs" / "lab-sim.toml"))
    plan = BrdfPlan(45.0, tuple(float(t) for t in range(71)), repeats=3, sample="sample:x")
    model = {"model": "facet", "n": 1.55, "surface": {"sq_um": 0.12, "rms_slope": 0.05},
             "calibration": {"run": 7, "age_h": 3.5}, "notes": ["x" * 60] * 12}  # fmt: skip
    return plan.to_dict(), config, model


def build(location: str | Path, runs: int, points: int) -> None:
    plan, config, model = _records()
    with RunStore(location) as s:
        for r in range(runs):
            kind = "gloss" if r % 5 == 4 else "brdf"
            rid = s.create_run(kind=kind, plan=plan, config=config, sample=f"sample:{r}",
                               model=model, version="b")  # fmt: skip
            with s.db.transaction() as db:
                if kind == "brdf":
                    db.executemany(
                        "INSERT INTO points(run_id, idx, repeat, theta_i_deg, theta_r_deg,"
                        " measured_theta_i_deg, measured_theta_r_deg, luminance_pct, raw_json,"
                        " timestamp) VALUES (?,?,?,?,?,?,?,?,?,?)",
                        [(rid, i, 0, 45.0, 1.0, 45.0, 1.0, 1.0, '{"values": [1, 2, 3]}', 0.0)
                         for i in range(points)],
                    )  # fmt: skip
                else:
                    db.executemany(
                        "INSERT INTO gloss_readings(run_id, seq, g20_gu, g60_gu, g85_gu, raw,"
                        " timestamp) VALUES (?,?,?,?,?,?,?)",
                        [(rid, i, 1.0, 2.0, 3.0, "x", 0.0) for i in range(points // 10)],
                    )


def per_run(s: RunStore) -> int:
    n = 0
    for r in s.list_runs():
        n += s.count_points(r.id) if r.kind == "brdf" else len(s.gloss_readings(r.id))
    return n


def median_s(fn: Callable[[], object], repeats: int) -> float:
    fn()  # warm-up (connection, caches)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


_API = (
    "import sys; from goniolab.api import open_runs; print(len(open_runs(sys.argv[1], limit=20)))"
)
_CLI = "import sys; from goniolab.cli import main; sys.exit(main(sys.argv[1:]))"


def api_in_process(location: str) -> None:
    from goniolab.api import open_runs

    open_runs(location, limit=20)


def whole_process(
    argv: list[str], env: dict[str, str], repeats: int, cwd: Path
) -> tuple[float, float]:
    """Medians of the wall time and of the CPU time (user + system) of a whole process
    (python start-up and imports included), run in ``cwd`` (not the checkout: ``python -c``
    puts the working directory first on the path). On a loaded machine the wall time waits
    for a core; the CPU time does much less."""
    cpu: list[float] = []

    def run() -> None:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(argv, check=True, capture_output=True, env=env, cwd=cwd, timeout=300)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)

    wall = median_s(run, repeats)
    return wall, statistics.median(cpu[1:])  # not the warm-up's


@contextlib.contextmanager
def store(backend: str, tmp: Path) -> Iterator[tuple[str, dict[str, str]] | str]:
    """The store's location and the environment its clients need, or why not."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "GONIOLAB_LOG_DIR": str(tmp)}
    if backend == "sqlite":
        yield str(tmp / "big.sqlite"), env
        return
    from tests.pg_server import PLANTED_PASSWORD, find_pg_bin, pg_server

    bindir, why = find_pg_bin()
    if bindir is None:
        yield f"PostgreSQL skipped: {why}"
        return
    with pg_server(bindir) as srv:
        os.environ["PGPASSWORD"] = PLANTED_PASSWORD
        env["PGPASSWORD"] = PLANTED_PASSWORD
        yield srv.create_db("bench"), env


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="?", type=int, default=500)
    ap.add_argument("points", nargs="?", type=int, default=500)
    ap.add_argument("--backend", choices=("sqlite", "postgres", "both"), default="both")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument(
        "--before",
        metavar="DIR",
        help="also time the whole processes with the goniolab of DIR (a checkout of an older "
        "commit: git archive BASE goniolab | tar -x -C DIR)",
    )
    args = ap.parse_args(argv)
    backends = ("sqlite", "postgres") if args.backend == "both" else (args.backend,)
    for backend in backends:
        with tempfile.TemporaryDirectory() as tmp, store(backend, Path(tmp)) as where:
            if isinstance(where, str):
                print(where)
                continue
            location, env = where
            t0 = time.perf_counter()
            build(location, args.runs, args.points)
            print(
                f"{backend}: {args.runs} runs of {args.points} points (a gloss run in five: "
                f"{args.points // 10} readings) written in {time.perf_counter() - t0:.1f} s"
            )
            if backend == "postgres":  # fresh tables: no visibility map, no statistics yet
                with RunStore(location, readonly=True) as s:
                    dt = median_s(lambda: s.list_briefs(), args.repeats)
                    print(f"  {'one query, before VACUUM':32s} {dt * 1e3:8.1f} ms")
                    s.db.execute("VACUUM ANALYZE")  # what autovacuum does within a minute
                print("  VACUUM ANALYZE (a store at rest); from here on:")
            with RunStore(location, readonly=True) as s:
                total = sum(n or 0 for _, n in s.list_briefs())
                for name, fn in (
                    ("one query (list_briefs)", lambda: s.list_briefs()),
                    ("per run (before)", lambda: per_run(s)),
                ):
                    dt = median_s(fn, args.repeats)
                    print(f"  {name:32s} {total} readings: {dt * 1e3:8.1f} ms")
                dt = median_s(functools.partial(api_in_process, location), args.repeats)
                print(
                    f"  {'open_runs(limit=20) in process':32s} {dt * 1e3:8.1f} ms (pandas loaded)"
                )
            cli = [sys.executable, "-c", _CLI, "runs", "list", "--store", location]
            api = [sys.executable, "-c", _API, location]
            cached = {k: v for k, v in env.items() if k != "PYTHONDONTWRITEBYTECODE"}
            cached["PYTHONPYCACHEPREFIX"] = str(Path(tmp) / "pyc")
            uncached = {**env, "PYTHONDONTWRITEBYTECODE": "1"}
            for label, e in (("bytecode cached", cached), ("no bytecode cache", uncached)):
                print(f"  whole process, {label}, load {_load()}:")
                before = {**e, "PYTHONPATH": str(args.before)}
                for name, cmd, env_k in (
                    ("python -c pass (floor)", [sys.executable, "-c", "pass"], e),
                    ("goniolab runs list", cli, e),
                    ("goniolab runs list (--before)", cli, before),
                    (
                        'python -c "import pandas" (floor)',
                        [sys.executable, "-c", "import pandas"],
                        e,
                    ),
                    ("open_runs(limit=20)", api, e),
                    ("open_runs(limit=20) (--before)", api, before),
                ):
                    if env_k is before and not args.before:
                        continue
                    wall, cpu = whole_process(cmd, env_k, args.repeats, Path(tmp))
                    print(f"    {name:34s} {wall * 1e3:8.1f} ms wall {cpu * 1e3:8.1f} ms CPU")
            print(f"  load after: {_load()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
