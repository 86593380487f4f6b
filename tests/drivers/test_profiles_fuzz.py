"""Property-based fuzzing of the device profiles (hypothesis, a deadline per case): any
key of any built-in profile set to a hostile value, a key removed, an unknown key added,
or random bytes, loads as a profile or raises one :class:`ProfileError` line that names
the file and the key -- nothing else escapes -- and a profile that loads works: a stepper
packs its move registers, a STIL profile's replies as the simulator formats them read back
through the driver, a line glossmeter's pattern parses a line (what validates does not
crash at run time)."""

from __future__ import annotations

import contextlib
import math
import tomllib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.base import DeviceFault, ProfileError, ProtocolError
from drivers.glossmeter import parse_gloss_line
from drivers.modbus_stepper import ModbusStepperAxis
from drivers.profiles import (
    PROFILES_DIR,
    LineGlossProfile,
    StepperProfile,
    StilProfile,
    load_profile,
)
from drivers.stil import match_reply, parse_measure_reply
from tests._fuzz import DELETE, fuzz_settings, leaves, set_path, toml_document

FUZZ = fuzz_settings(100)

BUILTIN = sorted(p.stem for p in PROFILES_DIR.glob("*.toml"))


_numbers = st.one_of(
    st.integers(-(2**63), 2**63 - 1),
    st.sampled_from([0, 1, -1, 2, 31, 32, 0xFFFF, 0x10000, 40000, 40001, 2**31, 2**32]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, 0.5, 1.0, 1e30, 1e308]),
)
#: Texts a profile's templates, regexes, terminators and encodings may meet.
_hostile_texts = st.sampled_from(
    [
        "", " ", "\x00", "\r", "\r\n", "\u00e9", "\u2603", "{", "}", "{}", "{0}", "{x}",
        "{exposure_us}", "{exposure_us.real}", "{exposure_us.foo}", "{exposure_us[0]}",
        "{exposure_us:d}", "{exposure_us:%%}", "{exposure_us!r}", "{exposure_us:>12}",
        "{luminance_pct}", "{luminance_pct:d}", "{luminance_pct:.0f}", "{luminance_pct:>20}",
        "{luminance_pct:,}", "{values}", "{values:.2f}", "{values!r}", "{count:x}",
        "Y={luminance_pct} {values}", "Y={luminance_pct:.4f} V={values}",
        "{luminance_pct} {luminance_pct:.1f} {values}", "{ident}", "ERR {code} {message}",
        "{code:f} {message}", "{message}", "ascii", "utf-8", "latin-1", "utf-16", "rot13",
        "base64", "idna", "a\x00b", "(?P<g60>\\S+)", "(?P<g60>a{4294967296})",
        "(?P<g60>\\d+)(?P<x>.)", "(?P<g20>" + "(" * 300 + ")" * 300 + ")", "(?P<g85>",
        "[", "(?P<g60>\\S+) GU", "OVER", "MEAS", "IDN?", "direct-data", "command-opcode",
        "modbus-stepper", "stil-spectro", "zgm1120", "line-gloss", "N", "E", "O",
        "registers.output_status", "serial.baudrate", "nope.key",
    ]
)  # fmt: skip
_values = st.one_of(
    st.just(DELETE),
    st.booleans(),
    _numbers,
    _hostile_texts,
    st.text(max_size=12),
    st.lists(st.one_of(_numbers, _hostile_texts), max_size=3),
    st.dictionaries(st.sampled_from(["baudrate", "x", "min_us", "start"]), _numbers, max_size=2),
)


def _value_like(original: Any) -> st.SearchStrategy[Any]:
    """Hostile values of the key's own kind first (they pass the type check and reach the
    checks behind it), then anything."""
    if isinstance(original, str):
        return st.one_of(_hostile_texts, _hostile_texts, st.text(max_size=12), _values)
    if isinstance(original, bool):
        return _values
    if isinstance(original, int | float):
        return st.one_of(_numbers, _numbers, _values)
    if isinstance(original, list):
        return st.one_of(st.lists(_hostile_texts, max_size=3), _values)
    return _values


def _assert_works(profile: Any) -> None:
    """Use a loaded profile as the drivers and the simulator do; nothing may fail."""
    if isinstance(profile, StepperProfile):
        try:
            axis = ModbusStepperAxis("lamp", profile=profile, limits_deg=(-10.0, 10.0))
        except ValueError as exc:
            # the counts per step meet the arm's speeds only in a lab config, which checks
            # them at load (tests/test_config_fuzz.py); the axis names the one that misses
            assert "register counts with profile" in str(exc), exc
            return
        if profile.move_style == "direct-data":
            axis.move_registers(axis.deg_to_steps(10.0))
    elif isinstance(profile, StilProfile):
        enc = profile.encoding
        for text in (profile.command_terminator, profile.reply_terminator, profile.cmd_identify,
                     profile.cmd_measure):  # fmt: skip
            text.encode(enc)
        profile.cmd_set_exposure.format(exposure_us=profile.exposure_default_us).encode(enc)
        fields: dict[str, Any] = {
            "luminance_pct": 12.3456, "start_nm": 380, "step_nm": 5, "count": 3,
            "values": "1.0000,2.0000,3.0000", "exposure_us": profile.exposure_default_us,
            "ident": "STIL RUBY", "peak_fraction": 0.5,
        }  # fmt: skip
        lines = [t.format(**fields) for t in profile.reply_measure]
        luminance, wavelengths, values = parse_measure_reply(profile, lines)
        assert len(values) == len(wavelengths) > 0 and math.isfinite(luminance)
        ident = profile.reply_identify.format(ident="STIL RUBY")
        match_reply(profile, profile.reply_identify, ident)
        echo = profile.reply_set_exposure.format(exposure_us=profile.exposure_default_us)
        match_reply(profile, profile.reply_set_exposure, echo)
        error = profile.reply_error.format(code=2, message="exposure out of range")
        with pytest.raises(DeviceFault):
            match_reply(profile, profile.reply_identify, error)
    elif isinstance(profile, LineGlossProfile):
        profile.trigger.encode(profile.encoding)
        profile.line_terminator.encode(profile.encoding)
        # a pattern may well not match this meter's line: then a clear ProtocolError
        with contextlib.suppress(ProtocolError):
            parse_gloss_line(profile, "20: 81.5 GU  60: 92.1 GU  85: 97.0 GU")


@pytest.mark.parametrize("name", BUILTIN)
def test_any_value_in_any_key_of_a_profile(tmp_path: Path, name: str) -> None:
    original = tomllib.loads((PROFILES_DIR / f"{name}.toml").read_text(encoding="utf-8"))
    paths = leaves(original)
    tables = [p for p in paths if isinstance(_get(original, p), dict)]

    @FUZZ
    @given(st.data())
    def run(data: st.DataObject) -> None:
        doc = tomllib.loads(toml_document(original, escape_controls=True))  # a deep copy
        for _ in range(data.draw(st.integers(1, 3), label="changes")):
            path = data.draw(st.sampled_from(paths), label="key")
            if tables and data.draw(st.integers(0, 9), label="new key?") == 0:
                path = (*data.draw(st.sampled_from(tables)), "typo")
            old = _get(original, path) if path in paths else None
            set_path(doc, path, data.draw(_value_like(old), label="/".join(path)))
        path = tmp_path / f"{name}.toml"
        path.write_text(toml_document(doc, escape_controls=True), encoding="utf-8")
        try:
            profile = load_profile(path)
        except ProfileError as exc:
            message = str(exc)
            assert message.startswith(f"{path}: ") and "\n" not in message, message
            assert len(message) < 600, message
            return
        _assert_works(profile)

    run()


def _get(data: dict[str, Any], path: tuple[str, ...]) -> Any:
    node: Any = data
    for part in path:
        node = node[part]
    return node


@FUZZ
@given(st.binary(max_size=256))
def test_random_bytes_are_a_profile_error(
    tmp_path_factory: pytest.TempPathFactory, raw: bytes
) -> None:
    path = tmp_path_factory.mktemp("profile") / "bytes.toml"
    path.write_bytes(raw)
    try:
        _assert_works(load_profile(path))
    except ProfileError as exc:
        assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc)
