"""One height spike on a 512 x 512 map through the lean facet backend (issue 23.5).

Run:  .venv/bin/python bench/bench_spike.py [--size 512] [--spikes 0,5,20] [--json]

Each map (Gaussian heights, Sq 50 nm, 1 um steps, one spike of the given height in um in
the middle) is written as ``.npy`` and ``goniolab predict gloss MAP --model facet --json``
runs as a whole process; reported: wall time, the child's peak RSS (``getrusage``) and the
dense histogram the lean backend used to allocate (``cells x 8`` bytes: the slope range in
1e-3 bins), against which the sparse one is bounded by the map.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _one(path: Path) -> dict[str, float]:
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "goniolab.cli", "predict", "gloss", str(path), "--model",
         "facet", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT,
    )  # fmt: skip
    assert proc.stdout is not None
    text = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)  # this child's own peak RSS
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{path.name}: exit {proc.returncode}")
    out = json.loads(text)
    return {"wall_s": wall, "peak_rss_mb": usage.ru_maxrss / 1024, "G60": out["G60"]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--spikes", default="0,5,20")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for spike in (float(s) for s in args.spikes.split(",")):
            rng = np.random.default_rng(1)
            z = rng.normal(0.0, 0.05, (args.size, args.size))
            z[args.size // 2, args.size // 2] += spike
            path = Path(d) / f"spike{spike:g}.npy"
            np.save(path, z)
            path.with_name(path.name + ".json").write_text('{"dx_um": 1.0, "dy_um": 1.0}')
            p = np.diff(z, axis=1)
            q = np.diff(z, axis=0)
            dense_gb = (np.ptp(p) / 1e-3 + 1) * (np.ptp(q) / 1e-3 + 1) * 8 / 1e9
            rows.append({"spike_um": spike, "dense_histogram_gb": dense_gb, **_one(path)})
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(f"{'spike':>6}  {'dense hist':>10}  {'wall':>7}  {'peak RSS':>9}  G60")
    for r in rows:
        print(f"{r['spike_um']:5g}um  {r['dense_histogram_gb']:8.2f}GB  {r['wall_s']:6.2f}s  "
              f"{r['peak_rss_mb']:7.0f}MB  {r['G60']:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
