"""``runs export --format csv|json|netcdf|parquet``: what is read back equals what was stored."""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from goniolab.cli import main
from tests._runs import T0, lum, make_store


@pytest.fixture
def store_file(tmp_path: Path) -> Path:
    return make_store(tmp_path / "s.sqlite")


def _export(store: Path, run: int, *extra: str) -> int:
    return main(["runs", "export", str(run), "--store", str(store), *extra])


def test_csv_has_iso_8601_timestamps_that_read_back(
    store_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _export(store_file, 1) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == 5
    first = rows[0]
    assert first["timestamp"] == "2026-01-01T00:00:00.125000+00:00"
    for row in rows:
        k, r = int(row["index"]), int(row["repeat"])
        back = dt.datetime.fromisoformat(row["timestamp"]).timestamp()
        assert back == pytest.approx(T0 + 2 * k + r, abs=1e-6)
        assert float(row["luminance_pct"]) == lum(k, r)


def test_json_carries_the_run_and_iso_times(
    store_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _export(store_file, 1, "--format", "json") == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["run"]["status"] == "aborted" and doc["run"]["plan"]["repeats"] == 2
    assert doc["run"]["created_at_iso"].endswith("+00:00")
    assert [r["timestamp"][:19] for r in doc["readings"][:2]] == [
        "2026-01-01T00:00:00",
        "2026-01-01T00:00:01",
    ]


def test_netcdf_round_trip(store_file: Path, tmp_path: Path) -> None:
    import xarray as xr

    out = tmp_path / "run1.nc"
    assert _export(store_file, 1, "-o", str(out)) == 0  # format from the suffix
    assert out.read_bytes()[:8] == b"\x89HDF\r\n\x1a\n"  # netCDF-4 is HDF5
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        ds.load()
    assert ds.sizes == {"theta_r_deg": 3, "repeat": 2, "wavelength_nm": 3}
    assert ds["theta_r_deg"].attrs["units"] == "degree"
    assert ds["luminance_pct"].attrs["units"] == "percent"
    assert ds["wavelength_nm"].attrs["units"] == "nm"
    expected = np.array([[lum(k, r) for r in range(2)] for k in range(3)])
    expected[2, 1] = np.nan  # the reading never taken
    np.testing.assert_array_equal(ds["luminance_pct"].values, expected)
    np.testing.assert_allclose(ds["luminance_mean_pct"].values, np.nanmean(expected, axis=1))
    np.testing.assert_allclose(ds["predicted_pct"].values, [1.0, 12.0, 3.0])
    np.testing.assert_allclose(
        ds["residual_pct"].values, np.nanmean(expected, axis=1) - [1.0, 12.0, 3.0]
    )
    np.testing.assert_allclose(
        ds["aspecular_deg"].values, [5.0, 0.0, -5.0]
    )  # E2194: theta_i - theta_r
    np.testing.assert_array_equal(ds["reflectance_pct"].sel(theta_r_deg=45.0).values[:, :2],
                                  [[1.0, 0.0], [1.0, 1.0]])  # fmt: skip
    t = ds["time"].values
    assert np.isnat(t[2, 1])
    assert t[1, 1] == np.datetime64(round((T0 + 3) * 1e9), "ns")
    # the run's metadata as attributes
    assert ds.attrs["run_id"] == 1 and ds.attrs["status"] == "aborted"
    assert ds.attrs["reason"] == "aborted by the operator"
    assert json.loads(ds.attrs["plan_json"])["theta_r_deg"] == [40.0, 45.0, 50.0]
    assert json.loads(ds.attrs["config_json"]) == {"lab": {"name": "t"}}
    assert ds.attrs["stored_readings"] == 5 and ds.attrs["planned_readings"] == 6


def test_parquet_round_trip(store_file: Path, tmp_path: Path) -> None:
    import pandas as pd
    import pyarrow.parquet as pq

    from goniolab.export import PARQUET_RUN_KEY

    out = tmp_path / "run1.parquet"
    assert _export(store_file, 1, "--format", "parquet", "-o", str(out)) == 0
    df = pd.read_parquet(out)
    assert len(df) == 5
    assert str(df["timestamp"].dtype) == "datetime64[us, UTC]"
    for row in df.itertuples():
        k, r = int(row.index), int(row.repeat)
        assert row.luminance_pct == lum(k, r)
        assert row.timestamp.timestamp() == pytest.approx(T0 + 2 * k + r, abs=1e-6)
    assert list(df["predicted_pct"]) == [1.0, 1.0, 12.0, 12.0, 3.0]
    meta = pq.read_schema(out).metadata
    run = json.loads(meta[PARQUET_RUN_KEY])
    assert run["id"] == 1 and run["plan"]["theta_i_deg"] == 45.0


def test_gloss_log_to_netcdf(store_file: Path, tmp_path: Path) -> None:
    import xarray as xr

    out = tmp_path / "gloss.nc"
    assert _export(store_file, 2, "--format", "netcdf", "-o", str(out)) == 0
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        ds.load()
    np.testing.assert_array_equal(ds["g60_gu"].values, [90.0, 91.0])
    np.testing.assert_array_equal(ds["predicted_g20_gu"].values, [81.0, 81.0])
    assert ds["g60_gu"].attrs["units"] == "1" and "GU" in ds["g60_gu"].attrs["units_metadata"]
    assert ds["temperature_c"].attrs["units"] == "degC"
    assert ds.attrs["kind"] == "gloss"
    dt_s = (ds["time"].values[1] - ds["time"].values[0]) / np.timedelta64(1, "s")
    assert math.isclose(dt_s, 60.0)


def test_binary_format_to_stdout_is_one_line_error(
    store_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _export(store_file, 1, "--format", "netcdf") == 2
    err = capsys.readouterr().err
    assert err.startswith("goniolab: error: ") and err.count("\n") == 1 and "-o" in err


def test_export_json_flag_reports_the_file(
    store_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "r.parquet"
    assert _export(store_file, 1, "-o", str(out), "--json") == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc == {"run_id": 1, "format": "parquet", "output": str(out.resolve())}


def test_export_json_flag_without_output_prints_the_run_as_json(
    store_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``runs export RUN --json`` answers in JSON like every other command (it printed CSV)."""
    assert _export(store_file, 1, "--format", "json") == 0
    expected = json.loads(capsys.readouterr().out)
    assert _export(store_file, 1, "--json") == 0
    assert json.loads(capsys.readouterr().out) == expected
    assert _export(store_file, 1, "--json", "--format", "csv") == 2
    err = capsys.readouterr().err
    assert (
        err.startswith("goniolab: error: runs export --json --format csv") and err.count("\n") == 1
    )


def test_predict_brdf_out_netcdf_round_trip(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import xarray as xr

    out = tmp_path / "curve.nc"
    args = ["predict", "brdf", "sample:wittmann-3", "--theta-r", "40,45,50", "--json"]
    assert main([*args, "--out", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        ds.load()
    np.testing.assert_array_equal(ds["luminance_pct"].values, doc["luminance_pct"])
    np.testing.assert_array_equal(ds["brdf_sr"].values, doc["brdf_sr"])
    np.testing.assert_array_equal(ds["theta_r_deg"].values, [40.0, 45.0, 50.0])
    assert ds["brdf_sr"].attrs["units"] == "sr-1"
    assert float(ds["theta_i_deg"]) == 45.0
    assert ds.attrs["map"] == "sample:wittmann-3" and ds.attrs["detector_cone_deg"] == 6.0


def test_predict_gloss_out_netcdf(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import xarray as xr

    out = tmp_path / "gloss.nc"
    assert (
        main(["predict", "gloss", "sample:flat", "--n", "1.567", "--json", "--out", str(out)]) == 0
    )
    doc = json.loads(capsys.readouterr().out)
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        ds.load()
    np.testing.assert_array_equal(ds["gloss_gu"].values, [doc["G20"], doc["G60"], doc["G85"]])
    assert float(ds["haze_index"]) == doc["haze_index"]
    assert ds.attrs["d523_recommended_angle_deg"] == doc["d523_angle"]


@pytest.mark.parametrize("fmt", ["csv", "json", "netcdf", "parquet"])
def test_export_to_a_full_disk_keeps_the_old_file(
    store_file: Path, tmp_path: Path, fmt: str
) -> None:
    # issue 23.14: netCDF raised then segfaulted; a re-export over an existing file on a full
    # disk destroyed it. Now: one line, exit 2, the old file byte for byte, no temp file left.
    import subprocess
    import sys

    from goniolab.export import FORMATS
    from tests._fulldisk import fill, small_tmpfs

    with small_tmpfs(tmp_path / "disk", 256) as disk:
        out = disk / f"run{FORMATS[fmt]}"
        old = b"an earlier export\n"
        out.write_bytes(old)
        fill(disk)
        code = (
            "import sys; from goniolab.cli import main; "
            f"sys.exit(main(['runs', 'export', '1', '--store', {str(store_file)!r}, "
            f"'--format', {fmt!r}, '-o', {str(out)!r}]))"
        )
        done = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
        )
        assert done.returncode == 2, done.stderr  # not -11 (a segfault)
        assert done.stderr.count("\n") == 1 and "No space left on device" in done.stderr
        assert f"{out} is left as it was" in done.stderr
        assert out.read_bytes() == old
        assert sorted(p.name for p in disk.iterdir()) == ["filler", "filler-tail", out.name]


# ---------------------------------------------------------------- the exporter registry


@pytest.mark.parametrize("name", ["run.xlsx", "run", "run.csv.bak"])
def test_a_suffix_no_exporter_has_is_refused_naming_the_known_ones(
    store_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    # issue 27: `runs export -o run.xlsx` wrote CSV into run.xlsx without a word
    out = tmp_path / name
    assert _export(store_file, 1, "-o", str(out)) == 2
    err = capsys.readouterr().err
    assert err.startswith("goniolab: error: runs export: ") and err.count("\n") == 1
    for suffix in (".csv", ".json", ".nc", ".parquet"):
        assert suffix in err, suffix
    assert not out.exists()


def test_an_explicit_format_writes_to_any_name_but_not_to_another_formats_suffix(
    store_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    named = tmp_path / "run.txt"  # --format says what it is: the name is the user's choice
    assert _export(store_file, 1, "--format", "csv", "-o", str(named)) == 0
    assert named.read_text().splitlines()[0].startswith("run_id,run_uuid,index,repeat,")
    capsys.readouterr()
    wrong = tmp_path / "run.parquet"  # a CSV file named as Parquet would not read back
    assert _export(store_file, 1, "--format", "csv", "-o", str(wrong)) == 2
    err = capsys.readouterr().err
    assert "parquet" in err and err.count("\n") == 1 and not wrong.exists()
    upper = tmp_path / "RUN.CSV"  # suffixes are matched whatever their case
    assert _export(store_file, 1, "-o", str(upper)) == 0
    assert upper.read_text() == named.read_text()


def test_an_unknown_format_is_refused_by_the_parser_listing_the_registry(
    store_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from goniolab.export import EXPORTERS

    assert _export(store_file, 1, "--format", "xlsx") == 2
    err = capsys.readouterr().err
    assert "xlsx" in err and all(repr(name) in err for name in EXPORTERS)


def _export_parser() -> argparse.ArgumentParser:
    from goniolab.cli import build_parser

    runs = next(
        a
        for a in build_parser()._subparsers._group_actions  # type: ignore[union-attr]
    ).choices["runs"]
    sub = next(a for a in runs._actions if isinstance(a, argparse._SubParsersAction))
    parser: argparse.ArgumentParser = sub.choices["export"]
    return parser


def test_runs_export_choices_and_help_come_from_the_registry(
    monkeypatch: pytest.MonkeyPatch, store_file: Path, tmp_path: Path
) -> None:
    """A format registered with ``register_exporter`` is a ``--format`` choice, named in
    the help, picked by its suffix and written: one writer and its registration."""
    import goniolab.export as ex

    monkeypatch.setattr(ex, "EXPORTERS", dict(ex.EXPORTERS))
    monkeypatch.setattr(ex, "FORMATS", dict(ex.FORMATS))

    def tsv_text(store: Any, run_id: int) -> str:
        rows = ex.export_rows(store, run_id)
        return "".join("\t".join(str(r[c]) for c in ("index", "repeat")) + "\n" for r in rows)

    ex.register_exporter(ex.Exporter("tsv", (".tsv",), "index and repeat, tab-separated",
                                     text=tsv_text))  # fmt: skip
    fmt_action = next(a for a in _export_parser()._actions if a.dest == "format")
    assert list(fmt_action.choices or ()) == ["csv", "json", "netcdf", "parquet", "tsv"]
    assert ".tsv" in (fmt_action.help or "") and ".parquet" in (fmt_action.help or "")
    assert "index and repeat, tab-separated" in (_export_parser().description or "")
    out = tmp_path / "run.tsv"
    assert _export(store_file, 1, "-o", str(out)) == 0
    # the 5 readings of tests/_runs.py: (k, r) for k in 0..2, r in 0..1 but (2, 1)
    assert out.read_text() == "0\t0\n0\t1\n1\t0\n1\t1\n2\t0\n"
    assert ex.FORMATS["tsv"] == ".tsv" and ex.format_for_path("a.TSV") == "tsv"


def test_register_exporter_refuses_a_taken_name_or_suffix_and_a_writerless_format(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import goniolab.export as ex

    monkeypatch.setattr(ex, "EXPORTERS", dict(ex.EXPORTERS))
    monkeypatch.setattr(ex, "FORMATS", dict(ex.FORMATS))
    csv_writer = ex.EXPORTERS["csv"].text
    bad = {
        "csv is taken": ex.Exporter("csv", (".csv2",), "x", text=csv_writer),
        ".nc is netcdf's": ex.Exporter("nc2", (".nc",), "x", text=csv_writer),
        "no dot": ex.Exporter("x1", ("x1",), "x", text=csv_writer),
        "no writer": ex.Exporter("x2", (".x2",), "x"),
    }
    for why, exporter in bad.items():
        with pytest.raises(ValueError, match="export format"):
            ex.register_exporter(exporter)
        assert exporter.name not in ex.EXPORTERS or exporter.name == "csv", why
    assert list(ex.EXPORTERS) == ["csv", "json", "netcdf", "parquet"]


def test_export_run_in_the_library_names_the_known_formats(store_file: Path) -> None:
    from goniolab.export import export_run
    from goniolab.store import RunStore

    with RunStore(store_file, readonly=True) as s:
        with pytest.raises(ValueError, match="csv, json, netcdf, parquet, got 'xlsx'"):
            export_run(s, 1, "xlsx")
        with pytest.raises(ValueError, match=r"-o run\.parquet"):
            export_run(s, 1, "parquet")
