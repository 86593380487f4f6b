"""The netCDF files of the faces (issue 24): a prediction saved (``goniolab predict brdf
--out FILE.nc``) and a file read back (:func:`goniolab.api.open_dataset`), through the
library's :func:`goniolab.datasets.write_netcdf` / :func:`goniolab.datasets.open_dataset`;
a file that cannot be written or read is one :class:`~goniolab.errors.UserError` here, so
no face catches the library's ``OSError`` itself.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from goniolab.errors import UserError

if TYPE_CHECKING:  # xarray loads when a file is written or read, not at --help
    import xarray as xr

__all__ = ["read_dataset", "save_dataset"]


def save_dataset(ds: xr.Dataset, out: str | Path) -> Path:
    """Write ``ds`` to ``out`` (CF-1.8 netCDF-4, replaced whole); the path written.

    Raises
    ------
    UserError
        The file cannot be written (the reason the system gives).
    """
    from goniolab.datasets import write_netcdf

    try:
        return write_netcdf(ds, out)
    except OSError as exc:
        raise UserError(f"cannot write {out}: {exc.strerror or exc}") from exc


def read_dataset(path: str | Path) -> xr.Dataset:
    """The Dataset of a netCDF file goniolab wrote (loaded, the file closed).

    Raises
    ------
    UserError
        The file cannot be read or is not netCDF (the library's message).
    """
    from goniolab.datasets import open_dataset

    try:
        return open_dataset(path)
    except OSError as exc:
        raise UserError(str(exc)) from None
