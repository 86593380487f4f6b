"""Lab configs a clumsy or hostile user writes: everything that would fail at run time (a
register value that does not fit, a boolean where a number belongs, an interlock switched
off, an exposure the spectro refuses, a file nested a thousand deep) is refused at load,
naming the file, the key and the reason."""

from __future__ import annotations

from pathlib import Path

import pytest

from goniolab.config import MIN_SEPARATION_FLOOR_DEG, ConfigError, load_lab_config

INT32_MAX = 2**31 - 1


def load(tmp_path: Path, text: str) -> ConfigError:
    p = tmp_path / "x.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_lab_config(p)
    message = str(info.value)
    assert message.startswith(f"{p}: ") and "\n" not in message
    return info.value


# ----------------------------------------------------------------------- defect 4: strict types
@pytest.mark.parametrize(
    ("section", "key"),
    [
        ("goniometer", "min_separation_deg"),
        ("goniometer", "source_cone_deg"),
        ("goniometer", "move_timeout_s"),
        ("goniometer.park", "theta_i_deg"),
        ("goniometer.lamp", "unit_id"),
        ("goniometer.lamp", "port"),
        ("goniometer.lamp", "baudrate"),
        ("goniometer.lamp", "steps_per_deg"),
        ("goniometer.lamp", "gear_ratio"),
        ("goniometer.detector", "speed_deg_s"),
        ("goniometer.detector", "accel_deg_s2"),
        ("goniometer.detector", "stall_tolerance_deg"),
        ("goniometer.detector", "timeout_s"),
        ("lab", "time_scale"),
        ("sample", "n"),
        ("spectro", "exposure_us"),
        ("spectro", "detector_cone_deg"),
        ("glossmeter", "baudrate"),
        ("sim", "seed"),
        ("sim", "noise_pct"),
        ("sim.faults", "timeout_rate"),
        ("sim.faults", "disconnect_after"),
        ("sim.faults", "lamp_stall_at_deg"),
    ],
)
def test_a_boolean_is_not_a_number(tmp_path: Path, section: str, key: str) -> None:
    """TOML ``true`` is not 1 (``min_separation_deg = true`` read as 1.0 let a forbidden
    plan run; ``unit_id = true`` addressed unit 1)."""
    err = load(tmp_path, f"[{section}]\n{key} = true\n")
    assert err.key == f"{section}.{key}"
    assert "got True" in err.reason


def test_a_boolean_is_not_an_angle_in_a_list(tmp_path: Path) -> None:
    err = load(tmp_path, "[goniometer.lamp]\nlimits_deg = [false, 85.0]\n")
    assert err.key == "goniometer.lamp.limits_deg[0]"


def test_a_float_is_not_an_integer(tmp_path: Path) -> None:
    err = load(tmp_path, "[goniometer.lamp]\nunit_id = 1.5\n")
    assert err.key == "goniometer.lamp.unit_id"


def test_an_integer_is_still_a_float(tmp_path: Path) -> None:
    p = tmp_path / "ok.toml"
    p.write_text("[goniometer]\nmin_separation_deg = 12\n[goniometer.lamp]\nspeed_deg_s = 10\n")
    cfg = load_lab_config(p)
    assert cfg.goniometer.min_separation_deg == 12.0
    assert isinstance(cfg.goniometer.lamp.speed_deg_s, float)


@pytest.mark.parametrize("value", ["0", "0.0", "-1.0", "0.5"])
def test_the_interlock_cannot_be_switched_off(tmp_path: Path, value: str) -> None:
    err = load(tmp_path, f"[goniometer]\nmin_separation_deg = {value}\n")
    assert err.key == "goniometer.min_separation_deg"
    assert f"{MIN_SEPARATION_FLOOR_DEG:g}" in err.reason


def test_the_arms_cannot_be_closer_than_their_cones(tmp_path: Path) -> None:
    """Lamp and detector cones of 16 deg each overlap when the arms are 10 deg apart: the
    detector would look into the lamp."""
    err = load(
        tmp_path,
        "[goniometer]\nmin_separation_deg = 10.0\nsource_cone_deg = 16.0\n"
        "[spectro]\ndetector_cone_deg = 16.0\n",
    )
    assert err.key == "goniometer.min_separation_deg"
    assert "16" in err.reason and "cone" in err.reason


# ------------------------------------------------- defect 3: derived register values at load
def test_steps_per_deg_whose_positions_overflow_the_int32_register(tmp_path: Path) -> None:
    """2e8 steps/deg: the upper limit 85 deg is 1.7e10 steps, beyond int32 (today a
    struct.error in the middle of a run)."""
    err = load(tmp_path, "[goniometer.lamp]\nsteps_per_deg = 2e8\nspeed_deg_s = 1e-3\n")
    assert err.key == "goniometer.lamp.steps_per_deg"
    assert str(INT32_MAX) in err.reason and "85" in err.reason


def test_gear_ratio_counts_in_the_overflow(tmp_path: Path) -> None:
    # 1e6 steps/deg x 100 = 1e8 steps per arm degree: 85 deg = 8.5e9 steps
    err = load(tmp_path, "[goniometer.detector]\nsteps_per_deg = 1e6\ngear_ratio = 100.0\n")
    assert err.key == "goniometer.detector.steps_per_deg"
    assert "gear_ratio" in err.reason


@pytest.mark.parametrize("value", ["1e30", "1e300"])
def test_absurd_steps_per_deg(tmp_path: Path, value: str) -> None:
    err = load(tmp_path, f"[goniometer.lamp]\nsteps_per_deg = {value}\n")
    assert err.key == "goniometer.lamp.steps_per_deg"


def test_steps_coarser_than_the_stall_tolerance(tmp_path: Path) -> None:
    """1e-6 steps/deg: one step is 1e6 deg; no position can be commanded or checked."""
    err = load(tmp_path, "[goniometer.lamp]\nsteps_per_deg = 1e-6\n")
    assert err.key == "goniometer.lamp.steps_per_deg"
    assert "stall_tolerance_deg" in err.reason


def test_a_speed_that_rounds_to_zero_register_counts(tmp_path: Path) -> None:
    err = load(tmp_path, "[goniometer.lamp]\nspeed_deg_s = 1e-6\n")
    assert err.key == "goniometer.lamp.speed_deg_s"
    assert "register" in err.reason


def test_an_acceleration_beyond_the_register(tmp_path: Path) -> None:
    # 1000 steps/deg: 3e6 deg/s^2 is 3e9 counts, beyond int32
    err = load(tmp_path, "[goniometer.detector]\naccel_deg_s2 = 3e6\n")
    assert err.key == "goniometer.detector.accel_deg_s2"
    assert str(INT32_MAX) in err.reason


def test_the_16_bit_registers_of_a_command_opcode_profile(tmp_path: Path) -> None:
    """The Applied Motion MDX+ map holds speed in one 16-bit register."""
    err = load(
        tmp_path,
        '[goniometer.lamp]\nprofile = "applied-motion-mdx"\nsteps_per_deg = 100000.0\n'
        "speed_deg_s = 80.0\n",
    )
    assert err.key == "goniometer.lamp.speed_deg_s"
    assert "65535" in err.reason


# ----------------------------------------------------------------- defect 10: exposure at load
@pytest.mark.parametrize("value", [100, 499, 250_001, 10**9])
def test_exposure_outside_the_profile_range(tmp_path: Path, value: int) -> None:
    err = load(tmp_path, f"[spectro]\nexposure_us = {value}\n")
    assert err.key == "spectro.exposure_us"
    assert "500..250000" in err.reason and "stil-ruby" in err.reason


# -------------------------------------------------------------- defect 8: deep nesting
@pytest.mark.parametrize(
    "text",
    [
        "x = " + "[" * 5000 + "]" * 5000 + "\n",
        "x = " + "{a = " * 2000 + "1" + "}" * 2000 + "\n",
        "[" + ".".join(["a"] * 3000) + "]\nb = 1\n",
    ],
    ids=["arrays", "inline-tables", "dotted-table"],
)
def test_deeply_nested_toml_is_one_clear_error(tmp_path: Path, text: str) -> None:
    err = load(tmp_path, text)
    assert len(str(err)) < 300


def test_a_device_profile_nested_too_deeply_is_one_clear_error(tmp_path: Path) -> None:
    from drivers.base import ProfileError
    from drivers.profiles import load_stepper_profile

    p = tmp_path / "deep.toml"
    p.write_text('kind = "modbus-stepper"\nx = ' + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(ProfileError, match="nested too deeply") as info:
        load_stepper_profile(p)
    assert str(info.value).startswith(str(p)) and len(str(info.value)) < 300
    err = load(tmp_path, f'[goniometer.lamp]\nprofile = "{p}"\n')
    assert err.key == "goniometer.lamp.profile" and "nested too deeply" in err.reason


# -------------------------------------------------------------- defect 1: homing reachable
def test_homes_that_cannot_be_reached_safely_are_refused_at_load(tmp_path: Path) -> None:
    """A lamp arm limited to 0..5 deg can never stand 10 deg clear of the detector's home
    (0 deg), and the detector cannot home beside the lamp: homing would be refused."""
    err = load(
        tmp_path,
        "[goniometer]\npark = { theta_i_deg = 5.0, theta_r_deg = 45.0 }\n"
        "[goniometer.lamp]\nlimits_deg = [0.0, 5.0]\n",
    )
    assert err.key == "goniometer"
    assert "home positions cannot be reached safely" in err.reason
