"""``goniolab predict gloss`` over many maps: worker processes, JSON Lines, a dask cluster.

The truth for every row is the single-map prediction of the same map (the facet model and
the gloss report are tested against papers and closed forms elsewhere); a flat map under
the ISO 2813 black-glass index reads 100 GU at every angle by definition of the scale.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from goniolab.batch import GlossOptions, gloss_row, run_dask, run_local
from goniolab.cli import main
from goniolab.errors import UserError
from goniolab.optics.apertures import ISO2813_BLACK_GLASS_N


def _write(path: Path, z: np.ndarray) -> str:
    np.save(path, z)
    path.with_name(path.name + ".json").write_text('{"dx_um": 1.0, "dy_um": 1.0}\n')
    return str(path)


def _maps(tmp_path: Path) -> list[str]:
    tmp_path.mkdir(exist_ok=True)
    rng = np.random.default_rng(5)
    maps = [_write(tmp_path / "flat.npy", np.zeros((48, 48)))]
    for k, rough in enumerate((0.01, 0.03, 0.08)):
        z = np.cumsum(np.cumsum(rng.normal(size=(48, 48)), axis=0), axis=1)
        z = z / np.std(np.diff(z, axis=1)) * rough
        maps.append(_write(tmp_path / f"rough{k}.npy", z))
    return maps


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def test_flat_map_reads_100_gu_under_the_black_glass_index(tmp_path: Path) -> None:
    flat = _maps(tmp_path)[0]
    row = gloss_row(flat, GlossOptions(n=complex(ISO2813_BLACK_GLASS_N)))
    for key in ("G20", "G60", "G85"):
        assert row[key] == pytest.approx(100.0, abs=1e-9)


def test_batch_streams_json_lines_equal_to_single_map_runs(tmp_path: Path) -> None:
    maps = _maps(tmp_path)
    code, out, _ = _run(["predict", "gloss", *maps, "--json", "--jobs", "2"])
    assert code == 0
    rows = [json.loads(line) for line in out.splitlines()]
    assert sorted(r["map"] for r in rows) == sorted(maps)  # one line per map
    for row in rows:
        code, single, _ = _run(["predict", "gloss", row["map"], "--json"])
        one = json.loads(single)
        for key in ("G20", "G60", "G85", "haze_index"):
            assert row[key] == pytest.approx(one[key], rel=1e-12, abs=1e-12)
        assert row["e430"] == pytest.approx(one["e430"], rel=1e-12, abs=1e-12)
        assert row["d523_angle"] == one["d523_angle"]
    # the rough maps read less gloss than the flat one, in order of roughness
    g60 = {Path(r["map"]).stem: r["G60"] for r in rows}
    assert g60["flat"] > g60["rough0"] > g60["rough1"] > g60["rough2"]


def test_a_bad_map_is_reported_and_the_others_finish(tmp_path: Path) -> None:
    maps = _maps(tmp_path)[:2]
    bad = tmp_path / "broken.npy"
    bad.write_bytes(b"not a numpy file")
    code, out, err = _run(["predict", "gloss", maps[0], str(bad), maps[1], "--jobs", "2"])
    assert code == 2
    assert "broken.npy" in err and "1 of 3 maps failed" in err
    assert len(out.splitlines()) == 2  # the two good maps, one line each


def test_local_pool_rows_do_not_depend_on_the_number_of_workers(tmp_path: Path) -> None:
    maps = _maps(tmp_path)
    one = {r["map"]: r for r in run_local(maps, GlossOptions(), jobs=1)}
    two = {r["map"]: r for r in run_local(maps, GlossOptions(), jobs=2)}
    assert one == two


def test_dask_scheduler_rows_are_identical_to_the_local_run(tmp_path: Path) -> None:
    distributed = pytest.importorskip(
        "distributed", reason="dask.distributed not installed (pip install 'goniolab[dask]')"
    )
    maps = _maps(tmp_path)
    opts = GlossOptions(n=complex(1.5))
    local = {r["map"]: r for r in run_local(maps, opts, jobs=2)}
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        remote = {r["map"]: r for r in run_dask(maps, opts, address=cluster.scheduler_address)}
        code, out, _ = _run(
            [
                "predict",
                "gloss",
                *maps,
                "--n",
                "1.5",
                "--json",
                "--scheduler",
                cluster.scheduler_address,
            ]
        )
    assert remote == local
    assert code == 0
    assert {json.loads(line)["map"]: json.loads(line) for line in out.splitlines()} == local


def test_scheduler_without_dask_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if absent
    with pytest.raises(UserError, match=r"goniolab\[dask\]"):
        list(run_dask(["sample:flat"], GlossOptions(), address="tcp://127.0.0.1:1"))


def test_hostile_maps_each_get_a_row_and_the_batch_goes_on(tmp_path: Path) -> None:
    """Issue 23.5: a 20 um spike, an int8 map of heights in um (slopes up to 255) and a map
    in the wrong units (slopes ~5e6) in one batch with a good map: every map has its row,
    the unusable one an ``{"map", "error"}`` row naming the reason, and the good map's row
    equals its single-map prediction."""
    rng = np.random.default_rng(2)
    good = _maps(tmp_path)[1]
    spike = rng.normal(0.0, 0.05, (256, 256))
    spike[128, 128] += 20.0
    maps = [
        good,
        _write(tmp_path / "spike.npy", spike),
        _write(tmp_path / "int8.npy", rng.integers(-128, 127, (256, 256), dtype=np.int8)),
        _write(tmp_path / "units.npy", np.pad([[5e6]], 8)),
    ]
    code, out, err = _run(["predict", "gloss", *maps, "--model", "facet", "--json", "--jobs", "2"])
    rows = {r["map"]: r for r in map(json.loads, out.splitlines())}
    assert sorted(rows) == sorted(maps)
    assert code == 2 and "1 of 4 maps failed" in err
    assert "height unit" in rows[maps[3]]["error"] and "units.npy" in rows[maps[3]]["error"]
    for m in maps[:3]:
        assert "error" not in rows[m] and np.isfinite(rows[m]["G60"])
    _, single, _ = _run(["predict", "gloss", good, "--model", "facet", "--json"])
    assert rows[good]["G60"] == pytest.approx(json.loads(single)["G60"], rel=1e-12)


def test_a_dead_worker_is_an_error_row_not_the_end_of_the_batch() -> None:
    from concurrent.futures import Future
    from concurrent.futures.process import BrokenProcessPool

    from goniolab.batch import _result_row

    fut: Future[dict[str, object]] = Future()
    fut.set_exception(BrokenProcessPool("A process in the process pool was terminated"))
    row = _result_row(fut, "maps/a.sur")
    assert row == {
        "map": "maps/a.sur",
        "error": "maps/a.sur: worker failed: BrokenProcessPool: A process in the process pool "
        "was terminated",
    }


@contextlib.contextmanager
def _environ_restored() -> Iterator[None]:
    """The environment as it was before: dask's nanny sets ``OMP_NUM_THREADS``,
    ``MKL_NUM_THREADS`` ... to 1 in the process that spawns its workers
    (``distributed.nanny.pre-spawn-environ``) and leaves them, and the tests after this
    one (their subprocesses too) ran the models' walks on one thread."""
    saved = os.environ.copy()
    try:
        yield
    finally:
        for name in set(os.environ) - set(saved):
            del os.environ[name]
        os.environ.update(saved)


def test_dask_workers_get_absolute_paths(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 22.10: a relative map path typed where the client runs is not found by a worker
    running in another directory. The cluster's worker process starts in ``elsewhere``; the
    client then works in ``maps`` and names its maps relative to it."""
    distributed = pytest.importorskip("distributed")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "maps").mkdir()
    names = [Path(m).name for m in _maps(tmp_path / "maps")[:2]]
    monkeypatch.chdir(tmp_path / "elsewhere")
    with (
        _environ_restored(),
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
    ):
        monkeypatch.chdir(tmp_path / "maps")
        remote = {
            r["map"]: r for r in run_dask(names, GlossOptions(), address=cluster.scheduler_address)
        }
    assert sorted(remote) == sorted(names)  # named as typed
    local = {r["map"]: r for r in run_local(names, GlossOptions(), jobs=1)}
    assert remote == local


def test_an_integer_map_reads_as_its_heights_in_float(tmp_path: Path) -> None:
    """Issue 23.5: an int8 map (heights in um as integers; slopes up to 255) once asked the
    dense histogram for 1.9 TiB. It is converted exactly (every int8 is a float64) and
    predicts what the same heights stored as float64 predict."""
    rng = np.random.default_rng(4)
    ints = rng.integers(-3, 4, (64, 64), dtype=np.int8)
    as_int = _write(tmp_path / "int8.npy", ints)
    as_float = _write(tmp_path / "f64.npy", ints.astype(np.float64))
    opts = GlossOptions(model="facet")
    a, b = gloss_row(as_int, opts), gloss_row(as_float, opts)
    assert "error" not in a
    for key in ("G20", "G60", "G85", "haze_index"):
        assert a[key] == b[key]
