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
``--floor`` measures only the floor of any wave computation on the smooth map, step by step
(:func:`floor_steps`: interpreter, numpy, reading the map, levelling, one 2048^2 or four
1024^2 transforms with numpy.fft / scipy.fft / pocketfft alone, goniolab's Taylor terms),
paired with the facet script.

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


# ------------------------------------------------------------------ the floor (--floor)
_LOAD = "import numpy as np\nz = np.load(MAP)\n"
_LEVEL = (
    _LOAD
    + """ny, nx = z.shape
x = np.arange(nx) - (nx - 1) / 2.0
y = np.arange(ny) - (ny - 1) / 2.0
b = float(z.sum(axis=0) @ x) / (ny * float(x @ x))
c = float(z.sum(axis=1) @ y) / (nx * float(y @ y))
h = (z - z.mean() - b * x[None, :] - c * y[:, None]).astype(np.float32)
w1 = np.hanning(ny // 2).astype(np.float32)
W = w1[:, None] * w1[None, :]
t2 = ny // 2
tiles = [h[i:i + t2, j:j + t2] for i in (0, t2) for j in (0, t2)]
"""
)
# scipy's compiled pocketfft alone, as goniolab.optics._fft loads it (no scipy import)
_POCKET = """import importlib.machinery, importlib.util, os
folder = os.path.join(importlib.util.find_spec("scipy").submodule_search_locations[0],
                      "fft", "_pocketfft")
path = [os.path.join(folder, f) for f in os.listdir(folder) if f.startswith("pypocketfft.")][0]
ld = importlib.machinery.ExtensionFileLoader("pypocketfft", path)
mod = importlib.util.module_from_spec(importlib.util.spec_from_file_location("pypocketfft", path,
                                                                          loader=ld))
ld.exec_module(mod)
def fft(a, axis):
    return mod.c2c(a, (axis,), True, 0, None, 1)
def fft2(a):
    return mod.c2c(a, (0, 1), True, 0, None, 1)
"""


def _taylor(n_terms: int, ky: int, kx: int) -> str:
    """Kirchhoff's transforms as goniolab forms them, and nothing else: per tile the
    float32 phase screen ``W exp(-i v_c h)``, then ``n_terms`` Taylor terms (the screen
    times ``h / h_max`` again each time), each transformed along x over the whole tile,
    ``kx`` columns kept and transformed along y, ``ky`` rows kept, ``|U|^2`` summed."""
    return (
        _LEVEL
        + _POCKET
        + f"""acc = np.zeros(({ky}, {kx}))
for t in tiles:
    u = t / np.float32(np.abs(t).max())
    ph = np.float32(20.0) * t
    term = np.empty(t.shape, np.complex64)
    term.real = W * np.cos(ph)
    term.imag = -W * np.sin(ph)
    for k in range({n_terms}):
        a = fft(term, 1)[:, :{kx}]
        s = fft(np.ascontiguousarray(a.T), 1)[:, :{ky}]
        acc += (s.real * s.real + s.imag * s.imag).T
        if k < {n_terms} - 1:
            term *= u
"""
    )


def floor_steps() -> dict[str, str]:
    """The floor of any wave computation on a 2048^2 map, step by step (each a whole
    ``python -c`` process; ``MAP`` is the map's path)."""
    tile4 = "[{f}((W * t).astype(np.complex64)) for t in tiles]"
    return {
        "python -c pass": "pass",
        "import numpy": "import numpy",
        "+ np.load (32 MB)": _LOAD,
        "+ level, float32, 4 tiles": _LEVEL,
        "+ fft2 2048^2 numpy.fft": _LEVEL + "np.fft.fft2(h.astype(np.complex64))",
        "+ fft2 2048^2 scipy.fft": _LEVEL
        + "import scipy.fft\nscipy.fft.fft2(h.astype(np.complex64))",
        "+ fft2 2048^2 pocketfft": _LEVEL + _POCKET + "fft2(h.astype(np.complex64))",
        "+ 4 fft2 1024^2 numpy.fft": _LEVEL + tile4.format(f="np.fft.fft2"),
        "+ 4 fft2 1024^2 scipy.fft": _LEVEL
        + "import scipy.fft\n"
        + tile4.format(f="scipy.fft.fft2"),
        "+ 4 fft2 1024^2 pocketfft": _LEVEL + _POCKET + tile4.format(f="fft2"),
        # the smooth map's 71-point curve at 45 deg: 8 terms, 199 x 759 cells kept; the
        # mixed map's: 13 terms, 393 x 999 (goniolab's band plan and boxes for them)
        "+ 1 Taylor term x 4 tiles": _taylor(1, 199, 759),
        "+ 8 Taylor terms x 4 tiles (smooth)": _taylor(8, 199, 759),
        "+ 13 Taylor terms x 4 tiles (mixed)": _taylor(13, 393, 999),
    }


def floor(mp: Path, repeats: int) -> dict[str, dict[str, float]]:
    """Medians of ``repeats`` whole processes of each :func:`floor_steps` step on ``mp``,
    and ``bench/baseline_numpy.py MAP brdf`` (the facet script) in the same rounds."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    cmds = {name: [PY, "-c", f"MAP = {str(mp)!r}\n" + code]
            for name, code in floor_steps().items()}  # fmt: skip
    cmds["facet script (baseline_numpy.py brdf)"] = [
        PY, str(ROOT / "bench" / "baseline_numpy.py"), str(mp), "brdf"
    ]  # fmt: skip
    for cmd in cmds.values():
        run(cmd, env)
    rows: dict[str, list[tuple[float, float]]] = {k: [] for k in cmds}
    for r in range(repeats):
        for name in list(cmds) if r % 2 == 0 else list(cmds)[::-1]:
            rows[name].append(run(cmds[name], env))
    return {
        name: {"wall_s": statistics.median(w for w, _ in v),
               "cpu_s": statistics.median(c for _, c in v)}
        for name, v in rows.items()
    }  # fmt: skip


def print_floor(size: int, repeats: int, as_json: bool) -> int:
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="goniolab-floor-") as tmp:
        mp = Path(tmp) / "smooth.npy"
        gaussian_map(mp, size, 0.05, 2.0, 0.5, seed=1)
        rows = floor(mp, repeats)
    out = {"load_before": load0, "load_after": os.getloadavg()[0], "floor": rows}
    if as_json:
        print(json.dumps(out, indent=2))
        return 0
    ref = rows["facet script (baseline_numpy.py brdf)"]
    print(f"the floor, whole processes, {size}^2 smooth map, median of {repeats}, load "
          f"{load0:.1f} before / {out['load_after']:.1f} after")  # fmt: skip
    print(f"{'step':40}{'wall':>9}{'cpu':>9}{'wall x':>8}{'cpu x':>7}  (x: over the facet script)")
    for name, r in rows.items():
        print(f"{name:40}{r['wall_s']:8.3f}s{r['cpu_s']:8.3f}s"
              f"{r['wall_s'] / ref['wall_s']:8.2f}{r['cpu_s'] / ref['cpu_s']:7.2f}")  # fmt: skip
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--before", help="another checkout to run the goniolab commands from")
    ap.add_argument("--in-process", action="store_true")
    ap.add_argument("--only", help="comma-separated maps (rough, mixed, smooth)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument(
        "--floor",
        action="store_true",
        help="only the floor of a wave computation on the smooth map (steps)",
    )
    args = ap.parse_args(argv)
    if args.floor:
        return print_floor(args.size, args.repeats, args.json)
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
