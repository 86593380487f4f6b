"""``runs show`` and ``runs colour`` say which calibration a BRDF run's readings rest on.

A scan stores in its record the calibration it started under (``calibration``: the latest
``goniolab calibrate`` run, its age then and its check standard's verdict:
:func:`goniolab.scan.calibration.calibration_notices`). It was in the one-line JSON dump of
the model only; the faces now say it, from what the stored run holds.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.cli import main
from tests.colour._spectral_runs import make_spectral_store

CITE = {"run": 3, "time_iso": "2026-11-26T09:00:00+00:00", "age_h": 2.5, "check_ok": False,
        "check_residual_pct": 0.42}  # fmt: skip


@pytest.mark.parametrize(
    ("model", "said"),
    [
        ({"calibration": CITE},
         "calibration: run 3 of 2026-11-26T09:00:00+00:00, 2.5 h old when the run started; "
         "check standard MISSED its certificate (+0.420 %)"),
        ({"calibration": {**CITE, "check_ok": True, "check_residual_pct": -0.05}},
         "calibration: run 3 of 2026-11-26T09:00:00+00:00, 2.5 h old when the run started; "
         "check standard within its certificate (-0.050 %)"),
        ({"calibration": {"run": None}},
         "calibration: none (no goniolab calibrate record when the run started)"),
        ({"computed_by": {}}, "calibration: not recorded with the run"),
    ],
)  # fmt: skip
def test_runs_show_and_colour_say_the_cited_calibration(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], model: dict, said: str
) -> None:
    store = str(make_spectral_store(tmp_path / "s.sqlite", model=model))
    assert main(["runs", "colour", "1", "--store", store, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["calibration"] == model.get("calibration")
    assert doc["calibration_note"] == said
    assert main(["runs", "colour", "1", "--store", store]) == 0
    assert f"\n{said}\n" in capsys.readouterr().out
    assert main(["runs", "show", "1", "--store", store]) == 0
    assert f"\n  {said}\n" in capsys.readouterr().out
