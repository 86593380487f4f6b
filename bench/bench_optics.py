"""Benchmark of the facet model: numba kernels vs their plain-numpy twins.

Run:  .venv/bin/python bench/bench_optics.py [--size 1024] [--repeats 7] [--json]

A ``size x size`` isotropic Gaussian height map (white noise convolved with a Gaussian
kernel of 1.5 px, rms slope 0.05, 1 um steps) is turned into a Surface (timed on its own),
then, per backend, each workload is run once as a warm-up (JIT compilation or cache load,
reported separately) and ``repeats`` times; the table shows the medians against the
targets:

- full-hemisphere BRDF, 0.5 deg bins, ti = 45 (target <= 20 ms)
- in-plane luminance curve, 71 points 0..70 deg, ti = 45, 6 deg cones (<= 50 ms; one
  cloud-in-cell deposit of the weights plus their first-order gradient channels)
- ISO 2813 gloss triplet 20/60/85 (<= 50 ms)

Columns: median wall time, best wall time, median process CPU time (all threads; on an
idle machine with the numba kernels split over k threads, wall ~ cpu / k).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from goniolab.optics.facet import FacetModel
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.surface import Surface

TARGETS_MS = {"hemisphere_0.5deg": 20.0, "luminance_71pt": 50.0, "gloss_triplet": 50.0}


def gaussian_map(n: int, slope_rms: float = 0.05, corr_px: float = 1.5, seed: int = 1) -> HeightMap:
    """Periodic Gaussian random surface with central-difference x-slope rms ``slope_rms``."""
    rng = np.random.default_rng(seed)
    k = np.fft.fftfreq(n)
    kernel_ft = np.exp(-0.5 * (2 * np.pi * corr_px) ** 2 * (k[:, None] ** 2 + k[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * kernel_ft))
    p = (z[:, 2:] - z[:, :-2]) / 2.0
    z *= slope_rms / float(np.sqrt(np.mean(p * p)))
    return HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source=f"bench-gaussian-{n}")


def timed(fn: Callable[[], object], repeats: int) -> tuple[float, float, list[float], float]:
    """(warm-up ms, median wall ms, all wall runs ms, median process-CPU ms).

    The CPU time (all threads of this process) is less sensitive than the wall time to
    other processes competing for the cores.
    """
    t0 = time.perf_counter()
    fn()
    warm = (time.perf_counter() - t0) * 1e3
    runs = []
    cpu = []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        runs.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    return warm, statistics.median(runs), runs, statistics.median(cpu)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--size", type=int, default=1024, help="map size in pixels (default 1024)")
    ap.add_argument("--repeats", type=int, default=7, help="timed runs per workload (>= 7)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = ap.parse_args(argv)
    if args.repeats < 7:
        ap.error("--repeats must be >= 7")

    hm = gaussian_map(args.size)
    surf_runs = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        surface = Surface.from_heightmap(hm)
        _ = surface.normals
        surf_runs.append((time.perf_counter() - t0) * 1e3)
    theta_r = np.arange(0.0, 71.0, 1.0)
    results: dict[str, object] = {
        "facets": surface.n_facets,
        "map": f"{args.size}x{args.size}",
        "cpus": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "repeats": args.repeats,
        "surface_construction_ms": statistics.median(surf_runs),
        "targets_ms": TARGETS_MS,
        "backends": {},
    }
    backends: dict[str, object] = {}
    for backend in ("numba", "numpy"):
        model = FacetModel(surface, n=1.55, backend=backend)
        work: dict[str, Callable[[], object]] = {
            "hemisphere_0.5deg": partial(model.brdf_hemisphere, 45.0, bin_deg=0.5),
            "luminance_71pt": partial(model.luminance_pct, 45.0, theta_r),
            "gloss_triplet": partial(model.gloss, (20, 60, 85)),
        }
        rows = {}
        for name, fn in work.items():
            warm, med, runs, cpu = timed(fn, args.repeats)
            rows[name] = {"warmup_ms": warm, "median_ms": med, "runs_ms": runs, "cpu_ms": cpu}
        backends[backend] = rows
    results["backends"] = backends

    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(
        f"facet model benchmark: {results['map']} map, {surface.n_facets} facets, "
        f"{os.cpu_count()} CPUs, median of {args.repeats}, "
        f"load average {os.getloadavg()[0]:.1f} (timings scale with other load)"
    )
    print(
        f"Surface.from_heightmap (level + slopes + normals): {results['surface_construction_ms']:.1f} ms"
    )
    print(
        f"{'workload':<20}{'target':>9}{'numba':>10}{'(min)':>9}{'(cpu)':>9}{'numpy':>10}"
        f"{'(min)':>9}{'speed-up':>10}{'JIT warm-up':>13}"
    )
    for name, target in TARGETS_MS.items():
        nb = backends["numba"][name]  # type: ignore[index]
        npy = backends["numpy"][name]  # type: ignore[index]
        ok = "ok" if nb["median_ms"] <= target else "SLOW"
        print(
            f"{name:<20}{target:>7.0f}ms{nb['median_ms']:>8.1f}ms{min(nb['runs_ms']):>7.1f}ms"
            f"{nb['cpu_ms']:>7.1f}ms{npy['median_ms']:>8.1f}ms{min(npy['runs_ms']):>7.1f}ms"
            f"{npy['median_ms'] / nb['median_ms']:>9.1f}x{nb['warmup_ms']:>11.0f}ms  {ok}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
