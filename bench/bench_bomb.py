"""Decompression bombs against the height-map readers (issue 10, defect 2).

Run:  .venv/bin/python bench/bench_bomb.py [--declared 20000] [--json]

Builds a Digital Surf ``DSCOMPRESSED`` file of about 1.5 MB whose header declares a
``declared x declared`` int32 map and whose zlib stream really inflates to that size (zeros;
~1.6 GB for 20000), then times ``load_heightmap`` in-process and ``goniolab predict gloss
bomb.sur`` as a whole process (the user's view: exit code, one-line error, wall time -- most
of it Python start-up -- and peak RSS), with the default limit (``GONIOLAB_MAX_MAP_POINTS``
unset). Before the fix this allocated 5.3 GB and ended in a numpy traceback after 37 s.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from goniolab.optics.heightmap import HeightMap, HeightMapError
from goniolab.surfaces import load_heightmap, save_heightmap


def build_bomb(path: Path, n: int) -> int:
    """Write the bomb; return its size in bytes."""
    small = path.with_suffix(".seed.sur")
    save_heightmap(
        HeightMap(z_um=np.zeros((1, 2)), dx_um=1.0, dy_um=1.0, source="bomb", meta={}), small
    )
    head = bytearray(small.read_bytes())
    small.unlink()
    comment_size, private_size = struct.unpack_from("<HH", head, 334)
    start = 512 + comment_size + private_size
    struct.pack_into("<iii", head, 108, n, n, n * n)
    raw_len = 4 * n * n
    stream = _zeros_stream(raw_len, rows_bytes=4 * n)
    directory = struct.pack("<III", 1, raw_len, len(stream))
    path.write_bytes(b"DSCOMPRESSED" + bytes(head[12:start]) + directory + stream)
    return path.stat().st_size


def _zeros_stream(raw_len: int, rows_bytes: int) -> bytes:
    """A zlib stream of ``raw_len`` zero bytes, built from one deflate block repeated (a
    block ended by a full flush does not depend on what came before), so a 1.6 GB bomb
    takes seconds to build: zlib header, the blocks, an empty final block, Adler-32."""
    chunk_len = rows_bytes
    while chunk_len * 2 <= 1 << 23 and raw_len % (chunk_len * 2) == 0:
        chunk_len *= 2
    chunk = bytes(chunk_len)
    deflate = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = deflate.compress(chunk) + deflate.flush(zlib.Z_FULL_FLUSH)
    final = zlib.compressobj(9, zlib.DEFLATED, -15).flush(zlib.Z_FINISH)
    adler = 1
    for _ in range(raw_len // chunk_len):
        adler = zlib.adler32(chunk, adler)
    assert raw_len % chunk_len == 0
    return b"\x78\xda" + block * (raw_len // chunk_len) + final + struct.pack(">I", adler)


def run(cmd: list[str], env: dict[str, str]) -> dict[str, object]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - t0
    peak_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return {
        "exit": proc.returncode,
        "wall_s": round(wall, 3),
        "children_peak_rss_mib": round(peak_kib / 1024, 1),
        "stderr": proc.stderr.strip()[-300:],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--declared", type=int, default=20000, help="declared map side (points)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    exe = str(Path(sys.executable).with_name("goniolab"))
    with tempfile.TemporaryDirectory() as tmp:
        bomb = Path(tmp) / "bomb.sur"
        t0 = time.perf_counter()
        size = build_bomb(bomb, args.declared)
        built_s = time.perf_counter() - t0
        env = {k: v for k, v in os.environ.items() if k != "GONIOLAB_MAX_MAP_POINTS"}
        os.environ.pop("GONIOLAB_MAX_MAP_POINTS", None)
        t0 = time.perf_counter()
        try:
            load_heightmap(bomb)
            refused = "read (!)"
        except HeightMapError as exc:
            refused = str(exc)
        reader_ms = (time.perf_counter() - t0) * 1e3
        default = run([exe, "predict", "gloss", str(bomb)], env)
        out = {
            "file_bytes": size,
            "declared": f"{args.declared}x{args.declared} int32 "
            f"({4 * args.declared**2 / 2**20:.0f} MiB)",
            "build_s": round(built_s, 2),
            "load_heightmap_ms": round(reader_ms, 2),
            "load_heightmap_error": refused,
            "predict_gloss_whole_process": default,
        }
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        for k, v in out.items():
            print(f"{k:32s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
