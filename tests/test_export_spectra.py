"""``runs export``: every format carries the scan's spectra as reflectance factors (issue 25).

The truth is the synthetic run of :mod:`tests.colour._spectral_runs`: each reading stores
``factor_spectrum(WL, aspecular) x (1 + 0.002 repeat) / scale x 100`` (% of the mirror, the
runner's form) and each geometry the predicted ``factor_spectrum(PRED_WL, aspecular,
shift)``; the export must give those factors back (to float round-off of the % -> factor
division) under the column names ``R_<nm>`` / ``predicted_R_<nm>``, with what they are
relative to. A run referenced to a certified mirror exports the referenced (absolute)
spectrum, not the instrument's, and names the certificate; a real twin scan's exported
spectra give back the colours its runner stored.
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
from goniolab.colour.exchange import read_spectra_csv
from goniolab.colour.spectra import ColourSettings, spectrum_to_colour
from goniolab.export import (
    PARQUET_SPECTRA_KEY,
    SCAN_COLUMNS,
    SPECTRUM_COLUMNS,
    export_columns,
    export_run,
)
from goniolab.scan.colour import PointColour
from goniolab.scan.plans import MIRROR_INDEX, BrdfPlan
from goniolab.store import RunStore
from tests.colour._spectral_runs import CONE_DEG, PRED_WL, WL, factor_spectrum, make_spectral_store

SHIFT = 0.05
#: float round-off of values / scale x 100 -> / 100 x scale (a few ulp)
RTOL = 1e-13


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_spectral_store(tmp_path_factory.mktemp("sp") / "s.sqlite", shift=SHIFT)


def _measured_truth(theta_r_deg: float, repeat: int) -> np.ndarray:
    return factor_spectrum(WL, 45.0 - theta_r_deg) * (1.0 + 0.002 * repeat)


def _predicted_truth(theta_r_deg: float) -> np.ndarray:
    return factor_spectrum(PRED_WL, 45.0 - theta_r_deg, SHIFT)


def _cells(row: dict[str, Any], names: list[str]) -> np.ndarray:
    return np.array([float(row[n]) for n in names])


R_NAMES = [f"R_{int(w)}" for w in WL]  # R_400 ... R_700, written out independently
P_NAMES = [f"predicted_R_{int(w)}" for w in PRED_WL]  # predicted_R_380 ... _780


def test_csv_headers_are_exactly_r_nm_per_wavelength_and_give_back_the_spectra(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["runs", "export", "1", "--store", str(store), "--format", "csv"]) == 0
    text = capsys.readouterr().out
    header = next(csv.reader(io.StringIO(text)))
    assert header == [*SCAN_COLUMNS, *SPECTRUM_COLUMNS, *R_NAMES, *P_NAMES]
    assert R_NAMES[0] == "R_400" and R_NAMES[-1] == "R_700" and len(R_NAMES) == 31
    rows = list(csv.DictReader(io.StringIO(text)))
    assert len(rows) == 6 * 2
    for row in rows:
        tr, r = float(row["theta_r_deg"]), int(row["repeat"])
        np.testing.assert_allclose(_cells(row, R_NAMES), _measured_truth(tr, r), rtol=RTOL)
        np.testing.assert_allclose(_cells(row, P_NAMES), _predicted_truth(tr), rtol=RTOL)
        assert row["spectrum_relative_to"] == "perfect diffuser"
        assert "no certified standard" in row["spectrum_referenced_to"]
        assert "," not in row["spectrum_referenced_to"]  # one cell for a naive awk -F,


def test_the_csv_export_reads_back_as_a_compare_file(store: Path) -> None:
    # the same file a lab would give `predict colour --compare`: the reader takes its
    # R_<nm> columns and geometry, and leaves the predicted_R_<nm> columns alone
    with RunStore(store, readonly=True) as s:
        text = export_run(s, 1, "csv")
    table = read_spectra_csv(text)
    np.testing.assert_array_equal(table.wavelengths_nm, WL)
    for k in range(table.factors.shape[0]):
        truth = _measured_truth(float(table.theta_r_deg[k]), table.repeat[k])
        np.testing.assert_allclose(table.factors[k], truth, rtol=RTOL)


def test_json_carries_the_spectra_and_what_they_are_relative_to(store: Path) -> None:
    with RunStore(store, readonly=True) as s:
        doc = json.loads(export_run(s, 1, "json"))
    sp = doc["spectra"]
    assert sp["quantity"] == "spectral reflectance factor" and sp["units"] == "1"
    assert sp["relative_to"].startswith("perfect reflecting diffuser")
    assert sp["colour_scale"] == "diffuser" and sp["detector_cone_deg"] == CONE_DEG
    assert sp["columns"] == R_NAMES and sp["predicted_columns"] == P_NAMES
    assert sp["wavelengths_nm"] == list(WL)
    for row in doc["readings"]:
        tr, r = row["theta_r_deg"], row["repeat"]
        np.testing.assert_allclose(_cells(row, R_NAMES), _measured_truth(tr, r), rtol=RTOL)
        np.testing.assert_allclose(_cells(row, P_NAMES), _predicted_truth(tr), rtol=RTOL)


def test_parquet_columns_carry_the_spectra_with_units_and_labels(
    store: Path, tmp_path: Path
) -> None:
    import pyarrow.parquet as pq

    out = tmp_path / "run.parquet"
    assert main(["runs", "export", "1", "--store", str(store), "-o", str(out)]) == 0
    table = pq.read_table(out)
    assert table.column_names == [*SCAN_COLUMNS, *SPECTRUM_COLUMNS, *R_NAMES, *P_NAMES]
    field = table.schema.field("R_550")
    assert field.type == "double"
    meta = field.metadata
    assert meta[b"units"] == b"1" and meta[b"wavelength_nm"] == b"550"
    assert b"measured spectral reflectance factor" in meta[b"long_name"]
    assert b"perfect reflecting diffuser" in meta[b"long_name"]
    assert b"predicted" in table.schema.field("predicted_R_780").metadata[b"long_name"]
    prov = json.loads(table.schema.metadata[PARQUET_SPECTRA_KEY])
    assert prov["columns"] == R_NAMES
    rows = table.to_pylist()
    for row in rows:
        tr, r = row["theta_r_deg"], row["repeat"]
        np.testing.assert_allclose(_cells(row, R_NAMES), _measured_truth(tr, r), rtol=RTOL)
        np.testing.assert_allclose(_cells(row, P_NAMES), _predicted_truth(tr), rtol=RTOL)


def test_netcdf_carries_the_spectra_with_their_reference(store: Path, tmp_path: Path) -> None:
    from goniolab.datasets import open_dataset

    out = tmp_path / "run.nc"
    assert main(["runs", "export", "1", "--store", str(store), "-o", str(out)]) == 0
    ds = open_dataset(out)
    rf = ds["reflectance_factor"]
    assert rf.dims == ("theta_r_deg", "repeat", "wavelength_nm")
    assert rf.attrs["units"] == "1" and rf.attrs["scale"] == "diffuser"
    assert rf.attrs["relative_to"].startswith("perfect reflecting diffuser")
    assert "no certified standard" in rf.attrs["referenced_to"]
    assert rf.attrs["detector_cone_deg"] == CONE_DEG
    np.testing.assert_array_equal(ds["wavelength_nm"].values, WL)
    np.testing.assert_array_equal(ds["predicted_wavelength_nm"].values, PRED_WL)
    for k, tr in enumerate(ds["theta_r_deg"].values):
        for r in range(2):
            np.testing.assert_allclose(rf.values[k, r], _measured_truth(float(tr), r), rtol=RTOL)
        np.testing.assert_allclose(
            ds["predicted_reflectance_factor"].values[k], _predicted_truth(float(tr)), rtol=RTOL
        )


def test_a_mirror_scale_run_is_labelled_a_fraction_of_the_mirror(tmp_path: Path) -> None:
    path = make_spectral_store(tmp_path / "m.sqlite", scale="mirror")
    pc = PointColour(detector_cone_deg=CONE_DEG)
    with RunStore(path, readonly=True) as s:
        rows = list(csv.DictReader(io.StringIO(export_run(s, 1, "csv"))))
        doc = json.loads(export_run(s, 1, "json"))
    assert {r["spectrum_relative_to"] for r in rows} == {"perfect mirror"}
    assert doc["spectra"]["quantity"].endswith("fraction of the perfect mirror")
    assert "not a reflectance factor" in doc["spectra"]["relative_to"]
    row = rows[0]
    tr = float(row["theta_r_deg"])
    cone_scale = float(pc.factors([100.0], tr)[0])  # the diffuser scale the fixture divided by
    np.testing.assert_allclose(
        _cells(row, R_NAMES), _measured_truth(tr, int(row["repeat"])) / cone_scale, rtol=RTOL
    )


def _referenced_store(path: Path) -> tuple[Path, np.ndarray]:
    """A mirror-referenced run (plan.mirror_reference): one reading whose instrument
    spectrum is flat 50 % and whose referenced spectrum (``absolute_values``) is known, and
    one the reference could not be applied to (no ``absolute_values``: as the runner,
    the export takes the reading as reported, the mirror level not divided out)."""
    plan = BrdfPlan(45.0, (30.0, 20.0), repeats=1, sample="sample:x", mirror_reference=True)
    absolute_pct = 40.0 + 0.05 * (WL - 400.0)  # % of a perfect mirror
    ref = {"standard": "mirror", "certificate": "CERT-42", "certified_on": "2026-01-01",
           "model": "table", "file": "standards.toml", "method": "spectral"}  # fmt: skip
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), sample="sample:x", version="t",
                           config={"colour": {"scale": "diffuser"},
                                   "spectro": {"detector_cone_deg": CONE_DEG}},
                           model={"calibration": {"run": 7, "check_ok": True}})  # fmt: skip
        s.add_point(rid, index=MIRROR_INDEX, repeat=0, theta_i_deg=45.0, theta_r_deg=45.0,
                    measured_theta_i_deg=45.0, measured_theta_r_deg=45.0, luminance_pct=90.0,
                    raw={"wavelengths_nm": list(WL), "values": [90.0] * WL.size},
                    timestamp=1.0)  # fmt: skip
        s.add_point(rid, index=0, repeat=0, theta_i_deg=45.0, theta_r_deg=30.0,
                    measured_theta_i_deg=45.0, measured_theta_r_deg=30.0, luminance_pct=45.0,
                    raw={"wavelengths_nm": list(WL), "values": [50.0] * WL.size,
                         "mirror_pct": 90.0, "reference": ref,
                         "absolute_values": list(absolute_pct)},
                    timestamp=2.0)  # fmt: skip
        s.add_point(rid, index=1, repeat=0, theta_i_deg=45.0, theta_r_deg=20.0,
                    measured_theta_i_deg=45.0, measured_theta_r_deg=20.0, luminance_pct=45.0,
                    raw={"wavelengths_nm": list(WL), "values": [50.0] * WL.size,
                         "mirror_pct": 90.0}, timestamp=3.0)  # fmt: skip
    return path, absolute_pct


def test_a_referenced_run_exports_the_referenced_spectrum_and_cites_the_certificate(
    tmp_path: Path,
) -> None:
    path, absolute_pct = _referenced_store(tmp_path / "r.sqlite")
    cone_scale = float(PointColour(detector_cone_deg=CONE_DEG).factors([100.0], 30.0)[0])
    with RunStore(path, readonly=True) as s:
        rows = list(csv.DictReader(io.StringIO(export_run(s, 1, "csv"))))
        doc = json.loads(export_run(s, 1, "json"))
    mirror, sample = (next(r for r in rows if int(r["index"]) == i) for i in (MIRROR_INDEX, 0))
    assert all(mirror[n] == "" for n in R_NAMES)  # the reference itself carries no factor
    assert mirror["spectrum_referenced_to"] == ""
    np.testing.assert_allclose(_cells(sample, R_NAMES), absolute_pct / 100.0 * cone_scale,
                               rtol=RTOL)  # fmt: skip
    assert sample["spectrum_referenced_to"] == "certified mirror (certificate CERT-42; spectral)"
    unreferenced = next(r for r in rows if int(r["index"]) == 1)
    scale_20 = float(PointColour(detector_cone_deg=CONE_DEG).factors([100.0], 20.0)[0])
    np.testing.assert_allclose(_cells(unreferenced, R_NAMES), 0.5 * scale_20, rtol=RTOL)
    assert "no certified standard" in unreferenced["spectrum_referenced_to"]
    sp = doc["spectra"]
    assert sp["standards"] == [{"standard": "mirror", "certificate": "CERT-42",
                                "certified_on": "2026-01-01", "model": "table",
                                "file": "standards.toml"}]  # fmt: skip
    assert sp["calibration"] == {"run": 7, "check_ok": True}


def test_export_columns_of_a_run_without_spectra_are_the_scan_columns(tmp_path: Path) -> None:
    plan = BrdfPlan(45.0, (30.0,), repeats=1, sample="sample:x")
    with RunStore(tmp_path / "n.sqlite") as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample="sample:x",
                           model={}, version="t")  # fmt: skip
        s.add_point(rid, index=0, repeat=0, theta_i_deg=45.0, theta_r_deg=30.0,
                    measured_theta_i_deg=45.0, measured_theta_r_deg=30.0, luminance_pct=4.0,
                    raw={}, timestamp=1.0)  # fmt: skip
        assert export_columns(s, rid) == SCAN_COLUMNS
        assert "spectra" not in json.loads(export_run(s, rid, "json"))


@pytest.mark.slow
def test_a_twin_scans_exported_spectra_give_back_its_stored_colours(tmp_path: Path) -> None:
    # the runner turned each reading into L*a*b* itself (with --mirror-reference: from the
    # spectrum referenced to the certified mirror); the exported R_<nm> must give it back
    from goniolab.config import configs_dir

    store = tmp_path / "t.sqlite"
    args = ["scan", "--config", str(configs_dir() / "lab-sim.toml"), "--theta-r", "15,35",
            "--repeats", "1", "--time-scale", "0", "--json", "--store", str(store),
            "--mirror-reference"]  # fmt: skip
    assert main(args) == 0
    with RunStore(store, readonly=True) as s:
        rec = s.list_runs()[0]
        colours = {p.index: p.colour for p in s.points(rec.id) if p.index >= 0}
        rows = list(csv.DictReader(io.StringIO(export_run(s, rec.id, "csv"))))
    cfg = rec.config["colour"]
    settings = ColourSettings(cfg["illuminant"], cfg["observer"], cfg.get("method", "ASTM E308"))
    names = [h for h in rows[0] if h.startswith("R_")]
    wl = np.array([float(h[2:]) for h in names])
    checked = 0
    for row in rows:
        k = int(row["index"])
        if k < 0 or colours.get(k) is None:
            continue
        assert row["spectrum_referenced_to"].startswith("certified mirror")
        c = spectrum_to_colour(wl, _cells(row, names), settings)
        stored = colours[k]
        assert c.lab == pytest.approx((stored["L"], stored["a"], stored["b"]), abs=1e-6)
        checked += 1
    assert checked == 2
