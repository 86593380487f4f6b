"""``goniolab tui`` reports bad input as one line naming the file/option (after the first
frame has been taken down, when the config is only read once the app shows)."""

from __future__ import annotations

from pathlib import Path

import pytest

from goniolab.cli import main

REPO = Path(__file__).resolve().parents[2]
SIM = str(REPO / "configs" / "lab-sim.toml")


def test_missing_config_file_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nope.toml"
    assert main(["tui", "--config", str(missing)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("goniolab: error: ") and str(missing) in err
    assert err.count("\n") == 1


def test_unknown_sample_is_named(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["tui", "--config", SIM, "--sample", "wittmann-99"]) == 2
    err = capsys.readouterr().err
    assert "--sample wittmann-99: no built-in sample 'wittmann-99'" in err
    assert "wittmann-3" in err  # the known names are listed


def test_negative_time_scale(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["tui", "--config", SIM, "--time-scale", "-1"]) == 2
    assert "--time-scale must be >= 0, got -1.0" in capsys.readouterr().err


def test_config_key_error_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(
        (REPO / "configs" / "lab-sim.toml")
        .read_text()
        .replace("min_separation_deg = 10.0", "min_separation_deg = -1.0")
    )
    assert main(["tui", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "goniometer.min_separation_deg" in err
