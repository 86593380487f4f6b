"""Profile loader: the built-in profiles' facts (docs/PROTOCOLS.md) and error messages."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.base import ProfileError
from drivers.profiles import (
    PROFILES_DIR,
    LineGlossProfile,
    StepperProfile,
    StilProfile,
    ZgmProfile,
    load_profile,
    load_stepper_profile,
    load_stil_profile,
    template_regex,
)


def test_builtin_profiles_load_with_their_kinds() -> None:
    kinds = {p.stem: type(load_profile(p.stem)) for p in PROFILES_DIR.glob("*.toml")}
    assert kinds == {
        "oriental-az": StepperProfile,
        "applied-motion-mdx": StepperProfile,
        "applied-motion-stq": StepperProfile,
        "stil-ruby": StilProfile,
        "stil-ruby-level": StilProfile,
        "zgm1120": ZgmProfile,
        "line-gloss-example": LineGlossProfile,
    }


def test_oriental_az_register_map_matches_protocols_md() -> None:
    p = load_stepper_profile("oriental-az")
    r, s, i = p.registers, p.status_bits, p.input_bits
    assert (r.direct_data, r.input_command, r.output_status, r.alarm_code) == (
        0x58,
        0x7C,
        0x7E,
        0x80,
    )
    assert (r.feedback_position, r.command_position) == (0x120, 0x122)
    assert i is not None
    assert (i.start, i.zhome, i.stop, i.free, i.alarm_reset, i.fw_pos, i.rv_pos) == (
        3,
        4,
        5,
        6,
        7,
        14,
        15,
    )
    assert (s.ready, s.alarm, s.busy, s.moving, s.in_position, s.home_end) == (5, 7, 8, 13, 14, 4)
    assert (p.serial.parity, p.serial.bytesize, p.serial.stopbits) == ("E", 8, 1)
    assert {"registers.command_position", "status_bits.home_end"} <= set(p.unconfirmed)
    # 0x0120 in one public AZ driver, 0x00CC in another (issue 28): not confirmed
    assert "registers.feedback_position" in p.unconfirmed


def test_applied_motion_numbers_become_protocol_addresses() -> None:
    p = load_stepper_profile("applied-motion-mdx")
    r = p.registers
    # protocol address = N - 40001
    assert (r.output_status, r.feedback_position, r.command) == (2, 6, 124)
    assert (r.accel, r.decel, r.velocity, r.target_position) == (344, 346, 348, 350)
    assert p.opcodes is not None
    assert (p.opcodes.relative_move, p.opcodes.absolute_move) == (0x66, 0x67)
    assert (p.opcodes.enable, p.opcodes.disable) == (0x9F, 0x9E)
    # 1 count = 1/240 rps; at 20000 steps/rev: 240 counts per 20000 steps/s
    assert p.speed_counts_per_step_s == pytest.approx(240 / 20000)
    assert p.accel_counts_per_step_s2 == pytest.approx(6 / 20000)
    # the SCL opcodes are confirmed by 920-0072 p. 9; the MDX+ register numbers are not
    # public (the old profile had both marks the wrong way round, issue 28)
    assert not any(k.startswith("opcodes") for k in p.unconfirmed)
    assert "registers" in p.unconfirmed and p.single_register_fields == ()


def test_applied_motion_stq_map_is_the_published_table() -> None:
    """920-0072 Rev E p. 7: alarm 40001 and status 40002 are SHORT; AC/DE/VE 40028-40030,
    DI 40031-32, immediate absolute position 40007-08."""
    p = load_stepper_profile("applied-motion-stq")
    r = p.registers
    assert (r.alarm_code, r.output_status, r.feedback_position) == (0, 1, 6)
    assert (r.accel, r.decel, r.velocity, r.target_position, r.command) == (27, 28, 29, 30, 124)
    assert p.single_register_fields == ("output_status", "alarm_code")
    assert p.opcodes is not None and p.opcodes.alarm_reset == 0xBA and p.opcodes.stop == 0xE1
    s = p.status_bits
    assert (s.ready, s.fault, s.in_position, s.moving, s.alarm) == (0, 2, 3, 4, 9)
    assert p.speed_counts_per_step_s == pytest.approx(240 / 20000)
    assert p.accel_counts_per_step_s2 == pytest.approx(6 / 20000)
    assert set(p.unconfirmed) == {"registers.command", "units.steps_per_rev", "serial"}


def test_single_register_fields_accept_only_status_and_alarm(tmp_path: Path) -> None:
    text = (PROFILES_DIR / "applied-motion-stq.toml").read_text()
    old = 'single_register_fields = ["output_status", "alarm_code"]'
    path = write(tmp_path, text.replace(old, 'single_register_fields = ["velocity"]'))
    with pytest.raises(ProfileError) as info:
        load_profile(path)
    assert str(info.value).startswith(f"{path}: key 'single_register_fields[0]': ")


def test_stil_profile_is_all_unconfirmed_and_templates_parse() -> None:
    p = load_stil_profile("stil-ruby")
    assert (p.exposure_min_us, p.exposure_max_us) == (500, 250000)
    assert all(f"commands.{k}" in p.unconfirmed for k in ("identify", "set_exposure", "measure"))
    line = p.reply_measure[1].format(start_nm=380, step_nm=5, count=2, values="1.5,2")
    found = template_regex(p.reply_measure[1]).match(line)
    assert found is not None and found.group("values") == "1.5,2"
    assert template_regex(p.reply_error).match("ERR 2 exposure out of range") is not None


AZ_TEXT = (PROFILES_DIR / "oriental-az.toml").read_text()


def write(tmp_path: Path, text: str, name: str = "bad.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("old", "new", "key", "reason"),
    [
        ("output_status = 0x007E", "", "registers.output_status", "missing"),
        (
            "output_status = 0x007E",
            'output_status = "0x7E"',
            "registers.output_status",
            "expected an integer",
        ),
        ("moving = 13", "moving = 40", "status_bits.moving", "above the maximum 31"),
        ('parity = "E"', 'parity = "X"', "serial.parity", "expected 'N', 'E' or 'O'"),
        ("trigger = 1 ", "trigerr = 1 ", "direct_data.trigerr", "unknown key"),
        (
            'move_style = "direct-data"',
            'move_style = "jog"',
            "move_style",
            "expected 'direct-data'",
        ),
        ('"status_bits.home_end",', '"status_bits.nope",', "unconfirmed", "'status_bits.nope'"),
        ('kind = "modbus-stepper"', 'kind = "laser"', "kind", "expected one of"),
        (
            "speed_counts_per_step_s = 1.0",
            "speed_counts_per_step_s = 0.0",
            "units.speed_counts_per_step_s",
            "must be > 0",
        ),
        # strict types: TOML true is not a number, 1.0 is not an integer
        (
            "baudrate = 115200",
            "baudrate = true",
            "serial.baudrate",
            "expected an integer, got True",
        ),
        (
            "speed_counts_per_step_s = 1.0",
            "speed_counts_per_step_s = true",
            "units.speed_counts_per_step_s",
            "expected a number, got True",
        ),
        ("current = 1000 ", "current = 1000.0 ", "direct_data.current", "got 1000.0"),
        (
            "feedback_position = 0x0120",
            "feedback_position = -1",
            "registers.feedback_position",
            "-1 is below the minimum 0",
        ),
        ('name = "oriental-az"', 'name = "oriental-az"\ncolour = "red"', "colour", "unknown key"),
        # a typo in a listed key is reported as the typo, not as a stale `unconfirmed` entry
        ("[status_bits]", "[status_bitz]", "status_bitz", "unknown key"),
    ],
)
def test_errors_name_file_key_and_reason(
    tmp_path: Path, old: str, new: str, key: str, reason: str
) -> None:
    assert old in AZ_TEXT
    path = write(tmp_path, AZ_TEXT.replace(old, new, 1))
    with pytest.raises(ProfileError) as info:
        load_profile(path)
    message = str(info.value)
    assert message.startswith(f"{path}: key '{key}': ")
    assert reason in message


@pytest.mark.parametrize(
    ("old", "new", "key", "reason"),
    [
        # Modicon numbers: 40001 is the first holding register, so 1 is no address at all
        ("alarm_code = 40001", "alarm_code = 1", "registers.alarm_code", "below the minimum 40001"),
        ("command = 40125", "command = 105537", "registers.command", "above the maximum 105536"),
        ("target_position = 40351", "", "registers.target_position", "missing"),
        ("register_base = 40001", "register_base = 1", "register_base", "expected 0 or 40001"),
        ("steps_per_rev = 20000", "steps_per_rev = false", "units.steps_per_rev", "got False"),
        ("[units]", "[direct_data]\n[units]", "direct_data", "not used with move_style"),
    ],
)
def test_command_opcode_errors_name_file_key_and_reason(
    tmp_path: Path, old: str, new: str, key: str, reason: str
) -> None:
    text = (PROFILES_DIR / "applied-motion-mdx.toml").read_text()
    assert old in text
    path = write(tmp_path, text.replace(old, new, 1))
    with pytest.raises(ProfileError) as info:
        load_profile(path)
    assert str(info.value).startswith(f"{path}: key '{key}': ")
    assert reason in str(info.value)


def test_missing_file_lists_builtin_profiles() -> None:
    with pytest.raises(ProfileError, match=r"no-such\.toml: profile file not found .*oriental-az"):
        load_profile("no-such")


def test_toml_syntax_error_names_file(tmp_path: Path) -> None:
    path = write(tmp_path, "kind = \n")
    with pytest.raises(ProfileError, match=f"{path}: TOML syntax error"):
        load_profile(path)


def test_wrong_kind_for_typed_loader() -> None:
    with pytest.raises(ProfileError, match="key 'kind': expected 'modbus-stepper', got 'zgm1120'"):
        load_stepper_profile("zgm1120")


def test_bad_line_pattern_and_template(tmp_path: Path) -> None:
    text = (PROFILES_DIR / "line-gloss-example.toml").read_text()
    path = write(tmp_path, text.replace("(?P<g20>", "(?P<g20", 1))
    with pytest.raises(ProfileError, match="key 'pattern': invalid regex"):
        load_profile(path)
    stil = (PROFILES_DIR / "stil-ruby.toml").read_text()
    path = write(tmp_path, stil.replace("{luminance_pct:.4f}", "{lum}", 1), "stil.toml")
    with pytest.raises(
        ProfileError, match=r"key 'replies.measure': bad reply template .*unknown field \{lum\}"
    ):
        load_profile(path)


@pytest.mark.parametrize(
    ("profile", "old", "new", "key", "reason"),
    [
        # found by tests/drivers/test_profiles_fuzz.py: each loaded, then failed at run time
        # (AttributeError / TypeError out of the loader, struct.error or UnicodeEncodeError
        # on the first move or command, a reply the driver cannot read back)
        ("stil-ruby", '"EXP {exposure_us}"', '"EXP {exposure_us.foo}"', "commands.set_exposure",
         "has no attribute 'foo'"),
        ("stil-ruby", '"EXP {exposure_us}"', '"EXP {exposure_us[0]}"', "commands.set_exposure",
         "not subscriptable"),
        ("stil-ruby", 'command_terminator = "\\r"', 'command_terminator = "\\u00e9"',
         "command_terminator", "'é' cannot be written in ascii"),
        ("stil-ruby", '"Y={luminance_pct:.4f}"', '"Y={luminance_pct:d}"', "replies.measure[0]",
         "cannot be written: Unknown format code 'd'"),
        ("stil-ruby", '"Y={luminance_pct:.4f}"', '"Y={luminance_pct:>12}"', "replies.measure[0]",
         "which it does not read back"),
        ("stil-ruby", "{count}", "{count:x}", "replies.measure[1]", "does not read back"),
        ("stil-ruby", 'identify = "{ident}"', 'identify = "{exposure_us}"', "replies.identify",
         "cannot be written: 'exposure_us'"),
        ("oriental-az", "data_number = 0", "data_number = 2147483648", "direct_data.data_number",
         "above the maximum 2147483647"),
        ("oriental-az", "trigger = 1 ", "trigger = -2147483649 ", "direct_data.trigger",
         "below the minimum"),
        ("line-gloss-example", "(?P<g20>\\S+)", "(?P<g20>a{4294967296})", "pattern",
         "invalid regex: the repetition number is too large"),
        ("line-gloss-example", 'line_terminator = "\\r\\n"', 'line_terminator = "\\u00b5"',
         "line_terminator", "cannot be written in ascii"),
    ],
)  # fmt: skip
def test_what_loads_runs(
    tmp_path: Path, profile: str, old: str, new: str, key: str, reason: str
) -> None:
    text = (PROFILES_DIR / f"{profile}.toml").read_text()
    assert old in text
    path = write(tmp_path, text.replace(old, new, 1))
    with pytest.raises(ProfileError) as info:
        load_profile(path)
    message = str(info.value)
    assert message.startswith(f"{path}: key '{key}': "), message
    assert reason in message and "\n" not in message, message


def test_a_long_wrong_kind_is_cut_short(tmp_path: Path) -> None:
    path = write(tmp_path, AZ_TEXT.replace('kind = "modbus-stepper"', f'kind = "{"(" * 5000}"', 1))
    with pytest.raises(ProfileError, match=r"key 'kind': expected one of .*\(\(\.\.\.$") as info:
        load_profile(path)
    assert len(str(info.value)) < 300
