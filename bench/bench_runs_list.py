"""``runs list`` on a big store: the one-query listing (counts from the indexes,
:meth:`RunStore.list_briefs`) against the per-run way it replaced (a record query, then a
count or a load of the gloss readings per run).

    PYTHONPATH=$PWD python bench/bench_runs_list.py [RUNS] [POINTS_PER_RUN]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from goniolab.store import RunStore


def build(path: Path, runs: int, points: int) -> None:
    with RunStore(path) as s:
        for r in range(runs):
            kind = "gloss" if r % 5 == 4 else "brdf"
            rid = s.create_run(kind=kind, plan={}, config={"lab": {"name": "b"}},
                               sample=f"sample:{r}", model={}, version="b")  # fmt: skip
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


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 500
    points = int(sys.argv[2]) if len(sys.argv) > 2 else 500
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "big.sqlite"
        build(path, runs, points)
        with RunStore(path, readonly=True) as s:
            for name, fn in (
                ("one query", lambda: sum(n or 0 for _, n in s.list_briefs())),
                ("per run (before)", lambda: per_run(s)),
            ):
                fn()
                t0 = time.perf_counter()
                total = fn()
                dt = time.perf_counter() - t0
                print(f"{name:18s} {runs} runs, {total} readings: {dt * 1e3:8.1f} ms")


if __name__ == "__main__":
    main()
