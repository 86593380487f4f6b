"""A large map predicted without its facets in memory (issue 26: 8192^2 within 2.5 x the map).

A float32 ``.npy`` stays float32 and gives what its float64 copy gives, bit for bit; a map's
surface forms its slopes block by block from the map and they equal the levelled map's
forward differences (Wittmann et al. 2021, sec. 3.1) computed whole; the per-facet kernels
run over those blocks give the sums over all facets; the ``auto`` model and its facet model
read one map. The memory itself is measured by bench/bench_memory.py, not asserted here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.model_cache import model_for
from goniolab.optics import facet as facet_mod
from goniolab.optics import surface as surface_mod
from goniolab.optics.facet import FacetModel
from goniolab.optics.facet_backends import facets_near, slope_cells, slope_cells_indexed
from goniolab.optics.heightmap import HeightMap, level_plane
from goniolab.optics.surface import MapSurface, Surface, roughness_stats
from goniolab.surfaces import resolve_map


def _rough(n: int = 192, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    k = np.fft.fftfreq(n)
    g = np.exp(-0.5 * (2 * np.pi * 2.0) ** 2 * (k[:, None] ** 2 + k[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * g))
    z *= 0.1 / z.std()
    return z + 0.002 * np.arange(n)[None, :] - 0.001 * np.arange(n)[:, None]  # a tilt


def _write(path: Path, z: np.ndarray) -> Path:
    np.save(path, z)
    path.with_name(path.name + ".json").write_text(json.dumps({"dx_um": 0.5, "dy_um": 0.5}))
    return path


def test_map_surface_blocks_are_the_levelled_maps_forward_differences() -> None:
    z = _rough()
    hm = HeightMap(z_um=z, dx_um=0.5, dy_um=0.7)
    surf = Surface.from_heightmap(hm)
    assert isinstance(surf, MapSurface) and surf.streamed
    lev = level_plane(hm).z_um  # the independent route: level, then difference
    p_want = ((lev[:-1, 1:] - lev[:-1, :-1]) / 0.5).ravel()
    q_want = ((lev[1:, :-1] - lev[:-1, :-1]) / 0.7).ravel()
    blocks = list(surf.slope_blocks(1000))
    assert len(blocks) > 10 and surf.streamed  # walked without forming the whole arrays
    p = np.concatenate([b[0] for b in blocks])
    q = np.concatenate([b[1] for b in blocks])
    np.testing.assert_allclose(p, p_want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(q, q_want, rtol=0, atol=1e-12)
    idx = np.array([0, 7, 191, 5000, surf.n_facets - 1])
    tp, tq = surf.take(idx)
    np.testing.assert_array_equal(tp, p[idx])
    np.testing.assert_array_equal(tq, q[idx])
    assert surf.streamed
    np.testing.assert_array_equal(surf.p, p)  # formed whole on demand: the same arrays
    np.testing.assert_array_equal(surf.q, q)
    assert not surf.streamed


def test_slope_cells_and_near_facets_of_a_map_equal_those_of_its_arrays() -> None:
    surf = Surface.from_heightmap(HeightMap(z_um=_rough(), dx_um=0.5, dy_um=0.5))
    held = Surface(p=surf.p.copy(), q=surf.q.copy())
    streamed = Surface.from_heightmap(HeightMap(z_um=_rough(), dx_um=0.5, dy_um=0.5))
    for got, want in zip(slope_cells(streamed), slope_cells(held), strict=True):
        np.testing.assert_array_equal(got, want)
    wi = np.array([np.sin(np.radians(60.0)), 0.0, np.cos(np.radians(60.0))])
    got_p, got_q = facets_near(streamed, None, wi, np.radians(60.0), 0.01, 0.02)
    want_p, want_q = facets_near(held.p, held.q, wi, np.radians(60.0), 0.01, 0.02)
    assert 0 < got_p.size < held.n_facets
    np.testing.assert_array_equal(got_p, want_p)
    np.testing.assert_array_equal(got_q, want_q)
    assert streamed.streamed
    # picked by the facets' cell indices of the one-walk count: the same facets, in order
    for surface in (streamed, held):
        _, index = slope_cells_indexed(surface)
        assert index is not None and index[0].size == held.n_facets
        for alpha_deg, reach in ((60.0, 0.01), (58.5, 0.004), (64.0, 0.03)):
            a = np.radians(alpha_deg)
            got = facets_near(surface, None, wi, a, reach, 0.02, index)
            want = facets_near(held.p, held.q, wi, a, reach, 0.02)
            assert 0 < want[0].size < held.n_facets
            np.testing.assert_array_equal(got[0], want[0])
            np.testing.assert_array_equal(got[1], want[1])
    assert streamed.streamed


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_kernels_over_blocks_sum_to_the_kernels_over_all_facets(
    backend: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    z = _rough()
    whole = FacetModel(
        Surface.from_heightmap(HeightMap(z_um=z, dx_um=0.5, dy_um=0.5)),
        masking=True,
        backend=backend,  # type: ignore[arg-type]
    )
    want_gloss = whole.gloss()
    want_curve = whole.luminance_pct(45.0, np.arange(20.0, 71.0, 5.0))
    monkeypatch.setattr(facet_mod, "STREAM_MIN_FACETS", 0)  # every map "large"
    monkeypatch.setattr(surface_mod, "STREAM_MIN_FACETS", 0)
    monkeypatch.setattr(surface_mod, "SLOPE_BLOCK_FACETS", 4096)
    seen: list[tuple[int, int, str]] = []
    surf = Surface.from_heightmap(HeightMap(z_um=z, dx_um=0.5, dy_um=0.5))
    assert isinstance(surf, MapSurface)
    surf.progress = lambda done, total, what: seen.append((done, total, what))
    streamed = FacetModel(surf, masking=True, backend=backend)  # type: ignore[arg-type]
    got_gloss = streamed.gloss()
    got_curve = streamed.luminance_pct(45.0, np.arange(20.0, 71.0, 5.0))
    assert surf.streamed  # the kernels ran over blocks, never the whole arrays
    for t, v in want_gloss.items():
        assert got_gloss[t] == pytest.approx(v, rel=1e-12, abs=1e-12)
    np.testing.assert_allclose(got_curve, want_curve, rtol=1e-12, atol=1e-14)
    assert seen and seen[-1][0] == seen[-1][1] == z.shape[0] - 1
    passes = [w for _, _, w in seen]
    assert all(w.startswith("facet slopes, pass ") for w in passes)
    assert passes[-1] == f"facet slopes, pass {len(set(passes))}"  # numbered 1, 2, ...


def test_float32_npy_stays_float32_and_predicts_what_its_float64_copy_does(
    tmp_path: Path,
) -> None:
    z32 = _rough().astype(np.float32)
    a = _write(tmp_path / "f32.npy", z32)
    b = _write(tmp_path / "f64.npy", z32.astype(np.float64))
    hm32, hm64 = resolve_map(a), resolve_map(b)
    assert hm32.z_um.dtype == np.float32 and hm64.z_um.dtype == np.float64
    np.testing.assert_array_equal(hm32.z_um, hm64.z_um)
    s32, s64 = Surface.from_heightmap(hm32), Surface.from_heightmap(hm64)
    np.testing.assert_array_equal(s32.p, s64.p)
    np.testing.assert_array_equal(s32.q, s64.q)
    assert roughness_stats(hm32) == roughness_stats(hm64)
    m32 = model_for(a, backend="lean")
    m64 = model_for(b, backend="lean")
    assert m32.gloss() == m64.gloss()
    tr = np.arange(0.0, 71.0)
    np.testing.assert_array_equal(m32.luminance_pct(45.0, tr), m64.luminance_pct(45.0, tr))


def test_auto_model_and_its_facet_model_read_the_map_once(tmp_path: Path) -> None:
    path = _write(tmp_path / "m.npy", _rough().astype(np.float32))
    model = model_for(path)
    surf = model.facet.surface  # type: ignore[attr-defined]
    assert isinstance(surf, MapSurface)
    assert surf._hm is model.kirchhoff._shared.hm  # type: ignore[attr-defined]
    assert resolve_map(path) is surf._hm  # held: the same map, not a second read


def test_rayleigh_rice_reports_its_psd_tiles_and_reads_the_same() -> None:
    from goniolab.optics.rayleigh_rice import RayleighRiceModel

    z = _rough(128) * 0.05  # Sq 5 nm: the Rayleigh-Rice regime
    hm = HeightMap(z_um=z, dx_um=0.5, dy_um=0.5)
    seen: list[tuple[int, int, str]] = []
    quiet = RayleighRiceModel(hm, tile=64).gloss()
    heard = RayleighRiceModel(hm, tile=64, progress=lambda d, t, w: seen.append((d, t, w))).gloss()
    assert heard == quiet
    assert seen and {w for _, _, w in seen} == {"rayleigh-rice PSD tiles"}
    # the gloss's three geometries (4 tiles each) run as tasks, possibly at once, and
    # report as one bar (wave_tasks.run_reporting, issue 26): the totals add up as the
    # geometries start, done never falls, and the bar closes once, at 12 of 12
    assert {t for _, t, _ in seen} == {4, 8, 12}
    assert seen[-1] == (12, 12, "rayleigh-rice PSD tiles")
    assert [d for d, _, _ in seen] == sorted(d for d, _, _ in seen)
    assert all(d < t for d, t, _ in seen[:-1])
