"""Spectral exchange: runs spectra / predict colour --spectra-out write reflectance factors
(CSV R_400.., Parquet, netCDF) and predict colour --compare reads a lab's measured file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.colour.exchange import read_spectra_csv
from goniolab.colour.spectra import ColourError, spectrum_to_colour
from goniolab.store import RunStore
from tests.colour._spectral_runs import PRED_WL, WL, factor_spectrum, make_spectral_store


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_spectral_store(tmp_path_factory.mktemp("ex") / "s.sqlite", shift=0.05)


def test_exported_factors_give_back_the_runners_colours(store: Path, tmp_path: Path) -> None:
    out = tmp_path / "run.csv"
    assert main(["runs", "spectra", "1", "--store", str(store), "-o", str(out)]) == 0
    text = out.read_text()
    assert "reflectance factor (1 = perfect reflecting diffuser)" in text.splitlines()[0]
    table = read_spectra_csv(text)  # the union grid: the measured rows are 400-700 nm
    meas = read_spectra_csv(text).select("measured")
    np.testing.assert_array_equal(meas.wavelengths_nm, WL)
    assert table.factors.shape[0] == 6 * 2 + 6
    # the factors are what the test wrote (independent of the export's own arithmetic)
    for k in range(meas.factors.shape[0]):
        a = 45.0 - meas.theta_r_deg[k]
        expected = factor_spectrum(WL, a) * (1.0 + 0.002 * meas.repeat[k])
        np.testing.assert_allclose(meas.factors[k], expected, rtol=1e-5)
    # and give the L*a*b* the runner stored for each reading
    with RunStore(store, readonly=True) as s:
        points = {(p.index, p.repeat): p for p in s.points(1)}
        tr_plan = list(s.get_run(1).plan["theta_r_deg"])
    for k in range(meas.factors.shape[0]):
        p = points[(tr_plan.index(meas.theta_r_deg[k]), meas.repeat[k])]
        c = spectrum_to_colour(meas.wavelengths_nm, meas.factors[k])
        assert c.lab == pytest.approx((p.colour["L"], p.colour["a"], p.colour["b"]), abs=1e-3)
    pred = table.select("predicted")
    np.testing.assert_allclose(
        pred.factors[0],
        factor_spectrum(pred.wavelengths_nm, 45.0 - pred.theta_r_deg[0], 0.05),
        rtol=1e-5,
    )


def test_parquet_and_netcdf_carry_the_same_factors(store: Path, tmp_path: Path) -> None:
    import pandas as pd
    import pyarrow.parquet as pq
    import xarray as xr

    csv_t = tmp_path / "r.csv"
    for suffix in ("csv", "parquet", "nc"):
        argv = ["runs", "spectra", "1", "--store", str(store), "-o", str(tmp_path / f"r.{suffix}")]
        assert main(argv) == 0
    ref = read_spectra_csv(csv_t.read_text())
    df = pd.read_parquet(tmp_path / "r.parquet")
    cols = [c for c in df.columns if c.startswith("R_")]
    assert cols[0] == "R_380" and "R_700" in cols
    meta = json.loads(pq.read_schema(tmp_path / "r.parquet").metadata[b"goniolab.spectra"])
    assert meta["values"].startswith("reflectance factor")
    np.testing.assert_allclose(
        df.loc[df.source == "measured", [f"R_{w:g}" for w in WL]].to_numpy()[:2],
        ref.select("measured").factors[:2],
        rtol=1e-5,
    )
    np.testing.assert_allclose(df.aspecular_deg, df.theta_i_deg - df.theta_r_deg)
    with xr.open_dataset(tmp_path / "r.nc", engine="h5netcdf") as ds:
        ds.load()
    assert ds["reflectance_factor"].attrs["units"] == "1"
    assert "reflectance factor" in ds["reflectance_factor"].attrs["long_name"]
    assert ds["wavelength_nm"].attrs["units"] == "nm"
    np.testing.assert_allclose(ds["aspecular_deg"], ds["theta_i_deg"] - ds["theta_r_deg"])
    np.testing.assert_allclose(
        ds["reflectance_factor"].values, df[cols].to_numpy(), rtol=1e-12, equal_nan=True
    )


def test_run_netcdf_export_holds_reflectance_factors(store: Path, tmp_path: Path) -> None:
    import xarray as xr

    out = tmp_path / "run.nc"
    assert main(["runs", "export", "1", "--store", str(store), "-o", str(out)]) == 0
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        ds.load()
    rf = ds["reflectance_factor"]
    assert rf.attrs["units"] == "1" and rf.attrs["scale"] == "diffuser"
    assert "not a reflectance factor" in ds["reflectance_pct"].attrs["long_name"]
    k = int(np.argmin(np.abs(ds["theta_r_deg"].values - 0.0)))  # 45 deg aspecular
    np.testing.assert_allclose(rf.values[k, 0], factor_spectrum(WL, 45.0), rtol=1e-9)
    prf = ds["predicted_reflectance_factor"]
    np.testing.assert_allclose(ds["predicted_wavelength_nm"].values, PRED_WL)
    np.testing.assert_allclose(prf.values[k], factor_spectrum(PRED_WL, 45.0, 0.05), rtol=1e-9)


def test_a_prediction_compared_with_its_own_exported_spectra_matches(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "pred.csv"
    args = ["predict", "colour", "sample:solid-red", "--step-nm", "20", "--json"]
    assert main([*args, "--spectra-out", str(out)]) == 0
    first = json.loads(capsys.readouterr().out)
    # relabel the predicted rows as a measurement, one duplicated as a repeat, in percent
    lines = out.read_text().splitlines()
    rows = [ln.replace("predicted,", "measured,", 1) for ln in lines[2:]]
    pct = [lines[1]] + [
        ",".join(c if k < 5 else f"{100 * float(c):.6g}" for k, c in enumerate(r.split(",")))
        for r in [*rows, rows[0]]
    ]
    meas = tmp_path / "meas.csv"
    meas.write_text("\n".join(pct) + "\n")
    assert main([*args, "--compare", str(meas), "--compare-unit", "percent"]) == 0
    doc = json.loads(capsys.readouterr().out)
    cmp_ = doc["compare"]
    assert cmp_["rows_read"] == 7
    assert [g["aspecular_deg"] for g in cmp_["tolerance"]["geometries"]] == [
        g["aspecular_deg"] for g in first["geometries"]
    ]
    assert max(g["dE00"] for g in cmp_["tolerance"]["geometries"]) < 1e-3
    assert cmp_["tolerance"]["overall"]["passed"] is True


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("aspecular_deg,a,b,c\n15,1,2,3\n", "no spectral columns"),
        ("x,R_400,R_500,R_600,R_700\n1,1,1,1,1\n", "needs an aspecular_deg or theta_r_deg"),
        ("aspecular_deg,R_400,R_500,R_600,R_700\n15,1,x,1,1\n", "line 2, R_500: 'x' is not"),
        ("aspecular_deg,R_450,R_550,R_650,R_750\n15,1,1,1,1\n", "do not cover 400-700 nm"),
        ("aspecular_deg,R_400,R_500,R_600,R_700\n15,1,-1,1,1\n", "500 nm is negative"),
        ("theta_r_deg,R_400,R_500,R_600,R_700\n95,1,1,1,1\n", "below the horizon"),
    ],
)
def test_bad_files_name_line_and_reason(text: str, needle: str) -> None:
    with pytest.raises(ColourError, match=needle):
        read_spectra_csv(text, where="m.csv")


def test_a_mirror_scale_run_is_not_labelled_reflectance_factor(tmp_path: Path) -> None:
    import xarray as xr

    store = make_spectral_store(tmp_path / "m.sqlite", scale="mirror")
    out = tmp_path / "m.csv"
    assert main(["runs", "spectra", "1", "--store", str(store), "-o", str(out)]) == 0
    assert "not reflectance factors" in out.read_text().splitlines()[0]
    nc = tmp_path / "m.nc"
    assert main(["runs", "export", "1", "--store", str(store), "-o", str(nc)]) == 0
    with xr.open_dataset(nc, engine="h5netcdf") as ds:
        assert "not a reflectance factor" in ds["reflectance_factor"].attrs["long_name"]
        assert ds["reflectance_factor"].attrs["scale"] == "mirror"
        # the mirror scale: the reading / 100, no detector-cone factor
        k = int(np.argmin(np.abs(ds["theta_r_deg"].values)))
        with RunStore(store, readonly=True) as s:
            p = next(p for p in s.points(1) if p.index == k and p.repeat == 0)
        np.testing.assert_allclose(
            ds["reflectance_factor"].values[k, 0], np.asarray(p.raw["values"]) / 100.0
        )


def test_compare_keeps_the_files_geometry_and_says_so(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    meas = tmp_path / "meas.csv"
    argv = ["runs", "spectra", "1", "--store", str(store), "-o", str(meas), "--which", "measured"]
    assert main(argv) == 0
    capsys.readouterr()
    base = ["predict", "colour", "sample:flat", "--compare", str(meas), "--step-nm", "20"]
    assert main([*base, "--theta-r", "10"]) == 2
    assert "leave out --theta-r" in capsys.readouterr().err
    assert main([*base, "--theta-i", "40", "--json"]) == 0
    cap = capsys.readouterr()
    assert "measured at theta_i 45 deg: predicting there" in cap.err
    assert json.loads(cap.out)["theta_i_deg"] == 45.0
