"""One place for the axis limits (issue 24): the lab config, the scan's plan check (the dry
run) and the driver refuse the same out-of-range angle and the same interlock distance,
each naming the limit that ``drivers/arm_limits.py`` holds."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from drivers.arm_limits import (
    DEFAULT_MIN_SEPARATION_DEG,
    DETECTOR_LIMITS_DEG,
    LAMP_LIMITS_DEG,
    MIN_SEPARATION_FLOOR_DEG,
    limits_problem,
    separation_floor_problem,
)
from drivers.base import LimitError
from drivers.goniometer import TwoArmGoniometer
from drivers.modbus_stepper import ModbusStepperAxis
from goniolab.config import ConfigError, LabConfig, load_lab_config
from goniolab.scan.dryrun import ArmMotion, PlanRefused, dry_run
from goniolab.scan.plans import BrdfPlan

#: "[lo, hi]" in a message, whatever the number format ("[0, 85]", "[0.0, 85.0]")
LIMITS_IN = re.compile(r"\[(-?\d+(?:\.\d*)?), (-?\d+(?:\.\d*)?)\]")


def limits_named(message: str) -> tuple[float, float]:
    found = LIMITS_IN.search(message)
    assert found, f"no [lo, hi] in {message!r}"
    return float(found[1]), float(found[2])


def lab_arms(cfg: LabConfig) -> TwoArmGoniometer:
    """The goniometer of a config's arms, built as the lab wiring builds it (no I/O)."""
    g = cfg.goniometer
    return TwoArmGoniometer(
        ModbusStepperAxis("lamp", limits_deg=g.lamp.limits_deg),
        ModbusStepperAxis("detector", limits_deg=g.detector.limits_deg),
        min_separation_deg=g.min_separation_deg,
        park_deg=(g.park.theta_i_deg, g.park.theta_r_deg),
    )


def test_the_defaults_are_the_ones_of_the_limits_module() -> None:
    g = LabConfig().goniometer
    assert g.lamp.limits_deg == LAMP_LIMITS_DEG == ModbusStepperAxis("lamp").limits_deg
    assert g.detector.limits_deg == DETECTOR_LIMITS_DEG
    assert g.min_separation_deg == DEFAULT_MIN_SEPARATION_DEG


@pytest.mark.parametrize("theta_i_deg", [LAMP_LIMITS_DEG[1] + 5.0, LAMP_LIMITS_DEG[0] - 1.0])
def test_config_plan_and_driver_refuse_one_lamp_angle_naming_one_limit(
    tmp_path: Path, theta_i_deg: float
) -> None:
    # the config: a park position beyond the lamp's limits
    path = tmp_path / "lab.toml"
    path.write_text(f"[goniometer]\npark = {{ theta_i_deg = {theta_i_deg}, theta_r_deg = 45.0 }}\n")
    with pytest.raises(ConfigError) as cfg_err:
        load_lab_config(path)
    assert cfg_err.value.key == "goniometer.park.theta_i_deg"
    assert "outside the arm limits" in cfg_err.value.reason

    # the driver, with the arms of the default config
    arms = lab_arms(LabConfig())
    with pytest.raises(LimitError) as drv_err:
        arms.check_geometry(theta_i_deg, 45.0)
    assert "lamp arm limits" in drv_err.value.message

    # the plan, checked by the dry run before anything moves
    plan = BrdfPlan(theta_i_deg, (45.0,))
    with pytest.raises(PlanRefused) as plan_err:
        dry_run(
            plan.points(),
            arms,
            ArmMotion.from_config(LabConfig().goniometer),
            start_deg=(45.0, 45.0),
            dwell_s=0.0,
            reading_time_s=0.1,
        )
    assert plan_err.value.what == "point 0"

    named = {
        "config": limits_named(cfg_err.value.reason),
        "driver": limits_named(drv_err.value.message),
        "plan": limits_named(plan_err.value.reason),
    }
    assert named == dict.fromkeys(named, LAMP_LIMITS_DEG)


def test_a_detector_angle_past_its_limit_is_refused_with_that_limit(tmp_path: Path) -> None:
    theta_r_deg = DETECTOR_LIMITS_DEG[1] + 1.0
    path = tmp_path / "lab.toml"
    path.write_text(f"[goniometer]\npark = {{ theta_i_deg = 45.0, theta_r_deg = {theta_r_deg} }}\n")
    with pytest.raises(ConfigError) as cfg_err:
        load_lab_config(path)
    with pytest.raises(LimitError) as drv_err:
        lab_arms(LabConfig()).check_geometry(45.0, theta_r_deg)
    assert cfg_err.value.key == "goniometer.park.theta_r_deg"
    assert limits_named(cfg_err.value.reason) == DETECTOR_LIMITS_DEG
    assert limits_named(drv_err.value.message) == DETECTOR_LIMITS_DEG


def test_config_and_driver_refuse_one_interlock_distance_in_the_same_words(
    tmp_path: Path,
) -> None:
    # below the floor (0 would switch the interlock off): the driver used to accept 0.5
    below = MIN_SEPARATION_FLOOR_DEG / 2.0
    path = tmp_path / "lab.toml"
    path.write_text(f"[goniometer]\nmin_separation_deg = {below}\n")
    with pytest.raises(ConfigError) as cfg_err:
        load_lab_config(path)
    cfg = LabConfig()
    with pytest.raises(ValueError, match="min_separation_deg") as drv_err:
        TwoArmGoniometer(
            ModbusStepperAxis("lamp", limits_deg=cfg.goniometer.lamp.limits_deg),
            ModbusStepperAxis("detector", limits_deg=cfg.goniometer.detector.limits_deg),
            min_separation_deg=below,
        )
    reason = separation_floor_problem(below)
    assert reason == "0.5 deg is below the floor 1 deg: the arm interlock cannot be switched off"
    assert cfg_err.value.key == "goniometer.min_separation_deg"
    assert cfg_err.value.reason == reason
    assert str(drv_err.value) == f"goniometer: min_separation_deg: {reason}"


@pytest.mark.parametrize(
    ("limits", "reason"),
    [
        ((10.0, 5.0), "lower limit 10 must be below upper limit 5"),
        ((-200.0, 85.0), "limits must lie within [-180, 180] deg, got [-200, 85]"),
    ],
)
def test_config_and_driver_refuse_the_same_limits(
    tmp_path: Path, limits: tuple[float, float], reason: str
) -> None:
    assert limits_problem(limits) == reason
    path = tmp_path / "lab.toml"
    path.write_text(f"[goniometer.lamp]\nlimits_deg = [{limits[0]}, {limits[1]}]\n")
    with pytest.raises(ConfigError) as cfg_err:
        load_lab_config(path)
    assert (cfg_err.value.key, cfg_err.value.reason) == ("goniometer.lamp.limits_deg", reason)
    with pytest.raises(ValueError) as drv_err:
        ModbusStepperAxis("lamp", limits_deg=limits)
    assert str(drv_err.value) == f"lamp: limits_deg: {reason}"


def test_the_architecture_doc_states_the_limits_of_the_module() -> None:
    doc = (Path(__file__).resolve().parents[2] / "docs" / "ARCHITECTURE.md").read_text()
    line = " ".join(doc[doc.index("`drivers/arm_limits.py`") :].split("\n")[:3])
    (lamp_lo, lamp_hi), (det_lo, det_hi) = LAMP_LIMITS_DEG, DETECTOR_LIMITS_DEG
    assert f"lamp {lamp_lo:g}..{lamp_hi:g} deg, detector {det_lo:g}..{det_hi:g} deg" in line
    assert f"`min_separation_deg` >= {MIN_SEPARATION_FLOOR_DEG:g} deg" in line
