"""Tests for goniolab.optics.heightmap: the container, levelling and file I/O."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from goniolab.optics.heightmap import (
    HeightMap,
    HeightMapError,
    fill_missing,
    level_plane,
    load_heightmap,
    save_heightmap,
)


def _sample_map(ny: int = 5, nx: int = 7, *, with_nan: bool = True) -> HeightMap:
    rng = np.random.default_rng(7)
    z = rng.normal(0.0, 0.8, (ny, nx))
    if with_nan:
        z[1, 2] = np.nan
        z[ny - 1, 0] = np.nan
    return HeightMap(z_um=z, dx_um=0.5, dy_um=0.75, source="mem", meta={"note": "t"})


# ---------------------------------------------------------------- the dataclass


def test_heightmap_properties() -> None:
    hm = _sample_map()
    assert hm.shape == (5, 7)
    assert hm.n_valid == 33
    assert hm.valid_fraction == pytest.approx(33 / 35)
    assert hm.z_um.dtype == np.float64
    with pytest.raises(ValueError):
        hm.z_um[0, 0] = 1.0  # read-only


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "x"])
def test_heightmap_rejects_bad_steps(bad: object) -> None:
    with pytest.raises(HeightMapError, match=r"mysrc: dx_um"):
        HeightMap(z_um=np.zeros((2, 2)), dx_um=bad, dy_um=1.0, source="mysrc")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("z", "msg"),
    [(np.zeros(4), "2-D"), (np.zeros((0, 3)), "zero points"), (np.full((2, 2), np.inf), "inf")],
)
def test_heightmap_rejects_bad_heights(z: np.ndarray, msg: str) -> None:
    with pytest.raises(HeightMapError, match=rf"mysrc: .*{msg}"):
        HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source="mysrc")


# ---------------------------------------------------------------- levelling


def test_level_plane_recovers_bumps_and_keeps_nan() -> None:
    ny, nx = 40, 50
    dx, dy = 0.5, 0.25
    yy, xx = np.meshgrid(np.arange(ny) * dy, np.arange(nx) * dx, indexing="ij")
    bumps = np.zeros((ny, nx))
    bumps[10, 10] = 2.0
    bumps[30, 35] = -1.5
    bumps[20, 5] = 0.7
    # Make the bumps zero-mean and uncorrelated with x and y so the best plane of the
    # bumps alone is exactly zero: subtract their own least-squares plane analytically.
    a = np.column_stack([np.ones(bumps.size), xx.ravel(), yy.ravel()])
    coef, *_ = np.linalg.lstsq(a, bumps.ravel(), rcond=None)
    bumps = bumps - (a @ coef).reshape(ny, nx)
    tilted = bumps + 3.0 + 0.02 * xx - 0.05 * yy
    tilted[5, 7] = np.nan
    hm = HeightMap(z_um=tilted, dx_um=dx, dy_um=dy, source="t")
    # NaN at (5, 7): the plane of the bumps over the remaining points is no longer exactly
    # zero; compare with the plane fitted independently over those points.
    valid = ~np.isnan(tilted)
    coef2, *_ = np.linalg.lstsq(a[valid.ravel()], bumps[valid], rcond=None)
    expected = bumps - (a @ coef2).reshape(ny, nx)
    out = level_plane(hm)
    assert np.isnan(out.z_um[5, 7])
    assert np.count_nonzero(np.isnan(out.z_um)) == 1
    np.testing.assert_allclose(out.z_um[valid], expected[valid], atol=1e-12)
    assert abs(coef2).max() < 1e-3  # one missing point barely moves the plane


def test_level_plane_exact_plane_goes_to_zero() -> None:
    yy, xx = np.meshgrid(np.arange(6) * 2.0, np.arange(9) * 1.0, indexing="ij")
    hm = HeightMap(z_um=1.0 + 0.3 * xx + 0.1 * yy, dx_um=1.0, dy_um=2.0, source="p")
    np.testing.assert_allclose(level_plane(hm).z_um, 0.0, atol=1e-12)


def test_level_plane_no_valid_points() -> None:
    hm = HeightMap(z_um=np.full((3, 3), np.nan), dx_um=1.0, dy_um=1.0, source="allnan")
    with pytest.raises(HeightMapError, match=r"allnan: cannot level"):
        level_plane(hm)


def test_fill_missing_nearest_and_mean() -> None:
    z = np.array([[1.0, np.nan, 3.0, 4.0], [5.0, 6.0, 7.0, np.nan]])
    hm = HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source="f")
    near = fill_missing(hm, "nearest").z_um
    # (0,1) is at distance 1 from 1.0, 3.0 and 6.0: any of them is a nearest neighbour.
    assert near[0, 1] in (1.0, 3.0, 6.0)
    assert near[1, 3] in (4.0, 7.0)
    mean = fill_missing(hm, "mean").z_um
    assert mean[0, 1] == pytest.approx(26.0 / 6.0)
    assert not np.isnan(mean).any()
    np.testing.assert_array_equal(mean[~np.isnan(z)], z[~np.isnan(z)])


# ---------------------------------------------------------------- .npy


def test_npy_round_trip_with_sidecar(tmp_path: Path) -> None:
    hm = _sample_map()
    p = tmp_path / "scan.npy"
    save_heightmap(hm, p)
    assert (tmp_path / "scan.npy.json").exists()
    back = load_heightmap(p)
    np.testing.assert_array_equal(back.z_um, hm.z_um)
    assert (back.dx_um, back.dy_um) == (0.5, 0.75)
    assert back.meta["note"] == "t"
    assert back.source == "scan.npy"


def test_npy_without_sidecar_needs_step(tmp_path: Path) -> None:
    p = tmp_path / "bare.npy"
    np.save(p, np.arange(12, dtype=np.int32).reshape(3, 4))
    with pytest.raises(HeightMapError, match=r"bare.npy: no lateral step"):
        load_heightmap(p)
    hm = load_heightmap(p, step_um=(0.5, 2.0))
    assert (hm.dx_um, hm.dy_um) == (0.5, 2.0)
    np.testing.assert_array_equal(hm.z_um, np.arange(12.0).reshape(3, 4))


def test_npy_step_conflict_and_bad_arrays(tmp_path: Path) -> None:
    hm = _sample_map()
    p = tmp_path / "a.npy"
    save_heightmap(hm, p)
    with pytest.raises(HeightMapError, match=r"a.npy: step_um=1.0 contradicts"):
        load_heightmap(p, step_um=1.0)
    obj = tmp_path / "obj.npy"
    np.save(obj, np.array([[{"a": 1}]], dtype=object), allow_pickle=True)
    with pytest.raises(HeightMapError, match=r"obj.npy"):
        load_heightmap(obj, step_um=1.0)
    one_d = tmp_path / "oned.npy"
    np.save(one_d, np.zeros(5))
    with pytest.raises(HeightMapError, match=r"oned.npy: .*2-D"):
        load_heightmap(one_d, step_um=1.0)
    empty = tmp_path / "empty.npy"
    np.save(empty, np.zeros((0, 4)))
    with pytest.raises(HeightMapError, match=r"empty.npy: .*zero points"):
        load_heightmap(empty, step_um=1.0)
    for bad_step in (float("nan"), float("inf"), 0.0):
        with pytest.raises(HeightMapError, match=r"oned.npy: step_um"):
            load_heightmap(one_d, step_um=bad_step)


def test_missing_file_directory_and_unknown_extension(tmp_path: Path) -> None:
    with pytest.raises(HeightMapError, match=r"nothere.npy: no such file"):
        load_heightmap(tmp_path / "nothere.npy")
    d = tmp_path / "adir.npy"
    d.mkdir()
    with pytest.raises(HeightMapError, match=r"adir.npy: is a directory"):
        load_heightmap(d)
    with pytest.raises(HeightMapError, match=r"x.bmp: unknown height-map extension"):
        load_heightmap(tmp_path / "x.bmp")
