"""The default path, whole process, in every regime (issue 26): paired A/B runs.

Run:  .venv/bin/python bench/bench_lean.py [--size 2048] [--repeats 5] [--before DIR]
      [--in-process] [--json]

On three ``size x size`` float64 ``.npy`` maps made in a temporary directory (periodic
Gaussian surfaces, Gaussian ACF):

- ``rough``: Sq 2.5 um, l 30 um, 1 um steps (a tilt to level). ``auto`` picks the facet model
  at every geometry (g >= 25 up to 85 deg);
- ``mixed``: ``bench/bench_whole.py``'s map (rms slope 0.05, Sq about 0.12 um, 1 um steps):
  Kirchhoff, Rayleigh-Rice and facet hand-overs;
- ``smooth``: Sq 50 nm, l 2 um, 0.5 um steps: Kirchhoff and Rayleigh-Rice only.

Each map: ``goniolab predict brdf MAP --theta-i 45 --theta-r 0:70:1`` and ``goniolab
predict gloss MAP`` with the defaults (``--model auto``, masking on), paired with
``bench/baseline_numpy.py MAP brdf|gloss`` (the plain-numpy facet script): each repetition
runs the pair back to back (order alternating), so both see the same load; medians of
``--repeats`` of wall and CPU time (user + system, from ``wait4``) and the ratios of the
medians. ``--before DIR`` adds the same goniolab commands run from another checkout
(``PYTHONPATH=DIR``, e.g. ``/work/main``), paired in the same repetitions: the A/B of a
change. ``--in-process`` adds the issue's in-process figures on a 1024^2 smooth map
(bench/bench_physical.py's): the Kirchhoff 71-point curve and the 16-wavelength gloss with
the default (numpy) sums, medians of ``--repeats`` with the FFT cache cleared each time.

Bytecode caching is on (``PYTHONDONTWRITEBYTECODE`` dropped; one untimed run of each
command writes the caches), as for an installed package; ``NUMBA_CACHE_DIR`` is a fresh
temporary directory, so a command that still loads numba pays its compilation once in
the untimed run and its cache loading in every timed one. The machine's load average is
printed before and after: on a shared 2-core machine the wall times scale with others'
work, the CPU times much less.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
sys.path.insert(0, str(ROOT / "bench"))


def run(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall s, CPU s of the process and its children), run from the temporary directory:
    ``python -c`` puts the working directory first on ``sys.path``, which would shadow
    ``PYTHONPATH`` (the checkout under test) with a checkout it was started in."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        cmd, env=env, cwd=tempfile.gettempdir(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    code = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if code != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({code}): {err[-800:]}")
    return wall, ru.ru_utime + ru.ru_stime


def gaussian_map(
    path: Path, n: int, sq_um: float, corr_um: float, step_um: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(n, step_um)
    filt = np.exp(-0.5 * (math.pi * corr_um) ** 2 * (f[:, None] ** 2 + f[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * filt))
    z *= sq_um / z.std()
    z += 0.01 * np.arange(n)[None, :] + 0.003 * np.arange(n)[:, None]  # a tilt to level
    np.save(path, z)
    path.with_name(path.name + ".json").write_text(
        json.dumps({"dx_um": step_um, "dy_um": step_um}) + "\n"
    )


def make_maps(tdir: Path, n: int) -> dict[str, Path]:
    from bench_whole import make_map

    maps = {"rough": tdir / "rough.npy", "mixed": tdir / "mixed.npy", "smooth": tdir / "smooth.npy"}
    gaussian_map(maps["rough"], n, 2.5, 30.0, 1.0, seed=2)
    make_map(maps["mixed"], n)
    gaussian_map(maps["smooth"], n, 0.05, 2.0, 0.5, seed=1)
    return maps


def goniolab_cmd(what: str, mp: Path) -> list[str]:
    # the console script's own call: main() reads sys.argv (what `goniolab` runs)
    code = "import sys; from goniolab.cli import main; sys.exit(main())"
    extra = ["--theta-i", "45", "--theta-r", "0:70:1"] if what == "brdf" else []
    return [PY, "-c", code, "predict", what, str(mp), *extra]


def whole(maps: dict[str, Path], repeats: int, before: str | None, tdir: Path) -> dict[str, object]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["NUMBA_CACHE_DIR"] = str(tdir / "numba-cache")
    envs = {"after": {**env, "PYTHONPATH": str(ROOT)}}
    if before:
        envs["before"] = {**env, "PYTHONPATH": str(Path(before).resolve()),
                          "NUMBA_CACHE_DIR": str(tdir / "numba-cache-before")}  # fmt: skip
    out: dict[str, object] = {}
    for name, mp in maps.items():
        for what in ("brdf", "gloss"):
            cmds = {label: (goniolab_cmd(what, mp), e) for label, e in envs.items()}
            cmds["numpy"] = ([PY, str(ROOT / "bench" / "baseline_numpy.py"), str(mp), what], env)
            for cmd, e in cmds.values():
                run(cmd, e)  # untimed: caches written, page cache warm
            rows: dict[str, list[tuple[float, float]]] = {k: [] for k in cmds}
            order = list(cmds)
            for r in range(repeats):
                for label in order if r % 2 == 0 else order[::-1]:
                    rows[label].append(run(*cmds[label]))
            med = {
                label: {
                    "wall_s": statistics.median(w for w, _ in v),
                    "cpu_s": statistics.median(c for _, c in v),
                    "min_wall_s": min(w for w, _ in v),
                }
                for label, v in rows.items()
            }
            for label in envs:
                med[label]["ratio_wall"] = med[label]["wall_s"] / med["numpy"]["wall_s"]
                med[label]["ratio_cpu"] = med[label]["cpu_s"] / med["numpy"]["cpu_s"]
            out[f"{name} {what}"] = med
    return out


def in_process(repeats: int) -> dict[str, dict[str, float]]:
    sys.path.insert(0, str(ROOT))
    from bench_physical import smooth_map

    from goniolab.optics.kirchhoff import KirchhoffModel

    hm = smooth_map(1024)
    model = KirchhoffModel(hm, n=1.55, wavelength_nm=550.0)
    tr = np.arange(0.0, 71.0, 1.0)
    jobs = {
        "kirchhoff curve 71 pts 1024^2": lambda: model.luminance_pct(45.0, tr),
        "kirchhoff gloss 16 wavelengths 1024^2": lambda: model.gloss((20, 60, 85)),
    }
    out: dict[str, dict[str, float]] = {}
    for name, fn in jobs.items():
        fn()  # warm: the map's statistics, the energy scales' first FFTs
        walls, cpus = [], []
        for _ in range(repeats):
            model._shared.cache.clear()
            t0, c0 = time.perf_counter(), time.process_time()
            fn()
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
        out[name] = {"wall_s": statistics.median(walls), "cpu_s": statistics.median(cpus),
                     "min_wall_s": min(walls)}  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--before", help="another checkout to run the goniolab commands from")
    ap.add_argument("--in-process", action="store_true")
    ap.add_argument("--only", help="comma-separated maps (rough, mixed, smooth)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    out: dict[str, object] = {"cpus": os.cpu_count(), "load_before": os.getloadavg()[0],
                              "size": args.size, "repeats": args.repeats}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="goniolab-lean-") as tmp:
        tdir = Path(tmp)
        maps = make_maps(tdir, args.size)
        if args.only:
            maps = {k: v for k, v in maps.items() if k in args.only.split(",")}
        out["whole"] = whole(maps, args.repeats, args.before, tdir)
    if args.in_process:
        out["in_process"] = in_process(args.repeats)
    out["load_after"] = os.getloadavg()[0]
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(
        f"whole process, {out['cpus']} CPUs, median of {args.repeats} paired runs, "
        f"{args.size}^2 maps, load average {out['load_before']:.1f} before / "
        f"{out['load_after']:.1f} after"
    )
    print(f"{'map command':15}{'run':>8}{'wall':>9}{'cpu':>9}{'wall x':>8}{'cpu x':>7}")
    whole_rows = out["whole"]
    assert isinstance(whole_rows, dict)
    for key, med in whole_rows.items():
        for label, r in med.items():
            ratio = (f"{r['ratio_wall']:8.2f}{r['ratio_cpu']:7.2f}" if "ratio_wall" in r
                     else f"{'':8}{'':7}")  # fmt: skip
            print(f"{key:15}{label:>8}{r['wall_s']:8.3f}s{r['cpu_s']:8.3f}s{ratio}")
    if "in_process" in out:
        ip = out["in_process"]
        assert isinstance(ip, dict)
        for name, r in ip.items():
            print(f"in process: {name}: {r['wall_s'] * 1e3:.0f} ms wall (min "
                  f"{r['min_wall_s'] * 1e3:.0f}), {r['cpu_s'] * 1e3:.0f} ms CPU")  # fmt: skip
    print("(x: the median over the numpy baseline's median; target <= 0.5)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
