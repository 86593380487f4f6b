"""bluesky extra: ophyd-async devices on the simulated lab, driven by a RunEngine."""

from __future__ import annotations

import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("bluesky", reason="the bluesky extra is not installed (goniolab[bluesky])")
pytest.importorskip("ophyd_async", reason="the bluesky extra is not installed")

from bluesky import RunEngine
from bluesky.utils import FailedStatus

from goniolab.bluesky_lab import connect_lab, inplane_scan

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "lab-sim.toml"


@pytest.fixture
def engine() -> Any:
    RE = RunEngine({}, call_returns_result=True)
    yield RE
    if RE.state != "idle":  # pragma: no cover - a failed test left it running
        RE.halt()


def test_inplane_scan_documents(engine: Any, tmp_path: Path) -> None:
    from goniolab.model_cache import model_for
    from goniolab.optics.apertures import Cone
    from tests.twin_configs import ideal_config

    # the ideal twin: the readings travel unchanged into the documents (the realistic one
    # measures its own truth, docs/TWIN.md)
    lab = connect_lab(ideal_config(tmp_path), sample="sample:wittmann-3", time_scale=0)
    docs: list[tuple[str, dict[str, Any]]] = []
    engine.subscribe(lambda name, doc: docs.append((name, doc)))
    try:
        result = engine(
            inplane_scan(lab, theta_i_deg=45.0, theta_r_deg=[35.0, 45.0, 55.0], repeats=2)
        )
        cfg = lab.lab.config
    finally:
        lab.close()
    names = [n for n, _ in docs]
    assert names[0] == "start" and names[-1] == "stop"
    assert names.count("descriptor") == 1 and names.count("event") == 6
    start = docs[0][1]
    assert start["plan_name"] == "goniolab_inplane_scan"
    assert start["sample"] == "sample:wittmann-3"
    assert start["plan_args"]["theta_r_deg"] == [35.0, 45.0, 55.0]
    assert uuid.UUID(start["run_uuid"]).version == 4 and start["tags"] == []  # issue 22.4
    assert result.run_start_uids == (start["uid"],)
    stop = docs[-1][1]
    assert stop["exit_status"] == "success" and stop["num_events"] == {"primary": 6}
    desc = next(d for n, d in docs if n == "descriptor")
    keys = desc["data_keys"]
    assert keys["detector-readback_deg"]["units"] == "deg"
    assert keys["spectro-luminance_pct"]["units"] == "%"
    assert keys["spectro-spectrum_pct"]["dtype"] == "array"
    assert {"spectro-L_star", "spectro-a_star", "spectro-b_star", "lamp-readback_deg"} <= set(keys)
    conf = desc["configuration"]["detector"]["data"]
    assert conf["detector-low_limit_deg"] == cfg.goniometer.detector.limits_deg[0]
    events = [d for n, d in docs if n == "event"]
    tr = np.array([e["data"]["detector-readback_deg"] for e in events])
    np.testing.assert_allclose(tr, [35, 35, 45, 45, 55, 55], atol=0.05)
    np.testing.assert_allclose([e["data"]["lamp-readback_deg"] for e in events], 45.0, atol=0.05)
    # the ideal twin measures what the model predicts through the same cones (its noise)
    model = model_for("sample:wittmann-3", n=cfg.sample.n)
    pred = model.luminance_pct(
        45.0,
        np.array([35.0, 45.0, 55.0]),
        source=Cone(cfg.goniometer.source_cone_deg),
        detector=Cone(cfg.spectro.detector_cone_deg),
    )
    lum = np.array([e["data"]["spectro-luminance_pct"] for e in events]).reshape(3, 2)
    np.testing.assert_allclose(lum.mean(axis=1), pred, rtol=0.05, atol=0.01)
    assert lum[1].mean() > 10 * lum[0].mean()  # the specular peak
    # L* on the [colour] diffuser scale, as the store reports it: above 100 at the specular
    # peak (a reflectance factor > 1 relative to the perfect diffuser), finite everywhere
    L = np.array([e["data"]["spectro-L_star"] for e in events]).reshape(3, 2)
    assert np.all(np.isfinite(L)) and np.all(L > 0.0)
    assert L[1].min() > 100.0 > L[0].max()
    assert len(events[0]["data"]["spectro-spectrum_pct"]) == len(
        desc["configuration"]["spectro"]["data"]["spectro-wavelengths_nm"]
    )


def test_the_interlock_fails_the_move(engine: Any) -> None:
    from bluesky import plan_stubs as bps

    lab = connect_lab(CONFIG, time_scale=0)
    try:
        cfg = lab.lab.config
        sep = cfg.goniometer.min_separation_deg
        engine(bps.mv(lab.lamp, 30.0))
        # theta_r = -30 puts the detector onto the lamp: |30 + (-30)| = 0 < min separation
        with pytest.raises(FailedStatus):
            engine(bps.mv(lab.detector, -30.0 + sep / 2))
        hi = cfg.goniometer.detector.limits_deg[1]
        with pytest.raises(FailedStatus):
            engine(bps.mv(lab.detector, hi + 1.0))
        # nothing moved
        ti, tr = engine(bps.rd(lab.lamp)).plan_result, None
        del tr
        assert ti == pytest.approx(30.0, abs=0.05)
    finally:
        lab.close()


def test_a_plan_out_of_reach_is_refused_before_the_run_opens(engine: Any, tmp_path: Path) -> None:
    """inplane_scan goes through the session's dry run (goniolab.app.lab_scan.check_plan):
    a detector angle beyond the arm's limit is refused with the CLI's words before any
    document or motion (it used to open the run, move the lamp, read 40 deg and fail on
    the move to the bad angle)."""
    from bluesky import plan_stubs as bps

    from goniolab.errors import UserError
    from tests.twin_configs import ideal_config

    lab = connect_lab(ideal_config(tmp_path), time_scale=0)
    names: list[str] = []
    try:
        hi = lab.lab.config.goniometer.detector.limits_deg[1]
        before = [engine(bps.rd(arm)).plan_result for arm in (lab.lamp, lab.detector)]
        engine.subscribe(lambda name, doc: names.append(name))
        with pytest.raises(UserError, match=r"^plan refused \(no arm moved\): "):
            engine(inplane_scan(lab, theta_i_deg=45.0, theta_r_deg=[40.0, hi + 5.0], repeats=1))
        after = [engine(bps.rd(arm)).plan_result for arm in (lab.lamp, lab.detector)]
    finally:
        lab.close()
    assert names == []  # no start, no event: the run never opened
    assert after == pytest.approx(before, abs=1e-9)  # nothing moved


def _sim_separation_monitor(lab: Any) -> Any:
    """Record the smallest |theta_i + theta_r| of the twin's arms (their encoders) at every
    10 ms of the lab clock, in the RunEngine's loop, until stopped."""
    import asyncio

    from bluesky.run_engine import call_in_bluesky_event_loop

    sims = lab.lab.sims
    clock = lab.lab.clock
    state: dict[str, Any] = {"min": float("inf"), "stop": False}

    async def watch() -> None:
        while not state["stop"]:
            now = clock.now()
            s = abs(sims.lamp.motor.position_deg(now) + sims.detector.motor.position_deg(now))
            state["min"] = min(state["min"], s)
            await clock.sleep(0.01)

    async def start() -> None:
        state["task"] = asyncio.ensure_future(watch())

    call_in_bluesky_event_loop(start())
    return state


def test_two_arms_set_at_once_keep_their_minimum(engine: Any) -> None:
    # issue 22 item 1: from (45, 45), bps.mv(lamp, 5, detector, 3) ended at (5, 3), 8 deg
    # apart; bp.scan(lamp 20->4, detector 20->4) ended at (4, 4)
    from bluesky import plan_stubs as bps
    from bluesky import plans as bp

    lab = connect_lab(CONFIG, time_scale=0)
    try:
        sep = lab.lab.config.goniometer.min_separation_deg
        engine(bps.mv(lab.goniometer, (45.0, 45.0)))
        state = _sim_separation_monitor(lab)
        with pytest.raises(FailedStatus):
            engine(bps.mv(lab.lamp, 5.0, lab.detector, 3.0))
        ti = engine(bps.rd(lab.lamp)).plan_result
        tr = engine(bps.rd(lab.detector)).plan_result
        assert (ti, tr) == (pytest.approx(5.0, abs=0.05), pytest.approx(45.0, abs=0.05))
        engine(bps.mv(lab.goniometer, (20.0, 20.0)))
        with pytest.raises(FailedStatus):
            engine(bp.scan([lab.spectro], lab.lamp, 20.0, 4.0, lab.detector, 20.0, 4.0, num=5))
        ti = engine(bps.rd(lab.lamp)).plan_result
        tr = engine(bps.rd(lab.detector)).plan_result
        assert ti + tr >= sep - 0.01
        state["stop"] = True
        assert state["min"] >= sep - 0.01, state["min"]
        # the two-arm device moves both arms in the safe order to a geometry
        engine(bps.mv(lab.goniometer, (30.0, 60.0)))
        ti = engine(bps.rd(lab.goniometer.theta_i_deg)).plan_result
        tr = engine(bps.rd(lab.goniometer.theta_r_deg)).plan_result
        assert (ti, tr) == (pytest.approx(30.0, abs=0.05), pytest.approx(60.0, abs=0.05))
        with pytest.raises(FailedStatus):  # 5 deg apart: refused, nothing moves
            engine(bps.mv(lab.goniometer, (2.0, 3.0)))
    finally:
        lab.close()


@pytest.mark.parametrize(
    "colour",
    [
        "",  # the defaults: D65, CIE 1964 10 deg, diffuser scale
        '[colour]\nilluminant = "A"\nobserver = "CIE 1931 2 Degree Standard Observer"\n'
        'scale = "mirror"\n',
    ],
)
def test_bluesky_colour_equals_the_stored_runs(engine: Any, tmp_path: Path, colour: str) -> None:
    """Issue 22.9: the Spectro device integrated the raw % as a reflectance factor with a
    fixed D65 / 10 deg (L* 0.31 against the store's 46.5 at theta_r 35, 18.7 against 263
    at the specular angle). The truth is the store's colour of the same readings: the
    simulated lab of one config and seed measures the same spectra through both faces, so
    L*a*b* must agree to rounding, with the config's [colour] honoured by both."""
    import goniolab.api as gl

    config = tmp_path / "lab.toml"
    config.write_text((ROOT / "configs" / "lab-sim.toml").read_text() + "\n" + colour)
    angles = [35.0, 45.0, 55.0]
    lab = connect_lab(config, time_scale=0)
    docs: list[tuple[str, dict[str, Any]]] = []
    engine.subscribe(lambda name, doc: docs.append((name, doc)))
    try:
        engine(inplane_scan(lab, theta_i_deg=45.0, theta_r_deg=angles, repeats=2))
    finally:
        lab.close()
    events = [d["data"] for n, d in docs if n == "event"]
    got = np.array([[e[f"spectro-{k}_star"] for k in "Lab"] for e in events]).reshape(3, 2, 3)
    # the bluesky Spectro reads at the configured exposure: so does this scan (auto-exposure
    # reads more often and draws other noise)
    run = gl.run_scan(config, theta_r_deg=angles, repeats=2, time_scale=0,
                      store=tmp_path / "runs.sqlite", progress=False,
                      auto_exposure=False)  # fmt: skip
    ds = run.to_xarray()
    stored = np.stack([ds[f"{k}_star"].values for k in "Lab"], axis=-1)
    assert np.all(np.isfinite(stored))
    np.testing.assert_allclose(got, stored, rtol=0, atol=1e-6)
    desc = next(d for n, d in docs if n == "descriptor")
    settings = desc["configuration"]["spectro"]["data"]["spectro-colour_settings"]
    assert ('"A"' in settings) == bool(colour)
