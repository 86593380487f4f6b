"""Benchmark of the spectral prediction (issue 11): 31 wavelengths vs one, 71-point curve.

Run:  .venv/bin/python bench/bench_colour.py [--sample sample:silver-metallic] [--repeats 5] [--json]

The facet model of the sample's height map with the sample's paint (Cauchy coat, KM body,
flakes) predicts the in-plane curve at theta_i = 45, theta_r = 0..70 deg (71 points, 6 deg
cones):

- single: ``FacetModel.luminance_pct`` at one index (the grey prediction);
- spectral: :meth:`goniolab.colour.spectral.SpectralPredictor.spectrum_pct` at 400..700 nm,
  10 nm (31 wavelengths): the coat surface at three indices interpolated in n, plus the
  paint term through the cones. Target: <= 10 x single.

Each is run once as a warm-up (JIT, colour-science import), then ``repeats`` times; medians.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from goniolab.model_cache import model_for, spectral_for


def _median_s(fn: Callable[[], object], repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sample", default="sample:silver-metallic")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    model = model_for(args.sample)
    sp = spectral_for(model)
    sp.wavelengths_nm = np.linspace(400.0, 700.0, 31)
    tr = np.linspace(0.0, 70.0, 71)
    single = _median_s(lambda: model.luminance_pct(45.0, tr), args.repeats)
    spectral = _median_s(lambda: sp.spectrum_pct(45.0, tr), args.repeats)
    out = {
        "sample": args.sample,
        "points": int(tr.size),
        "wavelengths": int(sp.wavelengths_nm.size),
        "single_s": single,
        "spectral_s": spectral,
        "ratio": spectral / single,
        "target_ratio": 10.0,
    }
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(
            f"{args.sample}: 71-point curve, single wavelength {1e3 * single:.1f} ms, "
            f"31 wavelengths {1e3 * spectral:.1f} ms, ratio {out['ratio']:.1f} (target <= 10)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
