"""Run identity (issue 22.4) and migration by UUID (23.10): a UUID per run that travels with
it, operator/notes/tags/physical sample id set and searched, old stores upgraded, migrate
matching by UUID, updating partial copies, refusing self-migration; damaged rows (23.11)
reported one line per run."""

from __future__ import annotations

import json
import sqlite3
import uuid
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.store import RunMeta, RunStore, StoreDamaged, legacy_uuid
from tests._runs import make_store

#: The first schema (before run identity and colour), as goniolab 0.1 wrote it.
OLD_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE runs (id INTEGER PRIMARY KEY AUTOINCREMENT, kind TEXT NOT NULL,
  plan_json TEXT NOT NULL, config_json TEXT NOT NULL, sample TEXT NOT NULL,
  model_json TEXT NOT NULL, version TEXT NOT NULL, status TEXT NOT NULL,
  reason TEXT NOT NULL DEFAULT '', created_at REAL NOT NULL, updated_at REAL NOT NULL,
  finished_at REAL);
CREATE TABLE points (id INTEGER PRIMARY KEY AUTOINCREMENT, run_id INTEGER NOT NULL,
  idx INTEGER NOT NULL, repeat INTEGER NOT NULL, theta_i_deg REAL NOT NULL,
  theta_r_deg REAL NOT NULL, measured_theta_i_deg REAL NOT NULL,
  measured_theta_r_deg REAL NOT NULL, luminance_pct REAL NOT NULL, raw_json TEXT NOT NULL,
  timestamp REAL NOT NULL, UNIQUE (run_id, idx, repeat));
CREATE TABLE predictions (run_id INTEGER NOT NULL, idx INTEGER NOT NULL,
  theta_i_deg REAL NOT NULL, theta_r_deg REAL NOT NULL, predicted_pct REAL NOT NULL,
  PRIMARY KEY (run_id, idx));
CREATE TABLE gloss_readings (id INTEGER PRIMARY KEY AUTOINCREMENT, run_id INTEGER NOT NULL,
  seq INTEGER NOT NULL, g20_gu REAL, g60_gu REAL, g85_gu REAL, temperature_c REAL,
  predicted_json TEXT, raw TEXT NOT NULL, timestamp REAL NOT NULL, UNIQUE (run_id, seq));
INSERT INTO meta VALUES ('schema_version', '1');
"""


def _old_store(path: Path, created: tuple[float, ...] = (1000.5, 2000.25)) -> Path:
    db = sqlite3.connect(path)
    db.executescript(OLD_SCHEMA)
    for t in created:
        db.execute(
            "INSERT INTO runs(kind, plan_json, config_json, sample, model_json, version, status,"
            " created_at, updated_at) VALUES ('brdf', '{}', '{}', 'sample:x', '{}', '0.1',"
            " 'done', ?, ?)",
            (t, t),
        )
    db.commit()
    db.close()
    return path


def _run(s: RunStore, **meta: object) -> int:
    return s.create_run(
        kind="brdf", plan={}, config={}, sample="sample:x", model={}, version="t",
        meta=RunMeta(**meta),  # type: ignore[arg-type]
    )  # fmt: skip


def test_each_run_has_a_uuid_and_metadata(tmp_path: Path) -> None:
    with RunStore(tmp_path / "s.sqlite") as s:
        a = _run(s, operator="ada", sample_id="LIMS-7", notes="first coat", tags=("q1", "wet"))
        b = _run(s)
        ra, rb = s.get_run(a), s.get_run(b)
    assert uuid.UUID(ra.uuid).version == 4 and ra.uuid != rb.uuid
    assert (ra.operator, ra.sample_id, ra.notes, ra.tags) == (
        "ada",
        "LIMS-7",
        "first coat",
        ("q1", "wet"),
    )
    assert ra.as_dict()["uuid"] == ra.uuid and ra.as_dict()["tags"] == ["q1", "wet"]  # fmt: skip


def test_an_old_store_is_upgraded_with_stable_uuids(tmp_path: Path) -> None:
    path = _old_store(tmp_path / "old.sqlite")
    with RunStore(path, readonly=True) as ro:  # read as it is: nothing written
        seen = [r.uuid for r in sorted(ro.list_runs(), key=lambda r: r.id)]
    assert seen == [legacy_uuid(str(path), 1, 1000.5), legacy_uuid(str(path), 2, 2000.25)]
    with RunStore(path) as s:  # upgraded: the same UUIDs, now stored
        assert [r.uuid for r in sorted(s.list_runs(), key=lambda r: r.id)] == seen
        assert s.store_uuid is not None
    db = sqlite3.connect(path)
    assert db.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone() == ("2",)
    assert db.execute("SELECT COUNT(*) FROM runs WHERE uuid IS NULL").fetchone() == (0,)


def test_cli_sets_and_searches_metadata(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    store = str(make_store(tmp_path / "s.sqlite"))
    assert main(["runs", "annotate", "1", "--store", store, "--operator", "ada",
                 "--sample-id", "P-12", "--tag", "gloss", "--tag", "lot4", "--note", "n1"]) == 0  # fmt: skip
    assert (
        main(["runs", "annotate", "2", "--store", store, "--operator", "bob", "--tag", "lot4"]) == 0
    )
    capsys.readouterr()

    def ids(*flags: str) -> list[int]:
        assert main(["runs", "list", "--store", store, "--json", *flags]) == 0
        return [r["id"] for r in json.loads(capsys.readouterr().out)]

    assert ids() == [2, 1]
    assert ids("--operator", "ada") == [1]
    assert ids("--tag", "lot4") == [2, 1]
    assert ids("--tag", "lot") == []  # a tag matches whole, not as a substring
    assert ids("--sample-id", "P-12") == [1]
    assert ids("--search", "N1") == [1]  # notes, case-insensitive
    assert ids("--search", "sample:g") == [2]
    assert main(["runs", "annotate", "1", "--store", store, "--untag", "gloss", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["tags"] == ["lot4"]
    assert main(["runs", "show", "1", "--store", store]) == 0
    out = capsys.readouterr().out
    assert "physical sample id: P-12" in out and "operator: ada" in out and "uuid " in out


def test_exports_carry_the_uuid(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    store = make_store(tmp_path / "s.sqlite")
    with RunStore(store) as s:
        want = s.get_run(1).uuid
    assert main(["runs", "export", "1", "--store", str(store), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["run"]["uuid"] == want
    assert main(["runs", "export", "1", "--store", str(store), "--format", "csv"]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[0].split(",")[:2] == ["run_id", "run_uuid"] and rows[1].startswith(f"1,{want},")
    import pyarrow.parquet as pq

    out = tmp_path / "r.parquet"
    assert main(["runs", "export", "1", "--store", str(store), "-o", str(out)]) == 0
    meta = pq.read_schema(out).metadata
    assert json.loads(meta[b"goniolab.run"])["uuid"] == want


def _migrate(src: Path | str, dst: Path, capsys: pytest.CaptureFixture[str]) -> dict:
    code = main(["runs", "migrate", "--from", str(src), "--store", str(dst), "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    return json.loads(out)


def test_two_pcs_stores_at_the_same_path_both_migrate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # issue 22.4: the second PC's run 1 was "already there as run 1" (deduped on path:id)
    target = tmp_path / "lab.sqlite"
    pc = tmp_path / "goniolab.sqlite"
    _old_store(pc, created=(1000.5,))
    first = _migrate(pc, target, capsys)
    pc.unlink()
    _old_store(pc, created=(5000.75,))  # the other PC: same path, same run id, another run
    second = _migrate(pc, target, capsys)
    assert [m["action"] for m in first["runs"]] == ["copied"]
    assert [(m["action"], m["to"]) for m in second["runs"]] == [("copied", 2)]
    again = _migrate(pc, target, capsys)
    assert [(m["action"], m["to"]) for m in again["runs"]] == [("unchanged", 2)]


def test_relative_and_absolute_source_do_not_duplicate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    src = make_store(tmp_path / "src.sqlite")
    target = tmp_path / "dst.sqlite"
    _migrate(src, target, capsys)
    monkeypatch.chdir(tmp_path)
    doc = _migrate("src.sqlite", target, capsys)
    assert [m["action"] for m in doc["runs"]] == ["unchanged", "unchanged"]
    with RunStore(target) as t:
        assert len(t.list_runs()) == 2


def test_a_partial_copy_is_brought_up_to_date(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = make_store(tmp_path / "src.sqlite")  # run 1 aborted with 5 of 6 readings
    target = tmp_path / "dst.sqlite"
    _migrate(src, target, capsys)
    with RunStore(src) as s:  # resumed and finished later
        s.add_point(1, index=2, repeat=1, theta_i_deg=45.0, theta_r_deg=50.0,
                    measured_theta_i_deg=45.0, measured_theta_r_deg=50.0, luminance_pct=7.0,
                    raw={}, timestamp=9.0)  # fmt: skip
        s.set_status(1, "done")
    doc = _migrate(src, target, capsys)
    assert [m["action"] for m in doc["runs"]] == ["updated", "unchanged"]
    with RunStore(src) as a, RunStore(target) as b:
        assert (
            b.get_run(1).status == "done" and b.get_run(1).finished_at == a.get_run(1).finished_at
        )
        assert a.points(1) == b.points(1)


def test_a_store_never_migrates_into_itself(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = make_store(tmp_path / "s.sqlite")
    link = tmp_path / "link.sqlite"
    link.symlink_to(src)
    for source in (src, link):
        assert main(["runs", "migrate", "--from", str(source), "--store", str(src)]) == 2
        assert "is the target store itself" in capsys.readouterr().err
    with RunStore(src) as s:
        assert len(s.list_runs()) == 2


def test_a_bad_plan_row_is_one_line_and_spares_the_others(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = make_store(tmp_path / "s.sqlite")
    db = sqlite3.connect(store)
    db.execute("UPDATE runs SET plan_json = '{not json' WHERE id = 1")
    db.commit()
    db.close()
    assert main(["runs", "list", "--store", str(store)]) == 0
    out = capsys.readouterr().out
    assert "damaged" in out and "plan_json is not valid JSON" in out and "sample:g" in out
    for cmd in (["runs", "show", "1"], ["runs", "export", "1"], ["scan", "resume", "1"]):
        assert main([*cmd, "--store", str(store)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "run 1 is damaged: plan_json" in err
    assert main(["runs", "show", "2", "--store", str(store)]) == 0  # the other run still reads
    assert "sample:g" in capsys.readouterr().out
    with RunStore(store) as s, pytest.raises(StoreDamaged):
        s.get_run(1)
    argv = ["runs", "migrate", "--from", str(store), "--store", str(tmp_path / "t.sqlite")]
    doc = json.loads(_cli_out([*argv, "--json"], capsys, code=1))
    assert [m["action"] for m in doc["runs"]] == ["error", "copied"]


def _cli_out(argv: list[str], capsys: pytest.CaptureFixture[str], code: int) -> str:
    assert main(argv) == code
    return capsys.readouterr().out


def test_a_damaged_page_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    store = tmp_path / "s.sqlite"
    with RunStore(store) as s:
        rid = _run(s)
        for i in range(400):  # enough readings to fill pages of their own
            s.add_point(rid, index=i, repeat=0, theta_i_deg=45.0, theta_r_deg=1.0,
                        measured_theta_i_deg=45.0, measured_theta_r_deg=1.0, luminance_pct=1.0,
                        raw={"values": list(range(50))}, timestamp=1.0)  # fmt: skip
        s.set_status(rid, "done")
    db = sqlite3.connect(store)
    db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    roots = [
        r for (r,) in db.execute("SELECT rootpage FROM sqlite_master WHERE tbl_name = 'points'")
    ]
    page = db.execute("PRAGMA page_size").fetchone()[0]
    db.close()
    data = bytearray(store.read_bytes())
    for root in roots:  # the points table's and its indexes' root pages: garbage
        off = (root - 1) * page
        data[off : off + page] = b"\xa5" * page
    store.write_bytes(bytes(data))
    assert main(["runs", "export", str(rid), "--store", str(store)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and "Traceback" not in err
    assert main(["runs", "list", "--store", str(store)]) == 0  # the run is listed
    out = capsys.readouterr().out
    assert f"{rid:>5}  brdf" in out and "cannot be counted" in out


def test_api_annotates_a_run(tmp_path: Path) -> None:
    from goniolab.api import open_run

    store = make_store(tmp_path / "s.sqlite")
    run = open_run(1, store)
    rec = run.annotate(operator="cy", tags=["api"], notes="from a notebook")
    assert (rec.operator, rec.tags, rec.notes) == ("cy", ("api",), "from a notebook")
    assert run.record.operator == "cy"


def test_config_run_table_sets_a_new_runs_metadata() -> None:
    from goniolab.config import LabConfig
    from goniolab.session import config_meta

    cfg = LabConfig.model_validate({"run": {"operator": "dee", "tags": ["night"]}})
    meta = config_meta(cfg, RunMeta(sample_id="S-1", tags=("cli",)))
    assert meta == RunMeta(operator="dee", sample_id="S-1", notes="", tags=("night", "cli"))
    assert config_meta(cfg, RunMeta(operator="eve")).operator == "eve"  # the CLI wins


@pytest.mark.timeout(60)
def test_a_fifo_as_the_store_is_refused_not_waited_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import os

    fifo = tmp_path / "s.sqlite"
    os.mkfifo(fifo)
    for argv in (["runs", "list"], ["runs", "show", "1"], ["scan", "resume", "1"]):
        assert main([*argv, "--store", str(fifo)]) == 2
        assert "not a regular file" in capsys.readouterr().err
