"""A map keeps what it derives from its heights only while they stay read-only (review of
2026-11-26: numpy lets the owner of a handed-over array make it writeable again, and a
changed map kept its old plane fit and range)."""

from __future__ import annotations

import numpy as np

from goniolab.optics.heightmap import HeightMap, plane_fit


def test_heights_made_writeable_and_changed_are_fitted_as_they_are() -> None:
    z = np.zeros((64, 64))
    z.setflags(write=False)  # read-only and owning its data: handed over without a copy
    hm = HeightMap(z_um=z, dx_um=1.0, dy_um=1.0, source="flat")
    assert hm.z_um is z
    assert plane_fit(hm) == (0.0, 0.0, 0.0) and hm.z_range == (0.0, 0.0)
    # z = 0.3 + 0.01 x on the map's centred x (HeightMap's convention): the fit's truth
    x = np.arange(64) - 31.5
    z.setflags(write=True)
    z[:] = 0.3 + 0.01 * x[None, :]
    a, b, c = plane_fit(hm)
    assert np.allclose((a, b, c), (0.3, 0.01, 0.0), atol=1e-12)
    assert np.allclose(hm.z_range, (0.3 - 0.315, 0.3 + 0.315), atol=1e-12)
    z[0, 0] = np.nan
    assert hm.n_valid == 64 * 64 - 1
