"""The facet model's numba-free ``"lean"`` backend (issue 13: a one-shot command must not pay
numba's ~1 s of import and set-up).

It reads cones, deposits and wide rectangles from the occupied cells of the slope histogram
(bin 1e-3, counts as weights) and narrow slits exactly, facet by facet, over a bounding box
of the slopes that can reach them. The truths: the per-facet kernels (themselves held to
brute-force source sampling in test_facet.py), and the law of reflection for the box.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from goniolab.optics import _kernels_numpy as KN
from goniolab.optics import gloss_standards as gs
from goniolab.optics.apertures import Cone
from goniolab.optics.facet import FacetModel
from goniolab.optics.facet_backends import LEAN_SLOPE_BIN
from goniolab.optics.gloss_standards import gloss_report
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.surface import Surface


def _flat_dict(d: dict[str, object], pre: str = "") -> dict[str, float]:
    out: dict[str, float] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat_dict(v, f"{pre}{k}."))
        elif isinstance(v, float):
            out[pre + k] = v
    return out


@pytest.mark.parametrize("masking", [False, True])
@pytest.mark.parametrize("slope_rms", [0.003, 0.05, 0.3])
def test_lean_curves_equal_the_per_facet_kernels(
    gaussian_factory: Callable[..., HeightMap], slope_rms: float, masking: bool
) -> None:
    """71-point goniometer curves (deposited grid) and two-point exact readings: the cells
    move each facet by at most half a bin, measured within 6e-4 of the peak over rms slopes
    0.003-0.3 and theta_i 20-85 (asserted 2e-3)."""
    surf = Surface.from_heightmap(gaussian_factory(256, slope_rms, seed=5))
    ref = FacetModel(surf, masking=masking)
    lean = FacetModel(surf, masking=masking, backend="lean")
    for ti in (20.0, 45.0, 80.0, 85.0):
        tr = np.arange(0.0, 71.0) if ti < 80 else np.arange(60.0, 89.0, 0.5)
        a, b = ref.luminance_pct(ti, tr), lean.luminance_pct(ti, tr)
        np.testing.assert_allclose(b, a, atol=2e-3 * a.max())
        pts = [ti, ti + 2.0]
        np.testing.assert_allclose(
            lean.luminance_pct(ti, pts), ref.luminance_pct(ti, pts), atol=2e-3 * a.max()
        )


@pytest.mark.parametrize("slope_rms", [0.001, 0.02, 0.1])
def test_lean_gloss_report_iso_within_0_2_percent_and_e430_slits_exact(
    gaussian_factory: Callable[..., HeightMap], slope_rms: float
) -> None:
    """ISO 2813 rectangles from the cells (measured within 0.17 %), the ASTM E430 slits
    (0.05-0.4 deg, too narrow for the cells) facet by facet: equal to the kernels' sums."""
    surf = Surface.from_heightmap(gaussian_factory(256, slope_rms, seed=2))
    ref = _flat_dict(gloss_report(FacetModel(surf, masking=False)).as_dict())
    got = _flat_dict(gloss_report(FacetModel(surf, masking=False, backend="lean")).as_dict())
    assert got.keys() == ref.keys()
    for key, want in ref.items():
        if key.startswith("e430.") and key != "e430.gloss_20":
            assert got[key] == pytest.approx(want, rel=1e-9, abs=1e-12), key
        else:
            assert got[key] == pytest.approx(want, rel=2e-3, abs=1e-9), key


def test_lean_hemisphere_albedo_equals_the_facets(gauss_surface_256: Surface) -> None:
    ref = FacetModel(gauss_surface_256).brdf_hemisphere(60.0, bin_deg=1.0)
    got = FacetModel(gauss_surface_256, backend="lean").brdf_hemisphere(60.0, bin_deg=1.0)
    assert got.albedo == pytest.approx(ref.albedo, rel=1e-3)


def test_slope_cells_keep_every_facet_within_half_a_bin(gauss_surface_256: Surface) -> None:
    """The cells' counts add up to the facets, and every facet's slopes round to a cell."""
    m = FacetModel(gauss_surface_256, backend="lean")
    cp, cq, counts = m._slope_cells
    assert counts.sum() == gauss_surface_256.n_facets
    b = LEAN_SLOPE_BIN
    key = np.floor(gauss_surface_256.p / b + 0.5) * 1e6 + np.floor(gauss_surface_256.q / b + 0.5)
    cells, n = np.unique(key, return_counts=True)
    np.testing.assert_array_equal(np.sort(n), np.sort(counts))
    np.testing.assert_array_equal(np.sort(cells), np.sort(np.rint(cp / b) * 1e6 + np.rint(cq / b)))


@pytest.mark.parametrize(
    ("theta_i", "alpha_deg", "reach_a_deg", "reach_b_deg"),
    [
        (20.0, 20.0, 0.1, 2.5),
        (30.0, 32.0, 0.2, 1.25),
        (60.0, 60.0, 2.6, 7.0),
        (85.0, 80.0, 2.4, 4.25),
    ],
)
def test_facets_near_keep_every_facet_that_reflects_into_the_rectangle(
    gaussian_factory: Callable[..., HeightMap],
    theta_i: float,
    alpha_deg: float,
    reach_a_deg: float,
    reach_b_deg: float,
) -> None:
    """The slope box is a superset: every facet whose mirror direction (law of reflection,
    reflect_numpy) has in-plane angle within reach_a of alpha and out-of-plane angle within
    reach_b is kept, and the box is much smaller than the map for narrow slits."""
    surf = Surface.from_heightmap(gaussian_factory(256, 0.1, seed=9))
    m = FacetModel(surf, backend="lean")
    t = math.radians(theta_i)
    wi = np.array([math.sin(t), 0.0, math.cos(t)])
    ox, oy, oz, w = KN.reflect_numpy(surf.p, surf.q, np.empty(0), wi, 1.55, 0.0, False)
    al, be = np.arctan2(-ox, oz), np.arcsin(np.clip(oy, -1.0, 1.0))
    hit = (
        (w > 0)
        & (np.abs(al - math.radians(alpha_deg)) <= math.radians(reach_a_deg))
        & (np.abs(be) <= math.radians(reach_b_deg))
    )
    p, q = m._facets_near(
        wi, math.radians(alpha_deg), math.radians(reach_a_deg), math.radians(reach_b_deg)
    )
    kept = set(zip(p.tolist(), q.tolist(), strict=True))
    assert hit.sum() > 0
    assert all((a, b) in kept for a, b in zip(surf.p[hit], surf.q[hit], strict=True))
    if reach_a_deg <= 0.2:
        assert p.size < 0.2 * surf.n_facets


def test_lean_narrow_slit_reading_equals_the_kernels_on_a_smooth_map(
    gaussian_factory: Callable[..., HeightMap],
) -> None:
    """The E430 distinctness-of-image slit on a high-gloss map, which the cells would read
    20 % high: read facet by facet over the box, it equals the per-facet kernel."""
    surf = Surface.from_heightmap(gaussian_factory(256, 0.003, seed=1))
    args = (
        gs.E430_A_ANGLE_DEG,
        gs.E430_A_ANGLE_DEG + gs.E430_A_DOI_OFFSET_DEG,
        gs.E430_A_SOURCE,
        gs.E430_A_SPECULAR_RECEPTOR,
    )
    want = FacetModel(surf).reflected_fraction(*args)
    assert want > 0
    assert FacetModel(surf, backend="lean").reflected_fraction(*args) == pytest.approx(
        want, rel=1e-9
    )


def test_lean_cone_responses_work_for_a_point_source(gauss_surface_256: Surface) -> None:
    ref = FacetModel(gauss_surface_256).reflected_fraction(45.0, 45.0, Cone(0.0), Cone(6.0))
    got = FacetModel(gauss_surface_256, backend="lean").reflected_fraction(
        45.0, 45.0, Cone(0.0), Cone(6.0)
    )
    assert got == pytest.approx(ref, rel=2e-3)


def test_cone_grid_counts_cells_without_the_index_and_the_slits_count_it_again(
    gaussian_factory: Callable[..., HeightMap],
) -> None:
    """A masked cone curve counts the slope cells and lets the facets' int16 cell indices
    go (their memory is the deposit's); a gloss report on the same model afterwards reads
    its narrow slits through indices counted again: every reading the bits of a fresh
    model's report, and the cells the same cells."""
    surf = Surface.from_heightmap(gaussian_factory(256, 0.02, seed=4))
    fresh = FacetModel(surf, masking=True, backend="lean")
    want = gloss_report(fresh).as_dict()
    used = FacetModel(surf, masking=True, backend="lean")
    curve = used.luminance_pct(45.0, np.arange(30.0, 61.0), source=Cone(6.0))
    assert float(curve.max()) > 0
    assert "_cell_index" not in used.__dict__  # counted by the grid: no index kept
    assert gloss_report(used).as_dict() == want
    index = used.__dict__["_cell_index"]
    assert index is not None and index[0].size == surf.n_facets  # the slits counted it
    for a, b in zip(used._slope_cells, fresh._slope_cells, strict=True):
        assert np.array_equal(a, b)
