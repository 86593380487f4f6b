"""The cone-aperture sum over direction-cosine cells (:func:`goniolab.optics._cell_kernels.cone_cells_numpy`)
against the sum written directly from its definition, and with its window formed once
for several calls (:func:`~goniolab.optics._cell_kernels.cone_window`, as the sub-cones of
a split source use it)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from goniolab.optics import _cell_kernels as CK
from goniolab.optics.apertures import cap_overlap_fraction
from goniolab.optics.facet_apertures import cone_table

FloatArray = NDArray[np.float64]


def _cells() -> tuple[FloatArray, FloatArray, FloatArray]:
    """A window reaching past the horizon in its corners, with rows that carry no power."""
    wox = np.linspace(-0.95, 0.95, 61)
    woy = np.linspace(-0.9, 0.9, 47)
    p = np.random.default_rng(11).uniform(0.0, 1.0, (woy.size, wox.size))
    p[:5] = 0.0
    p[-3:] = 0.0
    return wox, woy, p


def _direct(
    wox: FloatArray, woy: FloatArray, p: FloatArray, d: FloatArray, a_s: float, a_d: float
) -> float:
    """``sum_cells P O(gamma)``: ``gamma`` the angle between the cell's direction (above
    the horizon) and ``d``, ``O`` the cap overlap of a source cap of half-angle ``a_s``
    around the cell and the detector cap of ``a_d`` around ``d``, exact (not tabulated)."""
    x, y = np.meshgrid(wox, woy)
    z2 = 1.0 - x**2 - y**2
    up = z2 > 0.0
    wo = np.stack([x[up], y[up], np.sqrt(z2[up])], axis=-1)
    gamma = np.arccos(np.clip(wo @ d, -1.0, 1.0))
    return float(np.sum(p[up] * cap_overlap_fraction(gamma, a_s, a_d)))


def test_cone_sums_are_the_cap_overlaps_of_the_cells_and_the_same_with_a_shared_window() -> None:
    wox, woy, p = _cells()
    a_s, a_d = math.radians(2.0), math.radians(3.0)
    table, g0, g1, o_in, _ = cone_table(a_s, a_d)
    angles = np.radians([-60.0, -20.0, 0.0, 35.0, 70.0])
    dirs = np.stack([-np.sin(angles), 0.02 * np.ones_like(angles), np.cos(angles)], axis=-1)
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    got = CK.cone_cells_numpy(wox, woy, p, dirs, table, g0, g1, o_in)
    want = [_direct(wox, woy, p, d, a_s, a_d) for d in dirs]
    # the table is linear between its nodes (3e-8 of a reading here)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    assert all(w > 0.0 for w in want)
    window = CK.cone_window(wox, woy, p)
    assert window[2] == (5, woy.size - 3, 0, wox.size)  # the rows without power left out
    shared = CK.cone_cells_numpy(wox, woy, p, dirs, table, g0, g1, o_in, window=window)
    assert np.array_equal(shared, got)


def test_a_window_without_power_sums_to_zero() -> None:
    wox, woy, p = _cells()
    table, g0, g1, o_in, _ = cone_table(math.radians(2.0), math.radians(3.0))
    dirs = np.array([[0.0, 0.0, 1.0]])
    window = CK.cone_window(wox, woy, np.zeros_like(p))
    assert window[2] is None
    out = CK.cone_cells_numpy(wox, woy, p, dirs, table, g0, g1, o_in, window=window)
    assert out.tolist() == [0.0]  # the window's (zero) powers, not p's, are summed
