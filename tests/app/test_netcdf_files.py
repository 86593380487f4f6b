"""The faces' netCDF files: written and read back through the app layer, a file that
cannot be written or read is one UserError (no face catches OSError itself)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from goniolab.app.netcdf_files import read_dataset, save_dataset
from goniolab.errors import UserError


def test_a_dataset_round_trips_and_bad_files_are_user_errors(tmp_path: Path) -> None:
    ds = xr.Dataset(
        {"luminance_pct": ("theta_r_deg", np.array([1.5, 2.5]), {"units": "%"})},
        coords={"theta_r_deg": ("theta_r_deg", np.array([40.0, 45.0]), {"units": "degree"})},
    )
    out = save_dataset(ds, tmp_path / "p.nc")
    back = read_dataset(out)
    np.testing.assert_array_equal(back["luminance_pct"].values, [1.5, 2.5])
    assert back["luminance_pct"].attrs["units"] == "%"
    with pytest.raises(UserError, match=r"cannot write .*missing"):
        save_dataset(ds, tmp_path / "missing" / "p.nc")
    (tmp_path / "not.nc").write_text("not netCDF\n")
    with pytest.raises(UserError):
        read_dataset(tmp_path / "not.nc")
