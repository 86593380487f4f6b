"""The TUI's scan form refuses a sweep the arms cannot reach as it is typed, in the words
``goniolab scan`` prints for the same plan: the lamp's and the detector's limits and the
interlock between the arms, from the lab config (the values of drivers.arm_limits, the
one place of them), checked by the app layer (goniolab.app.lab_setup.check_reach) with
the driver's own check (drivers.arm_limits.geometry_problem)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from textual.widgets import Input

from drivers.arm_limits import DETECTOR_LIMITS_DEG, LAMP_LIMITS_DEG, geometry_problem
from drivers.base import InterlockError, LimitError
from drivers.goniometer import TwoArmGoniometer
from goniolab.app.lab_setup import brdf_plan, check_reach
from goniolab.config import load_lab_config
from goniolab.errors import UserError
from goniolab.optics.analytic import AnalyticModel
from goniolab.store import RunStore
from goniolab.tui.app import GonioApp
from goniolab.tui.session_backend import SessionBackend
from goniolab.tui.view_model import ScanSetup
from goniolab.tui.widgets import ScanForm
from tests._cli import run_cli
from tests.tui.test_lab import sim_config
from tests.tui.tui_scripted import wait_until

REPO = Path(__file__).resolve().parents[2]
CLI_PREFIX = "goniolab: error: "

#: (form fields, the same sweep as ``--theta-i`` / ``--theta-r``) of lab-sim.toml's arms:
#: lamp 0..85, detector 0..70 deg, 10 deg apart at least.
CASES = {
    "detector beyond its limit": (
        {"theta_i_deg": "45", "theta_r_start_deg": "0", "theta_r_stop_deg": "80"},
        "45",
        "0:80:1",
    ),
    "lamp beyond its limit": (
        {"theta_i_deg": "87", "theta_r_start_deg": "0", "theta_r_stop_deg": "20"},
        "87",
        "0:20:1",
    ),
    "arms too close": (
        {"theta_i_deg": "5", "theta_r_start_deg": "0", "theta_r_stop_deg": "20"},
        "5",
        "0:20:1",
    ),
}


def cli_error(cfg: Path, theta_i: str, theta_r: str) -> str:
    """What ``goniolab scan`` prints on stderr for the plan (its exit status checked; run in
    this process, tests/_cli.py: the message is the point, not the process)."""
    out = run_cli("scan", "--config", cfg, "--theta-i", theta_i, "--theta-r", theta_r,
                  "--time-scale", "0", cwd=REPO)  # fmt: skip
    assert out.returncode == 2, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.startswith(CLI_PREFIX)]
    assert len(lines) == 1, out.stderr
    return lines[0].removeprefix(CLI_PREFIX)


def test_the_form_says_what_goniolab_scan_says_as_it_is_typed(tmp_path: Path) -> None:
    cfg = sim_config(tmp_path)
    lab = load_lab_config(cfg)
    assert lab.goniometer.lamp.limits_deg == (0.0, 85.0)
    assert lab.goniometer.detector.limits_deg == (0.0, 70.0)
    assert lab.goniometer.min_separation_deg == 10.0
    cli = {name: cli_error(cfg, ti, tr) for name, (_form, ti, tr) in CASES.items()}
    # the driver's reasons, from the limits above (not from the code under test)
    assert cli["detector beyond its limit"].endswith(
        "point 71 (theta_i=45 deg, theta_r=71 deg) is unsafe: detector: theta_r=71.0 deg "
        "outside the detector arm limits [0.0, 70.0] deg"
    )
    assert cli["lamp beyond its limit"].endswith(
        "point 0 (theta_i=87 deg, theta_r=0 deg) is unsafe: lamp: theta_i=87.0 deg outside "
        "the lamp arm limits [0.0, 85.0] deg"
    )
    assert cli["arms too close"].endswith(
        "point 0 (theta_i=5 deg, theta_r=0 deg) is unsafe: goniometer: theta_i=5.0 deg, "
        "theta_r=0.0 deg puts the arms 5.000 deg apart, below the minimum 10.0 deg"
    )

    async def drive() -> dict[str, tuple[str, str]]:
        app = GonioApp(SessionBackend(cfg, model=AnalyticModel("beckmann", alpha=0.1)), poll_hz=0)
        seen: dict[str, tuple[str, str]] = {}
        async with app.run_test(size=(140, 42)) as pilot:
            await wait_until(pilot, app.ready.is_set)
            form = app.query_one(ScanForm)
            assert form.problem == ""  # the default sweep is within reach
            for name, (fields, _ti, _tr) in CASES.items():
                for key, value in {**fields, "theta_r_step_deg": "1"}.items():
                    app.query_one(f"#{key}", Input).value = value
                await wait_until(pilot, lambda: form.problem != "")
                typed = form.problem
                app.clear_notifications()
                await pilot.press("s")
                await wait_until(
                    pilot, lambda: any(n.title == "Scan setup" for n in app._notifications)
                )
                started = next(n.message for n in app._notifications if n.title == "Scan setup")
                seen[name] = (typed, started)
                # back within reach: the line goes
                for key, value in {"theta_i_deg": "45", "theta_r_start_deg": "10",
                                   "theta_r_stop_deg": "20"}.items():  # fmt: skip
                    app.query_one(f"#{key}", Input).value = value
                await wait_until(pilot, lambda: form.problem == "")
        return seen

    seen = asyncio.run(drive())
    for name, (typed, started) in seen.items():
        assert typed == cli[name], name
        assert started == cli[name], name
    with RunStore(tmp_path / "runs.sqlite") as store:
        assert store.list_runs() == []  # refused before a run was stored


def test_the_backend_checks_its_configs_limits_before_the_lab_is_open(tmp_path: Path) -> None:
    cfg = sim_config(tmp_path)
    text = cfg.read_text()
    assert "limits_deg = [0.0, 85.0]" in text  # the lamp's, the first limits_deg
    cfg.write_text(text.replace("limits_deg = [0.0, 85.0]", "limits_deg = [0.0, 80.0]", 1))
    backend = SessionBackend(cfg, model=AnalyticModel("beckmann", alpha=0.1))
    backend.check_setup(ScanSetup("sample:flat", 80.0, 0.0, 10.0, 5.0, 1))
    bad = ScanSetup("sample:flat", 82.0, 0.0, 10.0, 5.0, 1)
    reason = r"lamp: theta_i=82.0 deg outside the lamp arm limits \[0.0, 80.0\] deg"
    with pytest.raises(UserError, match=r"^plan refused \(no arm moved\): point 0 .*" + reason):
        backend.check_setup(bad)
    # the prediction and the start refuse it before anything is opened or moved
    with pytest.raises(UserError, match=reason):
        asyncio.run(backend.predict_curve(bad))
    with pytest.raises(UserError, match=reason):
        asyncio.run(backend.start(bad))


@pytest.mark.parametrize(
    "theta_i_deg, theta_r_deg",
    [(45.0, 45.0), (45.0, 86.0), (45.0, -85.5), (86.0, 0.0), (-1.0, 30.0), (5.0, 0.0),
     (30.0, -25.0), (30.0, -20.0), (float("nan"), 10.0), (40.0, -31.0)],
)  # fmt: skip
def test_the_config_check_is_the_drivers_check(theta_i_deg: float, theta_r_deg: float) -> None:
    # The driver (two arms at the default limits, with alignment corrections) and the
    # config's check (goniolab.scan.dryrun.config_reach) refuse the same geometries with
    # the same exception and text.
    from goniolab.config.sections import GoniometerConfig
    from goniolab.scan.dryrun import config_reach

    corr = (0.25, -0.5)
    # check_geometry reads the arms' names and limits only
    lamp: Any = SimpleNamespace(name="lamp", limits_deg=LAMP_LIMITS_DEG)
    det: Any = SimpleNamespace(name="detector", limits_deg=DETECTOR_LIMITS_DEG)
    driver = TwoArmGoniometer(lamp, det, min_separation_deg=10.0, corrections_deg=corr)
    check, _reach = config_reach(GoniometerConfig(), corr)

    def refusal(fn: object) -> tuple[type, str] | None:
        try:
            fn(theta_i_deg, theta_r_deg)  # type: ignore[operator]
        except (LimitError, InterlockError) as exc:
            return type(exc), str(exc)
        return None

    assert refusal(check) == refusal(driver.check_geometry)
    # and the expectation from the limits themselves: the arms at theta + correction
    ti, tr = theta_i_deg + corr[0], theta_r_deg + corr[1]
    ok = (0.0 <= ti <= 85.0) and (-85.0 <= tr <= 85.0) and abs(ti + tr) >= 10.0
    assert (refusal(check) is None) == ok
    assert (geometry_problem(ti, tr, lamp_limits_deg=LAMP_LIMITS_DEG,
                             detector_limits_deg=DETECTOR_LIMITS_DEG,
                             min_separation_deg=10.0) is None) == ok  # fmt: skip


def test_check_reach_names_the_range_an_alignment_leaves(tmp_path: Path) -> None:
    # A detector zero of +2 deg: the arm stands at theta_r - 2, so theta_r 71 is reachable
    # (arm at 69) and 73 is not (arm at 71), and the refusal says what is reachable.
    cfg = load_lab_config(sim_config(tmp_path))
    plan = brdf_plan(cfg, sample="sample:flat", theta_i_deg=45.0, theta_r_deg="60:71:1")
    corr = (0.0, -2.0)
    check_reach(cfg, plan, corrections_deg=corr)
    with pytest.raises(UserError) as err:
        check_reach(cfg, plan, corrections_deg=(0.0, 0.0))
    assert "point 11 (theta_i=45 deg, theta_r=71 deg)" in str(err.value)
    far = brdf_plan(cfg, sample="sample:flat", theta_i_deg=45.0, theta_r_deg="70:73:1")
    with pytest.raises(UserError) as err:
        check_reach(cfg, far, corrections_deg=corr)
    assert str(err.value) == (
        "plan refused (no arm moved): point 3 (theta_i=45 deg, theta_r=73 deg) is unsafe: "
        "detector: theta_r=71.0 deg outside the detector arm limits [0.0, 70.0] deg; with the "
        "alignment corrections (lamp +0.000, detector -2.000 deg) the arms reach "
        "theta_i 0.000..85.000 deg, theta_r 2.000..72.000 deg"
    )


def test_goniolab_scan_refuses_before_reaching_an_instrument(tmp_path: Path) -> None:
    # a lab whose controllers are not there (nothing listens on port 1): a sweep out of
    # reach is refused by the plan check in its words (exit 2), not by the connection
    from goniolab.config import configs_dir

    text = (configs_dir() / "lab-sim-wire.toml").read_text()
    text = text.replace("start_sim_servers = true", "start_sim_servers = false")
    text = text.replace("port = 5020", "port = 1")
    assert "port = 5020" not in text
    cfg = tmp_path / "lab.toml"
    cfg.write_text(text)
    said = cli_error(cfg, "45", "0:80:1")
    assert said == (
        "plan refused (no arm moved): point 71 (theta_i=45 deg, theta_r=71 deg) is unsafe: "
        "detector: theta_r=71.0 deg outside the detector arm limits [0.0, 70.0] deg"
    )
    lab = load_lab_config(cfg)
    plan = brdf_plan(lab, sample=lab.sample.map, theta_i_deg=45.0, theta_r_deg="0:80:1")
    with pytest.raises(UserError) as err:
        check_reach(lab, plan)
    assert str(err.value) == said
