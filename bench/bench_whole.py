"""Speed a user feels: whole ``goniolab`` processes beside a plain-numpy script (issue 13).

Run:  .venv/bin/python bench/bench_whole.py [--size 2048] [--repeats 5] [--batch 100]
      [--batch-size 1024] [--json]

Everything here runs as a separate process, exactly as a user types it, timed from spawn
to exit (median of ``--repeats``, with the CPU time and the peak RSS of that process from
``wait4``), on a ``size x size`` Gaussian ``.npy`` height map (float64, with a tilt, so
that levelling has work to do) made in a temporary directory:

- start-up: ``goniolab --help``, ``goniolab samples`` (target <= 0.2 s), beside bare
  ``python -c pass`` and ``python -c "import numpy"``;
- ``goniolab predict brdf MAP --theta-i 45 --theta-r 0:70:1`` (71 points, 6 deg cones) and
  ``goniolab predict gloss MAP`` beside ``bench/baseline_numpy.py MAP brdf|gloss`` (the same
  curve and readings written in plain numpy), target ratio <= 0.5;
- ``--model facet`` runs the facet model's numba-free "lean" backend (one command, one
  process: numba's import and set-up cost ~1 s); the defaults (``--model auto``, masking)
  run the wave models' numpy sums and the facet model's lean cells (no numba since issue
  26): their first run with an empty ``NUMBA_CACHE_DIR`` is timed beside the later runs
  (the two agree when nothing is JIT-compiled);
- the memory-bandwidth limit: the bytes the pipeline must touch (read the file into memory,
  two plane sums, the slopes written once, one read of the slopes per facet pass) over the
  measured ``numpy.copyto`` bandwidth (bytes read + written per second);
- batch: ``goniolab predict gloss`` of ``--batch`` maps of ``--batch-size``^2 with
  ``--json`` (JSON Lines), on every core and with ``--jobs 1`` (0 skips).

Bytecode caching is left on (``PYTHONDONTWRITEBYTECODE`` is dropped from the environment,
and one untimed run of each command writes the caches first), as for an installed package.
The machine's load average is printed: the timings scale with other users' work.
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
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
GONIOLAB = str(BIN / "goniolab")
PY = sys.executable


TIME = "/usr/bin/time"


def run(cmd: list[str], env: dict[str, str]) -> tuple[float, float, float, int]:
    """(wall s, cpu s of the process and its children, peak RSS MB, exit code).

    The peak RSS comes from GNU time (``%M``) when installed: a child forked from this
    (numpy-laden) process would otherwise count the parent's pages it shared before exec.
    """
    with tempfile.NamedTemporaryFile("r") as rss:
        wrap = [TIME, "-f", "%M", "-o", rss.name] if os.path.exists(TIME) else []
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [*wrap, *cmd], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        _, status, ru = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        err = proc.stderr.read().decode() if proc.stderr else ""
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {err[-500:]}")
        text = rss.read().strip().splitlines()
        peak_kb = float(text[-1]) if wrap and text else float(ru.ru_maxrss)
    return wall, ru.ru_utime + ru.ru_stime, peak_kb / 1024.0, proc.returncode


def timed(cmd: list[str], env: dict[str, str], repeats: int) -> dict[str, float]:
    run(cmd, env)  # untimed: bytecode and numba caches written, page cache warm
    rows = [run(cmd, env) for _ in range(repeats)]
    return {
        "wall_s": statistics.median(r[0] for r in rows),
        "min_s": min(r[0] for r in rows),
        "cpu_s": statistics.median(r[1] for r in rows),
        "rss_mb": max(r[2] for r in rows),
    }


def make_map(path: Path, n: int, seed: int = 1) -> None:
    rng = np.random.default_rng(seed)
    k = np.fft.fftfreq(n)
    kernel = np.exp(-0.5 * (2 * np.pi * 1.5) ** 2 * (k[:, None] ** 2 + k[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * kernel))
    p = (z[:, 2:] - z[:, :-2]) / 2.0
    z *= 0.05 / float(np.sqrt(np.mean(p * p)))
    z += 0.01 * np.arange(n)[None, :] + 0.003 * np.arange(n)[:, None]  # a tilt to level
    np.save(path, z)
    path.with_name(path.name + ".json").write_text('{"dx_um": 1.0, "dy_um": 1.0}\n')


def copy_bandwidth_gbs(mb: int = 256) -> float:
    """Best of 7 ``np.copyto`` of ``mb`` MB: (read + write) bytes per second, in GB/s."""
    src = np.ones(mb * 2**20 // 8)
    dst = np.empty_like(src)
    best = min(_copy_time(dst, src) for _ in range(7))
    return 2 * src.nbytes / best / 1e9


def _copy_time(dst: np.ndarray, src: np.ndarray) -> float:
    t0 = time.perf_counter()
    np.copyto(dst, src)
    return time.perf_counter() - t0


def bytes_touched(n: int, facet_passes: int) -> float:
    """Bytes the pipeline must move for one map (float64 heights and slopes)."""
    m = 8.0 * n * n
    load = 2 * m  # page cache -> array
    plane = 2 * m  # column and row sums
    slopes = m + 2 * m  # read the heights, write p and q
    passes = facet_passes * 2 * m  # each kernel pass reads p and q
    return load + plane + slopes + passes


def in_process(path: Path, repeats: int, backend: str) -> dict[str, float]:
    """Medians of the steps inside one process (kernels cached and warm), and the peak of
    the array memory (tracemalloc: numpy's buffers) of one read-to-curve run, with the
    facet model's ``backend`` (unmasked, as the baseline)."""
    import tracemalloc

    sys.path.insert(0, str(ROOT))
    from goniolab.optics.apertures import Cone
    from goniolab.optics.facet import FacetModel
    from goniolab.optics.gloss_standards import gloss_report
    from goniolab.optics.surface import Surface
    from goniolab.surfaces import load_heightmap

    tr = np.arange(0.0, 71.0, 1.0)

    def curve() -> None:
        hm = load_heightmap(path)
        surface = Surface.from_heightmap(hm)
        del hm
        FacetModel(surface, backend=backend).luminance_pct(  # type: ignore[arg-type]
            45.0, tr, source=Cone(6.0), detector=Cone(6.0)
        )

    curve()  # warm
    tracemalloc.start()
    curve()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    steps: dict[str, list[float]] = {"read": [], "level+slopes": [], "curve": [], "gloss": []}
    for _ in range(repeats):
        t0 = time.perf_counter()
        hm = load_heightmap(path)
        t1 = time.perf_counter()
        surface = Surface.from_heightmap(hm)
        t2 = time.perf_counter()
        model = FacetModel(surface, backend=backend)  # type: ignore[arg-type]
        model.luminance_pct(45.0, tr, source=Cone(6.0), detector=Cone(6.0))
        t3 = time.perf_counter()
        gloss_report(model)
        t4 = time.perf_counter()
        for k, v in zip(steps, (t1 - t0, t2 - t1, t3 - t2, t4 - t3), strict=True):
            steps[k].append(v)
        del hm, surface, model
    out = {f"{k}_s": statistics.median(v) for k, v in steps.items()}
    out["array_peak_mb"] = peak / 2**20
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--batch", type=int, default=100, help="maps in the batch run (0 = skip)")
    ap.add_argument("--batch-size", type=int, default=1024)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    out: dict[str, object] = {
        "cpus": os.cpu_count(),
        "load_before": os.getloadavg(),
        "map": f"{args.size}x{args.size} float64 .npy",
        "repeats": args.repeats,
    }
    with tempfile.TemporaryDirectory(prefix="goniolab-bench-") as tmp:
        tdir = Path(tmp)
        env["NUMBA_CACHE_DIR"] = str(tdir / "numba-cache")
        mp = tdir / f"map{args.size}.npy"
        make_map(mp, args.size)
        # the unmasked facet model, as the baseline computes it (the defaults --model auto
        # and --masking pick physical optics per geometry and add Smith masking)
        facet = ["--model", "facet", "--no-masking"]
        brdf = [GONIOLAB, "predict", "brdf", str(mp), "--theta-i", "45", "--theta-r", "0:70:1",
                *facet]  # fmt: skip
        gloss = [GONIOLAB, "predict", "gloss", str(mp), *facet]
        base = [PY, str(ROOT / "bench" / "baseline_numpy.py"), str(mp)]

        # the defaults (auto, masking): their first run with an empty numba cache (a JIT
        # compilation would show here; since issue 26 they load no numba)
        auto_brdf = [GONIOLAB, "predict", "brdf", str(mp), "--theta-i", "45", "--theta-r",
                     "0:70:1"]  # fmt: skip
        auto_gloss = [GONIOLAB, "predict", "gloss", str(mp)]
        out["jit_first_run_brdf_s"] = run([*auto_brdf, "--json"], env)[0]
        out["jit_first_run_gloss_s"] = run([*auto_gloss, "--json"], env)[0]
        run([*brdf, "--json"], env)  # bytecode caches of the facet path

        rows: dict[str, dict[str, float]] = {}
        rows["python -c pass"] = timed([PY, "-c", "pass"], env, args.repeats)
        rows["python -c 'import numpy'"] = timed([PY, "-c", "import numpy"], env, args.repeats)
        rows["python -c 'import numba'"] = timed([PY, "-c", "import numba"], env, args.repeats)
        rows["goniolab --help"] = timed([GONIOLAB, "--help"], env, args.repeats)
        rows["goniolab samples"] = timed([GONIOLAB, "samples"], env, args.repeats)
        rows["goniolab predict brdf"] = timed(brdf, env, args.repeats)
        rows["numpy baseline brdf"] = timed([*base, "brdf"], env, args.repeats)
        rows["goniolab predict gloss"] = timed(gloss, env, args.repeats)
        rows["numpy baseline gloss"] = timed([*base, "gloss"], env, args.repeats)
        rows["predict brdf (auto, masking)"] = timed(auto_brdf, env, args.repeats)
        rows["predict gloss (auto, masking)"] = timed(auto_gloss, env, args.repeats)
        out["rows"] = rows

        bw = copy_bandwidth_gbs()
        out["copy_bandwidth_gbs"] = bw
        out["limit_brdf_s"] = bytes_touched(args.size, 1) / (bw * 1e9)
        out["limit_gloss_s"] = bytes_touched(args.size, 4) / (bw * 1e9)
        out["map_float64_mb"] = 8 * args.size**2 / 2**20
        os.environ["NUMBA_CACHE_DIR"] = env["NUMBA_CACHE_DIR"]
        out["in_process"] = in_process(mp, args.repeats, "lean")
        out["in_process_numba"] = in_process(mp, args.repeats, "numba")

        if args.batch:
            bdir = tdir / "batch"
            bdir.mkdir()
            first_map = bdir / "m000.npy"
            make_map(first_map, args.batch_size, seed=2)
            maps = [first_map]
            for i in range(1, args.batch):
                target = bdir / f"m{i:03d}.npy"
                os.link(first_map, target)  # same bytes, distinct files: each is read
                os.link(
                    first_map.with_name(first_map.name + ".json"),
                    target.with_name(target.name + ".json"),
                )
                maps.append(target)
            cmd = [GONIOLAB, "predict", "gloss", *map(str, maps), "--json", *facet]
            run([*cmd[:5], "--json"], env)  # warm
            wall_all, cpu_all, _, _ = run(cmd, env)
            wall_one, cpu_one, _, _ = run([*cmd, "--jobs", "1"], env)
            out["batch"] = {
                "maps": args.batch,
                "size": args.batch_size,
                "all_cores_s": wall_all,
                "all_cores_cpu_s": cpu_all,
                "all_cores_maps_per_s": args.batch / wall_all,
                "one_job_s": wall_one,
                "one_job_cpu_s": cpu_one,
                "one_job_maps_per_s": args.batch / wall_one,
            }
    out["load_after"] = os.getloadavg()

    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print_table(out)
    return 0


def print_table(out: dict[str, object]) -> None:
    rows = out["rows"]
    assert isinstance(rows, dict)
    la, lb = out["load_before"], out["load_after"]
    print(
        f"whole-process timings, {out['cpus']} CPUs, median of {out['repeats']}, "
        f"load average {la[0]:.1f} before / {lb[0]:.1f} after; map {out['map']}"  # type: ignore[index]
    )
    print(f"{'command':34}{'wall':>9}{'(min)':>9}{'cpu':>9}{'peak RSS':>10}")
    for name, r in rows.items():
        print(
            f"{name:34}{r['wall_s']:8.3f}s{r['min_s']:8.3f}s{r['cpu_s']:8.3f}s{r['rss_mb']:8.0f}MB"
        )
    for what in ("brdf", "gloss"):
        g, b = rows[f"goniolab predict {what}"], rows[f"numpy baseline {what}"]
        print(
            f"predict {what}: {g['wall_s'] / b['wall_s']:.2f} x the numpy baseline's wall time "
            f"({g['cpu_s'] / b['cpu_s']:.2f} x its CPU time; target <= 0.5); memory-bandwidth "
            f"limit {out[f'limit_{what}_s'] * 1e3:.0f} ms at {out['copy_bandwidth_gbs']:.1f} GB/s"
        )
    print(
        f"the defaults (auto, masking), first run with an empty numba cache: "
        f"{out['jit_first_run_brdf_s']:.2f} s (brdf), {out['jit_first_run_gloss_s']:.2f} s "
        "(gloss); later runs: the table above"
    )
    for key, label in (("in_process", "lean backend"), ("in_process_numba", "numba, cached")):
        ip = out[key]
        assert isinstance(ip, dict)
        print(
            f"in process, {label}: read {ip['read_s'] * 1e3:.0f} ms, level + slopes "
            f"{ip['level+slopes_s'] * 1e3:.0f} ms, 71-point curve {ip['curve_s'] * 1e3:.0f} ms, "
            f"gloss report {ip['gloss_s'] * 1e3:.0f} ms; array memory peak read-to-curve "
            f"{ip['array_peak_mb']:.0f} MB (budget 3 x {out['map_float64_mb']:.0f} MB = "
            f"{3 * out['map_float64_mb']:.0f} MB)"  # type: ignore[operator]
        )
    if "batch" in out:
        bt = out["batch"]
        assert isinstance(bt, dict)
        print(
            f"batch gloss, {bt['maps']} maps of {bt['size']}^2: {bt['all_cores_s']:.1f} s on every "
            f"core ({bt['all_cores_maps_per_s']:.2f} maps/s, {bt['all_cores_cpu_s']:.1f} s CPU), "
            f"{bt['one_job_s']:.1f} s with --jobs 1 ({bt['one_job_maps_per_s']:.2f} maps/s, "
            f"{bt['one_job_cpu_s']:.1f} s CPU)"
        )


if __name__ == "__main__":
    raise SystemExit(main())
