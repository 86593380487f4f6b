"""``runs import`` restores a scan's spectra, and ``runs export --no-spectra`` (issue 25).

The truth is the source run: exported as JSON (the format ``runs import`` reads), imported
into another store and exported again, it gives the same export, bit for bit: every
``R_<nm>`` and ``predicted_R_<nm>`` cell, the colours, the spectra's provenance; and the
other formats of the imported run equal the source's. The spectra themselves are the known
ones of :mod:`tests.colour._spectral_runs` (``factor_spectrum``). ``--no-spectra`` gives
the full export's table without its spectral columns, in every format.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.export import SCAN_COLUMNS, SPECTRUM_COLUMNS
from goniolab.run_spectra import percent_of_mirror
from goniolab.store import RunStore
from tests.colour._spectral_runs import PRED_WL, WL, factor_spectrum, make_spectral_store
from tests.test_export_spectra import _referenced_store

SHIFT = 0.05


def _export(store: Path, out: Path, *args: str) -> None:
    assert main(["runs", "export", "1", "-o", str(out), "--store", str(store), *args]) == 0


def _round_trip(src: Path, tmp: Path) -> tuple[Path, dict[str, Any], dict[str, Any]]:
    """Export run 1 of ``src`` as JSON, import it into a new store, export it again."""
    _export(src, tmp / "a.json")
    target = tmp / "b.sqlite"
    assert main(["runs", "import", str(tmp / "a.json"), "--store", str(target)]) == 0
    _export(target, tmp / "b.json")
    a, b = (json.loads((tmp / f"{x}.json").read_text()) for x in "ab")
    return target, a, b


def test_export_import_export_gives_the_same_spectra_bit_for_bit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = make_spectral_store(tmp_path / "a.sqlite", shift=SHIFT)
    target, a, b = _round_trip(src, tmp_path)
    assert "12 measured and 6 predicted spectra" in capsys.readouterr().out
    assert a["readings"] == b["readings"]  # every cell, floats compared exactly
    assert a["spectra"] == b["spectra"]
    # the spectra are the known ones (the source's own % -> factor round-off aside)
    row = a["readings"][3]
    tr, rep = float(row["theta_r_deg"]), int(row["repeat"])
    measured = np.array([row[f"R_{int(w)}"] for w in WL])
    np.testing.assert_allclose(measured, factor_spectrum(WL, 45.0 - tr) * (1 + 0.002 * rep),
                               rtol=1e-13)  # fmt: skip
    predicted = np.array([row[f"predicted_R_{int(w)}"] for w in PRED_WL])
    np.testing.assert_allclose(predicted, factor_spectrum(PRED_WL, 45.0 - tr, SHIFT), rtol=1e-13)
    # the other formats of the imported run are the source's too
    for fmt in ("csv", "parquet", "nc"):
        _export(src, tmp_path / f"a.{fmt}")
        _export(target, tmp_path / f"b.{fmt}")
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()
    import pandas as pd
    import xarray as xr

    pd.testing.assert_frame_equal(
        pd.read_parquet(tmp_path / "a.parquet"), pd.read_parquet(tmp_path / "b.parquet")
    )
    with xr.open_dataset(tmp_path / "a.nc") as da, xr.open_dataset(tmp_path / "b.nc") as db:
        for name in ("reflectance_factor", "predicted_reflectance_factor"):
            xr.testing.assert_identical(da[name], db[name])
        # % of the mirror: the source's values and the import's map to the same factors
        # (the import's are chosen so); they may differ from each other by an ulp
        np.testing.assert_allclose(db["reflectance_pct"], da["reflectance_pct"], rtol=1e-15)


def test_a_referenced_run_comes_back_with_its_certificate(tmp_path: Path) -> None:
    src, _ = _referenced_store(tmp_path / "r.sqlite")
    _, a, b = _round_trip(src, tmp_path)
    assert a["readings"] == b["readings"]
    assert a["spectra"] == b["spectra"]
    assert a["spectra"]["standards"][0]["certificate"] == "CERT-42"
    labels = [r["spectrum_referenced_to"] for r in b["readings"]]
    assert labels[1] == "certified mirror (certificate CERT-42; spectral)"


def test_a_mirror_scale_run_round_trips(tmp_path: Path) -> None:
    src = make_spectral_store(tmp_path / "m.sqlite", scale="mirror", shift=SHIFT)
    _, a, b = _round_trip(src, tmp_path)
    assert a["readings"] == b["readings"] and a["spectra"] == b["spectra"]


def test_percent_of_mirror_inverts_the_exports_step_exactly() -> None:
    """The export computes ``values / 100 * scale``; the naive inverse
    ``factors / scale * 100`` misses some values by an ulp, the stepped one none."""
    rng = np.random.default_rng(7)
    for scale in (1.0, 0.37, 45.6, 365.25, 1e-3):
        values = rng.uniform(0.0, 250.0, 20_000)
        factors = values / 100.0 * scale
        naive = factors / scale * 100.0
        exact = percent_of_mirror(factors, scale)
        np.testing.assert_array_equal(exact / 100.0 * scale, factors)
        if scale != 1.0:
            assert np.any(naive / 100.0 * scale != factors)


def _columns(path: Path) -> list[str]:
    if path.suffix == ".csv":
        return next(csv.reader(io.StringIO(path.read_text())))
    import pandas as pd

    return list(pd.read_parquet(path).columns)


def test_no_spectra_gives_the_compact_table_in_every_format(tmp_path: Path) -> None:
    src = make_spectral_store(tmp_path / "a.sqlite", shift=SHIFT)
    for fmt in ("csv", "parquet"):
        full, compact = tmp_path / f"full.{fmt}", tmp_path / f"compact.{fmt}"
        _export(src, full)
        _export(src, compact, "--no-spectra")
        assert any(c.startswith("R_") for c in _columns(full))
        assert _columns(compact) == list(SCAN_COLUMNS)
    rows_full = list(csv.DictReader(io.StringIO((tmp_path / "full.csv").read_text())))
    rows_compact = list(csv.DictReader(io.StringIO((tmp_path / "compact.csv").read_text())))
    assert rows_compact == [{c: r[c] for c in SCAN_COLUMNS} for r in rows_full]
    _export(src, tmp_path / "c.json", "--no-spectra")
    doc = json.loads((tmp_path / "c.json").read_text())
    assert "spectra" not in doc and list(doc["readings"][0]) == list(SCAN_COLUMNS)
    assert not set(SPECTRUM_COLUMNS) & set(doc["readings"][0])
    _export(src, tmp_path / "c.nc", "--no-spectra")
    import xarray as xr

    with xr.open_dataset(tmp_path / "c.nc") as ds:
        assert "wavelength_nm" not in ds.dims and "predicted_wavelength_nm" not in ds.dims
        assert "reflectance_factor" not in ds and "luminance_pct" in ds and "L_star" in ds


def test_bad_spectra_in_an_export_are_refused_naming_file_reading_and_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = make_spectral_store(tmp_path / "a.sqlite", shift=SHIFT)
    _export(src, tmp_path / "a.json")
    doc = json.loads((tmp_path / "a.json").read_text())
    doc["readings"][2]["R_550"] = "0,45"  # a decimal comma typed in
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    doc = json.loads((tmp_path / "a.json").read_text())
    for row in doc["readings"]:  # a prediction on 400-780 nm: not the stored grid
        del row["predicted_R_380"], row["predicted_R_390"]
    grid = tmp_path / "grid.json"
    grid.write_text(json.dumps(doc))
    target = tmp_path / "t.sqlite"
    assert main(["runs", "import", str(bad), str(grid), "--store", str(target)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: readings[2], column R_550: '0,45' is not a finite number" in err
    assert f"{grid}: columns predicted_R_400..predicted_R_780:" in err
    with RunStore(target, readonly=True) as s:
        assert s.list_runs() == []  # nothing half-imported


def test_a_grid_finer_than_the_column_names_comes_back_unrounded(tmp_path: Path) -> None:
    """Column names carry 6 digits (``R_400.012``); the JSON's ``spectra`` block carries the
    grid itself, and the import takes it from there."""
    from goniolab.scan.plans import BrdfPlan

    wl = [400.0123456 + 50.0 * k for k in range(7)]
    plan = BrdfPlan(45.0, (30.0, 20.0), repeats=1, sample="sample:x")
    src = tmp_path / "f.sqlite"
    with RunStore(src) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), sample="sample:x", version="t",
                           config={"spectro": {"detector_cone_deg": 6.0}}, model={})  # fmt: skip
        for k, tr in enumerate(plan.theta_r_deg):
            s.add_point(rid, index=k, repeat=0, theta_i_deg=45.0, theta_r_deg=tr,
                        measured_theta_i_deg=45.0, measured_theta_r_deg=tr, luminance_pct=3.0,
                        raw={"wavelengths_nm": wl, "values": [3.0 + 0.1 * j for j in range(7)]},
                        timestamp=1.0 + k)  # fmt: skip
    _, a, b = _round_trip(src, tmp_path)
    assert "R_400.012" in a["readings"][0]
    assert b["spectra"]["wavelengths_nm"] == wl
    assert a["readings"] == b["readings"] and a["spectra"] == b["spectra"]


def test_a_parquet_export_imports_with_its_spectra(tmp_path: Path) -> None:
    """``runs import`` reads a Parquet export too (the run record and the spectra's
    provenance are in its schema metadata): Parquet -> import -> Parquet is the same
    table, and the JSON exports of both runs are the same."""
    import pandas as pd

    src = make_spectral_store(tmp_path / "a.sqlite", shift=SHIFT)
    _export(src, tmp_path / "a.parquet")
    target = tmp_path / "b.sqlite"
    assert main(["runs", "import", str(tmp_path / "a.parquet"), "--store", str(target)]) == 0
    _export(target, tmp_path / "b.parquet")
    pd.testing.assert_frame_equal(
        pd.read_parquet(tmp_path / "a.parquet"), pd.read_parquet(tmp_path / "b.parquet")
    )
    _export(src, tmp_path / "a.json")
    _export(target, tmp_path / "b.json")
    a, b = (json.loads((tmp_path / f"{x}.json").read_text()) for x in "ab")
    assert a["readings"] == b["readings"] and a["spectra"] == b["spectra"]


def test_a_parquet_file_that_is_not_an_export_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import pandas as pd

    other = tmp_path / "other.parquet"
    pd.DataFrame({"x": [1.0]}).to_parquet(other)
    broken = tmp_path / "broken.pq"
    broken.write_bytes(b"PAR1 not really")
    assert main(["runs", "import", str(other), str(broken), "--store",
                 str(tmp_path / "t.sqlite")]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert f"{other}: no goniolab.run schema metadata (not a goniolab run export" in err
    assert f"{broken}: not a Parquet file" in err
