"""A run of the twin at an instant clock is reproducible bit for bit (the closing note's
"known defect": RMSE 0.250 % on one machine, 0.247 % on another, for the same seed).

The cause was not the machine's load: the twin's disk cache of response tables was keyed by
the truth's content and settings only, so tables written by another version of the twin
(another branch or checkout: the cache lives under the user's cache directory) were read
back as this one's. They differ by ~1e-4 relative, and the spectro's Poisson noise, whose
sampler consumes a variable number of uniforms, turns any such change into a different noise
stream for every later reading. The key now holds the code that builds the tables
(``sim.truth.table_code_key``). The load test below holds the rest: the same seeded scan with
and without a CPU burner stores the same numbers.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from goniolab.surfaces.synthetic import make_sample
from sim import truth as truth_mod
from sim.truth import TruthOptics, TwinSettings, build_truth

ANGLES = [40.0, 45.0, 52.0]


def _tamper(cache_dir: Path, factor: float) -> None:
    """Rewrite every cached table scaled by ``factor`` (another twin version's numbers)."""
    (path,) = cache_dir.glob("twin-*.npz")
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    for k in arrays:
        if k.startswith("p_"):
            arrays[k] = arrays[k] * np.float32(factor)
    np.savez(path, **arrays)  # type: ignore[arg-type]


def test_tables_written_by_another_twin_version_are_not_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    hm = make_sample("wittmann-1", size=64)
    settings = TwinSettings(cache_dir=str(tmp_path))
    fresh = TruthOptics(build_truth(hm, settings=settings, name="w1"))
    want = fresh.luminance_pct(45.0, ANGLES)
    fresh.save_cache()
    _tamper(tmp_path, 2.0)
    # the same code reads its own cache (the tampering shows: the test can see the cache)
    same = TruthOptics(build_truth(hm, settings=settings, name="w1"))
    got = same.luminance_pct(45.0, ANGLES)
    assert same.ffts == 0
    assert got[1] > 1.5 * want[1]
    # another version of the table code: the cache is not its own, the tables are rebuilt
    monkeypatch.setattr(truth_mod, "table_code_key", lambda: "another-version")
    other = TruthOptics(build_truth(hm, settings=settings, name="w1"))
    np.testing.assert_array_equal(other.luminance_pct(45.0, ANGLES), want)
    assert other.ffts > 0


def test_the_code_key_follows_the_table_code() -> None:
    key = truth_mod.table_code_key()
    assert len(key) == 16 and int(key, 16) >= 0
    import hashlib
    import importlib

    import scipy

    # every module whose code decides a table's numbers (the review of 2026-11-26 added the
    # twin's spectra and flakes and the optics' levelling, Fresnel and apertures)
    names = (
        "sim.true_surface",
        "sim.kirchhoff_orders",
        "sim.twin_spectra",
        "sim.twin_flakes",
        "goniolab.optics.heightmap",
        "goniolab.optics.fresnel",
        "goniolab.optics.apertures",
    )
    h = hashlib.sha1(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    for mod in (truth_mod.__file__, *(importlib.import_module(n).__file__ for n in names)):
        h.update(Path(str(mod)).read_bytes())
    assert key == h.hexdigest()[:16]


def _burn(stop: threading.Event | None = None, seconds: float = 120.0) -> None:
    import time

    end = time.monotonic() + seconds
    x = 0
    while time.monotonic() < end and (stop is None or not stop.is_set()):
        x = (x * 1103515245 + 12345) % 2**31


#: :func:`_burn`'s loop for a process of its own
_BURN_SOURCE = """
import time
end = time.monotonic() + 120.0
x = 0
while time.monotonic() < end:
    x = (x * 1103515245 + 12345) % 2**31
"""


def _scan(store: Path) -> list[tuple[object, ...]]:
    from goniolab.api import run_scan
    from goniolab.config import configs_dir
    from goniolab.store import RunStore

    run = run_scan(
        configs_dir() / "lab-sim.toml",
        theta_r_deg=[30.0, 40.0, 45.0, 50.0],
        repeats=2,
        store=store,
        time_scale=0.0,
        progress=False,
    )
    s = RunStore(store)
    return [
        (
            p.index,
            p.repeat,
            p.theta_r_deg,
            p.luminance_pct,
            p.raw.get("values"),
            p.raw.get("exposure_us"),
            p.raw.get("clock_s"),
        )
        for p in s.points(run.id)
    ]


def test_an_instant_clock_scan_is_the_same_under_cpu_load(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    quiet = _scan(tmp_path / "quiet.sqlite")
    stop = threading.Event()
    burner_thread = threading.Thread(target=_burn, args=(stop,), daemon=True)
    # the same loop in a bare interpreter (a spawned multiprocessing child imported this
    # module, numpy and the twin first: a second of CPU before it loaded anything)
    burner_proc = subprocess.Popen([sys.executable, "-c", _BURN_SOURCE])
    burner_thread.start()
    try:
        loaded = _scan(tmp_path / "loaded.sqlite")
    finally:
        stop.set()
        burner_proc.terminate()
        burner_proc.wait(10)
        burner_thread.join(10)
    assert len(quiet) == 8
    assert loaded == quiet  # bit for bit: floats compared exactly
