"""Lab config loading: every shipped config loads; every error names file, key and reason."""

from __future__ import annotations

from pathlib import Path

import pytest

from goniolab.config import ConfigError, LabConfig, configs_dir, load_lab_config, resolve_profile
from goniolab.errors import UserError

SHIPPED = sorted(configs_dir().glob("lab-*.toml"))


def test_the_three_lab_configs_ship() -> None:
    assert {p.name for p in SHIPPED} >= {
        "lab-sim.toml",
        "lab-sim-wire.toml",
        "lab-real-example.toml",
    }


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_every_shipped_config_loads(path: Path) -> None:
    cfg = load_lab_config(path)
    assert isinstance(cfg, LabConfig)
    assert Path(cfg.goniometer.lamp.profile) == configs_dir() / "profiles" / "oriental-az.toml"
    assert Path(cfg.spectro.profile).is_file() and Path(cfg.glossmeter.profile).is_file()


def test_shipped_values() -> None:
    sim = load_lab_config(configs_dir() / "lab-sim.toml")
    assert (sim.lab.mode, sim.lab.time_scale, sim.sample.map) == ("sim", 1.0, "sample:wittmann-3")
    wire = load_lab_config(configs_dir() / "lab-sim-wire.toml")
    assert wire.lab.mode == "drivers" and wire.lab.start_sim_servers
    assert (
        wire.goniometer.lamp.host,
        wire.goniometer.lamp.unit_id,
        wire.goniometer.detector.unit_id,
    ) == (
        "127.0.0.1",
        1,
        2,
    )
    assert wire.spectro.port.startswith("/tmp/goniolab-sim/")
    real = load_lab_config(configs_dir() / "lab-real-example.toml")
    assert (
        real.goniometer.lamp.transport == "rtu"
        and real.goniometer.lamp.serial_port == "/dev/ttyUSB0"
    )
    lamp = real.goniometer.lamp  # 3600 steps/rev motor behind a 100:1 gearbox
    assert (lamp.steps_per_deg, lamp.gear_ratio) == (10.0, 100.0)
    assert wire.goniometer.lamp.gear_ratio == 1.0  # direct drive unless configured


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "x.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "[goniometer.lamp]\nlimits_deg = [10.0, 5.0]\n",
            "x.toml: goniometer.lamp.limits_deg: lower limit 10 must be below upper limit 5",
        ),
        ('[lab]\nmode = "sim"\ntime_scal = 2\n', "x.toml: lab.time_scal: unknown key (typo?)"),
        ('[lab]\ntime_scale = "fast"\n', "x.toml: lab.time_scale: Input should be a valid number"),
        (
            "[lab]\ntime_scale = -1\n",
            "x.toml: lab.time_scale: Input should be greater than or equal to 0",
        ),
        ("[sample]\nn = 0.5\n", "x.toml: sample.n: Input should be greater than 1"),
        (
            '[sample]\nmap = " "\n',
            "x.toml: sample.map: empty: name a height-map file or sample:NAME",
        ),
        (
            "[goniometer.detector]\nport = 70000\n",
            "x.toml: goniometer.detector.port: Input should be less than or equal to 65535",
        ),
        ('[lab]\nmode = "real"\n', "x.toml: lab.mode: Input should be 'sim' or 'drivers'"),
        (
            "[goniometer.lamp]\ngear_ratio = 0\n",
            "x.toml: goniometer.lamp.gear_ratio: Input should be greater than 0",
        ),
        (
            '[lab]\nmode = "drivers"\n[goniometer.detector]\nunit_id = 2\n'
            '[goniometer.lamp]\ntransport = "rtu"\nserial_port = "socket://127.0.0.1:0"\n',
            "x.toml: goniometer.lamp.serial_port: port 0 (any free port) only works",
        ),
        (
            '[goniometer.lamp]\ntransport = "rtu"\n',
            'x.toml: goniometer.lamp: transport = "rtu" needs serial_port',
        ),
        (
            "[sim.faults]\ntimeout_rate = 1.5\n",
            "x.toml: sim.faults.timeout_rate: Input should be less than or equal to 1",
        ),
        (
            "[goniometer]\npark = { theta_i_deg = 90.0, theta_r_deg = 45.0 }\n",
            "x.toml: goniometer.park.theta_i_deg: 90 deg outside the arm limits [0, 85] deg",
        ),
        (
            "[goniometer]\npark = { theta_i_deg = 5.0, theta_r_deg = 0.0 }\n",
            "x.toml: goniometer.park: arm separation 5 deg is below min_separation_deg 10",
        ),
        ('[spectro]\nprofile = "nope"\n', "x.toml: spectro.profile: "),
        ('[spectro]\nprofile = "zgm1120"\n', "x.toml: spectro.profile: profile "),
        ('[sample]\nmodel = "wave"\n', "x.toml: sample.model: Input should be 'auto', 'facet'"),
        ("[sample]\nwavelength_nm = 50.0\n", "x.toml: sample.wavelength_nm: Input should be"),
        (
            "[lab]\nstart_sim_servers = true\n",
            'x.toml: lab: start_sim_servers = true needs mode = "drivers"',
        ),
    ],
)
def test_errors_name_file_key_and_reason(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_lab_config(write(tmp_path, text))
    assert isinstance(err.value, UserError) and err.value.exit_code == 2
    assert str(err.value).startswith(str(tmp_path / "x.toml")) and message in str(err.value)


def test_bad_profile_reasons(tmp_path: Path) -> None:
    with pytest.raises(
        ConfigError, match=r"spectro\.profile: .*nope\.toml: profile file not found"
    ):
        load_lab_config(write(tmp_path, '[spectro]\nprofile = "nope"\n'))
    with pytest.raises(ConfigError, match=r"is not a 'stil-spectro' profile"):
        load_lab_config(write(tmp_path, '[spectro]\nprofile = "zgm1120"\n'))


def test_toml_syntax_error_has_line_and_column(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as err:
        load_lab_config(write(tmp_path, '[lab]\nname = "ok"\nmode = sim\n'))
    assert "x.toml: TOML syntax error: Invalid value (at line 3, column 8)" in str(err.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nothere\.toml: config file not found"):
        load_lab_config(tmp_path / "nothere.toml")


def test_empty_file_gives_the_documented_defaults(tmp_path: Path) -> None:
    cfg = load_lab_config(write(tmp_path, ""))
    assert cfg.lab.mode == "sim" and cfg.goniometer.min_separation_deg == 10.0
    assert cfg.goniometer.lamp.limits_deg == (0.0, 85.0) and cfg.sim.faults.devices == ()


def test_profile_paths_resolve_next_to_the_config_then_in_configs(tmp_path: Path) -> None:
    assert resolve_profile("oriental-az") == configs_dir() / "profiles" / "oriental-az.toml"
    own = tmp_path / "my" / "az.toml"
    own.parent.mkdir()
    own.write_text((configs_dir() / "profiles" / "oriental-az.toml").read_text())
    assert resolve_profile("my/az.toml", relative_to=tmp_path) == own
    assert (
        resolve_profile("profiles/zgm1120.toml", relative_to=tmp_path)
        == configs_dir() / "profiles" / "zgm1120.toml"
    )
    cfg = load_lab_config(write(tmp_path, '[goniometer.lamp]\nprofile = "my/az.toml"\n'))
    assert Path(cfg.goniometer.lamp.profile) == own


def test_documented_fault_keys_load_when_uncommented(tmp_path: Path) -> None:
    text = (configs_dir() / "lab-sim.toml").read_text()
    start = text.index("[sim.faults]")
    lines = [
        ln[2:] if ln.startswith("# ") and "=" in ln.split("#")[1] else ln
        for ln in text[start:].splitlines()
    ]
    cfg = load_lab_config(write(tmp_path, text[:start] + "\n".join(lines) + "\n"))
    f = cfg.sim.faults
    assert f.devices == ("spectro",) and f.timeout_rate == 0.05 and f.disconnect_after == 100
    assert (f.lamp_stall_at_deg, f.detector_alarm_at_deg, f.alarm_code) == (30.0, 10.0, 0x30)


def test_the_alignment_state_follows_the_store_the_user_chose(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--store`` decides where the alignment state is read and written: it was looked up
    beside the config's ``[lab] store`` (or in the user data directory, shared by every
    checkout with a ``lab-sim.toml``), so one clone's alignment corrected another's moves."""
    from goniolab.config import alignment_state_path, write_alignment_state

    cfg_path = tmp_path / "lab-sim.toml"
    cfg_path.write_text(
        (Path(__file__).parents[1] / "configs" / "lab-sim.toml").read_text(), encoding="utf-8"
    )
    mine, theirs = tmp_path / "mine", tmp_path / "theirs"
    mine.mkdir()
    theirs.mkdir()
    monkeypatch.chdir(mine)
    cfg = load_lab_config(cfg_path, store="runs.sqlite")  # relative to the working directory
    assert cfg.lab.store == str(mine / "runs.sqlite")
    assert alignment_state_path(cfg) == mine / "lab-sim.alignment.toml"
    write_alignment_state(cfg, {"lamp_zero_deg": 0.25, "detector_zero_deg": -0.5, "run": 3})
    assert load_lab_config(cfg_path, store=mine / "runs.sqlite").alignment.lamp_zero_deg == 0.25
    other = load_lab_config(cfg_path, store=theirs / "runs.sqlite").alignment
    assert other.lamp_zero_deg == 0.0 and other.loaded_from != str(mine / "lab-sim.alignment.toml")
    url = "postgresql://lab@db/runs"
    assert load_lab_config(cfg_path, store=url).lab.store == url
