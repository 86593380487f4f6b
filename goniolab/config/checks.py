"""The checks of a lab config that span several keys or need a device profile.

Each raises :class:`~goniolab.errors.ConfigError` against the key a user would edit:

* :func:`cross_checks`: park within the arm limits, ``min_separation_deg`` against the
  lamp and detector cones, homing plannable from the park position, ports;
* :func:`register_checks`: every register value derived from an arm's settings fits its
  register with the arm's profile;
* :func:`exposure_check`: ``spectro.exposure_us`` within the spectro profile's range.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from drivers.arm_limits import outside_limits
from goniolab.config.sections import AxisConfig, LabConfig
from goniolab.errors import ConfigError

#: Largest value of a signed 32-bit register (positions, and speeds of direct-data drives).
INT32_MAX = 2**31 - 1
#: Largest value of a 16-bit register (speeds and accelerations of command-opcode drives).
UINT16_MAX = 0xFFFF


def cross_checks(cfg: LabConfig, path: Path) -> None:
    """Checks that span several keys, reported against the key a user would edit."""
    g = cfg.goniometer
    for key, value, arm in (
        ("goniometer.park.theta_i_deg", g.park.theta_i_deg, g.lamp),
        ("goniometer.park.theta_r_deg", g.park.theta_r_deg, g.detector),
    ):
        lo, hi = arm.limits_deg
        if outside_limits(value, arm.limits_deg):
            raise ConfigError(
                path, key, f"{value:g} deg outside the arm limits [{lo:g}, {hi:g}] deg"
            )
    cones_deg = (g.source_cone_deg + cfg.spectro.detector_cone_deg) / 2.0
    if g.min_separation_deg < cones_deg:
        raise ConfigError(
            path,
            "goniometer.min_separation_deg",
            f"{g.min_separation_deg:g} deg is closer than the lamp and detector cones allow "
            f"(source_cone_deg {g.source_cone_deg:g} and spectro.detector_cone_deg "
            f"{cfg.spectro.detector_cone_deg:g} overlap below {cones_deg:g} deg: the detector "
            "would look into the lamp)",
        )
    sep = abs(g.park.theta_i_deg + g.park.theta_r_deg)
    if sep >= g.min_separation_deg:
        from drivers.base import InterlockError
        from drivers.goniometer import plan_homing

        park = (g.park.theta_i_deg, g.park.theta_r_deg)
        try:
            plan_homing(
                park,
                home_deg=(0.0, 0.0),
                limits_deg=(g.lamp.limits_deg, g.detector.limits_deg),
                min_separation_deg=g.min_separation_deg,
                park_deg=park,
            )
        except InterlockError as exc:
            raise ConfigError(
                path, "goniometer", f"{exc.message} (from the park position)"
            ) from None
    if sep < g.min_separation_deg:
        raise ConfigError(
            path,
            "goniometer.park",
            f"arm separation {sep:g} deg is below min_separation_deg {g.min_separation_deg:g}",
        )
    for name, arm in (("lamp", g.lamp), ("detector", g.detector)):
        if (
            cfg.lab.mode == "drivers"
            and not cfg.lab.start_sim_servers
            and (
                (arm.transport == "tcp" and arm.port == 0)
                or (arm.transport == "rtu" and arm.serial_port.endswith(":0"))
            )
        ):
            raise ConfigError(
                path,
                f"goniometer.{name}.{'port' if arm.transport == 'tcp' else 'serial_port'}",
                "port 0 (any free port) only works when the lab serves its own simulated "
                "controllers (start_sim_servers = true); give the controller's TCP port",
            )
    if (
        cfg.lab.mode == "drivers"
        and g.lamp.transport == "tcp"
        and g.detector.transport == "tcp"
        and (g.lamp.host, g.lamp.port, g.lamp.unit_id)
        == (g.detector.host, g.detector.port, g.detector.unit_id)
    ):
        raise ConfigError(
            path,
            "goniometer.detector.unit_id",
            f"lamp and detector both address {g.lamp.host}:{g.lamp.port} unit {g.lamp.unit_id}",
        )


def register_checks(cfg: LabConfig, path: Path, profiles: dict[str, Any]) -> None:
    """Every register value an arm's settings produce must fit its register.

    The stepper driver (:mod:`drivers.modbus_stepper`) writes positions as
    ``round(deg x steps_per_deg x gear_ratio)`` into int32 registers, and speed and
    acceleration as ``round(value x steps_per_deg x gear_ratio x counts_per_step)`` into
    int32 (direct-data) or 16-bit (command-opcode) registers. A value that does not fit
    would end in a packing error in the middle of a run.
    """
    for name in ("lamp", "detector"):
        ax: AxisConfig = getattr(cfg.goniometer, name)
        prof = profiles[f"goniometer.{name}.profile"]
        where = f"goniometer.{name}"
        spd = ax.steps_per_deg * ax.gear_ratio
        how = f"{ax.steps_per_deg:g} steps/deg" + (
            f" x gear_ratio {ax.gear_ratio:g} = {spd:g} steps per arm degree"
            if ax.gear_ratio != 1.0
            else ""
        )
        if not math.isfinite(spd):
            raise ConfigError(path, f"{where}.steps_per_deg", f"{how} overflows")
        if 1.0 / spd > ax.stall_tolerance_deg:
            raise ConfigError(
                path,
                f"{where}.steps_per_deg",
                f"{how}: one step is {1.0 / spd:.4g} deg, coarser than stall_tolerance_deg "
                f"{ax.stall_tolerance_deg:g}: no position can be commanded or checked",
            )
        for label, limit_deg in zip(("lower", "upper"), ax.limits_deg, strict=True):
            steps = limit_deg * spd
            if not abs(steps) <= INT32_MAX:
                raise ConfigError(
                    path,
                    f"{where}.steps_per_deg",
                    f"{how} puts the {label} limit {limit_deg:g} deg at {steps:.4g} steps, "
                    f"beyond the int32 position register (-{INT32_MAX + 1}..{INT32_MAX})",
                )
        top = UINT16_MAX if prof.move_style == "command-opcode" else INT32_MAX
        for key, value, per_step, unit in (
            ("speed_deg_s", ax.speed_deg_s, prof.speed_counts_per_step_s, "deg/s"),
            ("accel_deg_s2", ax.accel_deg_s2, prof.accel_counts_per_step_s2, "deg/s^2"),
        ):
            counts = value * spd * per_step
            rounded = round(counts) if math.isfinite(counts) else counts
            if not 1 <= rounded <= top:
                raise ConfigError(
                    path,
                    f"{where}.{key}",
                    f"{value:g} {unit} at {spd:g} steps per arm degree gives {counts:.4g} "
                    f"counts in the {key.split('_')[0]} register of profile {prof.name!r}; "
                    f"must be 1..{top}",
                )


def exposure_check(cfg: LabConfig, path: Path, profile: Any) -> None:
    """``spectro.exposure_us`` within the range the spectro's profile accepts."""
    lo, hi = int(profile.exposure_min_us), int(profile.exposure_max_us)
    value = cfg.spectro.exposure_us
    if not lo <= value <= hi:
        raise ConfigError(
            path,
            "spectro.exposure_us",
            f"{value} us outside the range {lo}..{hi} us of profile {profile.name!r}",
        )
