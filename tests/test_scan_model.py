"""``[sample] model`` / ``goniolab scan --model``: the run is predicted with the named model
and records its name (issue 15: the scan comparison uses the model the config names)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.config import configs_dir, load_lab_config
from goniolab.model_cache import model_for
from goniolab.optics.apertures import Cone
from goniolab.store import RunStore

SAMPLE = "sample:gloss-sq50-l2"  # a smooth sample: the wave and facet models differ
THETA_R = (40.0, 45.0, 50.0)


def _config(tmp_path: Path, model: str) -> Path:
    text = (configs_dir() / "lab-sim.toml").read_text()
    text = text.replace('model = "auto"', f'model = "{model}"', 1)
    assert f'model = "{model}"' in text
    path = tmp_path / f"lab-{model}.toml"
    path.write_text(text)
    return path


def _scan(tmp_path: Path, config: Path, *extra: str) -> tuple[dict[str, object], list[float]]:
    store = tmp_path / "runs.sqlite"
    args = ["scan", "--config", str(config), "--store", str(store), "--time-scale", "0"]
    args += ["--sample", SAMPLE, "--theta-r", "40:50:5", "--json", *extra]
    assert main(args) == 0
    with RunStore(store) as s:
        rid = max(r.id for r in s.list_runs())
        rec = s.get_run(rid)
        preds = [v for _, v in sorted(s.predictions(rid).items())]
    return dict(rec.model), preds


def _expected(model: str) -> np.ndarray:
    """The named model's predicted luminance: Y of its predicted spectrum (issue 21: the
    luminance prediction comes from the spectral one; a wave model is evaluated over the
    wavelengths the instrument's Y weights, within 0.4 % of its 550 nm reading here)."""
    from goniolab.colour.spectra import xyz_weights
    from goniolab.model_cache import spectral_for
    from goniolab.scan.colour import PointColour

    cfg = load_lab_config(configs_dir() / "lab-sim.toml")
    m = model_for(SAMPLE, n=cfg.sample.n, model=model)
    src, det = Cone(cfg.goniometer.source_cone_deg), Cone(cfg.spectro.detector_cone_deg)
    at_550 = np.asarray(m.luminance_pct(45.0, np.asarray(THETA_R), source=src, detector=det))
    sp = spectral_for(
        m,
        source_cone_deg=cfg.goniometer.source_cone_deg,
        detector_cone_deg=cfg.spectro.detector_cone_deg,
    )
    w_y = xyz_weights(sp.wavelengths_nm, PointColour.from_config(cfg).settings)[1]
    y = np.asarray(sp.spectrum_pct(45.0, THETA_R) @ w_y / 100.0)
    np.testing.assert_allclose(y, at_550, rtol=0.01)  # the same model
    return y


@pytest.mark.slow  # ~20 s: the simulated lab measures (and gloss-reads) with the wave model
def test_config_model_predicts_and_is_recorded(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    facet_params, facet = _scan(tmp_path, _config(tmp_path, "facet"))
    # Rayleigh-Rice, not Kirchhoff: the sim measures with the configured model too, and a
    # Kirchhoff scan costs ~40 s on the shared machine; both are wave models of the same path
    kh_params, kh = _scan(tmp_path, _config(tmp_path, "rayleigh-rice"))
    capsys.readouterr()
    assert facet_params["model_name"] == "facet"
    assert kh_params["model_name"] == "rayleigh-rice"
    # each run's predictions are its model's, computed independently here
    np.testing.assert_allclose(facet, _expected("facet"), rtol=1e-9)
    np.testing.assert_allclose(kh, _expected("rayleigh-rice"), rtol=1e-9)
    assert not np.allclose(facet, kh, rtol=0.05)
    # runs show tells which model predicted
    with RunStore(tmp_path / "runs.sqlite") as s:
        rid = max(r.id for r in s.list_runs())
    assert main(["runs", "show", str(rid), "--store", str(tmp_path / "runs.sqlite"), "--json"]) == 0
    assert "rayleigh-rice" in json.dumps(json.loads(capsys.readouterr().out))


def test_scan_model_option_overrides_the_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    params, preds = _scan(tmp_path, _config(tmp_path, "kirchhoff"), "--model", "facet")
    assert params["model_name"] == "facet"
    np.testing.assert_allclose(preds, _expected("facet"), rtol=1e-9)


def test_resume_goes_on_with_the_model_the_run_started_with(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run started with ``--model facet`` on a Kirchhoff config, interrupted before its
    last geometries were predicted, is resumed with the facet model, not the config's."""
    import sqlite3

    config = _config(tmp_path, "kirchhoff")
    params, _ = _scan(tmp_path, config, "--model", "facet")
    assert params["model_name"] == "facet"
    store = tmp_path / "runs.sqlite"
    db = sqlite3.connect(store)  # as a crash after the first reading would leave it
    with db:
        db.execute("DELETE FROM points WHERE run_id = 1 AND idx >= 1")
        db.execute("DELETE FROM predictions WHERE run_id = 1 AND idx >= 1")
        db.execute("UPDATE runs SET status = 'aborted', finished_at = NULL WHERE id = 1")
    db.close()
    args = ["scan", "resume", "1", "--store", str(store), "--time-scale", "0", "--json"]
    assert main(args) == 0
    capsys.readouterr()
    with RunStore(store, readonly=True) as s:
        assert s.get_run(1).status == "done"
        preds = [v for _, v in sorted(s.predictions(1).items())]
    # (2 geometries are computed exactly, 3 on the model's grid: they agree to ~1e-5)
    np.testing.assert_allclose(preds, _expected("facet"), rtol=1e-4)
    assert not np.allclose(preds[1:], _expected("kirchhoff")[1:], rtol=0.05)


def test_bad_model_in_the_config_is_one_error_naming_file_and_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _config(tmp_path, "auto")
    path.write_text(path.read_text().replace('model = "auto"', 'model = "wave"', 1))
    assert main(["scan", "--config", str(path), "--store", str(tmp_path / "r.sqlite")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("goniolab: error: ") and f"{path}: sample.model: " in err[0]
