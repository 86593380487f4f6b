"""The lean backend's slope histogram stays within the map's memory for any slope range
(issue 23.5: one 20 um spike on a 512^2 map asked the dense 1e-3 histogram for 48 GiB, an
int8 map of heights in um for 1.9 TiB).

Truth: the cells are the distinct ``(round(p / b), round(q / b))`` pairs of the facets and
each count the number of facets in that pair (a direct ``np.unique`` over the pairs); the
readings of the spiked map equal the per-facet kernels' (test_lean_backend.py's bound).
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from goniolab.optics import facet_backends
from goniolab.optics.facet import FacetModel
from goniolab.optics.facet_backends import LEAN_SLOPE_BIN
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.surface import Surface


def _spiked(n: int, spike_um: float, seed: int = 1) -> HeightMap:
    rng = np.random.default_rng(seed)
    z = rng.normal(0.0, 0.05, (n, n))
    z[n // 2, n // 2] += spike_um
    return HeightMap(z, 1.0, 1.0, source="spiked.npy")


def _direct_cells(surf: Surface) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    b = LEAN_SLOPE_BIN
    ip = np.floor(surf.p / b + 0.5).astype(np.int64)
    iq = np.floor(surf.q / b + 0.5).astype(np.int64)
    pairs, counts = np.unique(np.stack([ip, iq], axis=1), axis=0, return_counts=True)
    return pairs[:, 0] * b, pairs[:, 1] * b, counts.astype(np.float64)


def _sorted(cells: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    cp, cq, c = cells
    order = np.lexsort((cq, cp))
    return np.stack([cp[order], cq[order], c[order]])


@pytest.mark.parametrize("one_pass", [True, False])
@pytest.mark.parametrize("spike_um", [0.0, 5.0, 20.0, 40.0])
def test_cells_are_the_occupied_slope_pairs(
    spike_um: float, one_pass: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Both counts (the one-walk int16 count and the general two-walk one) give the
    distinct pairs; a 40 um spike's slopes (> 32.7) leave int16."""
    if not one_pass:
        monkeypatch.setattr(facet_backends, "_ONE_PASS_MAX_FACETS", 0)
    surf = Surface.from_heightmap(_spiked(128, spike_um))
    got = FacetModel(surf, backend="lean")._slope_cells
    np.testing.assert_allclose(_sorted(got), _sorted(_direct_cells(surf)), rtol=0, atol=1e-12)
    assert got[2].sum() == surf.n_facets


def test_sparse_and_dense_counting_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    surf = Surface.from_heightmap(_spiked(96, 0.0))  # a dense-sized range
    dense = _sorted(FacetModel(surf, backend="lean")._slope_cells)
    monkeypatch.setattr(facet_backends, "_DENSE_MIN_CELLS", 0)
    monkeypatch.setattr(facet_backends, "_DENSE_CELLS_PER_FACET", 0)
    monkeypatch.setattr(facet_backends, "_CELL_BLOCK", 1000)  # several blocks merged
    sparse = _sorted(FacetModel(surf, backend="lean")._slope_cells)
    np.testing.assert_array_equal(sparse, dense)


def test_a_20_um_spike_stays_within_a_few_times_the_map() -> None:
    """512^2 with a 20 um spike: slopes span about +-20, 1.6e9 cells of 1e-3 (12.8 GB
    dense). Counted sparse, the peak of the histogram is a few times the slopes' size."""
    surf = Surface.from_heightmap(_spiked(512, 20.0))
    model = FacetModel(surf, backend="lean")
    span = (float(np.ptp(surf.p)) / LEAN_SLOPE_BIN) * (float(np.ptp(surf.q)) / LEAN_SLOPE_BIN)
    assert span > 1e9  # the dense histogram would have been > 8 GB
    tracemalloc.start()
    try:
        cells = model._slope_cells
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 5 * surf.p.nbytes  # measured 3.0 x (a spike-free map, counted dense: 4.6 x)
    assert cells[2].sum() == surf.n_facets


def test_spiked_map_readings_equal_the_per_facet_kernels() -> None:
    surf = Surface.from_heightmap(_spiked(128, 20.0))
    ref = FacetModel(surf, masking=False, backend="numpy")
    lean = FacetModel(surf, masking=False, backend="lean")
    tr = np.arange(0.0, 71.0, 5.0)
    a = ref.luminance_pct(45.0, tr)
    np.testing.assert_allclose(lean.luminance_pct(45.0, tr), a, atol=2e-3 * a.max())


def test_slopes_beyond_the_index_are_refused_naming_the_map() -> None:
    z = np.zeros((16, 16))
    z[8, 8] = 5e6  # 5 m on a 1 um step: a unit error, not a surface
    surf = Surface.from_heightmap(HeightMap(z, 1.0, 1.0, source="wrong-units.npy"))
    with pytest.raises(ValueError, match=r"wrong-units\.npy: slopes up to .*height unit"):
        FacetModel(surf, backend="lean")._slope_cells  # noqa: B018
