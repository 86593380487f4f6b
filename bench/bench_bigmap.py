"""A 4096 x 4096 ``.sur`` through the Kirchhoff model as a whole process (issue 15, item 5).

Run:  .venv/bin/python bench/bench_bigmap.py [--size 4096] [--json]

Writes a smooth high-gloss map (Gaussian ACF, Sq 50 nm, correlation length 2 um, 0.5 um
steps: a 2 x 2 mm field) as a Digital Surf ``.sur`` file, then runs
``goniolab predict gloss big.sur --model kirchhoff`` in a pseudo-terminal, as a user would,
and reports:

- the peak RSS of the process (``getrusage`` of the child) against the map's own size as
  float64 (``size^2 x 8`` bytes): the phase screen is transformed in float32 tiles of at most
  1024 x 1024 (:mod:`goniolab.optics.psd`), so the FFT work adds a bounded few tens of MB
  whatever the map size; what grows with the map is the map itself and the facet model the
  regime rule and the fallbacks read;
- the wall and CPU time, and whether the terminal saw the progress display (shown for work over
  about 2 s);
- the gloss triplet.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pty
import re
import resource
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from goniolab.optics.heightmap import HeightMap  # noqa: E402 -- after the sys.path line
from goniolab.surfaces import save_heightmap  # noqa: E402

GLOSS_KEYS = ("G20", "G60", "G85")


def smooth_map(n: int, sq_um: float = 0.05, l_um: float = 2.0, step_um: float = 0.5) -> HeightMap:
    """Periodic Gaussian surface, ACF Sq^2 exp(-r^2/l^2) (float32 FFT to keep this script small)."""
    rng = np.random.default_rng(1)
    f = np.fft.fftfreq(n, step_um).astype(np.float32)
    gy = np.exp(-0.5 * (math.pi * l_um) ** 2 * f**2).astype(np.float32)
    spec = np.fft.rfft2(rng.standard_normal((n, n), dtype=np.float32))
    spec *= gy[:, None] * gy[None, : spec.shape[1]]
    z = np.fft.irfft2(spec, s=(n, n)).astype(np.float64)
    z *= sq_um / z.std()
    return HeightMap(z_um=z, dx_um=step_um, dy_um=step_um, source=f"bench-big-{n}")


def run_in_pty(argv: list[str]) -> tuple[int, str, float, int, float]:
    """Run ``argv`` with stdin/stderr on a pty (stdout piped); return exit code, everything
    the terminal showed plus stdout, wall time, the child's peak RSS in bytes and its CPU
    time (user + system, s)."""
    master, slave = pty.openpty()
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdin=slave, stdout=subprocess.PIPE, stderr=slave, cwd=ROOT)
    os.close(slave)
    seen = b""
    assert proc.stdout is not None
    while True:
        ready, _, _ = select.select([master], [], [], 0.2)
        if master in ready:
            try:
                chunk = os.read(master, 65536)
            except OSError:
                chunk = b""
            if chunk:
                seen += chunk
                continue
        if proc.poll() is not None:
            break
    out = proc.stdout.read()
    wall = time.perf_counter() - t0
    os.close(master)
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    rss = usage.ru_maxrss * 1024
    cpu = usage.ru_utime + usage.ru_stime
    return proc.returncode, seen.decode(errors="replace") + out.decode(), wall, rss, cpu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--size", type=int, default=4096, help="map size in pixels (default 4096)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.sur"
        save_heightmap(smooth_map(args.size), path)
        goniolab = Path(sys.executable).with_name("goniolab")
        cmd = [str(goniolab), "predict", "gloss", str(path), "--model", "kirchhoff", "--json"]
        code, text, wall, rss, cpu = run_in_pty(cmd)
        file_mb = path.stat().st_size / 2**20
    map_mb = args.size**2 * 8 / 2**20
    gloss = re.search(r"\{.*\}", text, re.S)
    result = {
        "size": args.size,
        "file_mb": round(file_mb, 1),
        "map_float64_mb": round(map_mb, 1),
        "exit": code,
        "wall_s": round(wall, 1),
        "cpu_s": round(cpu, 1),
        "peak_rss_mb": round(rss / 2**20, 1),
        "peak_rss_over_map": round(rss / 2**20 / map_mb, 2),
        "progress_shown": "kirchhoff FFT" in text,
        "gloss": (
            {k: round(v, 3) for k, v in json.loads(gloss.group(0)).items() if k in GLOSS_KEYS}
            if gloss and code == 0
            else None
        ),
        "load_average_1min": os.getloadavg()[0],
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k:>20}: {v}")
        if code != 0:
            print(text[-2000:])
    return 0 if code == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
