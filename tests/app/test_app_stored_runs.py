"""The stored-run use cases (goniolab.app.stored_runs) called directly on a store of known
content (tests/_runs.py): values read back exactly as written, one error for a missing run,
nothing created by a read."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.app.stored_runs import (
    annotate_run,
    export_run,
    get_run,
    import_runs,
    list_runs,
    migrate_runs,
    open_store,
    plot_run,
    show_run,
    store_path,
    summarize_run,
)
from goniolab.config import configs_dir
from goniolab.errors import UserError
from tests._runs import lum, make_store


@pytest.fixture
def store(tmp_path: Path) -> Path:
    return make_store(tmp_path / "s.sqlite")


def test_a_missing_run_is_one_user_error_naming_store_and_run(store: Path) -> None:
    with open_store(store) as s, pytest.raises(UserError) as err:
        get_run(s, 9)
    assert str(err.value) == f"store {store}: no run 9"
    for call in (show_run, summarize_run):
        with pytest.raises(UserError, match=r"no run 9$"):
            call(9, store)


def test_list_reads_back_what_was_stored(store: Path) -> None:
    listing = list_runs(store)
    assert listing.exists and listing.location == str(store) and not listing.filtered
    assert [(b.record.id, b.record.kind, b.readings) for b in listing.runs] == [
        (2, "gloss", 2),
        (1, "brdf", 5),  # 3 angles x 2 repeats, the last reading missing
    ]
    assert [b.record.status for b in listing.runs] == ["idle", "aborted"]
    assert listing.runs[1].as_dict()["sample"] == "sample:x"


def test_listing_a_store_not_made_yet_creates_nothing(tmp_path: Path) -> None:
    missing = tmp_path / "none.sqlite"
    listing = list_runs(missing)
    assert not listing.exists and listing.runs == [] and not missing.exists()
    with pytest.raises(UserError):
        list_runs(missing, missing_ok=False)
    assert not missing.exists()


def test_show_summarises_the_stored_readings(store: Path) -> None:
    view = show_run(1, store)
    assert view.record.id == 1 and view.record.status == "aborted"
    assert view.summary["readings"] == 5 and view.summary["planned_readings"] == 6
    assert view.resume is not None and view.resume.startswith("goniolab scan resume 1 --store ")
    gloss = show_run(2, store)
    assert gloss.summary["statistics"]["20"]["mean_gu"] == pytest.approx(80.5)
    assert gloss.resume is None


def test_export_as_json_holds_each_reading_exactly(store: Path, tmp_path: Path) -> None:
    done = export_run(1, "json", store=store)
    assert done.output is None and done.format == "json"
    doc = json.loads(done.text)
    assert [r["luminance_pct"] for r in doc["readings"]] == [
        lum(0, 0), lum(0, 1), lum(1, 0), lum(1, 1), lum(2, 0),
    ]  # fmt: skip
    out = tmp_path / "run.csv"
    assert export_run(1, None, out, store=store).format == "csv"  # from the suffix
    assert out.read_text().count("\n") == 6  # header + 5 readings
    with pytest.raises(UserError, match="binary format needs -o FILE"):
        export_run(1, "parquet", store=store)


def test_import_and_migrate_copy_runs_by_uuid(store: Path, tmp_path: Path) -> None:
    exported = tmp_path / "run1.json"
    export_run(1, "json", exported, store=store)
    other = tmp_path / "other.sqlite"
    rows = import_runs([str(exported), str(tmp_path / "nope.json")], other)
    assert rows[0]["run_id"] == 1 and rows[0]["action"] == "copied"
    assert set(rows[1]) == {"file", "error"}  # one file's failure, the others imported
    again = import_runs([str(exported)], other)
    assert again[0]["run_id"] == 1 and again[0]["action"] != "copied"  # matched by UUID
    told: list[str] = []
    moved = migrate_runs(
        str(store), tmp_path / "third.sqlite", on_run=lambda e, r: told.append(e["action"])
    )
    assert told == ["copied", "copied"] and moved.errors == 0
    with open_store(tmp_path / "third.sqlite") as s:
        assert [p.luminance_pct for p in s.points(1)] == [
            lum(0, 0), lum(0, 1), lum(1, 0), lum(1, 1), lum(2, 0),
        ]  # fmt: skip
    with pytest.raises(UserError, match="is the target store itself"):
        migrate_runs(str(store), store)


def test_annotate_edits_the_stored_tags(store: Path) -> None:
    rec = annotate_run(1, store=store, operator="ada", add_tags=["a", "b"])
    assert rec.operator == "ada" and list(rec.tags) == ["a", "b"]
    rec = annotate_run(1, store=store, remove_tags=["a"], add_tags=["c"])
    assert list(rec.tags) == ["b", "c"] and rec.operator == "ada"  # None keeps the operator
    with open_store(store) as s:
        assert list(get_run(s, 1).tags) == ["b", "c"]


def test_plot_writes_the_file_its_suffix_names(store: Path, tmp_path: Path) -> None:
    out = tmp_path / "run.png"
    drawn = plot_run(1, out, store=store)
    assert drawn.output == out and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(UserError, match="the suffix picks the format"):
        plot_run(1, tmp_path / "run.bmp", store=store)


def test_the_store_is_chosen_by_store_then_config(tmp_path: Path) -> None:
    assert store_path(tmp_path / "a.sqlite") == tmp_path / "a.sqlite"
    cfg = tmp_path / "lab.toml"
    text = (configs_dir() / "lab-sim.toml").read_text()
    assert 'store = ""' in text
    cfg.write_text(text.replace('store = ""', f'store = "{tmp_path / "cfg.sqlite"}"', 1))
    assert store_path(None, cfg) == tmp_path / "cfg.sqlite"
    assert store_path(tmp_path / "a.sqlite", cfg) == tmp_path / "a.sqlite"
