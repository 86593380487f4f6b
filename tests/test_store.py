"""The run store: WAL, one row per reading, exactly-once, durable across a reopen, export."""

from __future__ import annotations

import csv
import io
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from goniolab.export import export_run
from goniolab.store import (
    RunBusy,
    RunStore,
    StoreError,
    default_store_path,
    resolve_store_path,
)


def _run(store: RunStore) -> int:
    return store.create_run(
        kind="brdf",
        plan={"theta_i_deg": 45.0, "theta_r_deg": [0.0, 1.0]},
        config={"lab": {"name": "x"}},
        sample="sample:flat",
        model={"n": 1.55},
        version="0.1.0",
    )


def _point(store: RunStore, run_id: int, index: int, repeat: int, value: float) -> None:
    store.add_point(
        run_id, index=index, repeat=repeat, theta_i_deg=45.0, theta_r_deg=float(index),
        measured_theta_i_deg=45.001, measured_theta_r_deg=float(index) - 0.002,
        luminance_pct=value, raw={"luminance_pct": value}, timestamp=1700000000.0 + index,
    )  # fmt: skip


def test_store_is_wal_and_creates_its_directory(tmp_path: Path) -> None:
    path = tmp_path / "deep" / "dir" / "s.sqlite"
    with RunStore(path) as s:
        assert s.journal_mode == "wal"
    assert path.exists()


def test_points_survive_a_reopen_and_are_unique(tmp_path: Path) -> None:
    path = tmp_path / "s.sqlite"
    s = RunStore(path)
    rid = _run(s)
    _point(s, rid, 0, 0, 12.5)
    _point(s, rid, 0, 1, 12.7)
    with pytest.raises(sqlite3.IntegrityError):
        _point(s, rid, 0, 1, 99.0)
    s.close()
    # a second connection (as a resumed process would open) sees exactly the committed rows
    with RunStore(path) as s2:
        pts = s2.points(rid)
        assert [(p.index, p.repeat, p.luminance_pct) for p in pts] == [(0, 0, 12.5), (0, 1, 12.7)]
        assert s2.done_keys(rid) == {(0, 0), (0, 1)}
        assert pts[0].measured_theta_i_deg == 45.001
        rec = s2.get_run(rid)
        assert rec.plan["theta_r_deg"] == [0.0, 1.0] and rec.sample == "sample:flat"
        assert rec.status == "idle" and rec.finished_at is None


def test_committed_rows_are_visible_to_another_reader_before_close(tmp_path: Path) -> None:
    path = tmp_path / "s.sqlite"
    s = RunStore(path)
    rid = _run(s)
    _point(s, rid, 3, 0, 1.0)
    reader = sqlite3.connect(path)
    assert reader.execute("SELECT COUNT(*) FROM points").fetchone()[0] == 1
    reader.close()
    s.close()


def test_status_and_finish_time(store_path: Path) -> None:
    with RunStore(store_path) as s:
        rid = _run(s)
        s.set_status(rid, "running")
        assert s.get_run(rid).finished_at is None
        s.set_status(rid, "failed", "detector: stall")
        rec = s.get_run(rid)
        assert (rec.status, rec.reason) == ("failed", "detector: stall")
        assert rec.finished_at is not None
        with pytest.raises(StoreError, match="no run 999"):
            s.set_status(999, "done")
        with pytest.raises(StoreError, match=str(store_path)):
            s.get_run(999)


def test_export_csv_one_row_per_reading_with_prediction(store_path: Path) -> None:
    with RunStore(store_path) as s:
        rid = _run(s)
        for i in range(2):
            for r in range(3):
                _point(s, rid, i, r, 10.0 * i + r)
        s.add_predictions(rid, [(0, 45.0, 0.0, 1.5), (1, 45.0, 1.0, 11.5)])
        text = export_run(s, rid, "csv")
        rows = list(csv.DictReader(io.StringIO(text)))
        assert len(rows) == 6
        assert [(r["index"], r["repeat"]) for r in rows[:3]] == [("0", "0"), ("0", "1"), ("0", "2")]
        assert float(rows[4]["luminance_pct"]) == 11.0
        assert float(rows[4]["theta_r_deg"]) == 1.0
        assert float(rows[4]["predicted_pct"]) == 11.5
        doc = json.loads(export_run(s, rid, "json"))
        assert doc["run"]["id"] == rid and len(doc["readings"]) == 6
        with pytest.raises(ValueError, match="csv"):
            export_run(s, rid, "xlsx")


def test_gloss_readings_are_sequenced(store_path: Path) -> None:
    with RunStore(store_path) as s:
        rid = s.create_run(kind="gloss", plan={}, config={}, sample="", model={}, version="x")
        a = s.add_gloss_reading(rid, values_gu={20: 80.1, 60: 90.2, 85: None}, temperature_c=25.0,
                                predicted_gu={20: 81.0, 60: 91.0, 85: 97.0}, raw="1|...", timestamp=1.0)  # fmt: skip
        b = s.add_gloss_reading(rid, values_gu={60: 90.4}, temperature_c=None, predicted_gu=None,
                                raw="2|...", timestamp=2.0)  # fmt: skip
        assert (a, b) == (0, 1)
        rows = s.gloss_readings(rid)
        assert rows[0].values_gu == {20: 80.1, 60: 90.2, 85: None}
        assert rows[0].predicted_gu == {20: 81.0, 60: 91.0, 85: 97.0}
        assert rows[1].values_gu[20] is None and rows[1].predicted_gu is None
        exported = list(csv.DictReader(io.StringIO(export_run(s, rid, "csv"))))
        assert [e["g60_gu"] for e in exported] == ["90.2", "90.4"]


def test_store_path_resolution_order(tmp_path: Path) -> None:
    assert (
        resolve_store_path(str(tmp_path / "a.sqlite"), str(tmp_path / "b.sqlite"))
        == tmp_path / "a.sqlite"
    )
    assert resolve_store_path(None, str(tmp_path / "b.sqlite")) == tmp_path / "b.sqlite"
    assert resolve_store_path(None, "") == default_store_path()
    assert default_store_path().name == "goniolab.sqlite"


def test_store_below_a_file_names_the_blocking_file(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(StoreError, match=f"{blocker} is a file, not a directory"):
        RunStore(blocker / "sub" / "s.sqlite")


def test_directory_or_foreign_file_as_store_is_refused_by_name(tmp_path: Path) -> None:
    with pytest.raises(StoreError, match=f"store {tmp_path}: is a directory"):
        RunStore(tmp_path)
    toml = tmp_path / "lab.toml"
    toml.write_text("[lab]\n" * 200)
    for readonly in (False, True):
        with pytest.raises(StoreError, match=r"lab\.toml: cannot open: not a goniolab run store"):
            RunStore(toml, readonly=readonly)
    assert toml.read_text() == "[lab]\n" * 200


def test_missing_store_is_not_created_when_reading_or_resuming(tmp_path: Path) -> None:
    path = tmp_path / "typo" / "s.sqlite"
    for kwargs in ({"readonly": True}, {"create": False}):
        with pytest.raises(StoreError, match=f"store {path}: no such file"):
            RunStore(path, **kwargs)
    assert not (tmp_path / "typo").exists()


def test_readonly_store_reads_and_never_writes(tmp_path: Path) -> None:
    path = tmp_path / "s.sqlite"
    with RunStore(path) as s:
        rid = _run(s)
        _point(s, rid, 0, 0, 1.5)
    before = path.read_bytes()
    with RunStore(path, readonly=True) as ro:
        assert [r.id for r in ro.list_runs()] == [rid]
        assert [p.luminance_pct for p in ro.points(rid)] == [1.5]
        with pytest.raises(StoreError, match="readonly"):
            _point(ro, rid, 1, 0, 2.5)
    assert path.read_bytes() == before


def test_store_on_an_unwritable_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # a read-only mount: access(2) answers EROFS for W_OK (even for root), which a test
    # cannot mount; the store asks os.access, so deny writes to that directory there
    path = tmp_path / "ro" / "s.sqlite"
    with RunStore(path) as s:
        rid = _run(s)
        _point(s, rid, 0, 0, 1.5)
    real_access = os.access

    def access(p: str | os.PathLike[str], mode: int) -> bool:
        if mode & os.W_OK and Path(p).resolve().is_relative_to(tmp_path / "ro"):
            return False
        return real_access(p, mode)

    monkeypatch.setattr("goniolab.store.sqlite.os.access", access)
    for target in (path, tmp_path / "ro" / "new.sqlite"):
        with pytest.raises(StoreError, match=f"directory {tmp_path / 'ro'} is not writable"):
            RunStore(target)
    assert not (tmp_path / "ro" / "new.sqlite").exists()
    with RunStore(path, readonly=True) as ro:  # immutable read: still lists the run
        assert [p.luminance_pct for p in ro.points(rid)] == [1.5]


@pytest.fixture
def store_path(tmp_path: Path) -> Path:
    return tmp_path / "store.sqlite"


def test_export_of_a_run_without_readings_has_the_header(store_path: Path) -> None:
    with RunStore(store_path) as s:
        rid = _run(s)
        header = export_run(s, rid, "csv").splitlines()
        assert header == [
            "run_id,run_uuid,index,repeat,theta_i_deg,theta_r_deg,aspecular_deg,measured_theta_i_deg,"
            "measured_theta_r_deg,luminance_pct,predicted_pct,X,Y,Z,L_star,a_star,b_star,"
            "C_star,h_deg,predicted_L_star,predicted_a_star,predicted_b_star,colour_error,"
            "quality,peak_fraction,timestamp"
        ]


def test_a_run_is_claimed_by_one_runner_and_freed_when_its_process_dies(tmp_path: Path) -> None:
    path = tmp_path / "s.sqlite"
    with RunStore(path) as s:
        rid = _run(s)
        other = _run(s)
        with s.claim_run(rid):
            with (
                pytest.raises(RunBusy, match=f"run {rid} is already being measured"),
                s.claim_run(rid),
            ):
                pass
            with s.claim_run(other):  # another run of the same store is free
                pass
        # another process claims the run and is killed -9 while holding it
        code = (
            "import sys, os; from goniolab.store import RunStore\n"
            f"s = RunStore({str(path)!r})\n"
            f"c = s.claim_run({rid}); c.__enter__()\n"
            "print('held', flush=True); sys.stdin.readline()\n"
        )
        proc = subprocess.Popen(
            [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        try:
            assert proc.stdout is not None and proc.stdout.readline() == "held\n"
            assert s.is_claimed(rid) is True and s.is_claimed(other) is False
            with pytest.raises(RunBusy, match="another goniolab process"), s.claim_run(rid):
                pass
            assert s.is_claimed(rid) is True  # probing never breaks the other's claim
        finally:
            proc.kill()
            proc.wait()
        assert s.is_claimed(rid) is False  # the kernel dropped the dead process's lock
        with s.claim_run(rid):
            assert s.is_claimed(rid) is True
            pass
