"""The twin's disk cache of response tables (sim/twin_cache.py): files named with the
table code's key, written atomically, pruned after each write (other versions' files
unused for a day, temporary files of dead writers, then the least recently used down to
the size cap), and ``goniolab sim cache`` shows and clears it. Every test uses a
temporary cache directory."""

from __future__ import annotations

import contextlib
import io
import json
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import sim.truth as truth_mod
from goniolab.cli import main
from goniolab.surfaces.synthetic import make_sample
from sim.truth import TruthOptics, TwinSettings, build_truth, table_code_key
from sim.twin_cache import (
    FOREIGN_MAX_AGE_S,
    TMP_MAX_AGE_S,
    cache_file,
    clear,
    prune,
    scan,
    write_atomic,
)

NOW = 1_800_000_000.0
CODE = "0123456789abcdef"
OTHER = "fedcba9876543210"
HOUR = 3600.0


def _file(d: Path, name: str, size: int, age_s: float, *, now: float = NOW) -> Path:
    """A cache file of ``size`` bytes last used ``age_s`` before ``now``."""
    path = d / name
    path.write_bytes(b"x" * size)
    os.utime(path, (now - age_s, now - age_s))
    return path


def _key(i: int) -> str:
    return f"{i:020x}"


def test_prune_drops_old_foreign_files_and_dead_writers_temporaries(tmp_path: Path) -> None:
    mine_old = _file(tmp_path, cache_file(tmp_path, CODE, _key(1)).name, 100, 30 * 24 * HOUR)
    foreign_old = _file(tmp_path, cache_file(tmp_path, OTHER, _key(2)).name, 100, 25 * HOUR)
    foreign_young = _file(tmp_path, cache_file(tmp_path, OTHER, _key(3)).name, 100, 23 * HOUR)
    unkeyed_old = _file(tmp_path, f"twin-{_key(4)}.npz", 100, 48 * HOUR)  # before the code key
    tmp_dead = _file(tmp_path, f".twin-{CODE[:12]}-{_key(5)}.npz.k3j2.tmp", 50, 2 * HOUR)
    tmp_live = _file(tmp_path, f".twin-{CODE[:12]}-{_key(6)}.npz.a8f1.tmp", 50, 60.0)
    tmp_pid_dead = _file(tmp_path, f"twin-{_key(7)}.4242.tmp.npz", 50, 2 * HOUR)
    other = _file(tmp_path, "notes.txt", 10, 100 * 24 * HOUR)  # not the cache's
    assert FOREIGN_MAX_AGE_S == 24 * HOUR and TMP_MAX_AGE_S == HOUR
    removed = prune(tmp_path, code_key=CODE, now=NOW)
    assert {e.path for e in removed} == {foreign_old, unkeyed_old, tmp_dead, tmp_pid_dead}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        p.name for p in (mine_old, foreign_young, tmp_live, other)
    )


def test_prune_keeps_the_cap_least_recently_used_first_never_the_new_file(
    tmp_path: Path,
) -> None:
    # five files of 100 bytes, used 5, 4, 3, 2, 1 h ago; cap 250 bytes: the three least
    # recently used go (500 -> 200), except the one just written, which stays
    files = [
        _file(tmp_path, cache_file(tmp_path, CODE, _key(i)).name, 100, (5 - i) * HOUR)
        for i in range(5)
    ]
    removed = prune(tmp_path, code_key=CODE, max_bytes=250, now=NOW)
    assert [e.path for e in removed] == files[:3]
    assert scan(tmp_path).total_bytes == 200
    for i in range(3):
        _file(tmp_path, files[i].name, 100, (5 - i) * HOUR)
    removed = prune(tmp_path, code_key=CODE, max_bytes=250, keep=files[0], now=NOW)
    assert [e.path for e in removed] == files[1:4]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([files[0].name, files[4].name])


def test_scan_and_clear_count_only_the_caches_files(tmp_path: Path) -> None:
    _file(tmp_path, cache_file(tmp_path, CODE, _key(1)).name, 300, 0.0)
    _file(tmp_path, cache_file(tmp_path, OTHER, _key(2)).name, 200, 0.0)
    _file(tmp_path, f"twin-{_key(3)}.npz", 100, 0.0)
    _file(tmp_path, "twin-notes.txt", 7, 0.0)
    info = scan(tmp_path)
    assert info.total_bytes == 600
    assert [e.size_bytes for e in info.of_code(CODE)] == [300]
    assert sorted(e.size_bytes for e in info.others(CODE)) == [100, 200]
    assert len(clear(tmp_path)) == 3
    assert [p.name for p in tmp_path.iterdir()] == ["twin-notes.txt"]
    assert scan(tmp_path / "absent").entries == ()


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    path = cache_file(tmp_path / "twin", CODE, _key(1))
    write_atomic(path, lambda tmp: tmp.write_bytes(b"first"))

    def fail(tmp: Path) -> None:
        tmp.write_bytes(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        write_atomic(path, fail)
    assert path.read_bytes() == b"first"
    assert [p.name for p in path.parent.iterdir()] == [path.name]


def test_concurrent_writers_leave_one_whole_file(tmp_path: Path) -> None:
    path = cache_file(tmp_path, CODE, _key(1))
    arrays = {n: np.full(200_000, n, dtype=np.float32) for n in range(8)}

    def writer(value: float) -> None:
        def write(tmp: Path) -> None:
            with open(tmp, "wb") as f:
                np.savez(f, **{f"a{k}": v + value for k, v in arrays.items()})

        for _ in range(5):
            write_atomic(path, write)

    threads = [threading.Thread(target=writer, args=(v,)) for v in (0.0, 100.0)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    with np.load(path) as data:
        offset = float(data["a0"][0])
        assert offset in (0.0, 100.0)
        for k in range(8):  # every array of the same writer: never a mix, never cut
            np.testing.assert_array_equal(data[f"a{k}"], arrays[k] + offset)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_the_twin_names_its_file_by_code_marks_it_used_and_prunes_after_writing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the twin prunes at the real time: ages relative to it
    t = time.time()
    old_foreign = _file(tmp_path, f"twin-{_key(9)}.npz", 1000, 3 * 24 * HOUR, now=t)
    young_foreign = _file(tmp_path, cache_file(tmp_path, OTHER, _key(8)).name, 1000, HOUR, now=t)
    hm = make_sample("wittmann-1", size=64)
    settings = TwinSettings(cache_dir=str(tmp_path))
    first = TruthOptics(build_truth(hm, settings=settings, name="w1"))
    first.luminance_pct(45.0, [40.0, 45.0])
    first.save_cache()
    (mine,) = scan(tmp_path).of_code(table_code_key())
    assert mine.path.name.startswith(f"twin-{table_code_key()[:12]}-")
    assert not old_foreign.exists() and young_foreign.exists()
    # a reading process marks the file used (the least recently used go first)
    os.utime(mine.path, (t - 10 * HOUR, t - 10 * HOUR))
    again = TruthOptics(build_truth(hm, settings=settings, name="w1"))
    again.luminance_pct(45.0, [40.0, 45.0])
    assert again.ffts == 0
    assert os.path.getmtime(mine.path) > t - 60.0
    # the twin of another code version writes its own file beside it, keeps this one (young)
    monkeypatch.setattr(truth_mod, "table_code_key", lambda: OTHER)
    other = TruthOptics(build_truth(hm, settings=settings, name="w1"))
    other.luminance_pct(45.0, [40.0, 45.0])
    other.save_cache()
    info = scan(tmp_path)
    assert len(info.of_code(OTHER)) == 2 and mine.path.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def _cli(args: list[str]) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(args)
    return code, out.getvalue()


def test_goniolab_sim_cache_shows_the_location_and_size_and_clears(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    d = tmp_path / "goniolab" / "twin"
    d.mkdir(parents=True)
    code = table_code_key()
    t = time.time()
    _file(d, cache_file(d, code, _key(1)).name, 3000, 0.0, now=t)
    _file(d, cache_file(d, OTHER, _key(2)).name, 2000, 0.0, now=t)
    _file(d, f"twin-{_key(3)}.npz", 1000, 0.0, now=t)
    _file(d, "README", 5, 0.0, now=t)
    rc, out = _cli(["sim", "cache", "--json"])
    doc = json.loads(out)
    assert rc == 0 and doc["directory"] == str(d)
    assert (doc["files"], doc["bytes"]) == (3, 6000)
    assert doc["this_version"] == {"files": 1, "bytes": 3000}
    assert doc["other_versions"] == {"files": 2, "bytes": 3000}
    rc, out = _cli(["sim", "cache"])
    assert f"twin response-table cache: {d}" in out
    assert f"3 files, 0.0 MB: this version (code {code[:12]}) 1 files" in out
    # --prune with other versions' files unused for 0 h: both go, this version's stays
    rc, out = _cli(["sim", "cache", "--prune", "--other-versions-age-h", "0", "--json"])
    doc = json.loads(out)
    assert doc["removed"] == {"files": 2, "bytes": 3000} and doc["this_version"]["files"] == 1
    rc, out = _cli(["sim", "cache", "--clear"])
    assert rc == 0 and out.startswith("cleared: 1 files, 0.0 MB")
    assert [p.name for p in d.iterdir()] == ["README"]
    # --prune --max-mb: the cap (least recently used first)
    _file(d, cache_file(d, code, _key(4)).name, 3000, 2 * HOUR, now=t)
    _file(d, cache_file(d, code, _key(5)).name, 3000, HOUR, now=t)
    rc, out = _cli(["sim", "cache", "--prune", "--max-mb", "0.004", "--json"])
    doc = json.loads(out)
    assert doc["removed"] == {"files": 1, "bytes": 3000}
    assert [e.path.name for e in scan(d).of_code(code)] == [cache_file(d, code, _key(5)).name]
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["sim", "cache", "--max-mb", "5"]) == 2
    assert "--max-mb and --other-versions-age-h go with --prune" in err.getvalue()
