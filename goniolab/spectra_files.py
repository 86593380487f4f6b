"""Multi-angle spectra files: the flat exchange table a paint lab's software reads.

One row per geometry (and repeat), ``source`` (``measured`` / ``predicted``), the angles
(ASTM E2194 ``aspecular_deg = theta_i_deg - theta_r_deg``) and one ``R_<nm>`` column per
wavelength (:mod:`goniolab.colour.exchange`), written as

- **CSV** (``.csv``): a ``#`` line saying what the values are, then the table
  (:func:`goniolab.colour.exchange.spectra_csv`; it reads back with
  :func:`~goniolab.colour.exchange.read_spectra_csv`);
- **Parquet** (``.parquet``, ``.pq``): the same columns, typed, the provenance as JSON in the
  schema metadata under ``goniolab.spectra``;
- **netCDF** (``.nc``): ``reflectance_factor (geometry, wavelength_nm)`` with units, long
  names and the provenance as attributes (:func:`goniolab.datasets.write_netcdf`, CF-1.8).

What ``runs spectra`` and ``predict colour --spectra-out`` write (the faces call
:func:`write_spectra_file`; :func:`goniolab.run_spectra.spectra_tables` gives a stored run's
tables and :func:`goniolab.run_spectra.RunSpectra.provenance` what they are). Every file is
built in memory and replaced whole (:mod:`goniolab._atomic`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from goniolab._atomic import atomic_write_bytes

if TYPE_CHECKING:  # pragma: no cover - typing only
    from goniolab.colour.exchange import MultiAngleSpectra

__all__ = ["SPECTRA_SUFFIXES", "spectra_format", "write_spectra_file"]

#: Spectra file formats by suffix.
SPECTRA_SUFFIXES: dict[str, str] = {
    ".csv": "csv",
    ".parquet": "parquet",
    ".pq": "parquet",
    ".nc": "netcdf",
}


def spectra_format(path: str | Path) -> str:
    """``csv``, ``parquet`` or ``netcdf`` by ``path``'s suffix.

    Raises
    ------
    ValueError
        Another suffix (the message names the ones there are).
    """
    fmt = SPECTRA_SUFFIXES.get(Path(path).suffix.lower())
    if fmt is None:
        raise ValueError(f"{path}: spectra files are .csv, .parquet or .nc")
    return fmt


def _values_label(mirror_scale: bool) -> str:
    if mirror_scale:
        return "fraction of the mirror reference (scale = mirror): not a reflectance factor"
    return "reflectance factor (1 = perfect reflecting diffuser)"


def write_spectra_file(
    tables: Sequence[MultiAngleSpectra],
    path: str | Path,
    attrs: Mapping[str, Any],
    *,
    mirror_scale: bool = False,
) -> str:
    """Write multi-angle tables to ``path`` (on the union of their grids); returns the
    format.

    Parameters
    ----------
    tables
        Measured and/or predicted :class:`~goniolab.colour.exchange.MultiAngleSpectra`.
    attrs
        What the file says about itself (run, sample, scale, cone, what the spectra are
        relative to and referenced to, ...): Parquet schema metadata, netCDF attributes.
    mirror_scale
        The values are fractions of the mirror (``[colour] scale = "mirror"``), not
        reflectance factors: every label says so.

    Raises
    ------
    ValueError
        An unknown suffix (:func:`spectra_format`).
    OSError
        The file cannot be written (an existing file is left as it was).
    """
    fmt = spectra_format(path)
    if fmt == "csv":
        from goniolab.colour.exchange import CSV_HEADER_NOTE, MIRROR_NOTE, spectra_csv

        note = MIRROR_NOTE if mirror_scale else CSV_HEADER_NOTE
        atomic_write_bytes(path, spectra_csv(tables, note=note).encode("utf-8"))
    elif fmt == "parquet":
        atomic_write_bytes(path, _parquet_bytes(tables, attrs, mirror_scale))
    else:
        from goniolab.datasets import write_netcdf

        write_netcdf(_dataset(tables, attrs, mirror_scale), path)
    return fmt


def _parquet_bytes(
    tables: Sequence[MultiAngleSpectra], attrs: Mapping[str, Any], mirror_scale: bool
) -> bytes:
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    from goniolab.colour.exchange import spectral_column, union_table

    table = union_table(tables)
    df = pd.DataFrame(
        {
            "source": list(table.source),
            "theta_i_deg": table.theta_i_deg,
            "theta_r_deg": table.theta_r_deg,
            "aspecular_deg": table.aspecular_deg,
            "repeat": np.asarray(table.repeat, dtype=np.int64),
            **{spectral_column(w): table.factors[:, k] for k, w in enumerate(table.wavelengths_nm)},
        }
    )
    t = pa.Table.from_pandas(df, preserve_index=False)
    meta = dict(t.schema.metadata or {})
    meta[b"goniolab.spectra"] = json.dumps(
        {**attrs, "values": _values_label(mirror_scale),
         "aspecular": "theta_i_deg - theta_r_deg (ASTM E2194)"},
        sort_keys=True, default=str,
    ).encode()  # fmt: skip
    sink = pa.BufferOutputStream()  # in memory, then replaced whole (goniolab._atomic)
    pq.write_table(t.replace_schema_metadata(meta), sink)
    return bytes(sink.getvalue().to_pybytes())


def _dataset(
    tables: Sequence[MultiAngleSpectra], attrs: Mapping[str, Any], mirror_scale: bool
) -> Any:
    import xarray as xr

    from goniolab.colour.exchange import union_table
    from goniolab.datasets import LONG_NAMES, UNITS

    table = union_table(tables)
    geom = np.arange(table.factors.shape[0])
    return xr.Dataset(
        {
            "reflectance_factor": (
                ("geometry", "wavelength_nm"),
                table.factors,
                {
                    "units": "1",
                    "long_name": f"spectral {_values_label(mirror_scale)}, measured or "
                    "predicted per the source variable",
                },
            ),
            "source": (
                "geometry",
                np.array(table.source, dtype=str),
                {"long_name": "measured or predicted"},
            ),
            "repeat": (
                "geometry",
                np.asarray(table.repeat, dtype=np.int64),
                {"long_name": "repeat number", "units": "1"},
            ),
        },
        coords={
            "geometry": ("geometry", geom, {"long_name": "row number"}),
            "wavelength_nm": (
                "wavelength_nm",
                table.wavelengths_nm,
                {"units": UNITS["wavelength_nm"], "long_name": "wavelength"},
            ),
            **{
                name: (
                    "geometry",
                    values,
                    {"units": UNITS[name], "long_name": LONG_NAMES.get(name, name)},
                )
                for name, values in (
                    ("theta_i_deg", table.theta_i_deg),
                    ("theta_r_deg", table.theta_r_deg),
                    ("aspecular_deg", table.aspecular_deg),
                )
            },
        },
        attrs={"title": "goniolab multi-angle spectra", **attrs},
    )
