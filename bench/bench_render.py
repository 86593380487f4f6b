"""Benchmark of ``goniolab render`` (issue 11): a 512 x 512 panel of a painted sample.

Run:  .venv/bin/python bench/bench_render.py [--sample sample:silver-metallic] [--size 512]
                                             [--repeats 5] [--json]

- in process: the BRDF table (gloss + paint, 48 x 24 x 12 half/difference angles, 41
  wavelengths, to XYZ), the per-pixel lookup for one and for two lamps, sRGB and the PNG;
  after one warm-up (colour-science import, the E308 weights), ``repeats`` times; medians.
  Target: <= 5 s on 2 cores.
- whole command: ``goniolab render SAMPLE --out ... --size N`` as a separate process, once
  (spawn to exit: it includes importing colour-science, which imports matplotlib and pandas).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from goniolab.app.panel_render import write_png
from goniolab.colour.paint_render import render, tabulate_brdf
from goniolab.colour.spectra import colour_module, standard_grid_nm, xyz_weights
from goniolab.model_cache import paint_for
from goniolab.optics.surface import roughness_stats
from goniolab.surfaces.resolve import resolve_map

ROOT = Path(__file__).resolve().parents[1]


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
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    colour_module()
    wl = standard_grid_nm(10.0)
    xyz_weights(wl)
    paint = paint_for(args.sample)
    alpha = float(roughness_stats(resolve_map(args.sample)).Sdq)
    out = Path(tempfile.mkdtemp()) / "panel.png"

    def run(lamps: int) -> Callable[[], object]:
        def go() -> None:
            table = tabulate_brdf(paint, alpha, wavelengths_nm=wl)
            write_png(out, render(table, size=args.size, lamps=lamps).srgb)

        return go

    table_s = _median_s(lambda: tabulate_brdf(paint, alpha, wavelengths_nm=wl), args.repeats)
    one = _median_s(run(1), args.repeats)
    two = _median_s(run(2), args.repeats)
    exe = ROOT / ".venv" / "bin" / "goniolab"
    cmd = [str(exe), "render", args.sample, "--out", str(out), "--size", str(args.size)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    whole = time.perf_counter() - t0
    doc = {
        "sample": args.sample,
        "size": args.size,
        "cpus": os.cpu_count(),
        "load_average": os.getloadavg()[0],
        "table_s": table_s,
        "render_1_lamp_s": one,
        "render_2_lamps_s": two,
        "target_s": 5.0,
        "whole_command_s": whole,
    }
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print(
            f"{args.sample} {args.size}x{args.size}, {doc['cpus']} CPUs, load {doc['load_average']:.1f}: "
            f"table {table_s:.2f} s; render + PNG median {one:.2f} s (1 lamp), {two:.2f} s "
            f"(2 lamps), target <= 5 s; whole command (new process) {whole:.1f} s"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
