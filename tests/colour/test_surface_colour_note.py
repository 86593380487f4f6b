"""A predicted colour whose coat surface comes from a wavelength-free model says so.

The facet model (geometric optics) has no wavelength in its scattering: the near-specular
colour a surface's features make by diffraction (``bench/near_specular_colour.py``: the
scalar Kirchhoff model of ``sample:wittmann-3`` at 0.25 um steps swings a*, b* by C* up to ~20
within 25 deg of specular) is not in its prediction. ``goniolab runs colour`` (text and
JSON), the stored run's provenance (``Predictor.provenance``, shown at scan time) and each
row's ``predicted_model`` must say which model made the predicted colour and that it
cannot predict that colour.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.colour.multiangle import E2194_ASPECULAR_DEG, theta_r_for_aspecular
from goniolab.colour.spectral import surface_colour_note, wavelength_free
from tests.colour._spectral_runs import make_spectral_store

NOTE = (
    "model is wavelength-independent: near-specular colour from surface scattering is not predicted"
)
TR = sorted((theta_r_for_aspecular(a) for a in E2194_ASPECULAR_DEG), reverse=True)


def _doc(store: Path, capsys: pytest.CaptureFixture[str]) -> dict:
    assert main(["runs", "colour", "1", "--store", str(store), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_which_models_are_wavelength_free() -> None:
    assert wavelength_free("facet") and wavelength_free("analytic-ggx")
    for wave in ("kirchhoff", "rayleigh-rice"):
        assert not wavelength_free(wave)
    assert NOTE in surface_colour_note("facet", [30.0, 60.0])
    assert "theta_r 30..60 deg" in surface_colour_note("facet", [30.0, 60.0])


def test_runs_colour_names_the_facet_model_and_warns_per_row(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # the first three geometries predicted by Kirchhoff, the last three by the facet model
    facet_tr, wave_tr = TR[3:], TR[:3]
    store = make_spectral_store(
        tmp_path / "s.sqlite", model={"computed_by": {"kirchhoff": wave_tr, "facet": facet_tr}}
    )
    doc = _doc(store, capsys)
    rows = {r["theta_r_deg"]: r for r in doc["geometries"]}
    for t in facet_tr:
        assert rows[t]["predicted_model"] == "facet"
        assert NOTE in rows[t]["predicted_colour_note"]
    for t in wave_tr:
        assert rows[t]["predicted_model"] == "kirchhoff"
        assert "predicted_colour_note" not in rows[t]
    (note,) = doc["predicted_colour_notes"]
    assert f"the facet {NOTE}" in note
    assert f"theta_r {min(facet_tr):g}..{max(facet_tr):g} deg" in note
    assert main(["runs", "colour", "1", "--store", str(store)]) == 0
    assert f"note: {note}" in capsys.readouterr().out


def test_a_wave_model_run_carries_no_such_note(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = make_spectral_store(tmp_path / "s.sqlite", model={"computed_by": {"kirchhoff": TR}})
    doc = _doc(store, capsys)
    assert doc["predicted_colour_notes"] == []
    assert all(r["predicted_model"] == "kirchhoff" for r in doc["geometries"])


def test_a_run_without_computed_by_falls_back_to_its_model_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = make_spectral_store(tmp_path / "s.sqlite", model={"model_name": "facet"})
    doc = _doc(store, capsys)
    assert all(r["predicted_model"] == "facet" for r in doc["geometries"])
    assert len(doc["predicted_colour_notes"]) == 1


def test_the_scan_predictor_stores_the_warning_for_the_facet_model() -> None:
    from goniolab.config import load_lab_config
    from goniolab.model_cache import model_for
    from goniolab.scan.prediction import Predictor

    cfg = load_lab_config("configs/lab-sim.toml")
    # the lab's default: wittmann-3's 1 um map, where Kirchhoff hands over to the facet model
    # (cfg.sample.model = "auto")
    model = model_for(cfg.sample_map(), n=cfg.sample.n, model=cfg.sample.model)
    pred = Predictor.from_config(model, cfg)
    prov = pred.provenance(45.0, [55.0, 67.0])
    assert prov["computed_by"] == {"facet": [55.0, 67.0]}
    assert any(f"the facet {NOTE}" in w and "theta_r 55..67 deg" in w for w in prov["warnings"])
    # without a spectral prediction there is no predicted colour to warn about
    bare = Predictor(model, pred.source, pred.detector)
    assert not any(NOTE in w for w in bare.provenance(45.0, [55.0])["warnings"])


def test_predict_colour_names_the_surface_model_and_warns(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = ["predict", "colour", "sample:wittmann-3", "--theta-r", "55,67", "--json"]
    assert main(args) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert [g["surface_model"] for g in doc["geometries"]] == ["facet", "facet"]
    # the prediction is achromatic there: a constant-n coat over a black body
    assert all(abs(g["a"]) < 0.5 and abs(g["b"]) < 0.5 for g in doc["geometries"])
    (note,) = doc["predicted_colour_notes"]
    assert f"the facet {NOTE}" in note and "theta_r 55..67 deg" in note
    assert f"goniolab: note: {note}" in captured.err
