"""The default path, whole process, in every regime (issue 26): paired A/B runs.

Run:  .venv/bin/python bench/bench_lean.py [--size 2048] [--repeats 5] [--before DIR]
      [--in-process] [--only MAPS] [--no-wave] [--json]
      .venv/bin/python bench/bench_lean.py --check | --same-as DIR | --floor | --facet-floor

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
``--repeats`` of wall and CPU time (user + system, from ``wait4``), of the minor page faults
(``ru_minflt``) and the ratios of the medians. ``--before DIR`` adds the same goniolab commands run from another checkout
(``PYTHONPATH=DIR``, e.g. ``/work/main``), paired in the same repetitions: the A/B of a
change. ``--in-process`` adds the issue's in-process figures on a 1024^2 smooth map
(bench/bench_physical.py's): the Kirchhoff 71-point curve and the 16-wavelength gloss with
the default (numpy) sums, medians of ``--repeats`` with the FFT cache cleared each time.
The smooth and mixed maps (where ``auto`` picks the wave models) also pair
``bench/baseline_wave_numpy.py MAP brdf|gloss`` (the same wave physics in plain numpy, one
transform per reading and wavelength: 10-20 s a run; ``--no-wave`` leaves it out): the
``wave x`` columns. ``--check`` only compares that script with goniolab's ``--json`` on
those maps, reading by reading where goniolab's provenance names the script's model
(bounds ``CHECK_*``; exit 1 when one is exceeded).
``--facet-floor`` measures only the floor of ``predict brdf`` on the rough map: the
interpreter, numpy, reading the map, every module the command imports (imported, nothing
run), the command on one thread and with the defaults, paired with the facet script.
``--same-as DIR`` only checks that ``predict brdf|gloss MAP --json`` prints the same bytes
(stdout and stderr) from this checkout and from DIR on every map (a speed change that must
not change a reading). ``--floor`` measures only the floor of any wave computation on the smooth map, step by step
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
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
sys.path.insert(0, str(ROOT / "bench"))


def run(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall s, CPU s of the process and its children), run from the temporary directory:
    ``python -c`` puts the working directory first on ``sys.path``, which would shadow
    ``PYTHONPATH`` (the checkout under test) with a checkout it was started in."""
    wall, cpu, _ = run_faults(cmd, env)
    return wall, cpu


def run_faults(cmd: list[str], env: dict[str, str]) -> tuple[float, float, int]:
    """:func:`run`, and the process's minor page faults (``wait4``'s ``ru_minflt``: each
    first touch of a page; a transparent huge page counts once)."""
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
    return wall, ru.ru_utime + ru.ru_stime, ru.ru_minflt


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
    # the console script's own call (what `goniolab` runs): console() runs main() on
    # sys.argv and ends the process; a checkout from before console() (--before): main()
    code = "import sys\nfrom goniolab import cli\nsys.exit(getattr(cli, 'console', cli.main)())"
    extra = ["--theta-i", "45", "--theta-r", "0:70:1"] if what == "brdf" else []
    return [PY, "-c", code, "predict", what, str(mp), *extra]


#: The maps where ``auto`` picks wave models: the wave script is paired there too.
WAVE_MAPS = ("smooth", "mixed")


def whole(
    maps: dict[str, Path], repeats: int, before: str | None, tdir: Path, wave: bool = True
) -> dict[str, object]:
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
            if wave and name in WAVE_MAPS:
                cmds["wave"] = ([PY, str(ROOT / "bench" / "baseline_wave_numpy.py"), str(mp), what],
                                env)  # fmt: skip
            for cmd, e in cmds.values():
                run(cmd, e)  # untimed: caches written, page cache warm
            rows: dict[str, list[tuple[float, float, int]]] = {k: [] for k in cmds}
            order = list(cmds)
            for r in range(repeats):
                for label in order if r % 2 == 0 else order[::-1]:
                    rows[label].append(run_faults(*cmds[label]))
            med = {
                label: {
                    "wall_s": statistics.median(w for w, _, _ in v),
                    "cpu_s": statistics.median(c for _, c, _ in v),
                    "min_wall_s": min(w for w, _, _ in v),
                    "page_faults": statistics.median(f for _, _, f in v),
                }
                for label, v in rows.items()
            }
            for label in envs:
                med[label]["ratio_wall"] = med[label]["wall_s"] / med["numpy"]["wall_s"]
                med[label]["ratio_cpu"] = med[label]["cpu_s"] / med["numpy"]["cpu_s"]
                if "wave" in med:
                    med[label]["wave_wall"] = med[label]["wall_s"] / med["wave"]["wall_s"]
                    med[label]["wave_cpu"] = med[label]["cpu_s"] / med["wave"]["cpu_s"]
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


# ------------------------------------------------------------------ the facet floor (--facet-floor)
def _command_modules(mp: Path, env: dict[str, str]) -> list[str]:
    """The modules a ``predict brdf MAP`` process holds when it ends (run in process)."""
    code = (
        "import sys, io, contextlib\nfrom goniolab.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    main(['predict', 'brdf', {str(mp)!r}, '--theta-i', '45', '--theta-r', '0:70:1'])\n"
        "print('\\n'.join(sys.modules))"
    )
    out = subprocess.run([PY, "-c", code], env=env, cwd=tempfile.gettempdir(),
                         capture_output=True, text=True, check=True)  # fmt: skip
    return [m for m in out.stdout.split() if not m.startswith("__")]


def facet_floor(mp: Path, repeats: int) -> dict[str, dict[str, float]]:
    """The floor of ``predict brdf`` on the rough map, whole processes, paired in the same
    rounds: the interpreter, numpy's import, reading the map, every module the command
    imports (imported, nothing run) with and without reading the map, the command on one
    thread and with the defaults, and the facet script. OpenBLAS capped at one thread in
    all (as the CLI does before numpy loads)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env = {**env, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    mods = _command_modules(mp, env)
    imports = f"import importlib\nfor m in {mods!r}:\n    try:\n        importlib.import_module(m)\n    except Exception:\n        pass\n"  # fmt: skip
    load = f"import numpy as np\nnp.load({str(mp)!r})\n"
    steps = {
        "python -c pass": "pass",
        "import numpy": "import numpy",
        "+ np.load of the map": load,
        f"the command's {len(mods)} modules imported": imports,
        "+ np.load, after those imports": imports + load,
    }
    cmds = {name: ([PY, "-c", code], env) for name, code in steps.items()}
    cmds["predict brdf, one thread"] = (goniolab_cmd("brdf", mp), {**env, "GONIOLAB_THREADS": "1"})
    cmds["predict brdf (defaults)"] = (goniolab_cmd("brdf", mp), env)
    cmds["facet script (baseline_numpy.py brdf)"] = (
        [PY, str(ROOT / "bench" / "baseline_numpy.py"), str(mp), "brdf"], env
    )  # fmt: skip
    for cmd, e in cmds.values():
        run(cmd, e)
    rows: dict[str, list[tuple[float, float]]] = {k: [] for k in cmds}
    for r in range(repeats):
        for name in list(cmds) if r % 2 == 0 else list(cmds)[::-1]:
            rows[name].append(run(*cmds[name]))
    return {
        name: {"wall_s": statistics.median(w for w, _ in v),
               "cpu_s": statistics.median(c for _, c in v)}
        for name, v in rows.items()
    }  # fmt: skip


def facet_stages(mp: Path, repeats: int) -> dict[str, float]:
    """The rough map's 71-point curve (defaults) in this process, stage by stage on one
    thread: medians of ``repeats`` of each stage's wall time (a fresh model each time,
    the cone table's cache cleared; this process's heap is warm, so a fresh process
    faults in more pages than these figures include)."""
    import gc

    os.environ["GONIOLAB_THREADS"] = "1"
    from goniolab.model_cache import _check_numeric_range, build_model, resolve_map
    from goniolab.optics.apertures import Cone
    from goniolab.optics.facet_apertures import cone_table

    times: dict[str, list[float]] = {}

    def stage(name: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        times.setdefault(name, []).append(time.perf_counter() - t0)
        return out

    tr = np.arange(0.0, 71.0)
    cone = Cone(6.0)
    for _ in range(repeats + 1):  # the first round warms the imports and the heap
        cone_table.cache_clear()
        hm = stage("read the map (resolve_map)", resolve_map, str(mp))
        stage("its height range (the overflow check)", _check_numeric_range, "map", hm)
        auto = stage("level it (auto model, plane fit)", build_model, hm)
        stage("Sq and the rule's choice at 45 deg", auto.choice, 45.0)
        facet = auto.facet
        stage("slope cells (walk, count)", facet._cells, keep_index=False)
        stage("Smith Lambda table", getattr, facet.slopes, "_lambda_table")
        stage("deposit, nodes' Lambda, cone table, 71 readings", auto.luminance_pct, 45.0, tr,
              source=cone, detector=cone)  # fmt: skip
        del hm, auto, facet  # the next round reads and models the map afresh (the readers
        gc.collect()  # share a map still held; the model's closures are cycles)
    return {name: statistics.median(v[1:]) for name, v in times.items()}


def print_facet_floor(size: int, repeats: int, as_json: bool) -> int:
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="goniolab-facet-floor-") as tmp:
        mp = Path(tmp) / "rough.npy"
        gaussian_map(mp, size, 2.5, 30.0, 1.0, seed=2)
        rows = facet_floor(mp, repeats)
        stages = facet_stages(mp, repeats)
    out = {"load_before": load0, "load_after": os.getloadavg()[0], "floor": rows,
           "stages_s": stages}  # fmt: skip
    if as_json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"the curve in process, one thread, median of {repeats} (warm heap):")
    for name, t in stages.items():
        print(f"  {name:50}{1e3 * t:7.1f} ms")
    print_floor_rows(f"the facet floor, whole processes, {size}^2 rough map", rows, repeats, out)
    return 0


# ------------------------------------------------------------------ the wave script (--check)
#: Agreement of bench/baseline_wave_numpy.py with goniolab, checked by ``--check``: gloss
#: and E430 readings to this fraction of their value ...
CHECK_GLOSS_REL = 1e-3
#: ... the curve to this fraction of its peak at every angle ...
CHECK_CURVE_PEAK = 0.03
#: ... and to this fraction of the value where the curve is above 1e-3 of its peak.
CHECK_CURVE_REL = 0.07


def _json_of(cmd: list[str], env: dict[str, str]) -> dict[str, object]:
    out = subprocess.run(cmd, env=env, cwd=tempfile.gettempdir(), capture_output=True,
                         text=True, check=True)  # fmt: skip
    doc: dict[str, object] = json.loads(out.stdout)
    return doc


def check_wave(maps: dict[str, Path]) -> dict[str, dict[str, object]]:
    """The wave script against ``goniolab predict ... --json`` (defaults) on each wave map:
    every reading goniolab computes with the model the script uses (its provenance says
    which), the largest deviations and whether they are within the ``CHECK_*`` bounds."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out: dict[str, dict[str, object]] = {}
    for name, mp in maps.items():
        if name not in WAVE_MAPS:
            continue
        wave = [PY, str(ROOT / "bench" / "baseline_wave_numpy.py"), str(mp)]
        g = _json_of([*goniolab_cmd("brdf", mp), "--json"], env)
        w = _json_of([*wave, "brdf"], env)
        ours = np.asarray(g["luminance_pct"], dtype=np.float64)
        theirs = np.asarray(w["luminance_pct"], dtype=np.float64)
        same = np.array([m == w["model"] for m in g["models"]])  # type: ignore[union-attr]
        peak = float(ours.max())
        d = np.abs(theirs - ours)[same]
        big = (ours >= 1e-3 * peak)[same]
        rel = float(np.max(d[big] / ours[same][big])) if np.any(big) else 0.0
        out[f"{name} brdf"] = {
            "angles_compared": int(same.sum()), "model": w["model"],
            "max_dev_of_peak": float(d.max()) / peak, "max_rel_dev": rel,
            "ok": float(d.max()) / peak <= CHECK_CURVE_PEAK and rel <= CHECK_CURVE_REL,
        }  # fmt: skip
        g = _json_of([*goniolab_cmd("gloss", mp), "--json"], env)
        w = _json_of([*wave, "gloss"], env)
        wm: dict[str, str] = w["models"]  # type: ignore[assignment]
        gm: dict[str, str] = {**g["model"], **{f"e430.{k}": v for k, v in g["e430_model"].items()}}  # type: ignore[dict-item]
        devs: dict[str, float] = {}
        for key, model in wm.items():
            if gm.get(key) != model:
                continue
            if key.startswith("e430."):
                k = key.removeprefix("e430.")
                mine, theirs_v = w["e430"][k], g["e430"][k]  # type: ignore[index]
            else:
                mine, theirs_v = w[key], g[key]
            devs[key] = float(mine) / float(theirs_v) - 1.0  # type: ignore[arg-type]
        worst = max(abs(v) for v in devs.values())
        out[f"{name} gloss"] = {"compared": sorted(devs), "max_rel_dev": worst,
                                "ok": worst <= CHECK_GLOSS_REL}  # fmt: skip
    return out


def print_check(maps: dict[str, Path], as_json: bool) -> int:
    res = check_wave(maps)
    if as_json:
        print(json.dumps(res, indent=2))
    else:
        for key, r in res.items():
            print(f"{key:14} {'ok ' if r['ok'] else 'OUT'} " + ", ".join(
                f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                for k, v in r.items() if k != "ok"))  # fmt: skip
        print(
            f"(bounds: gloss readings {CHECK_GLOSS_REL:g} of the value; the curve "
            f"{CHECK_CURVE_PEAK:g} of its peak, {CHECK_CURVE_REL:g} of the value above 1e-3 "
            "of the peak; compared where goniolab's provenance names the script's model)"
        )
    return 0 if all(r["ok"] for r in res.values()) else 1


def same_as(maps: dict[str, Path], before: str) -> dict[str, bool]:
    """Whether ``goniolab predict brdf|gloss MAP --json`` (defaults) prints the same bytes
    (stdout and stderr) from this checkout and from ``before``, per map and command."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    out: dict[str, bool] = {}
    for name, mp in maps.items():
        for what in ("brdf", "gloss"):
            docs = []
            for root in (str(ROOT), str(Path(before).resolve())):
                r = subprocess.run([*goniolab_cmd(what, mp), "--json"],
                                   env={**env, "PYTHONPATH": root}, cwd=tempfile.gettempdir(),
                                   capture_output=True, check=True)  # fmt: skip
                docs.append((r.stdout, r.stderr))
            out[f"{name} {what}"] = docs[0] == docs[1]
    return out


def print_floor_rows(
    title: str, rows: dict[str, dict[str, float]], repeats: int, out: dict[str, Any]
) -> None:
    """A floor table (:func:`floor`, :func:`facet_floor`): each step's medians and their
    ratio to the facet script's, under ``title`` and the load before / after."""
    ref = rows["facet script (baseline_numpy.py brdf)"]
    print(f"{title}, median of {repeats}, load "
          f"{out['load_before']:.1f} before / {out['load_after']:.1f} after")  # fmt: skip
    print(f"{'step':40}{'wall':>9}{'cpu':>9}{'wall x':>8}{'cpu x':>7}  (x: over the facet script)")
    for name, r in rows.items():
        print(f"{name:40}{r['wall_s']:8.3f}s{r['cpu_s']:8.3f}s"
              f"{r['wall_s'] / ref['wall_s']:8.2f}{r['cpu_s'] / ref['cpu_s']:7.2f}")  # fmt: skip


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
    print_floor_rows(f"the floor, whole processes, {size}^2 smooth map", rows, repeats, out)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--before", help="another checkout to run the goniolab commands from")
    ap.add_argument("--in-process", action="store_true")
    ap.add_argument("--only", help="comma-separated maps (rough, mixed, smooth)")
    ap.add_argument(
        "--no-wave", action="store_true", help="leave out the wave script's column (10-20 s a run)"
    )
    ap.add_argument(
        "--same-as",
        metavar="DIR",
        help="only check that --json of brdf and gloss is byte-identical to DIR's",
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="only compare the wave script with goniolab on the smooth and mixed maps",
    )
    ap.add_argument("--json", action="store_true")
    ap.add_argument(
        "--floor",
        action="store_true",
        help="only the floor of a wave computation on the smooth map (steps)",
    )
    ap.add_argument(
        "--facet-floor",
        action="store_true",
        help="only the floor of predict brdf on the rough map (imports, reading, the command)",
    )
    args = ap.parse_args(argv)
    if args.facet_floor:
        return print_facet_floor(args.size, args.repeats, args.json)
    if args.floor and args.size != 2048:
        # the Taylor steps keep the cells goniolab keeps on the 2048^2 map's 1024^2 tiles
        ap.error(
            f"--floor measures the 2048^2 map (its kept cells are that map's); not --size {args.size}"
        )
    if args.floor:
        return print_floor(args.size, args.repeats, args.json)
    out: dict[str, object] = {"cpus": os.cpu_count(), "load_before": os.getloadavg()[0],
                              "size": args.size, "repeats": args.repeats}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="goniolab-lean-") as tmp:
        tdir = Path(tmp)
        maps = make_maps(tdir, args.size)
        if args.only:
            maps = {k: v for k, v in maps.items() if k in args.only.split(",")}
        if args.check:
            return print_check(maps, args.json)
        if args.same_as:
            same = same_as(maps, args.same_as)
            for key, ok in same.items():
                print(f"{key:14} {'identical' if ok else 'DIFFERENT'} (--json stdout and stderr)")
            return 0 if all(same.values()) else 1
        out["whole"] = whole(maps, args.repeats, args.before, tdir, not args.no_wave)
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
    print(f"{'map command':15}{'run':>8}{'wall':>9}{'cpu':>9}{'faults':>8}{'wall x':>8}"
          f"{'cpu x':>7}{'wave wall x':>12}{'wave cpu x':>11}")  # fmt: skip
    whole_rows = out["whole"]
    assert isinstance(whole_rows, dict)
    for key, med in whole_rows.items():
        for label, r in med.items():
            ratio = (f"{r['ratio_wall']:8.2f}{r['ratio_cpu']:7.2f}" if "ratio_wall" in r
                     else f"{'':8}{'':7}")  # fmt: skip
            if "wave_wall" in r:
                ratio += f"{r['wave_wall']:12.3f}{r['wave_cpu']:11.3f}"
            faults = f"{r['page_faults']:8.0f}"
            print(f"{key:15}{label:>8}{r['wall_s']:8.3f}s{r['cpu_s']:8.3f}s{faults}{ratio}")
    if "in_process" in out:
        ip = out["in_process"]
        assert isinstance(ip, dict)
        for name, r in ip.items():
            print(f"in process: {name}: {r['wall_s'] * 1e3:.0f} ms wall (min "
                  f"{r['min_wall_s'] * 1e3:.0f}), {r['cpu_s'] * 1e3:.0f} ms CPU")  # fmt: skip
    print("(faults: the median of the process's minor page faults; x: the median over the facet "
          "script's median (bench/baseline_numpy.py); wave x: over the wave script's "
          "(bench/baseline_wave_numpy.py); target <= 0.5)")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
