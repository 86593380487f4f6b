"""The spectra exchange files below the faces (goniolab/spectra_files.py, run_spectra.spectra_tables).

A stored run with known spectra (:mod:`tests.colour._spectral_runs`) written by the library
gives the known factors back in CSV, Parquet and netCDF, with what they are relative to;
and the library writes what ``runs spectra`` writes today (the same CSV bytes, the same
Parquet/netCDF values), so the face can call it instead of its own copy.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.colour.exchange import read_spectra_csv
from goniolab.run_spectra import spectra_tables
from goniolab.spectra_files import spectra_format, write_spectra_file
from goniolab.store import RunStore
from tests.colour._spectral_runs import PRED_WL, WL, factor_spectrum, make_spectral_store

SHIFT = 0.05


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_spectral_store(tmp_path_factory.mktemp("sf") / "s.sqlite", shift=SHIFT)


def _write(store: Path, out: Path, which: str = "both") -> dict:
    with RunStore(store, readonly=True) as s:
        tables, attrs = spectra_tables(s, 1, which)
    assert write_spectra_file(tables, out, attrs) == spectra_format(out)
    return attrs


def test_the_library_csv_gives_back_the_known_spectra(store: Path, tmp_path: Path) -> None:
    attrs = _write(store, tmp_path / "s.csv")
    table = read_spectra_csv((tmp_path / "s.csv").read_text())
    meas, pred = table.select("measured"), table.select("predicted")
    np.testing.assert_array_equal(meas.wavelengths_nm, WL)
    assert meas.factors.shape == (12, WL.size) and pred.factors.shape[0] == 6
    for k in range(12):
        truth = factor_spectrum(WL, float(meas.aspecular_deg[k])) * (1 + 0.002 * meas.repeat[k])
        np.testing.assert_allclose(meas.factors[k], truth, rtol=1e-5)  # 6 digits in the CSV
    for k in range(6):
        truth = factor_spectrum(pred.wavelengths_nm, float(pred.aspecular_deg[k]), SHIFT)
        np.testing.assert_allclose(pred.factors[k], truth, rtol=1e-5)
    assert attrs["colour_scale"] == "diffuser" and "no certified standard" in attrs["referenced_to"]


def test_the_library_writes_what_runs_spectra_writes(store: Path, tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    from goniolab.datasets import open_dataset

    for suffix in ("csv", "parquet", "nc"):
        face, lib = tmp_path / f"face.{suffix}", tmp_path / f"lib.{suffix}"
        assert main(["runs", "spectra", "1", "--store", str(store), "-o", str(face)]) == 0
        _write(store, lib)
        if suffix == "csv":
            assert lib.read_bytes() == face.read_bytes()
        elif suffix == "parquet":
            a, b = pq.read_table(face), pq.read_table(lib)
            assert a.column_names == b.column_names and a.to_pylist() == b.to_pylist()
            meta = json.loads(b.schema.metadata[b"goniolab.spectra"])
            assert meta["relative_to"].startswith("perfect reflecting diffuser")
            assert meta["values"] == "reflectance factor (1 = perfect reflecting diffuser)"
        else:
            a, b = open_dataset(face), open_dataset(lib)
            np.testing.assert_array_equal(a["reflectance_factor"].values,
                                          b["reflectance_factor"].values)  # fmt: skip
            np.testing.assert_array_equal(a["aspecular_deg"].values, b["aspecular_deg"].values)
            assert b.attrs["colour_scale"] == "diffuser" and "referenced_to" in b.attrs


def test_which_selects_and_a_bad_suffix_is_refused(store: Path, tmp_path: Path) -> None:
    with RunStore(store, readonly=True) as s:
        only_pred, _ = spectra_tables(s, 1, "predicted")
        with pytest.raises(ValueError, match="measured, predicted or both"):
            spectra_tables(s, 1, "all")
    assert [t.source[0] for t in only_pred] == ["predicted"]
    np.testing.assert_array_equal(only_pred[0].wavelengths_nm, PRED_WL)
    with pytest.raises(ValueError, match=r"\.csv, \.parquet or \.nc"):
        write_spectra_file(only_pred, tmp_path / "s.xlsx", {})
    assert not (tmp_path / "s.xlsx").exists()
