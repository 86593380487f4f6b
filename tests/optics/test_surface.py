"""Slopes, facet normals, slope histogram and roughness statistics against exact geometry."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from goniolab.optics.heightmap import HeightMap
from goniolab.optics.surface import (
    Surface,
    roughness_stats,
    slope_histogram,
    slopes,
)


def _plane(
    a: float, b: float, ny: int = 7, nx: int = 9, dx: float = 0.5, dy: float = 2.0
) -> HeightMap:
    """z = a x + b y with x = j dx, y = i dy (row i is the y index)."""
    i, j = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    return HeightMap(z_um=a * j * dx + b * i * dy + 3.0, dx_um=dx, dy_um=dy, source="plane")


@pytest.mark.parametrize("method", ["forward", "central", "plane8"])
def test_tilted_plane_slopes_are_exact(method: str) -> None:
    a, b = 0.031, -0.017
    p, q = slopes(_plane(a, b), method)  # type: ignore[arg-type]
    ok = np.isfinite(p) & np.isfinite(q)
    assert ok.sum() > 0
    np.testing.assert_allclose(p[ok], a, rtol=1e-12)
    np.testing.assert_allclose(q[ok], b, rtol=1e-12)


def test_undefined_edges_per_method() -> None:
    hm = _plane(0.1, 0.2, ny=5, nx=6)
    p, q = slopes(hm, "forward")
    assert np.isnan(p[:, -1]).all() and np.isfinite(p[:, :-1]).all()
    assert np.isnan(q[-1, :]).all() and np.isfinite(q[:-1, :]).all()
    p, q = slopes(hm, "central")
    assert np.isnan(p[:, [0, -1]]).all() and np.isfinite(p[:, 1:-1]).all()
    assert np.isnan(q[[0, -1], :]).all() and np.isfinite(q[1:-1, :]).all()
    p, q = slopes(hm, "plane8")
    assert np.isfinite(p).sum() == (5 - 2) * (6 - 2)


def test_nan_heights_make_their_neighbours_undefined() -> None:
    z = _plane(0.1, 0.2, ny=6, nx=6).z_um.copy()
    z[2, 3] = np.nan
    hm = HeightMap(z_um=z, dx_um=0.5, dy_um=2.0, source="holey")
    p, q = slopes(hm, "forward")
    assert np.isnan(p[2, 2]) and np.isnan(p[2, 3]) and np.isfinite(p[2, 1])
    assert np.isnan(q[1, 3]) and np.isnan(q[2, 3]) and np.isfinite(q[3, 3])
    p8, _ = slopes(hm, "plane8")
    assert np.isnan(p8[1:4, 2:5]).all()
    assert np.isfinite(p8[4, 1])
    surf = Surface.from_heightmap(hm, level=False)
    assert surf.n_facets == int((np.isfinite(p) & np.isfinite(q)).sum())
    np.testing.assert_allclose(surf.p, 0.1, rtol=1e-12)


def test_axis_convention_row_is_y() -> None:
    # heights grow down the rows only: a pure y slope
    hm = _plane(0.0, 0.05)
    p, q = slopes(hm, "forward")
    np.testing.assert_allclose(p[:, :-1], 0.0, atol=1e-15)
    np.testing.assert_allclose(q[:-1, :], 0.05, rtol=1e-12)


def test_normals_sign_of_y_component() -> None:
    """A plane rising along +y has its normal tilted towards -y (the seed's eq. 4 slip)."""
    b = 0.2
    surf = Surface.from_heightmap(_plane(0.0, b), level=False)
    mx, my, mz = surf.normals
    s = math.sqrt(1 + b * b)
    np.testing.assert_allclose(mx, 0.0, atol=1e-15)
    np.testing.assert_allclose(my, -b / s, rtol=1e-12)
    np.testing.assert_allclose(mz, 1 / s, rtol=1e-12)
    # the normal is perpendicular to the surface's y tangent (0, 1, b)
    np.testing.assert_allclose(my + b * mz, 0.0, atol=1e-15)
    assert surf.normals is surf.normals  # cached


def test_levelling_removes_the_tilt() -> None:
    surf = Surface.from_heightmap(_plane(0.03, -0.02))
    np.testing.assert_allclose(surf.p, 0.0, atol=1e-12)
    np.testing.assert_allclose(surf.q, 0.0, atol=1e-12)
    assert surf.slope_method == "forward" and surf.dy_um == 2.0


def test_slope_histogram_counts_and_h_r() -> None:
    p = np.array([0.0, 0.0004, -0.0004, 0.002, 0.0021, -0.0031])
    q = np.array([0.0, 0.0, 0.0004, 0.0, 0.0, 0.0009])
    h = slope_histogram(p, q, bin_size=1e-3)
    assert h.h_r == pytest.approx(3 / 6)
    bin_area = 1e-6
    assert h.density.sum() * bin_area == pytest.approx(1.0)
    # the bin centred on (0.002, 0): two facets
    a = int(np.searchsorted(h.p_edges, 0.002)) - 1
    b = int(np.searchsorted(h.q_edges, 0.0)) - 1
    assert h.p_edges[a] == pytest.approx(0.0015) and h.q_edges[b] == pytest.approx(-0.0005)
    assert h.density[a, b] == pytest.approx(2 / 6 / bin_area)


def test_slope_histogram_of_gaussian_slopes() -> None:
    rng = np.random.default_rng(5)
    s = 0.02
    p, q = rng.normal(0, s, 400_000), rng.normal(0, s, 400_000)
    h = slope_histogram(p, q, bin_size=4e-3)
    # h_r against the integral of the Gaussian over the central bin
    expected = math.erf(2e-3 / (s * math.sqrt(2))) ** 2
    assert h.h_r == pytest.approx(expected, rel=0.05)
    pc = 0.5 * (h.p_edges[1:] + h.p_edges[:-1])
    i0 = int(np.argmin(np.abs(pc)))
    assert h.density[i0, :].max() == pytest.approx(1 / (2 * math.pi * s * s), rel=0.05)


def test_slope_histogram_guards() -> None:
    with pytest.raises(ValueError, match="larger bin_size"):
        slope_histogram(np.array([-100.0, 100.0]), np.array([-100.0, 100.0]), bin_size=1e-3)
    with pytest.raises(ValueError, match="bin_size"):
        slope_histogram(np.zeros(3), np.zeros(3), bin_size=0.0)


def test_roughness_stats_of_a_cosine() -> None:
    """z = A cos(2 pi x / L) over whole periods, symmetric about the centre (levelling is a no-op)."""
    amp_um, period, n = 0.1, 64, 256
    x = np.arange(n) - (n - 1) / 2
    z = np.tile(amp_um * np.cos(2 * np.pi * x / period), (8, 1))
    hm = HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source="cosine")
    st = roughness_stats(hm)
    assert st.Ra_nm == pytest.approx(2 * amp_um / math.pi * 1e3, rel=1e-3)
    assert st.Sq_nm == pytest.approx(amp_um / math.sqrt(2) * 1e3, rel=1e-9)
    # forward difference of a sampled cosine: 2 A sin(pi/L) sin(...) -> rms 2 A sin(pi/L)/sqrt 2
    expected_slope = 2 * amp_um * math.sin(math.pi / period) / math.sqrt(2)
    assert st.slope_rms_x == pytest.approx(expected_slope, rel=1e-2)
    assert st.slope_rms_y == pytest.approx(0.0, abs=1e-12)
    assert st.Sdq == pytest.approx(st.slope_rms_x, rel=1e-12)
    assert st.n_facets == 7 * 255


def test_roughness_stats_gaussian_h_r_orders_roughness(
    gaussian_factory: Callable[..., HeightMap],
) -> None:
    smooth = roughness_stats(gaussian_factory(128, 0.01, seed=2), slope_method="central")
    rough = roughness_stats(gaussian_factory(128, 0.05, seed=2), slope_method="central")
    assert smooth.slope_rms_x == pytest.approx(0.01, rel=0.02)
    assert rough.Sdq == pytest.approx(0.05 * math.sqrt(2), rel=0.05)
    assert smooth.h_r > rough.h_r


def test_surface_validation_names_the_source() -> None:
    with pytest.raises(ValueError, match="bad-source"):
        Surface(p=np.array([np.nan]), q=np.array([0.0]), source="bad-source")
    with pytest.raises(ValueError, match="equal length"):
        Surface(p=np.zeros(3), q=np.zeros(2))
    with pytest.raises(ValueError, match=r"tiny\.npy"):
        Surface.from_heightmap(
            HeightMap(z_um=np.zeros((1, 1)), dx_um=1.0, dy_um=1.0, source="tiny.npy")
        )
    with pytest.raises(ValueError, match="unknown slope method"):
        slopes(_plane(0, 0), "sobel")  # type: ignore[arg-type]
