"""``goniolab runs import``: goniolab reads its own JSON exports back (issue 22 item 11).

The truth is the source store: a run exported and imported into another store has the
same UUID, identity, creation time, readings (luminance, geometry, colour) and predictions
as the run it came from; importing it again changes nothing; a gloss run comes back with
its readings; a file that is not an export is refused naming the file and the key."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.store import RunStore
from tests.scan.test_integration import NOISELESS, lab_config


@pytest.fixture
def source(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    cfg = lab_config(tmp_path, sim=NOISELESS)
    store = tmp_path / "lab-pc.sqlite"
    assert main(["scan", "--config", str(cfg), "--theta-r", "40:50:5", "--repeats", "2",
                 "--time-scale", "0", "--store", str(store), "--operator", "ada",
                 "--tag", "q3", "--json"]) == 0  # fmt: skip
    assert main(["gloss", "log", "--config", str(cfg), "--count", "2", "--time-scale", "0",
                 "--store", str(store)]) == 0  # fmt: skip
    capsys.readouterr()
    return store


def test_an_exported_run_comes_back_the_same(
    tmp_path: Path, source: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = []
    for run in (1, 2):
        out = tmp_path / f"run{run}.json"
        assert main(["runs", "export", str(run), "--format", "json", "-o", str(out),
                     "--store", str(source)]) == 0  # fmt: skip
        files.append(str(out))
    capsys.readouterr()
    target = tmp_path / "office.sqlite"
    assert main(["runs", "import", *files, "--store", str(target), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [r["action"] for r in report] == ["copied", "copied"]
    with RunStore(source, readonly=True) as a, RunStore(target, readonly=True) as b:
        for src_id, r in zip((1, 2), report, strict=True):
            ra, rb = a.get_run(src_id), b.get_run(r["run_id"])
            assert rb.uuid == ra.uuid == r["uuid"]
            assert (rb.kind, rb.sample, rb.status, rb.operator, rb.tags) == (
                ra.kind,
                ra.sample,
                ra.status,
                ra.operator,
                ra.tags,
            )
            assert rb.created_at == pytest.approx(ra.created_at, abs=1e-6)
            assert rb.plan == ra.plan
        pa, pb = a.points(1), b.points(report[0]["run_id"])
        assert len(pa) == len(pb) == 6
        for x, y in zip(pa, pb, strict=True):
            assert (x.index, x.repeat, x.theta_r_deg) == (y.index, y.repeat, y.theta_r_deg)
            assert y.luminance_pct == x.luminance_pct
            assert y.colour == pytest.approx(x.colour)
        assert b.predictions(report[0]["run_id"]) == pytest.approx(a.predictions(1))
        ga, gb = a.gloss_readings(2), b.gloss_readings(report[1]["run_id"])
        assert [g.values_gu for g in gb] == [g.values_gu for g in ga]
    # again: matched by UUID, nothing duplicated
    assert main(["runs", "import", *files, "--store", str(target), "--json"]) == 0
    assert [r["action"] for r in json.loads(capsys.readouterr().out)] == ["unchanged"] * 2
    with RunStore(target, readonly=True) as b:
        assert len(b.list_runs()) == 2


def test_a_file_that_is_not_an_export_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"run": {"kind": "brdf"}}))
    notjson = tmp_path / "notes.json"
    notjson.write_text("hello")
    assert main(["runs", "import", str(bad), str(notjson), "--store",
                 str(tmp_path / "s.sqlite")]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "bad.json: run.uuid: missing (not a goniolab run export)" in err
    assert "notes.json: not a JSON file" in err
