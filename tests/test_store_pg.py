"""The run store on a real PostgreSQL server the tests start themselves.

Same schema and semantics as SQLite: one row per reading, UNIQUE(run_id, idx, repeat),
per-point commit, claims (row locks here), resume after ``kill -9``, two scans writing at
once, ``runs migrate`` from SQLite. A planted password must never show up in a log line,
a config snapshot, ``runs show`` or an error message.
"""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from goniolab.store import RunBusy, RunStore, StoreError
from tests._cli import run_cli
from tests._runs import lum, make_store
from tests.pg_server import PLANTED_PASSWORD, PgServer, find_pg_bin

ROOT = Path(__file__).resolve().parents[1]
GONIOLAB = str(Path(sys.executable).with_name("goniolab"))
BIN, WHY = find_pg_bin()
pytestmark = pytest.mark.skipif(BIN is None, reason=WHY)
_names = itertools.count()


@pytest.fixture(scope="module")
def server(pg_shared: PgServer) -> PgServer:
    """The test process's server (tests/conftest.py); each test makes its own database."""
    return pg_shared


@pytest.fixture
def url(server: PgServer, monkeypatch: pytest.MonkeyPatch) -> str:
    """A fresh database; the password reaches libpq through PGPASSWORD only."""
    monkeypatch.setenv("PGPASSWORD", PLANTED_PASSWORD)
    return server.create_db(f"t{os.getpid()}_{next(_names)}")


def _env(log_dir: Path) -> dict[str, str]:
    return {**os.environ, "PGPASSWORD": PLANTED_PASSWORD, "GONIOLAB_LOG_DIR": str(log_dir)}


def _cli(*args: str, env: dict[str, str], check: bool = True) -> subprocess.CompletedProcess[str]:
    """``goniolab ARGS`` in this process (tests/_cli.py: the scans of
    :func:`test_two_scans_write_at_once` and :func:`test_kill_9_mid_scan_then_resume` are the
    real ``goniolab`` processes here)."""
    out = run_cli(*args, env={"PGPASSWORD": env["PGPASSWORD"],
                              "GONIOLAB_LOG_DIR": env["GONIOLAB_LOG_DIR"]}, cwd=ROOT)  # fmt: skip
    if check:
        assert out.returncode == 0, out.stderr
    return out


def _add(s: RunStore, rid: int, k: int, r: int) -> None:
    s.add_point(rid, index=k, repeat=r, theta_i_deg=45.0, theta_r_deg=40.0 + k,
                measured_theta_i_deg=45.0, measured_theta_r_deg=40.0 + k,
                luminance_pct=lum(k, r), raw={"k": k}, timestamp=1000.0 + k)  # fmt: skip


def test_same_semantics_as_sqlite(url: str) -> None:
    with RunStore(url) as s:
        assert s.is_postgres and PLANTED_PASSWORD not in s.location
        rid = s.create_run(kind="brdf", plan={"theta_i_deg": 45.0}, config={}, sample="x",
                           model={}, version="t")  # fmt: skip
        _add(s, rid, 0, 0)
        _add(s, rid, 0, 1)
        import psycopg

        with pytest.raises(psycopg.IntegrityError):  # UNIQUE(run_id, idx, repeat)
            _add(s, rid, 0, 1)
        s.add_predictions(rid, [(0, 45.0, 40.0, 1.5)])
        s.add_predictions(rid, [(0, 45.0, 40.0, 2.5)])  # upsert
        seq = s.add_gloss_reading(rid, values_gu={20: 1.0, 60: None, 85: 3.0},
                                  temperature_c=None, predicted_gu=None, raw="r",
                                  timestamp=5.0)  # fmt: skip
        s.set_status(rid, "done")
    # a second connection (another instrument) sees every committed row
    with RunStore(url, readonly=True) as s2:
        assert s2.done_keys(rid) == {(0, 0), (0, 1)}
        assert [p.luminance_pct for p in s2.points(rid)] == [lum(0, 0), lum(0, 1)]
        assert s2.predictions(rid) == {0: 2.5}
        assert seq == 0 and s2.gloss_readings(rid)[0].values_gu == {20: 1.0, 60: None, 85: 3.0}
        assert s2.get_run(rid).status == "done" and s2.get_run(rid).finished_at is not None
        with pytest.raises(StoreError, match="no run 99"):
            s2.get_run(99)


def test_claims_are_row_locks(url: str) -> None:
    with RunStore(url) as a, RunStore(url) as b:
        rid = a.create_run(kind="brdf", plan={}, config={}, sample="", model={}, version="t")
        assert b.is_claimed(rid) is False
        with a.claim_run(rid):
            assert b.is_claimed(rid) is True
            with pytest.raises(RunBusy, match="another goniolab process"), b.claim_run(rid):
                pass
            with pytest.raises(RunBusy, match="this process"), a.claim_run(rid):
                pass
        assert b.is_claimed(rid) is False
        with b.claim_run(rid):
            assert a.is_claimed(rid) is True


def test_a_readonly_open_of_an_empty_database_is_a_clear_error(server: PgServer) -> None:
    os.environ.setdefault("PGPASSWORD", PLANTED_PASSWORD)
    url = server.create_db(f"empty{os.getpid()}_{next(_names)}")
    with pytest.raises(StoreError, match="no goniolab run store"):
        RunStore(url, readonly=True)


def _scan_args(url: str, *extra: str) -> list[str]:
    return ["scan", "--config", "configs/lab-sim.toml", "--store", url,
            "--sample", "sample:wittmann-3", "--theta-i", "45", *extra]  # fmt: skip


@pytest.mark.slow
def test_two_scans_write_at_once(url: str, tmp_path: Path) -> None:
    env = _env(tmp_path)
    args = _scan_args(url, "--theta-r", "30:60:2", "--time-scale", "20", "--json")
    procs = [
        subprocess.Popen(
            [GONIOLAB, *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            cwd=ROOT,
        )
        for _ in range(2)
    ]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1] for o in outs]
    ids = sorted(json.loads(o[0])["run_id"] for o in outs)
    assert ids == [1, 2]
    with RunStore(url, readonly=True) as s:
        for rid in ids:
            assert s.get_run(rid).status == "done"
            assert s.done_keys(rid) == {(k, 0) for k in range(16)}
            assert len(s.predictions(rid)) == 16


def _wait(what: str, cond: Any, timeout_s: float = 120.0) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.1)


def _alive(proc: subprocess.Popen[bytes]) -> bool:
    if proc.poll() is not None:
        raise AssertionError(f"the scan ended early, exit status {proc.returncode}")
    return True


@pytest.mark.slow
@pytest.mark.timeout(300)  # a subprocess scan at real time, then a resume
def test_kill_9_mid_scan_then_resume(url: str, tmp_path: Path) -> None:
    env = _env(tmp_path)
    args = _scan_args(url, "--theta-r", "20:70:1", "--time-scale", "1", "--dwell", "0.1")
    err_path = tmp_path / "scan.stderr"
    with err_path.open("wb") as err:
        proc = subprocess.Popen([GONIOLAB, *args], stdout=subprocess.DEVNULL, stderr=err,
                                env=env, cwd=ROOT)  # fmt: skip
    with RunStore(url) as s:
        try:
            _wait("the scan's run", lambda: _alive(proc) and bool(s.list_runs()))
            _wait("three readings", lambda: _alive(proc) and s.count_points(1) >= 3)
        except AssertionError as exc:
            # where the scan waits: its thread stacks (SIGUSR1) and its log
            proc.send_signal(signal.SIGUSR1)
            time.sleep(2.0)
            logs = "".join(p.read_text() for p in sorted(tmp_path.glob("goniolab.log*")))
            raise AssertionError(f"{exc}\n--- stderr:\n{err_path.read_text()}\n"
                                 f"--- log:\n{logs[-6000:]}") from None  # fmt: skip
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=60)
        before = {(p.index, p.repeat): p.timestamp for p in s.points(1)}
        assert 3 <= len(before) < 51
        # the server drops the dead process's connection, and its row lock with it
        _wait("the claim to go", lambda: s.is_claimed(1) is False)
    listed = json.loads(_cli("runs", "list", "--store", url, "--json", env=env).stdout)
    assert listed[0]["interrupted"] is True and listed[0]["status"] == "running"
    _cli("scan", "resume", "1", "--store", url, "--time-scale", "0", env=env)
    with RunStore(url, readonly=True) as s:
        assert s.get_run(1).status == "done"
        after = {(p.index, p.repeat): p.timestamp for p in s.points(1)}
    assert set(after) == {(k, 0) for k in range(51)}  # every reading exactly once
    assert all(after[k] == t for k, t in before.items())  # what was measured stays


@pytest.mark.slow
def test_the_password_never_shows(url: str, server: PgServer, tmp_path: Path) -> None:
    env = _env(tmp_path)
    secret_url = url.replace("goniolab@", f"goniolab:{PLANTED_PASSWORD}@")
    config = tmp_path / "lab.toml"
    text = (ROOT / "configs" / "lab-sim.toml").read_text()
    config.write_text(text.replace('store = ""', f'store = "{secret_url}"'))
    out = _cli(
        "scan",
        "--config",
        str(config),
        "--theta-r",
        "40:50:5",
        "--time-scale",
        "0",
        env={**env, "PGPASSWORD": ""},
    )  # fmt: skip: the URL's own password only
    shown = [out.stdout, out.stderr]
    shown.append(_cli("runs", "show", "1", "--store", url, "--json", env=env).stdout)
    shown.append(_cli("runs", "show", "1", "--store", secret_url, env=env).stdout)
    bad = _cli("runs", "list", "--store", secret_url.replace(url.rsplit("/", 1)[1], "nodb"),
               env=env, check=False)  # fmt: skip
    assert bad.returncode == 2 and "nodb" in bad.stderr
    shown.append(bad.stderr)
    with RunStore(url, readonly=True) as s:
        snap = s.get_run(1).config
        shown.append(json.dumps(snap))
    assert snap["lab"]["store"].startswith("postgresql://goniolab:***@127.0.0.1:")
    logs = "".join(p.read_text() for p in tmp_path.glob("goniolab.log*"))
    assert "scan --config" in logs and "runs list" in logs and "nodb" in logs
    shown.append(logs)
    for text in shown:
        assert PLANTED_PASSWORD not in text


@pytest.mark.slow
def test_migrate_from_sqlite(url: str, tmp_path: Path) -> None:
    env = _env(tmp_path)
    src = make_store(tmp_path / "instrument.sqlite")
    out = _cli("runs", "migrate", "--from", str(src), "--store", url, "--json", env=env)
    doc = json.loads(out.stdout)
    assert [(m["from"], m["to"], m["copied"]) for m in doc["runs"]] == [(1, 1, True), (2, 2, True)]
    again = json.loads(_cli("runs", "migrate", "--from", str(src), "--store", url, "--json",
                            env=env).stdout)  # fmt: skip
    assert [m["copied"] for m in again["runs"]] == [False, False]
    with RunStore(src, readonly=True) as a, RunStore(url, readonly=True) as b:
        for rid in (1, 2):
            ra, rb = a.get_run(rid), b.get_run(rid)
            assert (ra.kind, ra.status, ra.reason, ra.plan, ra.created_at) == (
                rb.kind, rb.status, rb.reason, rb.plan, rb.created_at)  # fmt: skip
        assert a.points(1) == b.points(1) and a.predictions(1) == b.predictions(1)
        assert a.gloss_readings(2) == b.gloss_readings(2)
    # and the netCDF export of the migrated run equals the original's
    import xarray as xr

    _cli("runs", "export", "1", "--store", str(src), "-o", str(tmp_path / "a.nc"), env=env)
    _cli("runs", "export", "1", "--store", url, "-o", str(tmp_path / "b.nc"), env=env)
    with xr.open_dataset(tmp_path / "a.nc") as da, xr.open_dataset(tmp_path / "b.nc") as db:
        xr.testing.assert_equal(da, db)


def test_test_server_retries_a_port_taken_before_its_bind(monkeypatch: pytest.MonkeyPatch) -> None:
    """tests/pg_server.py: a port found free and then taken by another process (an xdist
    worker's server) before PostgreSQL binds it makes the start fail with "could not bind";
    the helper starts on another port instead of failing the module's tests."""
    import socket

    import tests.pg_server as pgs

    assert BIN is not None
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        busy = int(taken.getsockname()[1])
        ports = iter([busy])
        real = pgs._free_port
        monkeypatch.setattr(pgs, "_free_port", lambda: next(ports, None) or real())
        with pgs.pg_server(BIN) as srv:
            assert srv.port != busy
            import psycopg

            with psycopg.connect(srv.url(), password=PLANTED_PASSWORD) as conn:
                assert conn.execute("SELECT 1").fetchone() == (1,)
