"""Benchmark of the physical-optics models (Kirchhoff, Rayleigh-Rice): numba vs numpy sums.

Run:  .venv/bin/python bench/bench_physical.py [--size 1024] [--repeats 7] [--json]
      [--backend numba|numpy|both] [--checkout DIR]

``--checkout DIR`` imports goniolab from another checkout (e.g. ``git archive BASE goniolab
| tar -x -C DIR``) instead of this one: run it beside a run without, at the same load, for
a paired A/B of a change (issue 26: the 16-wavelength gloss).

A ``size x size`` smooth Gaussian map (Gaussian ACF, Sq 50 nm, correlation length 2 um,
0.5 um steps: a high-gloss coat) is tiled once; each workload then runs with the model's
cell-power cache cleared before every repetition (so each run transforms the map again),
one warm-up (JIT compilation or cache load, colour-science import) and ``repeats`` timed
runs; medians against the issue-15 targets:

- Kirchhoff in-plane luminance curve, 71 points 0..70 deg at ti = 45, 6 deg cones, one
  wavelength (target <= 200 ms);
- Kirchhoff ISO 2813 gloss triplet weighted over 16 wavelengths, C x V(lambda) (<= 1 s);
- the same two for Rayleigh-Rice (one PSD, shared by every geometry and wavelength);
- without a target (issue 20): Kirchhoff gloss of a 50 um field (256 x 256, the ISO
  receptors zero-padded to 6 cells across), the Kirchhoff albedo at 85 deg over the
  whole Nyquist window of the 1024^2 map, and a Kirchhoff curve at 80 deg, where the
  source cone is summed over 169 sub-cones.

Threads: a gloss's geometries, Kirchhoff's readings beside its energy check and the energy
checks' per-cell work run as tasks on up to two threads
(:func:`goniolab.optics.facet_threads.run_tasks`: one thread when the load average leaves
less than half a CPU free, or as ``GONIOLAB_THREADS`` says; the same numbers either way).
The header gives the threads the load rule allowed at the start; ``GONIOLAB_THREADS=1``
gives the one-thread figure.

The "numpy" column runs the per-cell sums (aperture sums, and Kirchhoff's Horner sums of the
Taylor terms) with the plain-numpy twins (FFTs are scipy's in both); the physical-optics FFT
work is the same in both columns.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np

# --checkout, read before the imports below (they come from that checkout)
sys.path.insert(
    0,
    next(
        (str(Path(sys.argv[i + 1]).resolve()) for i, a in enumerate(sys.argv[:-1])
         if a == "--checkout"),
        str(Path(__file__).resolve().parents[1]),
    ),
)  # fmt: skip

from goniolab.optics.facet_threads import walk_threads
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.kirchhoff import KirchhoffModel
from goniolab.optics.physical import PhysicalOpticsModel
from goniolab.optics.rayleigh_rice import RayleighRiceModel

TARGETS_MS = {"luminance_71pt": 200.0, "gloss_16wl": 1000.0}


def smooth_map(n: int, sq_um: float = 0.05, l_um: float = 2.0, step_um: float = 0.5) -> HeightMap:
    """Periodic Gaussian surface, ACF Sq^2 exp(-r^2/l^2)."""
    rng = np.random.default_rng(1)
    f = np.fft.fftfreq(n, step_um)
    filt = np.exp(-0.5 * (math.pi * l_um) ** 2 * (f[:, None] ** 2 + f[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * filt))
    z *= sq_um / z.std()
    return HeightMap(z_um=z, dx_um=step_um, dy_um=step_um, source=f"bench-smooth-{n}")


def timed(model: PhysicalOpticsModel, fn: Callable[[], object], repeats: int) -> dict[str, object]:
    def run() -> None:
        model._shared.cache.clear()  # every repetition transforms again
        fn()

    t0 = time.perf_counter()
    run()
    warm = (time.perf_counter() - t0) * 1e3
    runs, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        run()
        runs.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    return {
        "warmup_ms": warm,
        "median_ms": statistics.median(runs),
        "min_ms": min(runs),
        "cpu_ms": statistics.median(cpu),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--size", type=int, default=1024, help="map size in pixels (default 1024)")
    ap.add_argument("--repeats", type=int, default=7, help="timed runs per workload (>= 3)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    ap.add_argument("--backend", choices=("numba", "numpy", "both"), default="both",
                    help="the per-cell sums to time (default both)")  # fmt: skip
    ap.add_argument("--checkout", help="import goniolab from this checkout (module docstring)")
    args = ap.parse_args(argv)
    if args.repeats < 3:
        ap.error("--repeats must be >= 3")
    hm = smooth_map(args.size)
    theta_r = np.arange(0.0, 71.0, 1.0)
    import goniolab

    results: dict[str, object] = {
        "goniolab": str(Path(goniolab.__file__).parent),
        "map": f"{args.size}x{args.size} at 0.5 um, Sq 50 nm, l 2 um",
        "cpus": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "threads": walk_threads(),
        "repeats": args.repeats,
        "targets_ms": TARGETS_MS,
    }
    table: dict[str, dict[str, object]] = {}
    for cls in (KirchhoffModel, RayleighRiceModel):
        for backend in ("numba", "numpy") if args.backend == "both" else (args.backend,):
            m = cls(hm, n=1.55, wavelength_nm=550.0, backend=backend)  # type: ignore[arg-type]
            key = f"{cls.kind}/{backend}"
            table[key] = {
                "luminance_71pt": timed(
                    m, lambda m=m: m.luminance_pct(45.0, theta_r), args.repeats
                ),
                "gloss_16wl": timed(m, lambda m=m: m.gloss((20, 60, 85)), args.repeats),
            }
    # peak traced memory of one Kirchhoff curve (numpy allocations; the map itself excluded)
    m = KirchhoffModel(hm, n=1.55)
    tracemalloc.start()
    m.luminance_pct(45.0, theta_r)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    results["kirchhoff_curve_peak_traced_mb"] = peak / 2**20
    results["models"] = table
    # issue 20 (no target): a 50 um AFM field, whose ISO receptors span a cell or less of
    # the tile's transform (zero-padded to 6 cells), and the whole-window albedo at 85 deg
    afm = smooth_map(256, step_um=50.0 / 256)
    k_afm = KirchhoffModel(afm, n=1.55)
    k_big = KirchhoffModel(hm, n=1.55)
    results["issue20"] = {
        "kirchhoff gloss_16wl, 50 um field": timed(k_afm, k_afm.gloss, args.repeats),
        "kirchhoff albedo 85 deg, whole window": timed(
            k_big, lambda: k_big.albedo_tis(85.0), args.repeats
        ),
        # the 6 deg source split into 169 sub-cones (G2 per source direction, from 78 deg)
        "kirchhoff curve at 80 deg, 71 pts (169 sub-cones)": timed(
            k_big, lambda: k_big.luminance_pct(80.0, np.arange(15.0, 86.0, 1.0)), args.repeats
        ),
    }
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(
        f"physical-optics benchmark: {results['map']}, {os.cpu_count()} CPUs, median of "
        f"{args.repeats}, load average {os.getloadavg()[0]:.1f} (timings scale with other load), "
        f"{results['threads']} thread(s) at the start; "
        f"goniolab from {results['goniolab']}"
    )
    print(
        f"{'model/backend':<24}{'workload':<18}{'target':>9}{'median':>10}{'min':>9}{'cpu':>9}{'warm-up':>10}"
    )
    for key, rows in table.items():
        for name, r in rows.items():
            assert isinstance(r, dict)
            ok = "ok" if r["median_ms"] <= TARGETS_MS[name] else "SLOW"
            print(
                f"{key:<24}{name:<18}{TARGETS_MS[name]:>7.0f}ms{r['median_ms']:>8.1f}ms"
                f"{r['min_ms']:>7.1f}ms{r['cpu_ms']:>7.1f}ms{r['warmup_ms']:>8.0f}ms  {ok}"
            )
    print(f"Kirchhoff curve peak traced memory: {results['kirchhoff_curve_peak_traced_mb']:.0f} MB")
    extra = results["issue20"]
    assert isinstance(extra, dict)
    for name, r in extra.items():
        print(f"{name:<42}{r['median_ms']:>8.1f}ms (no target; warm-up {r['warmup_ms']:.0f} ms)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
