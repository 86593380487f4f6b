"""Cost of the realistic twin: building the truth, its response tables, and a 71-point scan.

CPU seconds (user + sys) are reported beside wall seconds: on a shared, loaded machine the
wall clock mostly measures waiting for a core.

    .venv/bin/python bench/bench_twin.py [--sample sample:wittmann-3]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _scan(cfg: Path, store: Path, env: dict[str, str]) -> tuple[float, float]:
    """CPU and wall seconds of `goniolab scan --theta-r 0:70:1 --time-scale 0` in a child."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "goniolab.cli", "scan", "--config", str(cfg), "--time-scale", "0",
         "--theta-r", "0:70:1", "--store", str(store), "--json"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
    )  # fmt: skip
    _, status, usage = os.wait4(proc.pid, 0)
    if status != 0:
        raise SystemExit(f"scan failed with status {status}")
    return usage.ru_utime + usage.ru_stime, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sample", default="sample:wittmann-3")
    args = ap.parse_args()
    from goniolab.surfaces.resolve import resolve_map
    from sim.truth import TruthOptics, TwinSettings, build_truth

    hm = resolve_map(args.sample)
    c0, w0 = _cpu(), time.perf_counter()
    truth = build_truth(hm, settings=TwinSettings(), name=args.sample)
    c1, w1 = _cpu(), time.perf_counter()
    optics = TruthOptics(truth)
    tr = np.arange(0.0, 70.5, 1.0)
    optics.luminance_pct(45.0, tr)
    c2, w2 = _cpu(), time.perf_counter()
    optics.luminance_pct(45.0, tr)
    c3, w3 = _cpu(), time.perf_counter()
    print(f"truth tile {truth.z_um.shape}: {c1 - c0:.1f} s CPU ({w1 - w0:.1f} s wall)")
    print(
        f"71 readings at 45 deg, cold ({optics.ffts} tables): {c2 - c1:.1f} s CPU ({w2 - w1:.1f} s wall)"
    )
    print(f"71 readings at 45 deg, warm: {c3 - c2:.1f} s CPU ({w3 - w2:.1f} s wall)")
    with tempfile.TemporaryDirectory() as tmp:
        text = (REPO / "configs" / "lab-sim.toml").read_text()
        cfg = Path(tmp) / "lab.toml"
        cfg.write_text(text.replace('map = "sample:wittmann-3"', f'map = "{args.sample}"'))
        env = {**os.environ, "XDG_CACHE_HOME": str(Path(tmp) / "cache")}
        cold = _scan(cfg, Path(tmp) / "a.sqlite", env)
        warm = _scan(cfg, Path(tmp) / "b.sqlite", env)
    print(
        f"goniolab scan 0:70:1 --time-scale 0, empty twin cache: {cold[0]:.1f} s CPU ({cold[1]:.1f} s wall)"
    )
    print(
        f"goniolab scan 0:70:1 --time-scale 0, warm twin cache:  {warm[0]:.1f} s CPU ({warm[1]:.1f} s wall)"
    )


if __name__ == "__main__":
    main()
