"""Multi-angle spectra files: a run's spectra as tables and any such tables written as
CSV (``R_400..`` columns), Parquet or netCDF (``runs spectra``, ``predict colour
--spectra-out``).

Named ``spectra_files``: a module name is used once in the tree.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from goniolab.errors import UserError

__all__ = ["SPECTRA_SUFFIXES", "run_spectra_tables", "write_spectra"]


#: Spectra file formats by suffix.
SPECTRA_SUFFIXES = {".csv": "csv", ".parquet": "parquet", ".pq": "parquet", ".nc": "netcdf"}


def write_spectra(
    tables: list[Any], path: str, attrs: dict[str, Any], *, mirror_scale: bool = False
) -> str:
    """Write multi-angle reflectance-factor tables (:class:`MultiAngleSpectra`) to ``path``:
    CSV (``R_400..`` columns), Parquet (the same columns, ``attrs`` as JSON in the schema
    metadata under ``goniolab.spectra``) or netCDF (``reflectance_factor`` over
    ``(geometry, wavelength_nm)`` with units and long names). Returns the format."""
    import numpy as np

    from goniolab.colour.exchange import (
        CSV_HEADER_NOTE,
        MIRROR_NOTE,
        spectra_csv,
        spectral_column,
        union_table,
    )

    values_label = (
        "fraction of the mirror reference (scale = mirror): not a reflectance factor"
        if mirror_scale
        else "reflectance factor (1 = perfect reflecting diffuser)"
    )

    fmt = SPECTRA_SUFFIXES.get(Path(path).suffix.lower())
    if fmt is None:
        raise UserError(f"{path}: spectra files are .csv, .parquet or .nc")
    table = union_table(tables)
    try:
        if fmt == "csv":
            note = MIRROR_NOTE if mirror_scale else CSV_HEADER_NOTE
            Path(path).write_text(spectra_csv(tables, note=note), encoding="utf-8")
        elif fmt == "parquet":
            import pandas as pd
            import pyarrow as pa
            import pyarrow.parquet as pq

            df = pd.DataFrame(
                {
                    "source": list(table.source),
                    "theta_i_deg": table.theta_i_deg,
                    "theta_r_deg": table.theta_r_deg,
                    "aspecular_deg": table.aspecular_deg,
                    "repeat": np.asarray(table.repeat, dtype=np.int64),
                    **{
                        spectral_column(w): table.factors[:, k]
                        for k, w in enumerate(table.wavelengths_nm)
                    },
                }
            )
            t = pa.Table.from_pandas(df, preserve_index=False)
            meta = dict(t.schema.metadata or {})
            meta[b"goniolab.spectra"] = json.dumps(
                {**attrs, "values": values_label,
                 "aspecular": "theta_i_deg - theta_r_deg (ASTM E2194)"},
                sort_keys=True, default=str,
            ).encode()  # fmt: skip
            pq.write_table(t.replace_schema_metadata(meta), path)
        else:
            import xarray as xr

            from goniolab.datasets import LONG_NAMES as _LONG_NAMES
            from goniolab.datasets import UNITS, write_netcdf

            geom = np.arange(table.factors.shape[0])
            ds = xr.Dataset(
                {
                    "reflectance_factor": (
                        ("geometry", "wavelength_nm"),
                        table.factors,
                        {
                            "units": "1",
                            "long_name": f"spectral {values_label}, measured or "
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
                            {"units": UNITS[name], "long_name": _LONG_NAMES.get(name, name)},
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
            write_netcdf(ds, path)
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None
    return fmt


def run_spectra_tables(store: Any, rec: Any, which: str) -> list[Any]:
    """A run's spectra as :class:`MultiAngleSpectra` tables (``measured`` per reading,
    ``predicted`` per geometry)."""
    import numpy as np

    from goniolab.colour.exchange import MultiAngleSpectra
    from goniolab.datasets import predicted_grid_nm, run_reflectance_factors

    wl, measured, predicted = run_reflectance_factors(store, rec.id)
    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    tr = np.asarray(rec.plan.get("theta_r_deg", []), dtype=np.float64)
    out: list[Any] = []
    if which in ("measured", "both") and wl.size:
        n, reps, _ = measured.shape
        keep = [
            (k, r) for k in range(n) for r in range(reps) if np.all(np.isfinite(measured[k, r]))
        ]
        if keep:
            out.append(
                MultiAngleSpectra(
                    wl,
                    np.full(len(keep), theta_i),
                    np.array([tr[k] for k, _ in keep]),
                    np.array([measured[k, r] for k, r in keep]),
                    tuple("measured" for _ in keep),
                    tuple(r for _, r in keep),
                )
            )
    if which in ("predicted", "both") and predicted is not None:
        keep_p = [k for k in range(predicted.shape[0]) if np.all(np.isfinite(predicted[k]))]
        if keep_p:
            out.append(
                MultiAngleSpectra(
                    predicted_grid_nm(predicted.shape[-1]),
                    np.full(len(keep_p), theta_i),
                    tr[keep_p],
                    predicted[keep_p],
                    tuple("predicted" for _ in keep_p),
                    tuple(0 for _ in keep_p),
                )
            )
    return out
