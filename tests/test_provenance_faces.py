"""Every stored or shown prediction names the model that computed it (issue 20: "each
number carries the model that computed it and why ... the TUI's metrics and gloss log,
stored runs").

The reference is ``goniolab predict gloss --json``, whose ``models`` name the model of each
ISO 2813 reading: a gloss log of the same sample stores and shows the same names, and a
scan's stored run says which model computed the curve at each angle."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.model_registry import model_names
from goniolab.store import RunStore
from tests.scan.test_integration import NOISELESS, lab_config


def test_gloss_and_scan_runs_name_their_models(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["predict", "gloss", "sample:wittmann-3", "--json"]) == 0
    expected = json.loads(capsys.readouterr().out)["model"]  # {"G20": "facet", ...}
    cfg = lab_config(tmp_path, sim=NOISELESS)
    store = str(tmp_path / "s.sqlite")
    assert main(["gloss", "log", "--config", str(cfg), "--count", "1", "--time-scale", "0",
                 "--store", store, "--json"]) == 0  # fmt: skip
    line = json.loads(capsys.readouterr().out.splitlines()[0])
    shown = {f"G{a}": m for a, m in line["predicted_models"].items()}
    assert shown == {k: expected[k] for k in ("G20", "G60", "G85")}
    assert main(["scan", "--config", str(cfg), "--theta-r", "40:50:5", "--time-scale", "0",
                 "--store", store, "--json"]) == 0  # fmt: skip
    capsys.readouterr()
    with RunStore(store, readonly=True) as s:
        gloss_run, scan_run = s.get_run(1), s.get_run(2)
    assert {f"G{a}": m for a, m in gloss_run.model["computed_by"].items()} == shown
    computed_by = scan_run.model["computed_by"]
    assert set(computed_by) <= set(model_names()) - {"auto"}
    assert sorted(a for angles in computed_by.values() for a in angles) == [40.0, 45.0, 50.0]
    assert isinstance(scan_run.model["warnings"], list)
