"""The sections of a lab config file (``[lab]``, ``[sample]``, ``[goniometer]``, ...) as
strict pydantic models, and :class:`LabConfig`, the whole file.

Numbers are strict (a TOML boolean is not a number, a float is not an integer; an integer
is accepted where a float is expected) and unknown keys are errors (``extra="forbid"``).
Checks that span several sections, and those that need a device profile, are made by the
loader (:mod:`goniolab.config.checks`).
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
    field_validator,
    model_validator,
)

from drivers.arm_limits import (
    DEFAULT_MIN_SEPARATION_DEG,
    DETECTOR_LIMITS_DEG,
    LAMP_LIMITS_DEG,
    limits_problem,
    separation_floor_problem,
)
from drivers.protocols import GLOSSMETERS, SPECTROS, STEPPERS, ProtocolTable
from goniolab.model_registry import DEFAULT_MODEL, model_names


class StrictSection(BaseModel):
    """A config table: unknown keys are errors, instances are frozen."""

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


class LabSection(StrictSection):
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


class SampleConfig(StrictSection):
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


class ParkConfig(StrictSection):
    """Park geometry (degrees)."""

    theta_i_deg: FiniteFloat = 45.0
    theta_r_deg: FiniteFloat = 45.0


class AxisConfig(StrictSection):
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
    limits_deg: tuple[FiniteFloat, FiniteFloat] = LAMP_LIMITS_DEG
    speed_deg_s: PositiveFloat = 20.0
    accel_deg_s2: PositiveFloat = 40.0
    stall_tolerance_deg: Annotated[
        float, Field(strict=True, gt=0.0, le=STALL_TOLERANCE_MAX_DEG, allow_inf_nan=False)
    ] = 0.5
    timeout_s: TimeoutS = 1.0

    @field_validator("limits_deg")
    @classmethod
    def _limits_increasing(cls, v: tuple[float, float]) -> tuple[float, float]:
        problem = limits_problem(v)  # drivers.arm_limits: the one place of the limits
        if problem:
            raise ValueError(problem)
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


class GoniometerConfig(StrictSection):
    """``[goniometer]``: interlock, source cone, park, move timeout and the two arms."""

    min_separation_deg: FiniteFloat = DEFAULT_MIN_SEPARATION_DEG
    source_cone_deg: Annotated[float, Field(strict=True, ge=0.0, lt=90.0)] = 6.0
    park: ParkConfig = ParkConfig()
    move_timeout_s: TimeoutS = 30.0
    lamp: AxisConfig = AxisConfig(unit_id=1, limits_deg=LAMP_LIMITS_DEG)
    detector: AxisConfig = AxisConfig(unit_id=2, limits_deg=DETECTOR_LIMITS_DEG)

    @field_validator("min_separation_deg")
    @classmethod
    def _interlock_floor(cls, v: float) -> float:
        problem = separation_floor_problem(v)  # drivers.arm_limits, as the driver checks
        if problem:
            raise ValueError(problem)
        return v


class SpectroConfig(StrictSection):
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
    #: a run warns when the newest `goniolab calibrate` record is older than this (h; a
    #: number, ``inf`` = never)
    calibration_max_age_h: Annotated[float, Field(strict=True, gt=0.0)] = 24.0

    @model_validator(mode="before")
    @classmethod
    def _default_profile(cls, data: Any) -> Any:
        return _protocol_profile(data, SPECTROS, "stil")


class GlossmeterConfig(StrictSection):
    """``[glossmeter]``: a glossmeter on a serial port; ``protocol`` is a name in
    :data:`drivers.protocols.GLOSSMETERS` (ZGM1120, a line-printing meter, ...), and
    ``profile`` defaults to that protocol's built-in profile."""

    protocol: GlossmeterProtocol = "zgm1120"
    profile: str = "zgm1120"
    port: str = "/tmp/goniolab-sim/gloss"
    serial_number: str = "401120999"
    baudrate: Annotated[int, Field(strict=True, ge=300, le=4_000_000)] = 9600
    timeout_s: TimeoutS = 2.0
    #: a gloss run (``goniolab gloss log``, the TUI's log) warns when the meter's newest
    #: ``goniolab gloss calibrate`` record is older than this (h, the lab's rule; ``inf`` =
    #: never, as for ``[spectro]``)
    calibration_max_age_h: Annotated[float, Field(strict=True, gt=0.0)] = 24.0

    @model_validator(mode="before")
    @classmethod
    def _default_profile(cls, data: Any) -> Any:
        return _protocol_profile(data, GLOSSMETERS, "zgm1120")


class FaultsConfig(StrictSection):
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


class TwinConfig(StrictSection):
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


class SimConfig(StrictSection):
    """``[sim]``: seed, noise and misalignments of the simulated lab."""

    seed: Annotated[int, Field(strict=True, ge=0)] = 1
    noise_pct: Annotated[float, Field(strict=True, ge=0.0, le=50.0)] = 0.5
    sample_tilt_deg: Annotated[float, Field(strict=True, ge=-10.0, le=10.0)] = 0.0
    lamp_zero_offset_deg: Annotated[float, Field(strict=True, ge=-10.0, le=10.0)] = 0.0
    detector_zero_offset_deg: Annotated[float, Field(strict=True, ge=-10.0, le=10.0)] = 0.0
    gloss_autosend_s: NonNegFloat = 0.0
    faults: FaultsConfig = FaultsConfig()
    twin: TwinConfig = TwinConfig()


class ColourConfig(StrictSection):
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


class AlignmentConfig(StrictSection):
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


class RunSection(StrictSection):
    """``[run]``: what every run started with this config records about itself unless the
    command says otherwise (``scan --operator/--sample-id/--note/--tag``): who measures,
    the physical sample's id (a label, a LIMS number), notes and tags."""

    operator: str = ""
    sample_id: str = ""
    notes: str = ""
    tags: tuple[str, ...] = ()


class LabConfig(StrictSection):
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
