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

Whatever would only fail at run time is refused at load:

* numbers are strict: TOML ``true`` is not 1 and ``1.5`` is not an integer (an integer is
  accepted where a float is expected);
* safety limits have a floor: ``min_separation_deg`` >= :data:`MIN_SEPARATION_FLOOR_DEG`
  (0 would switch the arm interlock off) and >= half the sum of the lamp and detector
  cones (closer, the detector would look into the lamp);
* every register value derived from an arm's settings fits its register with the arm's
  profile: positions ``limit_deg x steps_per_deg x gear_ratio`` in the int32 position
  register, speed and acceleration counts in theirs (int32, or 16 bits for a
  ``command-opcode`` drive), one step no coarser than ``stall_tolerance_deg``;
* homing can be planned from the park position (:func:`drivers.goniometer.plan_homing`:
  one arm must be able to stand clear of the other's home within its limits);
* ``spectro.exposure_us`` lies in the range of the spectro's profile;
* a file nested too deeply for the TOML parser is one error, not a RecursionError.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

import goniolab
from drivers.protocols import GLOSSMETERS, SPECTROS, STEPPERS, ProtocolTable
from drivers.toml_schema import TomlFileError, first_issue, read_toml
from goniolab.errors import ConfigError
from goniolab.model_registry import DEFAULT_MODEL, model_names

__all__ = [
    "INT32_MAX",
    "MIN_SEPARATION_FLOOR_DEG",
    "AlignmentConfig",
    "AxisConfig",
    "ColourConfig",
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
    "TwinConfig",
    "alignment_state_path",
    "configs_dir",
    "load_lab_config",
    "resolve_profile",
    "write_alignment",
    "write_alignment_state",
]


def configs_dir() -> Path:
    """The directory of the shipped configs (source checkout or installed wheel)."""
    here = Path(goniolab.__file__).resolve().parent
    for candidate in (here.parent / "configs", here / "_configs"):
        if candidate.is_dir():
            return candidate
    return here.parent / "configs"


#: Smallest ``min_separation_deg`` a config may set: 0 would switch the interlock off.
MIN_SEPARATION_FLOOR_DEG = 1.0
#: Largest value of a signed 32-bit register (positions, and speeds of direct-data drives).
INT32_MAX = 2**31 - 1
#: Largest value of a 16-bit register (speeds and accelerations of command-opcode drives).
UINT16_MAX = 0xFFFF


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)


# Numbers are strict (a TOML boolean is not a number, a float is not an integer); an
# integer is still accepted where a float is expected.
PositiveFloat = Annotated[float, Field(strict=True, gt=0.0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(strict=True, ge=0.0, allow_inf_nan=False)]
FiniteFloat = Annotated[float, Field(strict=True, allow_inf_nan=False)]
AngleOrNone = Annotated[float, Field(strict=True)] | None
#: A timeout or wait in seconds: positive, at most an hour (a longer one is a typo that
#: would hang a scan without a word).
TimeoutS = Annotated[float, Field(strict=True, gt=0.0, le=3600.0, allow_inf_nan=False)]
#: Following error tolerated before a move counts as stalled, deg: beyond 5 deg an arm
#: could be held by an obstacle (or the other arm, min_separation 10 deg) unnoticed, and
#: ``stall_tolerance_deg = 1e9`` switched stall detection off (issue 23, Low).
STALL_TOLERANCE_MAX_DEG = 5.0


def _known_protocol(table: ProtocolTable) -> AfterValidator:
    """A ``protocol`` key: a name in the device's protocol table (:mod:`drivers.protocols`,
    read when the file is validated, so a protocol registered since is known)."""

    def check(name: str) -> str:
        if name not in table:
            known = ", ".join(repr(n) for n in table.names())
            raise ValueError(f"unknown {table.device} protocol {name!r} (known: {known})")
        return name

    return AfterValidator(check)


def _protocol_profile(data: Any, table: ProtocolTable, default: str) -> Any:
    """A device section without ``profile`` gets the built-in profile of its protocol."""
    if isinstance(data, dict) and "profile" not in data:
        name = data.get("protocol", default)
        if isinstance(name, str) and name in table:
            return {**data, "profile": table[name].default_profile}
    return data


StepperProtocol = Annotated[str, Field(strict=True), _known_protocol(STEPPERS)]
SpectroProtocol = Annotated[str, Field(strict=True), _known_protocol(SPECTROS)]
GlossmeterProtocol = Annotated[str, Field(strict=True), _known_protocol(GLOSSMETERS)]


class LabSection(_Strict):
    """``[lab]``: name, mode, sim-server switch, clock scale, store file."""

    name: str = "goniolab lab"
    mode: Literal["sim", "drivers"] = "sim"
    start_sim_servers: bool = False
    time_scale: NonNegFloat = 1.0
    store: str = ""
    #: how long a scan waits for a lost instrument link (a controller or sim-server restart)
    reconnect_window_s: Annotated[float, Field(strict=False, ge=0.0, le=3600.0)] = 30.0

    @model_validator(mode="after")
    def _servers_need_drivers(self) -> LabSection:
        if self.start_sim_servers and self.mode != "drivers":
            raise ValueError('start_sim_servers = true needs mode = "drivers"')
        return self


class SampleConfig(_Strict):
    """``[sample]``: the height map (path or ``sample:NAME``), refractive index, and the
    reflectance model that predicts it (:func:`goniolab.model_cache.model_for`: a name of
    :mod:`goniolab.model_registry`, ``auto`` by default) with its optional wavelength
    (nm; unset: 550 nm for BRDF curves, ISO 2813 weighting for gloss). ``step_um`` is the
    lateral step of a map file that carries none (a ``.npy`` without sidecar; ``scan
    --step-um``)."""

    map: str = "sample:wittmann-3"
    n: Annotated[float, Field(strict=True, gt=1.0, lt=4.0, allow_inf_nan=False)] = 1.55
    model: str = DEFAULT_MODEL
    step_um: PositiveFloat | None = None
    wavelength_nm: (
        Annotated[float, Field(strict=True, ge=100.0, le=20000.0, allow_inf_nan=False)] | None
    ) = None

    @field_validator("map")
    @classmethod
    def _names_a_map(cls, v: str) -> str:
        if not v.strip():
            raise ValueError("empty: name a height-map file or sample:NAME")
        return v

    @field_validator("model")
    @classmethod
    def _registered_model(cls, v: str) -> str:
        names = [repr(name) for name in model_names()]
        if v not in model_names():
            raise ValueError(f"Input should be {', '.join(names[:-1])} or {names[-1]}")
        return v


class ParkConfig(_Strict):
    """Park geometry (degrees)."""

    theta_i_deg: FiniteFloat = 45.0
    theta_r_deg: FiniteFloat = 45.0


class AxisConfig(_Strict):
    """``[goniometer.lamp]`` / ``[goniometer.detector]``: one Modbus stepper arm."""

    protocol: StepperProtocol = "modbus"
    profile: str = "oriental-az"
    transport: Literal["tcp", "rtu"] = "tcp"
    host: str = "127.0.0.1"
    # 0 = any free port, picked when the lab serves its own simulated controllers
    port: Annotated[int, Field(strict=True, ge=0, le=65535)] = 5020
    unit_id: Annotated[int, Field(strict=True, ge=1, le=247)] = 1
    serial_port: str = ""
    baudrate: Annotated[int, Field(strict=True, ge=300, le=4_000_000)] = 115200
    parity: Literal["N", "E", "O"] = "E"
    steps_per_deg: PositiveFloat = 1000.0  # motor steps per degree of the motor shaft
    gear_ratio: PositiveFloat = 1.0  # motor turns per arm turn (1 = direct drive)
    limits_deg: tuple[FiniteFloat, FiniteFloat] = (0.0, 85.0)
    speed_deg_s: PositiveFloat = 20.0
    accel_deg_s2: PositiveFloat = 40.0
    stall_tolerance_deg: Annotated[
        float, Field(strict=True, gt=0.0, le=STALL_TOLERANCE_MAX_DEG, allow_inf_nan=False)
    ] = 0.5
    timeout_s: TimeoutS = 1.0

    @field_validator("limits_deg")
    @classmethod
    def _limits_increasing(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not lo < hi:
            raise ValueError(f"lower limit {lo:g} must be below upper limit {hi:g}")
        if lo < -180.0 or hi > 180.0:
            raise ValueError(f"limits must lie within [-180, 180] deg, got [{lo:g}, {hi:g}]")
        return v

    @model_validator(mode="before")
    @classmethod
    def _default_profile(cls, data: Any) -> Any:
        return _protocol_profile(data, STEPPERS, "modbus")

    @model_validator(mode="after")
    def _rtu_needs_port(self) -> AxisConfig:
        if self.transport == "rtu" and not self.serial_port:
            raise ValueError('transport = "rtu" needs serial_port (e.g. "/dev/ttyUSB0")')
        return self


class GoniometerConfig(_Strict):
    """``[goniometer]``: interlock, source cone, park, move timeout and the two arms."""

    min_separation_deg: FiniteFloat = 10.0
    source_cone_deg: Annotated[float, Field(strict=True, ge=0.0, lt=90.0)] = 6.0
    park: ParkConfig = ParkConfig()
    move_timeout_s: TimeoutS = 30.0
    lamp: AxisConfig = AxisConfig(unit_id=1, limits_deg=(0.0, 85.0))
    detector: AxisConfig = AxisConfig(unit_id=2, limits_deg=(-85.0, 85.0))

    @field_validator("min_separation_deg")
    @classmethod
    def _interlock_floor(cls, v: float) -> float:
        if v < MIN_SEPARATION_FLOOR_DEG:
            raise ValueError(
                f"{v:g} deg is below the floor {MIN_SEPARATION_FLOOR_DEG:g} deg: the arm "
                "interlock cannot be switched off"
            )
        return v


class SpectroConfig(_Strict):
    """``[spectro]``: STIL spectro-colorimeter on a serial port."""

    protocol: SpectroProtocol = "stil"
    profile: str = "stil-ruby"
    port: str = "/tmp/goniolab-sim/spectro"
    baudrate: Annotated[int, Field(strict=True, ge=300, le=4_000_000)] = 115200
    exposure_us: Annotated[int, Field(strict=True, ge=1)] = 10000
    detector_cone_deg: Annotated[float, Field(strict=True, ge=0.0, lt=90.0)] = 6.0
    timeout_s: TimeoutS = 2.0
    #: the certified standards (goniolab/scan/standards.py), relative to this file's
    #: directory, else the shipped configs/standards.toml
    standards: str = "standards.toml"
    #: a run warns when the newest `goniolab calibrate` record is older than this
    calibration_max_age_h: Annotated[float, Field(strict=False, gt=0.0)] = 24.0

    @model_validator(mode="before")
    @classmethod
    def _default_profile(cls, data: Any) -> Any:
        return _protocol_profile(data, SPECTROS, "stil")


class GlossmeterConfig(_Strict):
    """``[glossmeter]``: a glossmeter on a serial port; ``protocol`` is a name in
    :data:`drivers.protocols.GLOSSMETERS` (ZGM1120, a line-printing meter, ...), and
    ``profile`` defaults to that protocol's built-in profile."""

    protocol: GlossmeterProtocol = "zgm1120"
    profile: str = "zgm1120"
    port: str = "/tmp/goniolab-sim/gloss"
    serial_number: str = "401120999"
    baudrate: Annotated[int, Field(strict=True, ge=300, le=4_000_000)] = 9600
    timeout_s: TimeoutS = 2.0

    @model_validator(mode="before")
    @classmethod
    def _default_profile(cls, data: Any) -> Any:
        return _protocol_profile(data, GLOSSMETERS, "zgm1120")


class FaultsConfig(_Strict):
    """``[sim.faults]``: injected faults of the simulated lab (all off by default).

    The rates apply to each device named in ``devices``; stall and alarm positions are
    encoder angles of the lamp / detector arm (``nan`` or absent = none).
    ``disconnect_after`` cuts a device off for good after that many operations;
    ``disconnect_rate`` drops its link now and then, and it is back ``recover_after_s``
    seconds (lab clock) later (:mod:`sim.faults`).
    """

    devices: tuple[Literal["lamp", "detector", "spectro", "glossmeter"], ...] = ()
    timeout_rate: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] = 0.0
    garble_rate: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] = 0.0
    disconnect_after: Annotated[int, Field(strict=True, ge=0)] = 0
    disconnect_rate: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] = 0.0
    recover_after_s: Annotated[float, Field(strict=True, ge=0.0, le=3600.0)] = 0.5
    lamp_stall_at_deg: AngleOrNone = None
    detector_stall_at_deg: AngleOrNone = None
    lamp_alarm_at_deg: AngleOrNone = None
    detector_alarm_at_deg: AngleOrNone = None
    alarm_code: Annotated[int, Field(strict=True, ge=1, le=0xFFFF)] = 0x30

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


class TwinConfig(_Strict):
    """``[sim.twin]``: the digital twin's own truth and instruments (sim/truth.py,
    sim/instruments.py; docs/TWIN.md).

    ``mode = "realistic"`` (default): the simulated instruments measure a hidden true
    surface (finer than the map, with sub-resolution roughness and spot-scale waviness)
    by scalar Kirchhoff optics, through a spectro with lamp spectrum, detector response,
    dark current, shot noise, saturation and stray light, on arms with backlash and zero
    offsets, with a sample tilt drawn per session, and a drifting glossmeter.
    ``mode = "ideal"``: the instruments read the prediction's own model with only
    ``[sim] noise_pct`` noise and the fixed ``[sim]`` misalignments (tests of plumbing).
    """

    mode: Literal["realistic", "ideal"] = "realistic"
    # the truth (sim/truth.py)
    step_um: Annotated[float, Field(strict=True, ge=0.05, le=1.0)] = 0.25
    subres_rq_nm: Annotated[float, Field(strict=True, ge=0.0, le=50.0)] = 4.0
    subres_corr_um: Annotated[float, Field(strict=True, gt=0.0, le=5.0)] = 0.3
    profilometer_noise_nm: Annotated[float, Field(strict=True, ge=0.0, le=50.0)] = 2.0
    waviness_slope_rms: Annotated[float, Field(strict=True, ge=0.0, le=0.02)] = 3e-4
    body: Literal["black", "white", "grey", "red", "blue"] = "black"
    cache: bool = True
    # the spectro (sim/instruments.py, SpectroChain)
    lamp: Literal["halogen", "led"] = "halogen"
    full_scale_pct: Annotated[float, Field(strict=True, gt=0.0, le=100.0)] = 5.0
    dark_counts_per_s: Annotated[float, Field(strict=True, ge=0.0, le=1e5)] = 300.0
    read_noise_counts: Annotated[float, Field(strict=True, ge=0.0, le=1000.0)] = 5.0
    stray_pct: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] = 0.002
    flicker_pct: Annotated[float, Field(strict=True, ge=0.0, le=10.0)] = 0.3
    # share of the spectro's response to s-polarised light (0.5: insensitive); 0.51 is a
    # 2 % polarisation dependence, a fibre-fed grating spectrometer's few % (sim/spectro_chain.py)
    s_weight: Annotated[float, Field(strict=True, ge=0.4, le=0.6)] = 0.51
    # the arms and the sample seating, drawn per session (uniform in +/- range)
    backlash_deg: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] = 0.02
    lamp_zero_range_deg: Annotated[float, Field(strict=True, ge=0.0, le=5.0)] = 0.5
    detector_zero_range_deg: Annotated[float, Field(strict=True, ge=0.0, le=5.0)] = 0.5
    sample_tilt_range_deg: Annotated[float, Field(strict=True, ge=0.0, le=5.0)] = 0.5
    # the glossmeter (sim/instruments.py, GlossDrift)
    gloss_drift_pct_per_h: Annotated[float, Field(strict=True, ge=-10.0, le=10.0)] = 0.5
    gloss_temp_coeff_pct_per_c: Annotated[float, Field(strict=True, ge=-2.0, le=2.0)] = 0.05
    gloss_warmup_c: Annotated[float, Field(strict=True, ge=0.0, le=20.0)] = 4.0
    gloss_noise_gu: Annotated[float, Field(strict=True, ge=0.0, le=5.0)] = 0.1


class SimConfig(_Strict):
    """``[sim]``: seed, noise and misalignments of the simulated lab."""

    seed: Annotated[int, Field(strict=True, ge=0)] = 1
    noise_pct: Annotated[float, Field(strict=True, ge=0.0, le=50.0)] = 0.5
    sample_tilt_deg: Annotated[float, Field(strict=True, ge=-10.0, le=10.0)] = 0.0
    lamp_zero_offset_deg: Annotated[float, Field(strict=True, ge=-10.0, le=10.0)] = 0.0
    detector_zero_offset_deg: Annotated[float, Field(strict=True, ge=-10.0, le=10.0)] = 0.0
    gloss_autosend_s: NonNegFloat = 0.0
    faults: FaultsConfig = FaultsConfig()
    twin: TwinConfig = TwinConfig()


class ColourConfig(_Strict):
    """``[colour]``: how every spectro reading becomes colour (ASTM E308, CIE 15).

    ``scale = "diffuser"`` reports reflectance factors relative to the perfect reflecting
    diffuser (what multi-angle spectrophotometers report; the reading divided by
    ``sin^2(a_d) cos(theta_r)``), ``"mirror"`` the spectrum as measured (% of the mirror).
    """

    illuminant: str = "D65"
    observer: str = "CIE 1964 10 Degree Standard Observer"
    method: Literal["ASTM E308", "Integration"] = "ASTM E308"
    scale: Literal["diffuser", "mirror"] = "diffuser"

    @field_validator("observer")
    @classmethod
    def _known_observer(cls, v: str) -> str:
        from goniolab.colour.spectra import OBSERVERS

        if v not in OBSERVERS:
            raise ValueError(
                f"unknown observer {v!r} (CIE 1964 10 Degree Standard Observer, "
                "CIE 1931 2 Degree Standard Observer, or 10 / 2)"
            )
        return OBSERVERS[v]

    @field_validator("illuminant")
    @classmethod
    def _known_illuminant(cls, v: str) -> str:
        # only a non-default value gets here (pydantic skips defaults); the usual names are
        # known without importing colour-science (seconds), the rest are checked by it
        from goniolab.colour.spectra import (
            COMMON_ILLUMINANTS,
            ColourError,
            ColourSettings,
            resolve_illuminant,
        )

        v = resolve_illuminant(v)  # F11 / TL84 -> FL11 (the name colour-science knows)
        if v in COMMON_ILLUMINANTS:
            return v

        try:
            ColourSettings(illuminant=v).validated()
        except ColourError as exc:
            raise ValueError(str(exc)) from None
        return v


class AlignmentConfig(_Strict):
    """``[alignment]``: what ``goniolab scan --plan align`` found (it writes this table).

    The sample sees ``theta_i = lamp + lamp_zero_deg + sample_tilt_deg`` and
    ``theta_r = detector + detector_zero_deg - sample_tilt_deg``; every move is corrected
    so that it sees the requested angles (:class:`drivers.goniometer.TwoArmGoniometer`
    ``corrections_deg``). The tilt belongs to the sample's seating: align again after
    placing another sample.
    """

    lamp_zero_deg: Annotated[float, Field(strict=True, ge=-5.0, le=5.0)] = 0.0
    detector_zero_deg: Annotated[float, Field(strict=True, ge=-5.0, le=5.0)] = 0.0
    sample_tilt_deg: Annotated[float, Field(strict=True, ge=-5.0, le=5.0)] = 0.0
    run: Annotated[int, Field(strict=True, ge=0)] = 0
    #: Where ``scan --plan align`` keeps its result (a per-lab state file, never the tracked
    #: config): relative to the config's directory; "" = beside the store
    #: (:func:`alignment_state_path`). Its values replace the three above when it exists.
    state_file: str = ""
    #: Set by the loader: the state file the values came from ("" = this config).
    loaded_from: str = ""

    def corrections_deg(self) -> tuple[float, float]:
        """``(lamp, detector)`` added to requested angles before the arms move."""
        return (
            -(self.lamp_zero_deg + self.sample_tilt_deg),
            -(self.detector_zero_deg - self.sample_tilt_deg),
        )


class RunSection(_Strict):
    """``[run]``: what every run started with this config records about itself unless the
    command says otherwise (``scan --operator/--sample-id/--note/--tag``): who measures,
    the physical sample's id (a label, a LIMS number), notes and tags."""

    operator: str = ""
    sample_id: str = ""
    notes: str = ""
    tags: tuple[str, ...] = ()


class LabConfig(_Strict):
    """A whole lab config file (docs/ARCHITECTURE.md, "Lab config")."""

    lab: LabSection = LabSection()
    sample: SampleConfig = SampleConfig()
    goniometer: GoniometerConfig = GoniometerConfig()
    spectro: SpectroConfig = SpectroConfig()
    glossmeter: GlossmeterConfig = GlossmeterConfig()
    sim: SimConfig = SimConfig()
    colour: ColourConfig = ColourConfig()
    alignment: AlignmentConfig = AlignmentConfig()
    run: RunSection = RunSection()
    #: The file this config came from ("" when built in code).
    source: str = Field(default="", exclude=True)

    def sample_map(self) -> str:
        """``[sample] map``, with a relative file path taken relative to the config file."""
        spec = self.sample.map
        if spec.startswith("sample:") or not self.source:
            return spec
        p = Path(spec).expanduser()
        if not p.is_absolute():
            candidate = Path(self.source).resolve().parent / p
            if candidate.exists():
                return str(candidate)
        return spec


# --------------------------------------------------------------------------- loading
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
        key, reason = first_issue(exc)
        raise ConfigError(p, key, reason + did_you_mean_key(key, reason)) from None
    except RecursionError:
        raise ConfigError(p, "", TOO_DEEP) from None
    _cross_checks(cfg, p)
    cfg, profiles = _resolve_profiles(cfg, p)
    _register_checks(cfg, p, profiles)
    _exposure_check(cfg, p, profiles["spectro.profile"])
    return _with_alignment_state(cfg)


def did_you_mean_key(key: str, reason: str) -> str:
    """``"; did you mean 'time_scale'?"`` for an unknown ``key`` close to a field of its
    table in :class:`LabConfig` (difflib), else ``""`` (issue 27: config key typos)."""
    import difflib
    import typing

    if not key or "unknown key" not in reason:
        return ""
    *tables, name = key.split(".")
    model: Any = LabConfig
    for part in tables:
        field = model.model_fields.get(part)
        if field is None:
            return ""
        inner = [
            t
            for t in (field.annotation, *typing.get_args(field.annotation))
            if isinstance(t, type) and issubclass(t, BaseModel)
        ]
        if not inner:  # a free-form table (dict): no fixed names to suggest
            return ""
        model = inner[0]
    names = [n for n in model.model_fields if n != "source"]
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


#: The reason given for a TOML file nested deeper than the parser's recursion allows.
TOO_DEEP = "arrays or tables nested too deeply to be a lab config"


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


def _resolve_profiles(cfg: LabConfig, path: Path) -> tuple[LabConfig, dict[str, Any]]:
    """Load every profile the config names; the config with resolved paths, and the
    loaded profiles by config key."""
    from drivers.base import ProfileError  # drivers never import goniolab: this way is allowed

    base = path.resolve().parent
    resolved: dict[str, str] = {}
    loaded: dict[str, Any] = {}
    g = cfg.goniometer
    # each profile is read by the protocol that speaks it (drivers.protocols)
    keys = (
        ("goniometer.lamp.profile", STEPPERS[g.lamp.protocol]),
        ("goniometer.detector.profile", STEPPERS[g.detector.protocol]),
        ("spectro.profile", SPECTROS[cfg.spectro.protocol]),
        ("glossmeter.profile", GLOSSMETERS[cfg.glossmeter.protocol]),
    )
    for key, entry in keys:
        name = _get(cfg.model_dump(), key)
        target = resolve_profile(str(name), relative_to=base)
        try:
            loaded[key] = entry.load_profile(target)
        except ProfileError as exc:
            reason = str(exc)
            if "key 'kind'" in reason:
                reason = f"profile {target} is not a {entry.profile_kind!r} profile ({reason})"
            raise ConfigError(path, key, reason) from None
        resolved[key] = str(target)
    resolved_cfg = cfg.model_copy(
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
    return resolved_cfg, loaded


def _register_checks(cfg: LabConfig, path: Path, profiles: dict[str, Any]) -> None:
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


def _exposure_check(cfg: LabConfig, path: Path, profile: Any) -> None:
    """``spectro.exposure_us`` within the range the spectro's profile accepts."""
    lo, hi = int(profile.exposure_min_us), int(profile.exposure_max_us)
    value = cfg.spectro.exposure_us
    if not lo <= value <= hi:
        raise ConfigError(
            path,
            "spectro.exposure_us",
            f"{value} us outside the range {lo}..{hi} us of profile {profile.name!r}",
        )


def write_alignment(path: str | Path, values: dict[str, float | int], *, note: str = "") -> None:
    """Write (or replace) the ``[alignment]`` table of a lab config file.

    The rest of the file, comments included, is kept byte for byte; the table goes at the
    end (an existing ``[alignment]`` table, up to the next table header, is removed
    first). The result is validated before the file is replaced (atomically).

    Raises
    ------
    ConfigError
        The file cannot be read or written, or the values are out of range.
    """
    import re

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(p, "alignment", f"cannot read the config to write it: {exc}") from None
    text = re.sub(r"(?ms)^\[alignment\][^\n]*\n(?:(?!^\[).*?\n)*", "", text)
    if not text.endswith("\n"):
        text += "\n"
    lines = [f"[alignment]{'  # ' + note if note else ''}"]
    for key, value in values.items():
        lines.append(f"{key} = {value:.4f}" if isinstance(value, float) else f"{key} = {value}")
    new = text.rstrip("\n") + "\n\n" + "\n".join(lines) + "\n"
    try:
        AlignmentConfig.model_validate(values)
    except ValidationError as exc:
        key, reason = first_issue(exc)
        raise ConfigError(p, f"alignment.{key}", reason) from None
    _replace_text(p, new, key="alignment")


# --------------------------------------------------------------------------- alignment state
#: The keys an alignment state file carries in its ``[alignment]`` table.
_STATE_KEYS = ("lamp_zero_deg", "detector_zero_deg", "sample_tilt_deg", "run")


def alignment_state_path(cfg: LabConfig) -> Path:
    """The per-lab alignment state file of a config (issue 22: never the tracked config).

    ``[alignment] state_file`` relative to the config's directory when set; otherwise
    ``<config stem>.alignment.toml`` beside the store (``[lab] store``: its directory for an
    SQLite file, resolved against the config's directory; the user data directory for the
    default store or a PostgreSQL one).
    """
    import platformdirs

    base = Path(cfg.source).resolve().parent if cfg.source else Path.cwd()
    if cfg.alignment.state_file:
        p = Path(cfg.alignment.state_file).expanduser()
        return p if p.is_absolute() else base / p
    stem = Path(cfg.source).stem if cfg.source else "lab"
    store = cfg.lab.store
    if store and "://" not in store and "=" not in store:
        sp = Path(store).expanduser()
        return (sp if sp.is_absolute() else base / sp).parent / f"{stem}.alignment.toml"
    return Path(platformdirs.user_data_dir("goniolab", appauthor=False)) / f"{stem}.alignment.toml"


def _with_alignment_state(cfg: LabConfig) -> LabConfig:
    """``cfg`` with the values of its alignment state file (if there is one), which cites it.

    Raises
    ------
    ConfigError
        The state file exists but is unreadable or holds out-of-range values (naming it).
    """
    path = alignment_state_path(cfg)
    if not path.is_file():
        return cfg
    try:
        data = read_toml(path, what="alignment state file")
    except TomlFileError as exc:
        raise ConfigError(path, "", exc.reason) from None
    table = data.get("alignment")
    if not isinstance(table, dict):
        raise ConfigError(path, "alignment", "the state file has no [alignment] table")
    values = {k: table[k] for k in _STATE_KEYS if k in table}
    try:
        AlignmentConfig.model_validate(values)
    except ValidationError as exc:
        key, reason = first_issue(exc)
        raise ConfigError(path, f"alignment.{key}", reason) from None
    update = {**values, "loaded_from": str(path)}
    return cfg.model_copy(update={"alignment": cfg.alignment.model_copy(update=update)})


def write_alignment_state(
    cfg: LabConfig, values: dict[str, float | int], *, note: str = ""
) -> Path:
    """Write the alignment result to the config's state file (:func:`alignment_state_path`);
    the config file itself is not touched. Validated first; written atomically (a temp file
    beside it, then ``os.replace``), an existing file's mode kept. Returns the path.

    Raises
    ------
    ConfigError
        Out-of-range values (nothing written) or the file cannot be written.
    """

    path = alignment_state_path(cfg)
    try:
        AlignmentConfig.model_validate(values)
    except ValidationError as exc:
        key, reason = first_issue(exc)
        raise ConfigError(path, f"alignment.{key}", reason) from None
    lines = [
        "# goniolab alignment state: written by `goniolab scan --plan align`, read with the",
        f"# lab config {Path(cfg.source).resolve() if cfg.source else '(none)'}. Not a config.",
    ]
    if note:
        lines.append(f"# {note}")
    lines.append("[alignment]")
    for key, value in values.items():
        lines.append(f"{key} = {value:.4f}" if isinstance(value, float) else f"{key} = {value}")
    _replace_text(path, "\n".join(lines) + "\n", key="alignment")
    return path


def _replace_text(path: Path, text: str, *, key: str) -> None:
    """Replace ``path``'s content atomically, keeping what the file is: a symlink's target is
    replaced (the link stays), and the mode (and owner, where permitted) of an existing file
    are kept (issue 23: a config holding a password must not become world-readable)."""
    import contextlib
    import os

    target = path.resolve() if path.is_symlink() else path
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        st = target.stat() if target.exists() else None
        tmp = target.with_name(target.name + f".{os.getpid()}.tmp")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        if st is not None:
            os.chmod(tmp, st.st_mode & 0o7777)
            with contextlib.suppress(OSError, AttributeError):
                os.chown(tmp, st.st_uid, st.st_gid)
        else:
            os.chmod(tmp, 0o644)
        os.replace(tmp, target)
    except OSError as exc:
        raise ConfigError(path, key, f"cannot write {path}: {exc}") from None
