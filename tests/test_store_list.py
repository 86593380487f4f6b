"""``runs list``'s one query (:meth:`RunStore.list_briefs`) against counted truth.

The listing counts readings in SQL (issue 26); these tests count them the slow, obvious way
(every point and gloss reading loaded, ``len``) and compare, with the filters and the limit
applied by hand to the full truth, in SQLite and in PostgreSQL (a throw-away server, skipped
with the reason when the binaries are missing).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from goniolab.store import RunMeta, RunRecord, RunStore
from tests.pg_server import PLANTED_PASSWORD, PgServer, find_pg_bin

BIN, WHY = find_pg_bin()
_names = itertools.count()

#: (kind, readings, status, operator, sample_id, tags, notes) per run, in creation order
RUNS = [
    ("brdf", 7, "done", "ada", "P-1", ("blue",), "first panel"),
    ("gloss", 3, "done", "bob", "P-2", ("blue", "metallic"), ""),
    ("align", 0, "failed", "ada", "", (), "no light"),
    ("brdf", 0, "aborted", "", "P-1", ("metallic",), ""),
    ("gloss", 0, "idle", "bob", "", (), "Blue note"),
    ("brdf", 12, "aborted", "ada", "P-3", ("blue",), ""),
    ("calibration", 0, "done", "cy", "", (), ""),
    ("gloss", 5, "done", "", "P-3", ("metallic", "blue-ish"), ""),
]


def _fill(s: RunStore) -> None:
    for j, (kind, n, status, operator, sample_id, tags, notes) in enumerate(RUNS):
        meta = RunMeta(operator=operator, sample_id=sample_id, notes=notes, tags=tags)
        rid = s.create_run(kind=kind, plan={"kind": kind, "theta_i_deg": 45.0 + j},
                           config={"lab": {"name": f"lab{j}"}}, sample=f"sample:s{j}",
                           model={"n": 1.5 + j}, version="t", meta=meta)  # fmt: skip
        for k in range(n):
            if kind == "brdf":  # two repeats per angle: idx and repeat both vary
                s.add_point(rid, index=k // 2, repeat=k % 2, theta_i_deg=45.0,
                            theta_r_deg=10.0 + k // 2, measured_theta_i_deg=45.0,
                            measured_theta_r_deg=10.0 + k // 2, luminance_pct=1.0 + k,
                            raw={"k": k}, timestamp=1000.0 + k)  # fmt: skip
            else:
                s.add_gloss_reading(rid, values_gu={20: 1.0 * k, 60: 2.0, 85: None},
                                    temperature_c=None, predicted_gu=None, raw="r",
                                    timestamp=2000.0 + k)  # fmt: skip
        if status != "idle":
            s.set_status(rid, status, "why" if status in ("failed", "aborted") else "")


def _truth(s: RunStore) -> list[tuple[RunRecord, int]]:
    """Every run, newest first, with its readings counted by loading them."""
    out = []
    for rid in sorted((r.id for r in s.list_runs()), reverse=True):
        rec = s.get_run(rid)
        n = len(s.gloss_readings(rid)) if rec.kind == "gloss" else len(s.points(rid))
        out.append((rec, n))
    return out


def _mentions(rec: RunRecord, text: str) -> bool:
    """The documented text filter: a case-insensitive substring of the sample, sample id,
    operator, notes or one of the tags."""
    fields = [rec.sample, rec.sample_id, rec.operator, rec.notes, *rec.tags]
    return any(text.lower() in f.lower() for f in fields)


@pytest.fixture(scope="module")
def server(request: pytest.FixtureRequest) -> PgServer | None:
    """The test process's server (tests/conftest.py), or None without PostgreSQL."""
    if BIN is None:
        return None
    srv: PgServer = request.getfixturevalue("pg_shared")
    return srv


@pytest.fixture(scope="module", params=["sqlite", "postgres"])
def store(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[RunStore]:
    """One filled store per backend for the module (the tests only read it)."""
    with pytest.MonkeyPatch.context() as mp:
        if request.param == "sqlite":
            location: str | Path = tmp_path_factory.mktemp("list") / "runs.sqlite"
        else:
            if BIN is None:
                pytest.skip(WHY)
            srv = request.getfixturevalue("server")
            mp.setenv("PGPASSWORD", PLANTED_PASSWORD)
            location = srv.create_db(f"list{os.getpid()}_{next(_names)}")
        with RunStore(location) as s:
            _fill(s)
        with RunStore(location, readonly=True) as s:
            yield s


def test_runs_of_one_kind_are_those_the_whole_list_holds(store: RunStore) -> None:
    everything = store.list_runs()
    for kind in ("brdf", "gloss", "glosscal"):
        want = [r.id for r in everything if r.kind == kind]
        assert [r.id for r in store.list_runs(kind=kind)] == want
        assert [r.id for r in store.list_runs(1, kind=kind)] == want[:1]
    assert {r.kind for r in everything} >= {"brdf", "gloss"}


def test_counts_status_and_times_equal_the_counted_truth(store: RunStore) -> None:
    truth = _truth(store)
    assert [n for _, n in truth] == [r[1] for r in reversed(RUNS)]  # the truth is what we wrote
    briefs = store.list_briefs()
    assert [(r.id, n) for r, n in briefs] == [(r.id, n) for r, n in truth]
    for (got, _), (want, _) in zip(briefs, truth, strict=True):
        assert (got.kind, got.status, got.reason) == (want.kind, want.status, want.reason)
        assert (got.created_at, got.finished_at) == (want.created_at, want.finished_at)
        assert (got.operator, got.sample_id, got.tags, got.notes) == (
            want.operator, want.sample_id, want.tags, want.notes,
        )  # fmt: skip
        assert (got.uuid, got.plan, got.damage) == (want.uuid, want.plan, "")
        # a listing's record leaves the config snapshot and the model unread, and says so
        assert got.brief and (got.config, got.model) == ({}, {})
        assert not want.brief and want.config == {"lab": {"name": f"lab{got.id - 1}"}}
        # terminal states have a finish time, the idle one none
        assert (got.finished_at is None) == (got.status == "idle")


@pytest.mark.parametrize(
    "filters",
    [
        {},
        {"operator": "ada"},
        {"sample_id": "P-3"},
        {"tag": "blue"},  # not "blue-ish": a tag matches whole
        {"tag": "metallic"},
        {"text": "blue"},  # tags and notes, case-insensitively
        {"operator": "bob", "tag": "blue"},
        {"operator": "nobody"},
    ],
)
@pytest.mark.parametrize("limit", [None, 1, 2, 100])
def test_filters_and_limit_equal_the_truth_filtered_by_hand(
    store: RunStore, filters: dict[str, str], limit: int | None
) -> None:
    want = [
        (rec.id, n)
        for rec, n in _truth(store)
        if rec.operator == filters.get("operator", rec.operator)
        and rec.sample_id == filters.get("sample_id", rec.sample_id)
        and ("tag" not in filters or filters["tag"] in rec.tags)
        and ("text" not in filters or _mentions(rec, filters["text"]))
    ][:limit]
    got = [(r.id, n) for r, n in store.list_briefs(limit=limit, **filters)]  # type: ignore[arg-type]
    assert got == want


@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_a_garbled_config_or_model_is_listed_as_damaged(
    backend: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest
) -> None:
    """The listing does not decode config and model but has the server check them: a run
    whose column is no JSON object is read whole, its damage the one get_run reports."""
    if backend == "sqlite":
        location: str | Path = tmp_path / "d.sqlite"
    else:
        if BIN is None:
            pytest.skip(WHY)
        monkeypatch.setenv("PGPASSWORD", PLANTED_PASSWORD)
        location = request.getfixturevalue("server").create_db(f"dmg{os.getpid()}")
    with RunStore(location) as s:
        for j in range(4):
            s.create_run(kind="brdf", plan={}, config={"lab": {"nan": float("nan")}} if j == 3
                         else {}, sample=f"s{j}", model={}, version="t")  # fmt: skip
        s.db.execute("UPDATE runs SET config_json = '{not json' WHERE id = 1")
        s.db.execute("UPDATE runs SET model_json = '[1, 2]' WHERE id = 2")
    with RunStore(location, readonly=True) as s:
        listed = {r.id: r for r, _ in s.list_briefs()}
        truth = {i: s.get_run(i, allow_damaged=True) for i in range(1, 5)}
        assert truth[1].damage == "config_json is not valid JSON (Expecting property name " \
            "enclosed in double quotes: line 1 column 2 (char 1))"  # fmt: skip
        assert truth[2].damage == "model_json is not a JSON object"
        # NaN: Python's JSON (json_text wrote it), not the server's: read whole, not damaged
        assert truth[4].damage == "" and listed[4].damage == ""
        assert listed[3].brief and listed[3].damage == ""
        if s.db.is_postgres and s.db.raw.info.server_version < 160000:
            # no check the server can run without failing the query: shown when opened
            assert listed[1].damage == listed[2].damage == ""
            return
        assert (listed[1].damage, listed[2].damage) == (truth[1].damage, truth[2].damage)


def test_a_postgresql_session_runs_without_jit(store: RunStore) -> None:
    """The listing's first query in a fresh session paid for a JIT compile (see
    :func:`goniolab.store.postgres.pg_connect`): every store session has it off."""
    if not store.db.is_postgres:
        pytest.skip("PostgreSQL only")
    assert store.db.execute("SHOW jit").fetchone()[0] == "off"


def test_the_kind_column_is_as_wide_as_its_longest_kind(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``runs list``'s columns stay aligned when a kind is longer than 5 characters (a
    calibration or a gloss calibration): every row's STATUS starts under the header's."""
    from goniolab.cli import main

    location = tmp_path / "runs.sqlite"
    with RunStore(location) as s:
        for kind in ("brdf", "calibration", "glosscal"):
            s.create_run(kind=kind, plan={"kind": kind}, config={}, sample="sample:x",
                         model={}, version="t")  # fmt: skip
    assert main(["runs", "list", "--store", str(location)]) == 0
    header, *rows = capsys.readouterr().out.splitlines()
    col = header.index("STATUS")
    assert [r[col:].split()[0] for r in rows] == ["idle"] * 3
    assert [r.split()[1] for r in rows] == ["glosscal", "calibration", "brdf"]
