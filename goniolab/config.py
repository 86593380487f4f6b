"""Lab configuration: the ``configs/lab-*.toml`` files as validated pydantic models.

``load_lab_config(path)`` reads a TOML file into a :class:`LabConfig` (schema in
docs/ARCHITECTURE.md). Unknown keys are errors (``extra="forbid"``): a typo must not fall
back to a default silently. Every problem raises :class:`ConfigError`, a
:class:`goniolab.errors.UserError` whose one-line message names the FILE, the dotted KEY
and the REASON, for example::

    configs/x.toml: goniometer.lamp.limits_deg: lower limit 10 must be below upper limit 5

TOML syntax errors carry the line and column. Reading the file and naming the key of a
pydantic error are shared with the device profiles (:mod:`drivers.toml_schema`). Device profile names (``"oriental-az"``)
are resolved against the ``configs/profiles`` directory found next to the package source
(``Path(goniolab.__file__).parents[1] / "configs"``) or, in an installed wheel,
``goniolab/_configs``; relative profile paths are tried next to the config file first.
Each profile is loaded once at config time so that a bad profile is reported against the
config key that names it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

import goniolab
from drivers.toml_schema import TomlFileError, first_issue, read_toml
from goniolab.errors import UserError

__all__ = [
    "AxisConfig",
    "ConfigError",
    "FaultsConfig",
    "GlossmeterConfig",
    "GoniometerConfig",
    "LabConfig",
    "LabSection",
    "ParkConfig",
    "SampleConfig",
    "SimConfig",
    "SpectroConfig",
    "configs_dir",
    "load_lab_config",
    "resolve_profile",
]


class ConfigError(UserError):
    """A lab config file is unreadable or invalid; the message names file, key and reason."""

    def __init__(self, path: str | Path, key: str, reason: str) -> None:
        self.path = str(path)
        self.key = key
        self.reason = reason
        where = f"{self.path}: {key}: " if key else f"{self.path}: "
        super().__init__(where + reason, exit_code=2)


def configs_dir() -> Path:
    """The directory of the shipped configs (source checkout or installed wheel)."""
    here = Path(goniolab.__file__).resolve().parent
    for candidate in (here.parent / "configs", here / "_configs"):
        if candidate.is_dir():
            return candidate
    return here.parent / "configs"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)


PositiveFloat = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class LabSection(_Strict):
    """``[lab]``: name, mode, sim-server switch, clock scale, store file."""

    name: str = "goniolab lab"
    mode: Literal["sim", "drivers"] = "sim"
    start_sim_servers: bool = False
    time_scale: NonNegFloat = 1.0
    store: str = ""

    @model_validator(mode="after")
    def _servers_need_drivers(self) -> LabSection:
        if self.start_sim_servers and self.mode != "drivers":
            raise ValueError('start_sim_servers = true needs mode = "drivers"')
        return self


class SampleConfig(_Strict):
    """``[sample]``: the height map (path or ``sample:NAME``) and refractive index."""

    map: str = "sample:wittmann-3"
    n: Annotated[float, Field(gt=1.0, lt=4.0, allow_inf_nan=False)] = 1.55


class ParkConfig(_Strict):
    """Park geometry (degrees)."""

    theta_i_deg: FiniteFloat = 45.0
    theta_r_deg: FiniteFloat = 45.0


class AxisConfig(_Strict):
    """``[goniometer.lamp]`` / ``[goniometer.detector]``: one Modbus stepper arm."""

    profile: str = "oriental-az"
    transport: Literal["tcp", "rtu"] = "tcp"
    host: str = "127.0.0.1"
    # 0 = any free port, picked when the lab serves its own simulated controllers
    port: Annotated[int, Field(ge=0, le=65535)] = 5020
    unit_id: Annotated[int, Field(ge=1, le=247)] = 1
    serial_port: str = ""
    baudrate: Annotated[int, Field(ge=300, le=4_000_000)] = 115200
    parity: Literal["N", "E", "O"] = "E"
    steps_per_deg: PositiveFloat = 1000.0  # motor steps per degree of the motor shaft
    gear_ratio: PositiveFloat = 1.0  # motor turns per arm turn (1 = direct drive)
    limits_deg: tuple[FiniteFloat, FiniteFloat] = (0.0, 85.0)
    speed_deg_s: PositiveFloat = 20.0
    accel_deg_s2: PositiveFloat = 40.0
    stall_tolerance_deg: PositiveFloat = 0.5
    timeout_s: PositiveFloat = 1.0

    @field_validator("limits_deg")
    @classmethod
    def _limits_increasing(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not lo < hi:
            raise ValueError(f"lower limit {lo:g} must be below upper limit {hi:g}")
        if lo < -180.0 or hi > 180.0:
            raise ValueError(f"limits must lie within [-180, 180] deg, got [{lo:g}, {hi:g}]")
        return v

    @model_validator(mode="after")
    def _rtu_needs_port(self) -> AxisConfig:
        if self.transport == "rtu" and not self.serial_port:
            raise ValueError('transport = "rtu" needs serial_port (e.g. "/dev/ttyUSB0")')
        return self


class GoniometerConfig(_Strict):
    """``[goniometer]``: interlock, source cone, park, move timeout and the two arms."""

    min_separation_deg: NonNegFloat = 10.0
    source_cone_deg: Annotated[float, Field(ge=0.0, lt=90.0)] = 6.0
    park: ParkConfig = ParkConfig()
    move_timeout_s: PositiveFloat = 30.0
    lamp: AxisConfig = AxisConfig(unit_id=1, limits_deg=(0.0, 85.0))
    detector: AxisConfig = AxisConfig(unit_id=2, limits_deg=(-85.0, 85.0))


class SpectroConfig(_Strict):
    """``[spectro]``: STIL spectro-colorimeter on a serial port."""

    profile: str = "stil-ruby"
    port: str = "/tmp/goniolab-sim/spectro"
    baudrate: Annotated[int, Field(ge=300, le=4_000_000)] = 115200
    exposure_us: Annotated[int, Field(ge=1)] = 10000
    detector_cone_deg: Annotated[float, Field(ge=0.0, lt=90.0)] = 6.0
    timeout_s: PositiveFloat = 2.0


class GlossmeterConfig(_Strict):
    """``[glossmeter]``: ZGM1120 (or a line-printing meter) on a serial port."""

    protocol: Literal["zgm1120", "line"] = "zgm1120"
    profile: str = "zgm1120"
    port: str = "/tmp/goniolab-sim/gloss"
    serial_number: str = "401120999"
    baudrate: Annotated[int, Field(ge=300, le=4_000_000)] = 9600
    timeout_s: PositiveFloat = 2.0


class FaultsConfig(_Strict):
    """``[sim.faults]``: injected faults of the simulated lab (all off by default).

    The rates apply to each device named in ``devices``; stall and alarm positions are
    encoder angles of the lamp / detector arm (``nan`` or absent = none).
    ``disconnect_after`` cuts a device off for good after that many operations;
    ``disconnect_rate`` drops its link now and then, and it is back ``recover_after_s``
    seconds (lab clock) later (:mod:`sim.faults`).
    """

    devices: tuple[Literal["lamp", "detector", "spectro", "glossmeter"], ...] = ()
    timeout_rate: Annotated[float, Field(ge=0.0, le=1.0)] = 0.0
    garble_rate: Annotated[float, Field(ge=0.0, le=1.0)] = 0.0
    disconnect_after: Annotated[int, Field(ge=0)] = 0
    disconnect_rate: Annotated[float, Field(ge=0.0, le=1.0)] = 0.0
    recover_after_s: Annotated[float, Field(ge=0.0, le=3600.0)] = 0.5
    lamp_stall_at_deg: float | None = None
    detector_stall_at_deg: float | None = None
    lamp_alarm_at_deg: float | None = None
    detector_alarm_at_deg: float | None = None
    alarm_code: Annotated[int, Field(ge=1, le=0xFFFF)] = 0x30

    @model_validator(mode="after")
    def _rates_sum_to_at_most_one(self) -> FaultsConfig:
        total = self.timeout_rate + self.garble_rate + self.disconnect_rate
        if total > 1.0:
            raise ValueError(
                f"timeout_rate + garble_rate + disconnect_rate must be <= 1, got {total:g}"
            )
        return self

    @field_validator(
        "lamp_stall_at_deg", "detector_stall_at_deg", "lamp_alarm_at_deg", "detector_alarm_at_deg"
    )
    @classmethod
    def _nan_is_none(cls, v: float | None) -> float | None:
        if v is None or math.isnan(v):
            return None
        if math.isinf(v):
            raise ValueError("must be a finite angle")
        return v


class SimConfig(_Strict):
    """``[sim]``: seed, noise and misalignments of the simulated lab."""

    seed: Annotated[int, Field(ge=0)] = 1
    noise_pct: Annotated[float, Field(ge=0.0, le=50.0)] = 0.5
    sample_tilt_deg: Annotated[float, Field(ge=-10.0, le=10.0)] = 0.0
    lamp_zero_offset_deg: Annotated[float, Field(ge=-10.0, le=10.0)] = 0.0
    detector_zero_offset_deg: Annotated[float, Field(ge=-10.0, le=10.0)] = 0.0
    gloss_autosend_s: NonNegFloat = 0.0
    faults: FaultsConfig = FaultsConfig()


class LabConfig(_Strict):
    """A whole lab config file (docs/ARCHITECTURE.md, "Lab config")."""

    lab: LabSection = LabSection()
    sample: SampleConfig = SampleConfig()
    goniometer: GoniometerConfig = GoniometerConfig()
    spectro: SpectroConfig = SpectroConfig()
    glossmeter: GlossmeterConfig = GlossmeterConfig()
    sim: SimConfig = SimConfig()
    #: The file this config came from ("" when built in code).
    source: str = Field(default="", exclude=True)


# --------------------------------------------------------------------------- loading
_PROFILE_KEYS: tuple[tuple[str, str, str], ...] = (
    ("goniometer.lamp.profile", "modbus-stepper", "load_stepper_profile"),
    ("goniometer.detector.profile", "modbus-stepper", "load_stepper_profile"),
    ("spectro.profile", "stil-spectro", "load_stil_profile"),
)


def resolve_profile(name: str, *, relative_to: Path | None = None) -> Path:
    """The file a profile name or path refers to.

    A bare name (``"oriental-az"``) is ``configs/profiles/NAME.toml``; a relative path is
    tried next to the config file (``relative_to``), then under the configs directory.
    """
    if "/" not in name and "\\" not in name and not name.endswith(".toml"):
        return configs_dir() / "profiles" / f"{name}.toml"
    p = Path(name).expanduser()
    if p.is_absolute():
        return p
    if relative_to is not None and (relative_to / p).is_file():
        return relative_to / p
    return configs_dir() / p


def _get(data: dict[str, Any], dotted: str) -> Any:
    node: Any = data
    for part in dotted.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    return node


def load_lab_config(path: str | Path) -> LabConfig:
    """Read and validate a lab config file.

    Parameters
    ----------
    path
        The TOML file.

    Returns
    -------
    LabConfig
        With profile names replaced by the resolved profile file paths.

    Raises
    ------
    ConfigError
        Missing/unreadable file, TOML syntax error (line and column), unknown key, wrong
        type, out-of-range value or bad device profile; the message names the file, the
        dotted key and the reason.
    """
    p = Path(path)
    try:
        data = read_toml(p, what="config file")
    except TomlFileError as exc:
        raise ConfigError(p, "", exc.reason) from None
    if "source" in data:
        raise ConfigError(p, "source", "unknown key (typo?)")
    try:
        cfg = LabConfig.model_validate({**data, "source": str(p)})
    except ValidationError as exc:
        raise ConfigError(p, *first_issue(exc)) from None
    _cross_checks(cfg, p)
    return _resolve_profiles(cfg, p, data)


def _cross_checks(cfg: LabConfig, path: Path) -> None:
    """Checks that span several keys, reported against the key a user would edit."""
    g = cfg.goniometer
    for key, value, arm in (
        ("goniometer.park.theta_i_deg", g.park.theta_i_deg, g.lamp),
        ("goniometer.park.theta_r_deg", g.park.theta_r_deg, g.detector),
    ):
        lo, hi = arm.limits_deg
        if not lo <= value <= hi:
            raise ConfigError(
                path, key, f"{value:g} deg outside the arm limits [{lo:g}, {hi:g}] deg"
            )
    sep = abs(g.park.theta_i_deg + g.park.theta_r_deg)
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


def _resolve_profiles(cfg: LabConfig, path: Path, data: dict[str, Any]) -> LabConfig:
    import drivers.profiles as dp  # drivers never import goniolab: this direction is allowed
    from drivers.base import ProfileError

    base = path.resolve().parent
    resolved: dict[str, str] = {}
    keys = list(_PROFILE_KEYS)
    if cfg.glossmeter.protocol == "zgm1120":
        keys.append(("glossmeter.profile", "zgm1120", "load_zgm_profile"))
    else:
        keys.append(("glossmeter.profile", "line-gloss", "load_line_gloss_profile"))
    for key, kind, loader in keys:
        name = _get(cfg.model_dump(), key)
        target = resolve_profile(str(name), relative_to=base)
        try:
            getattr(dp, loader)(target)
        except ProfileError as exc:
            reason = str(exc)
            if "key 'kind'" in reason:
                reason = f"profile {target} is not a {kind!r} profile ({reason})"
            raise ConfigError(path, key, reason) from None
        resolved[key] = str(target)
    g = cfg.goniometer
    return cfg.model_copy(
        update={
            "goniometer": g.model_copy(
                update={
                    "lamp": g.lamp.model_copy(
                        update={"profile": resolved["goniometer.lamp.profile"]}
                    ),
                    "detector": g.detector.model_copy(
                        update={"profile": resolved["goniometer.detector.profile"]}
                    ),
                }
            ),
            "spectro": cfg.spectro.model_copy(update={"profile": resolved["spectro.profile"]}),
            "glossmeter": cfg.glossmeter.model_copy(
                update={"profile": resolved["glossmeter.profile"]}
            ),
        }
    )
