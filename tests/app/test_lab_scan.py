"""The use cases on a lab (goniolab.app.lab_scan, lab_setup, lab_gloss) on the in-process
twin: what they store, how often they read the config, what progress they report."""

from __future__ import annotations

import asyncio
import contextlib
import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import goniolab.config
from goniolab.app import lab_gloss, lab_scan, lab_setup
from goniolab.errors import UserError
from goniolab.progress import CallbackProgress, ProgressUpdate
from goniolab.scan.events import RunState
from goniolab.store import RunStore
from tests.twin_configs import ideal_config

SAMPLE = "sample:wittmann-3"


@pytest.fixture
def config_loads(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Every path :func:`goniolab.config.load_lab_config` is called with (a spy)."""
    calls: list[str] = []
    real = goniolab.config.load_lab_config

    def spy(path: Any, *args: Any, **kwargs: Any) -> Any:
        calls.append(str(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(goniolab.config, "load_lab_config", spy)
    yield calls


def _main(args: list[str]) -> tuple[int, str, str]:
    from goniolab.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(args)
    return code, out.getvalue(), err.getvalue()


def test_scan_stores_the_plan_as_requested_and_reports_each_reading(tmp_path: Path) -> None:
    cfg = lab_setup.load_config(ideal_config(tmp_path))
    plan = lab_setup.brdf_plan(cfg, sample=SAMPLE, theta_r_deg="30:40:5", repeats=2)
    updates: list[ProgressUpdate] = []
    notices: list[str] = []
    with lab_setup.open_store(tmp_path / "runs.sqlite") as store:
        out = asyncio.run(
            lab_scan.scan(cfg, store, plan, time_scale=0,
                          reporter=CallbackProgress(updates.append), notify=notices.append)
        )  # fmt: skip
        rec = store.get_run(out.run_id)
        points = store.points(out.run_id)
    assert out.state is RunState.DONE and out.reason == ""
    assert rec.kind == "brdf" and rec.status == "done" and rec.sample == SAMPLE
    assert rec.plan["theta_r_deg"] == [30.0, 35.0, 40.0] and rec.plan["repeats"] == 2
    assert len(points) == 3 * 2 == out.summary["readings"]
    assert sorted({p.theta_r_deg for p in points}) == [30.0, 35.0, 40.0]
    # provenance: the config file, the store and the model of each angle
    assert out.config_source == cfg.source and out.store == str(tmp_path / "runs.sqlite")
    assert out.model["computed_by"] and out.model == rec.model
    # progress: started with the total, one step per reading 1..N of N, finished once
    # (messages, e.g. the model's warnings, may come before the start: they are not progress)
    kinds = [u.kind for u in updates if u.kind != "message"]
    assert kinds[0] == "start" and kinds[-1] == "finish" and kinds.count("finish") == 1
    assert all(u.text for u in updates if u.kind == "message")
    # (the runner's first Progress, before any reading, says 0 of N with the run's ETA)
    steps = [u for u in updates if u.kind == "advance"]
    assert [u.done for u in steps] == [0, 1, 2, 3, 4, 5, 6]
    assert {u.total for u in steps} == {6} and steps[-1].eta_s == 0.0
    assert steps[-1].detail.startswith("theta_r=40 L=")
    assert notices[0].startswith("6 readings, ") and f"run {out.run_id} in store" in notices[1]


def test_the_cli_scan_reads_the_config_once(tmp_path: Path, config_loads: list[str]) -> None:
    config = ideal_config(tmp_path)
    code, out, err = _main(["scan", "--config", str(config), "--sample", SAMPLE,
                            "--theta-r", "35,45", "--repeats", "1", "--time-scale", "0",
                            "--store", str(tmp_path / "s.sqlite"), "--json"])  # fmt: skip
    assert code == 0, err
    assert config_loads == [str(config)]
    doc = json.loads(out)
    assert doc["state"] == "done" and doc["readings"] == 2


def test_the_api_scan_reads_the_config_once(tmp_path: Path, config_loads: list[str]) -> None:
    import goniolab.api as gl

    config = ideal_config(tmp_path)
    run = gl.run_scan(config, sample=SAMPLE, theta_r_deg=[40.0, 50.0], repeats=1, time_scale=0,
                      store=tmp_path / "s.sqlite", progress=False)  # fmt: skip
    assert len(config_loads) == 1
    assert run.status == "done" and len(run.to_dataframe()) == 2


def test_resume_takes_only_the_readings_left(tmp_path: Path, config_loads: list[str]) -> None:
    """An aborted run resumed: the readings stored are kept, the rest taken, the stored
    config used (the file read once, to compare it with the snapshot)."""
    config = ideal_config(tmp_path)
    cfg = lab_setup.load_config(config)
    plan = lab_setup.brdf_plan(cfg, sample=SAMPLE, theta_r_deg="20:60:10", repeats=1)
    updates: list[ProgressUpdate] = []

    def abort_after_two(u: ProgressUpdate) -> None:
        if u.kind == "advance" and u.done == 2:
            runner.abort(by="test")

    def keep(r: Any) -> None:
        nonlocal runner
        runner = r

    runner: Any = None
    with lab_setup.open_store(tmp_path / "runs.sqlite") as store:
        first = asyncio.run(
            lab_scan.scan(cfg, store, plan, time_scale=0, on_start=keep,
                          reporter=CallbackProgress(abort_after_two))
        )  # fmt: skip
        assert first.state is RunState.ABORTED
        kept = store.count_points(first.run_id)
        assert 2 <= kept < 5
        config_loads.clear()
        again = asyncio.run(
            lab_scan.resume(store, first.run_id, time_scale=0,
                            reporter=CallbackProgress(updates.append))
        )  # fmt: skip
        assert again.run_id == first.run_id and again.state is RunState.DONE
        assert store.count_points(first.run_id) == 5
    assert config_loads == [str(config.resolve())]  # the run's own file, once
    steps = [u.done for u in updates if u.kind == "advance"]
    assert steps == list(range(kept, 6))  # from the readings kept to the last


def test_an_unreachable_plan_is_refused_before_anything_is_stored(tmp_path: Path) -> None:
    cfg = lab_setup.load_config(ideal_config(tmp_path))
    hi = cfg.goniometer.detector.limits_deg[1]
    plan = lab_setup.brdf_plan(cfg, sample=SAMPLE, theta_r_deg=[40.0, hi + 5.0], repeats=1)
    with lab_setup.open_store(tmp_path / "runs.sqlite") as store:
        with pytest.raises(UserError, match=r"^plan refused \(no arm moved\): "):
            asyncio.run(lab_scan.scan(cfg, store, plan, time_scale=0))
        assert store.list_runs() == []


def test_plans_are_built_once_for_every_face(tmp_path: Path) -> None:
    cfg = lab_setup.load_config(ideal_config(tmp_path))
    plan = lab_setup.brdf_plan(cfg, sample=SAMPLE, theta_i_deg=30, theta_r_deg=[10, 20.5])
    assert plan.theta_i_deg == 30.0 and plan.theta_r_deg == (10.0, 20.5)
    assert plan.exposure_us == cfg.spectro.exposure_us  # the config's, when not given
    with pytest.raises(UserError, match=r"^run_scan: theta_r_deg: empty angle list"):
        lab_setup.brdf_plan(cfg, sample=SAMPLE, theta_r_deg="", what="run_scan",
                            angles_option="theta_r_deg")  # fmt: skip
    with pytest.raises(UserError, match=r"^scan: repeats"):
        lab_setup.brdf_plan(cfg, sample=SAMPLE, theta_r_deg="1,2", repeats=0)
    angles, skipped = lab_setup.e2194_angles(cfg, 45.0, theta_r_given=False)
    # -15, 15, 25, 45, 75, 110 deg aspecular at 45 deg incidence (ASTM E2194): theta_r =
    # 45 - aspecular, kept when the detector arm reaches it and it is not beyond the lamp
    lo, hi = cfg.goniometer.detector.limits_deg
    want = sorted(t for a in (-15, 15, 25, 45, 75, 110) if (t := 45.0 - a) >= -45 and lo <= t <= hi)
    assert [float(a) for a in angles.split(",")] == want
    assert len(skipped) == 6 - len(want) and any("aspecular 110 deg skipped" in s for s in skipped)


def test_calibrate_and_align_store_their_runs(tmp_path: Path) -> None:
    cfg = lab_setup.load_config(ideal_config(tmp_path))
    with lab_setup.open_store(tmp_path / "runs.sqlite") as store:
        cal = asyncio.run(lab_scan.calibrate(cfg, store, repeats=1, time_scale=0))
        rec = store.get_run(cal.run_id)
        assert rec.kind == "calibration" and rec.status == "done"
        assert cal.record["check"]["standard"] == "black_glass"
        plan = lab_setup.align_plan(cfg, sample=SAMPLE, theta_i_deg="20,40,60", exposure_us=None)
        updates: list[ProgressUpdate] = []
        out = asyncio.run(
            lab_scan.align(cfg, store, plan, time_scale=0, save_state=False,
                           reporter=CallbackProgress(updates.append))
        )  # fmt: skip
        assert store.get_run(out.run_id).kind == "align"
        assert store.get_run(out.run_id).status == "done"
    assert out.as_dict()["state"] == "done" and out.result.state_file == ""
    # one step per reading, after the run's opening 0 of N (before any reading)
    store_points = [u for u in updates if u.kind == "advance" and u.done]
    assert [u.done for u in store_points] == list(range(1, out.result.readings + 1))
    assert store_points[-1].done == store_points[-1].total


def test_gloss_log_stores_its_readings(tmp_path: Path) -> None:
    cfg = lab_setup.load_config(ideal_config(tmp_path))
    plan = lab_gloss.gloss_plan(3, [20, 60, 85], SAMPLE)
    seen: list[Any] = []

    async def watch(q: asyncio.Queue[Any]) -> None:
        while (ev := await q.get()) is not None:
            seen.append(ev)

    with lab_setup.open_store(tmp_path / "runs.sqlite") as store:
        result = asyncio.run(
            lab_gloss.gloss_log(store, plan, config=cfg, time_scale=0, watch=watch)
        )
        rec = store.get_run(result.run_id)
        readings = store.gloss_readings(result.run_id)
    assert rec.kind == "gloss" and result.state is RunState.DONE and result.readings == 3
    assert len(readings) == 3 and set(readings[0].values_gu) == {20, 60, 85}
    assert rec.model["computed_by"]  # the prediction's models, stored with the run
    from goniolab.scan.events import GlossRead

    assert sum(isinstance(e, GlossRead) for e in seen) == 3
    with pytest.raises(UserError, match="one of them"):
        asyncio.run(lab_gloss.gloss_log(store, plan))


def test_the_store_error_is_one_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError) as info:
        lab_setup.open_store(tmp_path / "missing.sqlite", create=False)
    assert "missing.sqlite" in str(info.value) and info.value.exit_code == 2
    assert isinstance(lab_setup.open_store(tmp_path / "s.sqlite"), RunStore)


def test_the_reporter_gets_the_runs_wall_eta_as_it_is() -> None:
    """issue 27: ``Progress.eta_s`` is already wall seconds measured from the run's own
    rates (goniolab.scan.eta); the CLI divided it again by the clock scale (a tenth of the
    real time at --time-scale 10). NaN (not known yet) reaches the reporter as None."""
    import asyncio
    import math as _math

    from goniolab.app.lab_scan import report_events
    from goniolab.scan.events import Progress

    class Seen:
        def __init__(self) -> None:
            self.etas: list[float | None] = []

        def start(self, total: int, label: str = "") -> None:
            pass

        def advance(self, done=None, *, total=None, eta_s=None, detail=""):  # type: ignore[no-untyped-def]
            self.etas.append(eta_s)

        def message(self, text: str) -> None:
            pass

        def finish(self) -> None:
            pass

    async def feed() -> list[float | None]:
        queue: asyncio.Queue[object] = asyncio.Queue()
        for done, eta in ((0, _math.nan), (1, 12.5), (2, 6.0)):
            queue.put_nowait(Progress(run_id=1, done=done, total=3, eta_s=eta))
        queue.put_nowait(None)
        seen = Seen()
        await report_events(queue, seen)  # type: ignore[arg-type]
        return seen.etas

    assert asyncio.run(feed()) == [None, 12.5, 6.0]
