"""Peak memory of ``predict gloss`` and ``predict brdf`` on a large float32 map (issue 26).

Run:  .venv/bin/python bench/bench_memory.py [--size 8192] [--maps rough,smooth]
      [--commands gloss,brdf] [--json]

Writes a synthetic ``size x size`` float32 height map as ``.npy`` (``np.save``, with a
``.npy.json`` step sidecar), then runs, each in its own process as a user would,

- ``goniolab predict gloss MAP --json`` and
- ``goniolab predict brdf MAP --json`` (71 points, 0..70 deg, 6 deg cones, defaults),

with stdin and stderr on a pseudo-terminal (so the progress display shows, as it would to a
user) and reports per command the child's peak resident set (``/usr/bin/time``'s ``%M``:
of that child alone) against the map's own size (``size^2 x 4`` bytes; the issue's target
is <= 2.5 x), the wall time, whether the terminal saw a progress line, and the models that
computed the result. Maps:

- ``rough``: Gaussian random surface, Sq 3 um, correlation length 16 um at 1 um steps
  (the facet regime: ``g`` >= 20 at 20-85 deg);
- ``smooth``: Sq 5 nm, correlation length 2 um at 0.5 um steps (the wave-optics regime,
  Rayleigh-Rice / Kirchhoff).

The maps are made with float32 FFTs (scipy.fft) in this process; each measured command is
a fresh child, so the parent's own memory does not enter its figure.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import pty
import re
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: The issue's target: peak RSS of the whole process over the map's float32 bytes.
TARGET_OVER_MAP = 2.5
#: ``goniolab`` as the console script runs it (``console()``: a one-shot ``predict``
#: process, with its heap and collector settings, goniolab.process_heap and goniolab.cli).
_CLI = "from goniolab.cli import console; console()"


def make_map(path: Path, n: int, kind: str, seed: int = 1) -> None:
    """Write a periodic Gaussian random surface of ``n x n`` float32 heights (um) and its
    step sidecar. ``rough``: Sq 3 um, correlation length 16 um at 1 um steps; ``smooth``:
    Sq 5 nm, correlation length 2 um at 0.5 um steps."""
    import scipy.fft

    rng = np.random.default_rng(seed)
    step_um, l_px = (1.0, 16.0) if kind == "rough" else (0.5, 4.0)
    f = np.fft.fftfreq(n).astype(np.float32)
    g = np.exp(-((math.pi * l_px * f) ** 2) / 2.0).astype(np.float32)
    spec = scipy.fft.rfft2(rng.standard_normal((n, n), dtype=np.float32), workers=2)
    spec *= g[:, None]
    spec *= g[None, : spec.shape[1]]
    z = scipy.fft.irfft2(spec, s=(n, n), workers=2).astype(np.float32, copy=False)
    del spec
    sq_um = 3.0 if kind == "rough" else 0.005
    z *= np.float32(sq_um / float(np.std(z[: min(n, 512)], dtype=np.float64)))
    np.save(path, z)
    path.with_name(path.name + ".json").write_text(
        json.dumps({"dx_um": step_um, "dy_um": step_um}) + "\n"
    )


def run_in_pty(argv: list[str]) -> tuple[int, str, float, int]:
    """Run ``argv`` with stdin/stderr on a pty (stdout piped); return its exit code, what
    the terminal showed plus stdout, the wall time and the child's own peak RSS (bytes).

    The peak comes from ``/usr/bin/time`` (a small C process between this one and the
    command): Linux keeps a process's peak RSS across ``exec``, so a child forked straight
    from this process (which holds the map it wrote) would report this process's size.
    """
    master, slave = pty.openpty()
    env = dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="100")
    fd, rss_file = tempfile.mkstemp(prefix="bench-memory-rss-")
    os.close(fd)
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        ["/usr/bin/time", "-f", "%M", "-o", rss_file, *argv],
        stdin=slave,
        stdout=subprocess.PIPE,
        stderr=slave,
        cwd=ROOT,
        env=env,
    )
    os.close(slave)
    assert proc.stdout is not None
    os.set_blocking(proc.stdout.fileno(), False)
    seen, out = b"", b""
    status = None
    while status is None:
        out_fd = proc.stdout.fileno()
        ready, _, _ = select.select([master, out_fd], [], [], 0.2)
        if master in ready:
            with contextlib.suppress(OSError):
                seen += os.read(master, 65536)
        if out_fd in ready:
            out += proc.stdout.read() or b""
        pid, st = os.waitpid(proc.pid, os.WNOHANG)
        if pid:
            status = st
    wall = time.perf_counter() - t0
    out += proc.stdout.read() or b""
    try:
        while select.select([master], [], [], 0.05)[0]:
            chunk = os.read(master, 65536)
            if not chunk:
                break
            seen += chunk
    except OSError:
        pass
    os.close(master)
    proc.returncode = os.waitstatus_to_exitcode(status)
    text = Path(rss_file).read_text().strip().splitlines()
    os.unlink(rss_file)
    rss_kb = int(text[-1]) if text and text[-1].isdigit() else -1
    return proc.returncode, seen.decode(errors="replace") + out.decode(), wall, rss_kb * 1024


def measure(path: Path, command: str, map_bytes: int) -> dict[str, Any]:
    argv = [sys.executable, "-c", _CLI, "predict", command, str(path), "--json"]
    code, text, wall, rss = run_in_pty(argv)
    found = re.search(r"^\{.*\}\s*$", text, re.S | re.M)
    result: Any = None
    if found and code == 0:
        try:
            result = json.loads(found.group(0))
        except ValueError:
            result = None
    row: dict[str, Any] = {
        "command": f"predict {command}",
        "exit": code,
        "wall_s": round(wall, 1),
        "peak_rss_mb": round(rss / 2**20, 1),
        "peak_rss_over_map": round(rss / map_bytes, 2),
        "target_met": rss <= TARGET_OVER_MAP * map_bytes and code == 0,
        "progress_shown": bool(re.search(r"\d+ % \(\d+/\d+\)", text)),
    }
    if isinstance(result, dict):
        if command == "gloss":
            row["gloss"] = {
                k: round(float(result[k]), 2) for k in ("G20", "G60", "G85") if k in result
            }
            row["models"] = result.get("model")
        else:
            lum = result.get("luminance_pct") or []
            row["peak_pct"] = round(max(lum), 4) if lum else None
            models = result.get("models")
            row["models"] = sorted(set(models)) if isinstance(models, list) else models
    if code != 0:
        row["tail"] = text.strip().splitlines()[-3:]
    row["terminal"] = text
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--size", type=int, default=8192, help="map size in pixels (default 8192)")
    ap.add_argument("--maps", default="rough,smooth", help="maps: rough, smooth (default both)")
    ap.add_argument("--commands", default="gloss,brdf", help="commands: gloss, brdf (default both)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    ap.add_argument(
        "--show", action="store_true", help="also print what the terminal showed (stderr)"
    )
    args = ap.parse_args(argv)
    map_bytes = args.size * args.size * 4
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench-memory-") as tmp:
        for kind in args.maps.split(","):
            path = Path(tmp) / f"{kind}-{args.size}.npy"
            make_map(path, args.size, kind)
            for command in args.commands.split(","):
                row = {"map": kind, "size": args.size, **measure(path, command, map_bytes)}
                rows.append(row)
                if not args.json:
                    print(
                        f"{kind:6s} {row['command']:14s} exit {row['exit']}  "
                        f"peak {row['peak_rss_mb']:7.1f} MB = {row['peak_rss_over_map']:.2f} x "
                        f"map ({map_bytes / 2**20:.0f} MB; target <= {TARGET_OVER_MAP} x: "
                        f"{'met' if row['target_met'] else 'NOT met'})  "
                        f"{row['wall_s']:6.1f} s  progress "
                        f"{'shown' if row['progress_shown'] else 'not shown'}  "
                        f"{row.get('gloss', row.get('peak_pct', ''))} {row.get('models', '')}",
                        flush=True,
                    )
                    if "tail" in row:
                        print("    " + "\n    ".join(row["tail"]), flush=True)
                if args.show:
                    # each terminal line as it was left (a progress line redraws after \r)
                    shown = row["terminal"].split("{", 1)[0].replace("\r\n", "\n")
                    lines = [ln.rsplit("\r", 1)[-1] for ln in shown.split("\n") if ln.strip()]
                    print("    | " + "\n    | ".join(lines), flush=True)
                row.pop("terminal")
    if args.json:
        print(json.dumps(rows, indent=1))
    return 0 if all(r["target_met"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
