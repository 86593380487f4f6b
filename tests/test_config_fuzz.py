"""Property-based fuzzing of every lab config section (hypothesis): whatever a user writes,
loading ends in a :class:`LabConfig` or one :class:`ConfigError` line ``file: key: reason``
-- nothing else escapes, no case takes more than the deadline -- and a config that loads
builds every instrument without an error (what validates does not crash at run time)."""

from __future__ import annotations

import math
import string
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import BaseModel

from drivers.goniometer import TwoArmGoniometer
from drivers.modbus_stepper import ModbusStepperAxis, int32_registers
from drivers.stil import StilSpectro
from drivers.timing import SimClock
from goniolab.colour.spectra import ColourSettings
from goniolab.config import (
    AlignmentConfig,
    AxisConfig,
    ColourConfig,
    ConfigError,
    FaultsConfig,
    GlossmeterConfig,
    GoniometerConfig,
    LabConfig,
    LabSection,
    ParkConfig,
    SampleConfig,
    SimConfig,
    SpectroConfig,
    TwinConfig,
    load_lab_config,
)
from goniolab.lab_wiring import build_sim_instruments, draw_session, sample_truth, twin_settings
from tests._fuzz import fuzz_settings, toml_value
from tests.sim.lobe import LobeModel

FUZZ = fuzz_settings(25)

SECTIONS: dict[str, type[BaseModel]] = {
    "lab": LabSection,
    "sample": SampleConfig,
    "goniometer": GoniometerConfig,
    "goniometer.park": ParkConfig,
    "goniometer.lamp": AxisConfig,
    "goniometer.detector": AxisConfig,
    "spectro": SpectroConfig,
    "glossmeter": GlossmeterConfig,
    "sim": SimConfig,
    "sim.faults": FaultsConfig,
    "sim.twin": TwinConfig,
    "colour": ColourConfig,
    "alignment": AlignmentConfig,
}


def _scalar_keys(model: type[BaseModel]) -> list[str]:
    """The section's own keys (nested tables are sections of their own)."""
    out = []
    for key, info in model.model_fields.items():
        ann = info.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            continue
        out.append(key)
    return out


# ----------------------------------------------------------------- a small TOML writer
def _document(tables: dict[str, dict[str, Any]]) -> str:
    return "".join(
        f"[{name}]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in body.items())
        for name, body in tables.items()
    )


# ----------------------------------------------------------------- values a user may write
_numbers = st.one_of(
    st.integers(-(2**63), 2**63 - 1),
    st.sampled_from([0, 1, -1, 2, 247, 248, 65535, 65536, 2**31 - 1, 2**31, -(2**31) - 1]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, 1e-6, 0.5, 1.0, 10.0, 85.0, 1e8, 2e8, 1e30, 1e308]),
)
_texts = st.text(alphabet=string.ascii_letters + string.digits + " ._-:/", max_size=24)
_values = st.one_of(
    st.booleans(),
    _numbers,
    _texts,
    st.sampled_from(["sim", "drivers", "tcp", "rtu", "E", "zgm1120", "line", "oriental-az",
                     "applied-motion-mdx", "sample:wittmann-3", "spectro", "lamp", "ideal",
                     "realistic", "led", "white", "D65", "A", "F2", "FL2", "2", "10",
                     "ASTM E308", "Integration", "mirror", "diffuser",
                     "CIE 1931 2 Degree Standard Observer", "\u00b5m", "D65\u0000"]),
    st.lists(_numbers, max_size=3),
    st.lists(st.sampled_from(["lamp", "detector", "spectro", "glossmeter", "x"]), max_size=3),
    st.dictionaries(st.sampled_from(["theta_i_deg", "theta_r_deg", "x"]), _numbers, max_size=2),
)  # fmt: skip


def _plausible(model: type[BaseModel], key: str) -> st.SearchStrategy[Any]:
    """The default scaled by a random factor: values near the valid ones reach the checks
    that span keys (registers, interlock floor, exposure range)."""
    default = model.model_fields[key].default
    if isinstance(default, bool) or not isinstance(default, int | float):
        return _values
    factors = st.sampled_from([0.0, 1e-9, 1e-3, 0.1, 0.5, 1.0, 2.0, 10.0, 1e3, 1e6, 1e9, -1.0])
    return factors.map(lambda f: type(default)(default * f) if math.isfinite(default * f) else 0)


@pytest.fixture(scope="module")
def default_truth() -> Any:
    """The realistic twin's truth of the default sample, built once: a fuzzed ``[sim.twin]``
    would otherwise compute a truth table per case (seconds each). colour-science is
    imported here too, before the cases the deadline times."""
    ColourSettings("A").validated()
    return sample_truth(LabConfig())


def _assert_builds(cfg: LabConfig, truth: Any = None) -> None:
    """Everything a run builds from the config, without connecting: no error may remain."""
    g = cfg.goniometer
    axes = []
    for name in ("lamp", "detector"):
        ax: AxisConfig = getattr(g, name)
        axis = ModbusStepperAxis(
            name, profile=ax.profile, transport=ax.transport, host=ax.host, port=ax.port,
            serial_port=ax.serial_port or "/dev/null", baudrate=ax.baudrate, parity=ax.parity,
            unit_id=ax.unit_id, steps_per_deg=ax.steps_per_deg, gear_ratio=ax.gear_ratio,
            limits_deg=ax.limits_deg, speed_deg_s=ax.speed_deg_s, accel_deg_s2=ax.accel_deg_s2,
            stall_tolerance_deg=ax.stall_tolerance_deg, timeout_s=ax.timeout_s,
        )  # fmt: skip
        for angle in (*ax.limits_deg, 0.0):
            if axis.profile.move_style == "direct-data" and ax.limits_deg[0] <= angle:
                axis.move_registers(axis.deg_to_steps(min(angle, ax.limits_deg[1])))
        axes.append(axis)
    TwoArmGoniometer(
        axes[0],
        axes[1],
        min_separation_deg=g.min_separation_deg,
        park_deg=(g.park.theta_i_deg, g.park.theta_r_deg),
        corrections_deg=cfg.alignment.corrections_deg(),
    )
    StilSpectro("spectro", port=cfg.spectro.port, profile=cfg.spectro.profile,
                exposure_us=cfg.spectro.exposure_us)  # fmt: skip
    c = cfg.colour
    ColourSettings(c.illuminant, c.observer, c.method).validated()
    twin_settings(cfg)
    draw_session(cfg)
    build_sim_instruments(cfg, LobeModel(), SimClock(0), truth=truth)


@pytest.mark.parametrize("section", sorted(SECTIONS))
def test_any_value_in_any_key_of_a_section(
    tmp_path: Path, section: str, default_truth: Any
) -> None:
    model = SECTIONS[section]
    truth = default_truth if section == "sim.twin" else None
    keys = _scalar_keys(model)

    @FUZZ
    @given(st.data())
    def run(data: st.DataObject) -> None:
        chosen = data.draw(st.lists(st.sampled_from(keys), min_size=1, max_size=3, unique=True))
        body = {}
        for key in chosen:
            body[key] = data.draw(st.one_of(_values, _plausible(model, key)), label=key)
        if data.draw(st.booleans(), label="typo"):
            body[data.draw(st.sampled_from(["speed", "unit", "x"]))] = 1
        path = tmp_path / "fuzz.toml"
        path.write_text(_document({section: body}))
        try:
            cfg = load_lab_config(path)
        except ConfigError as exc:
            message = str(exc)
            assert message.startswith(f"{path}: ") and "\n" not in message, message
            assert len(message) < 600, message
            return
        try:
            _assert_builds(cfg, truth)
        except ConfigError as exc:
            # a [sample] map that names no readable map is found when the twin reads it:
            # the same one-line error, naming the file and the key
            message = str(exc)
            assert message.startswith(f"{path}: sample.map: ") and "\n" not in message, message

    run()


@FUZZ
@given(st.binary(max_size=256))
def test_random_bytes_are_a_config_error(
    tmp_path_factory: pytest.TempPathFactory, raw: bytes
) -> None:
    path = tmp_path_factory.mktemp("cfg") / "bytes.toml"
    path.write_bytes(raw)
    try:
        load_lab_config(path)
    except ConfigError as exc:
        assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc)


_log_floats = st.builds(
    lambda mantissa, exponent: mantissa * 10.0**exponent,
    st.floats(1.0, 9.99),
    st.integers(-9, 12),
)


@pytest.mark.parametrize("profile", ["oriental-az", "applied-motion-mdx"])
def test_arm_numbers_that_load_fit_their_registers(tmp_path: Path, profile: str) -> None:
    """Every number of an arm drawn over 21 decades: a config that loads packs every
    position, speed and acceleration register of its profile (defect 3: 2e8 steps/deg
    loaded, then failed in struct packing mid-run)."""

    @FUZZ
    @given(
        steps=_log_floats,
        gear=_log_floats,
        speed=_log_floats,
        accel=_log_floats,
        tolerance=_log_floats,
        high=st.floats(1.0, 180.0),
    )
    def run(
        steps: float, gear: float, speed: float, accel: float, tolerance: float, high: float
    ) -> None:
        body = {
            "profile": profile, "steps_per_deg": steps, "gear_ratio": gear,
            "speed_deg_s": speed, "accel_deg_s2": accel, "stall_tolerance_deg": tolerance,
            "limits_deg": [0.0, max(high, 45.0)],
        }  # fmt: skip
        path = tmp_path / "arm.toml"
        path.write_text(_document({"goniometer.lamp": body}))
        try:
            cfg = load_lab_config(path)
        except ConfigError as exc:
            assert exc.key.startswith("goniometer"), str(exc)
            return
        _assert_builds(cfg)
        lamp = cfg.goniometer.lamp
        axis = ModbusStepperAxis("lamp", profile=lamp.profile, steps_per_deg=lamp.steps_per_deg,
                                 gear_ratio=lamp.gear_ratio, limits_deg=lamp.limits_deg,
                                 speed_deg_s=lamp.speed_deg_s, accel_deg_s2=lamp.accel_deg_s2,
                                 stall_tolerance_deg=lamp.stall_tolerance_deg)  # fmt: skip
        for angle in lamp.limits_deg:
            int32_registers(axis.deg_to_steps(angle))

    run()
