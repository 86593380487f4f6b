"""``goniolab plot``: the files are real pictures and show the stored numbers."""

from __future__ import annotations

import json
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.store import RunStore
from tests._runs import lum, make_store


@pytest.fixture
def store_file(tmp_path: Path) -> Path:
    return make_store(tmp_path / "s.sqlite")


def _plot(store: Path, *args: str) -> int:
    return main(["plot", *args, "--store", str(store)])


def test_png_has_the_figure_size(store_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "r.png"
    assert _plot(store_file, "1", "--out", str(out)) == 0
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    assert (width, height) == (8 * 120, 6 * 120)  # 8 x 6 in at 120 dpi
    assert len(data) > 20_000  # drawn, not blank


def test_svg_parses_and_names_the_panels(store_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "r.svg"
    assert _plot(store_file, "1", "--out", str(out), "--log") == 0
    root = ET.parse(out).getroot()
    assert root.tag.endswith("svg")
    # matplotlib draws text as paths and keeps each string in a comment beside it
    text = out.read_text()
    assert "<!-- run 1 on sample:x: aborted (aborted by the operator) -->" in text
    assert "<!-- measured - -->" in text or "measured -" in text


def test_pdf_of_a_gloss_log(store_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "g.pdf"
    assert _plot(store_file, "2", "-o", str(out)) == 0
    assert out.read_bytes()[:5] == b"%PDF-" and out.stat().st_size > 5_000


def test_the_figure_shows_the_stored_values(store_file: Path) -> None:
    from goniolab.run_plots import plot_run

    with RunStore(store_file, readonly=True) as s:
        fig = plot_run(s, 1, log=True)
    main_ax, resid_ax = fig.axes[:2]
    assert main_ax.get_yscale() == "log"
    lines = {ln.get_label(): ln for ln in main_ax.get_lines()}
    pred = lines["predicted"]  # the run names no model: no name is made up
    np.testing.assert_array_equal(pred.get_xdata(), [40.0, 45.0, 50.0])
    np.testing.assert_array_equal(pred.get_ydata(), [1.0, 12.0, 3.0])
    # the error-bar markers sit at the repeat means (the last geometry has one reading)
    means = [np.mean([lum(0, 0), lum(0, 1)]), np.mean([lum(1, 0), lum(1, 1)]), lum(2, 0)]
    markers = [ln for ln in main_ax.get_lines() if ln.get_marker() == "o"]
    np.testing.assert_allclose(markers[0].get_ydata(), means)
    res = resid_ax.get_lines()[-1]
    np.testing.assert_allclose(res.get_ydata(), np.array(means) - [1.0, 12.0, 3.0])


@pytest.mark.parametrize("name", ["kirchhoff", "facet", "auto"])
def test_the_predicted_curve_names_the_runs_model(tmp_path: Path, name: str) -> None:
    """issue 27: the label said "facet model" for every run, whatever model predicted it."""
    from goniolab.datasets import run_dataset
    from goniolab.run_plots import plot_dataset

    with RunStore(make_store(tmp_path / "s.sqlite"), readonly=True) as s:
        ds = run_dataset(s, 1)
    ds.attrs["model_json"] = json.dumps({"model_name": name, "n": [1.55, 0.0]})
    labels = [ln.get_label() for ln in plot_dataset(ds).axes[0].get_lines()]
    assert f"predicted ({name} model)" in labels
    assert not [t for t in labels if "model" in t and name not in t]


def test_bad_suffix_is_one_line_error(
    store_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _plot(store_file, "1", "--out", str(tmp_path / "r.jpg")) == 2
    err = capsys.readouterr().err
    assert err.startswith("goniolab: error: --out") and err.count("\n") == 1


def test_json_names_the_file(
    store_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "x.png"
    assert _plot(store_file, "1", "--out", str(out), "--json") == 0
    assert json.loads(capsys.readouterr().out)["output"] == str(out.resolve())


def _colour_store(path: Path) -> Path:
    """A 3-angle x 2-repeat scan whose readings carry a measured colour and whose
    geometries carry a predicted L*a*b* (the store's colour columns), last reading missing."""
    from goniolab.scan.plans import BrdfPlan
    from goniolab.store import PredictedColour

    plan = BrdfPlan(45.0, (40.0, 45.0, 50.0), repeats=2, sample="sample:x")
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample="sample:x",
                           model={}, version="t")  # fmt: skip
        for k, tr in enumerate(plan.theta_r_deg):
            for r in range(2):
                if (k, r) == (2, 1):
                    continue
                c = {"X": 1.0, "Y": 2.0, "Z": 3.0, "L": 50.0 + k, "a": -1.0 * k,
                     "b": 2.0 * r, "C": 1.0, "h_deg": 90.0}  # fmt: skip
                s.add_point(rid, index=k, repeat=r, theta_i_deg=45.0, theta_r_deg=tr,
                            measured_theta_i_deg=45.0, measured_theta_r_deg=tr,
                            luminance_pct=lum(k, r), raw={}, timestamp=1.0, colour=c)  # fmt: skip
        s.add_predictions(rid, [(k, 45.0, tr, 1.0) for k, tr in enumerate(plan.theta_r_deg)])
        s.add_predicted_colours(rid, [(k, PredictedColour(60.0 + k, 0.5, -0.5)) for k in range(3)])
    return path


def test_colour_per_point_reaches_the_dataset_and_the_plot(tmp_path: Path) -> None:
    from goniolab.datasets import run_dataset
    from goniolab.run_plots import plot_dataset

    with RunStore(_colour_store(tmp_path / "c.sqlite"), readonly=True) as s:
        ds = run_dataset(s, 1)
    np.testing.assert_array_equal(ds["L_star"].values[:, 0], [50.0, 51.0, 52.0])
    np.testing.assert_array_equal(ds["b_star"].values[1], [0.0, 2.0])
    assert np.isnan(ds["L_star"].values[2, 1])  # the reading never taken
    np.testing.assert_array_equal(ds["predicted_L_star"].values, [60.0, 61.0, 62.0])
    assert ds["a_star"].dims == ("theta_r_deg", "repeat")
    # and the netCDF export carries it
    import xarray as xr

    from goniolab.datasets import write_netcdf

    write_netcdf(ds, tmp_path / "c.nc")
    with xr.open_dataset(tmp_path / "c.nc", engine="h5netcdf") as back:
        np.testing.assert_array_equal(back["L_star"].values, ds["L_star"].values)
        np.testing.assert_array_equal(back["predicted_b_star"].values, [-0.5, -0.5, -0.5])
    fig = plot_dataset(ds)
    assert len(fig.axes) == 4  # luminance, residuals, L*, a*/b*
    lab_ax = fig.axes[2]
    assert lab_ax.get_xlabel() == "" and fig.axes[3].get_xlabel() == "aspecular angle (deg)"
    measured = next(ln for ln in lab_ax.get_lines() if ln.get_label() == "L* measured")
    np.testing.assert_array_equal(measured.get_xdata(), [5.0, 0.0, -5.0])  # E2194 aspecular
    np.testing.assert_array_equal(measured.get_ydata(), [50.0, 51.0, 52.0])


def test_an_auto_run_names_the_models_auto_picked(tmp_path: Path) -> None:
    """issue 27: an auto run's legend said "predicted (auto model)"; it names the models the
    auto rule picked, as the run's stored ``computed_by`` records them."""
    from goniolab.datasets import run_dataset
    from goniolab.run_plots import plot_dataset

    with RunStore(make_store(tmp_path / "s.sqlite"), readonly=True) as s:
        ds = run_dataset(s, 1)
    computed_by = {"kirchhoff": [60.0, 70.0], "facet": [40.0, 45.0]}
    ds.attrs["model_json"] = json.dumps({"model_name": "auto", "computed_by": computed_by})
    labels = [ln.get_label() for ln in plot_dataset(ds).axes[0].get_lines()]
    assert "predicted (auto: facet, kirchhoff)" in labels


def test_python_dash_m_runs_the_same_command_line() -> None:
    """``python -m goniolab`` is the ``goniolab`` script (it failed: no __main__ module)."""
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", "goniolab", "--help"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0 and out.stdout.startswith("usage: goniolab")
