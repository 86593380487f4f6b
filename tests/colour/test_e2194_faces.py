"""One aspecular convention in every face (issue 25 item 1): ASTM E2194 / DIN 6175-2.

The core (:func:`goniolab.colour.multiangle.aspecular_deg`) defines the aspecular angle as
``theta_i - theta_r``: at 45 deg incidence, 15 deg aspecular is theta_r 30 (near specular),
45 is the normal, -15 lies beyond the specular direction (theta_r 60). E2194 fig. 1 is the
independent truth for the core; every face is held to the core here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.colour.multiangle import aspecular_deg, theta_r_for_aspecular
from goniolab.store import PredictedColour, RunStore


def test_the_core_is_e2194() -> None:
    # ASTM E2194-14 fig. 1: illumination 45 deg, "15 deg aspecular" is 15 deg from the
    # specular direction towards the lamp, i.e. 30 deg from the normal on the specular side
    assert theta_r_for_aspecular(15.0) == 30.0
    assert theta_r_for_aspecular(45.0) == 0.0
    assert theta_r_for_aspecular(110.0) == -65.0
    assert theta_r_for_aspecular(-15.0) == 60.0
    assert aspecular_deg(30.0, 45.0) == 15.0


def _store(path: Path) -> Path:
    from goniolab.scan.plans import BrdfPlan

    plan = BrdfPlan(45.0, (60.0, 30.0, 0.0, -65.0), repeats=1, sample="sample:x")
    with RunStore(path) as s:
        rid = s.create_run(
            kind="brdf", plan=plan.to_dict(), config={}, sample="sample:x", model={}, version="t"
        )
        for k, tr in enumerate(plan.theta_r_deg):
            c = {"X": 1.0, "Y": 2.0, "Z": 3.0, "L": 50.0 + k, "a": 1.0, "b": 2.0}
            c.update(C=float(np.hypot(1.0, 2.0)), h_deg=63.4)
            s.add_point(
                rid, index=k, repeat=0, theta_i_deg=45.0, theta_r_deg=tr,
                measured_theta_i_deg=45.0, measured_theta_r_deg=tr, luminance_pct=1.0,
                raw={}, timestamp=1.0, colour=c,
            )  # fmt: skip
        s.add_predictions(rid, [(k, 45.0, tr, 1.0) for k, tr in enumerate(plan.theta_r_deg)])
        s.add_predicted_colours(rid, [(k, PredictedColour(51.0 + k, 1.0, 2.0)) for k in range(4)])
    return path


def test_run_dataset_netcdf_and_plot_follow_the_core(tmp_path: Path) -> None:
    from goniolab.datasets import run_dataset
    from goniolab.run_plots import plot_dataset

    with RunStore(_store(tmp_path / "s.sqlite"), readonly=True) as s:
        ds = run_dataset(s, 1)
    tr = ds["theta_r_deg"].values
    core = [aspecular_deg(float(t), 45.0) for t in tr]
    np.testing.assert_array_equal(ds["aspecular_deg"].values, core)
    np.testing.assert_array_equal(ds["aspecular_deg"].values, [-15.0, 15.0, 45.0, 110.0])
    assert "theta_i - theta_r" in ds["aspecular_deg"].attrs["long_name"]
    fig = plot_dataset(ds)
    measured = next(ln for ln in fig.axes[2].get_lines() if ln.get_label() == "L* measured")
    np.testing.assert_array_equal(measured.get_xdata(), core)


def test_csv_json_and_parquet_exports_follow_the_core(tmp_path: Path) -> None:
    import csv
    import io

    import pyarrow.parquet as pq

    from goniolab.export import export_run

    with RunStore(_store(tmp_path / "s.sqlite"), readonly=True) as s:
        csv_rows = list(csv.DictReader(io.StringIO(export_run(s, 1, "csv"))))
        json_rows = json.loads(export_run(s, 1, "json"))["readings"]
        export_run(s, 1, "parquet", tmp_path / "r.parquet")
    pq_rows = pq.read_table(tmp_path / "r.parquet").to_pylist()
    for rows in (csv_rows, json_rows, pq_rows):
        got = [float(r["aspecular_deg"]) for r in rows]
        core = [aspecular_deg(float(r["theta_r_deg"]), float(r["theta_i_deg"])) for r in rows]
        assert got == core == [-15.0, 15.0, 45.0, 110.0]


def test_brdf_dataset_and_api_follow_the_core() -> None:
    import goniolab.api as gl
    from goniolab.datasets import brdf_dataset

    ds = brdf_dataset(30.0, [10.0, 30.0, 50.0], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(ds["aspecular_deg"].values, [20.0, 0.0, -20.0])
    ds = gl.predict_brdf("sample:flat", theta_i_deg=45, theta_r_deg=[30.0, 45.0, 60.0])
    np.testing.assert_array_equal(
        ds["aspecular_deg"].values, [aspecular_deg(t, 45.0) for t in (30.0, 45.0, 60.0)]
    )


def test_runs_colour_json_follows_the_core(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = _store(tmp_path / "s.sqlite")
    assert main(["runs", "colour", "1", "--store", str(store), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    for g in doc["geometries"]:
        assert g["aspecular_deg"] == aspecular_deg(g["theta_r_deg"], 45.0)


def test_predict_colour_json_follows_the_core(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["predict", "colour", "sample:flat", "--theta-i", "40", "--theta-r", "10,40", "--json"]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [g["aspecular_deg"] for g in doc["geometries"]] == [30.0, 0.0]
    # no flop index away from 45 deg incidence, and the JSON says why
    assert doc["flop_index"] is None and "45 deg incidence" in doc["flop_index_note"]


def test_predict_colour_help_does_not_crash(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["predict", "colour", "--help"])
    assert exc.value.code == 0
    assert "% of the mirror" in capsys.readouterr().out
