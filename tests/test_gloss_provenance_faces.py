"""A gloss log's predicted gloss carries its model and its warnings on every face.

The stored gloss run holds, per ISO 2813 geometry, the model that computed the predicted
gloss (``computed_by``) and the warnings of those numbers (``warnings``:
:func:`goniolab.optics.provenance.gloss_provenance_of`'s notes, e.g. the Kirchhoff model's
energy rescale at 85 deg). ``goniolab gloss log`` (stderr; the last ``--json`` line) and
``goniolab runs show`` must show what the stored run holds.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.store import RunStore
from tests.scan.test_integration import NOISELESS, lab_config


def test_gloss_log_and_runs_show_say_the_stored_models_and_warnings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = lab_config(tmp_path, sim=NOISELESS)
    store = str(tmp_path / "s.sqlite")
    assert main(["gloss", "log", "--config", str(cfg), "--count", "1", "--time-scale", "0",
                 "--store", store, "--json"]) == 0  # fmt: skip
    captured = capsys.readouterr()
    with RunStore(store, readonly=True) as s:
        model = s.get_run(1).model
    # wittmann-3 at 85 deg: the Kirchhoff model rescales its diffuse light (a warning)
    assert model["warnings"], model
    last = json.loads(captured.out.splitlines()[-1])
    assert last["prediction"] == {
        "computed_by": model["computed_by"],
        "warnings": model["warnings"],
    }
    for w in model["warnings"]:
        assert f"goniolab: warning: model: {w}\n" in captured.err
    assert main(["runs", "show", "1", "--store", store]) == 0
    out = capsys.readouterr().out
    for angle, name in model["computed_by"].items():
        pred = float(model["predicted_gu"][angle])
        assert f", predicted {pred:.1f} GU ({name})\n" in out
    for w in model["warnings"]:
        assert f"  prediction warning: {w}\n" in out
    # no gloss calibrate in this store: the run says so (tests/test_gloss_calibration.py
    # covers a calibrated meter)
    assert (
        "  glossmeter calibration: none recorded in this store (for SimGlossmeter glossmeter)\n"
        in out
    )


def test_a_gloss_run_without_a_prediction_shows_no_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "g.sqlite"
    with RunStore(path) as s:
        rid = s.create_run(kind="gloss", plan={"kind": "gloss", "count": 1, "angles_deg": [60]},
                           config={}, sample="", model={}, version="t")  # fmt: skip
        s.add_gloss_reading(rid, values_gu={60: 50.0}, temperature_c=None, predicted_gu=None,
                            raw="", timestamp=0.0)  # fmt: skip
    assert main(["runs", "show", str(rid), "--store", str(path)]) == 0
    out = capsys.readouterr().out
    assert "  G60: 50.0 +- " in out and "predicted" not in out.split("plan:")[1]
