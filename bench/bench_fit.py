"""Benchmark and calibration of ``goniolab fit colour`` (issue 11): speed, and whether the
reported 1-sigma uncertainties match the scatter of the estimates over noise draws.

Run:  .venv/bin/python bench/bench_fit.py [--draws 20] [--noise 0.3] [--json]

For each built-in paint (silver metallic, solid red) a "true" paint (parameters moved off the
library's) gives L*a*b* at the six ASTM E2194 angles (paint alone, 41 wavelengths); each draw
adds Gaussian noise (``--noise`` per L*, a*, b*) and fits from the library paint. Reported per
parameter: the spread (sd) of the estimates, the mean reported sigma, their ratio (1 = the
uncertainties are right), and the rms of (estimate - truth) / sigma; and the median fit time.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from goniolab.colour.multiangle import E2194_ASPECULAR_DEG, theta_r_for_aspecular
from goniolab.colour.paint_fit import _Model, fit_paint, paint_with, parameter_values
from goniolab.colour.spectra import ColourSettings, standard_grid_nm
from goniolab.colour.spectral import SpectralPredictor
from goniolab.model_cache import paint_for

CASES: dict[str, dict[str, float]] = {
    "silver-metallic": {
        "body.ks_scale": 1.6,
        "metallic.area_fraction": 0.45,
        "metallic.spread_deg": 9.0,
        "coat.n": 1.53,
    },
    "solid-red": {"body.ks_scale": 1.5, "coat.n": 1.55},
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    wl = standard_grid_nm(10.0)
    tr = np.array([theta_r_for_aspecular(a) for a in E2194_ASPECULAR_DEG])
    settings = ColourSettings().validated()
    report: dict[str, object] = {"draws": args.draws, "noise_lab": args.noise}
    for name, truth in CASES.items():
        paint0 = paint_for(f"sample:{name}")
        names = list(truth)
        true_paint = paint_with(paint0, parameter_values(paint0, names), truth)
        sp = SpectralPredictor(None, true_paint, wavelengths_nm=wl)
        lab = _Model(sp, 45.0, tr, settings, "diffuser", None, None).lab(true_paint)
        est, sig, secs = [], [], []
        for seed in range(args.draws):
            noisy = lab + np.random.default_rng(seed).normal(0.0, args.noise, lab.shape)
            t0 = time.perf_counter()
            fit = fit_paint(SpectralPredictor(None, paint0, wavelengths_nm=wl), 45.0, tr, noisy)
            secs.append(time.perf_counter() - t0)
            est.append([fit.value(n) for n in names])
            sig.append([fit.sigma(n) for n in names])
        e, s = np.array(est), np.array(sig)
        z = (e - np.array([truth[n] for n in names])) / s
        report[name] = {
            "median_fit_s": statistics.median(secs),
            "parameters": {
                n: {
                    "truth": truth[n],
                    "mean_estimate": float(e[:, k].mean()),
                    "sd_estimates": float(e[:, k].std(ddof=1)),
                    "mean_sigma": float(s[:, k].mean()),
                    "sd_over_sigma": float(e[:, k].std(ddof=1) / s[:, k].mean()),
                    "rms_z": float(np.sqrt(np.mean(z[:, k] ** 2))),
                }
                for k, n in enumerate(names)
            },
        }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"{args.draws} noise draws, {args.noise} per L*, a*, b*, six E2194 angles")
    for name in CASES:
        r = report[name]
        assert isinstance(r, dict)
        print(f"{name}: median fit {r['median_fit_s']:.2f} s")
        for n, p in r["parameters"].items():
            print(
                f"  {n:<24} truth {p['truth']:<6g} mean {p['mean_estimate']:.4g}  "
                f"sd {p['sd_estimates']:.3g}  mean sigma {p['mean_sigma']:.3g}  "
                f"sd/sigma {p['sd_over_sigma']:.2f}  rms z {p['rms_z']:.2f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
