"""Issue 11's "bad input" paragraph end to end: a spectrum with the wrong length, negative or
NaN values or a grid short of 380-780 nm, and an unknown illuminant or observer, each give one
clear error naming what is wrong; nothing already stored is lost."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.config import ConfigError, configs_dir, load_lab_config

# the bad spectra during a scan: tests/scan/test_colour_points.py


@pytest.mark.parametrize(
    ("table", "key", "needle"),
    [
        ('illuminant = "D66"', "colour.illuminant", "unknown illuminant 'D66'"),
        ('observer = "5"', "colour.observer", "unknown observer '5'"),
    ],
)
def test_unknown_illuminant_or_observer_in_a_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], table: str, key: str, needle: str
) -> None:
    src = configs_dir() / "lab-sim.toml"
    cfg = tmp_path / "lab.toml"
    text = src.read_text()
    assert "[colour]" not in text
    cfg.write_text(text + f"\n[colour]\n{table}\n")
    shutil.copytree(configs_dir() / "profiles", tmp_path / "profiles")
    with pytest.raises(ConfigError) as err:
        load_lab_config(cfg)
    assert str(cfg) in str(err.value) and key in str(err.value) and needle in str(err.value)
    # the command line says the same in one line, exit 2, and stores nothing
    store_file = tmp_path / "runs.sqlite"
    args = ["scan", "--config", str(cfg), "--store", str(store_file), "--theta-r", "40,45"]
    assert main([*args, "--time-scale", "0"]) == 2
    out = capsys.readouterr().err
    assert out.startswith("goniolab: error:") and needle in out and out.count("\n") == 1
    assert not store_file.exists()


def test_unknown_illuminant_or_observer_on_the_colour_commands(
    capsys: pytest.CaptureFixture[str],
) -> None:
    for argv, needle in (
        (["predict", "colour", "sample:flat", "--observer", "5"], "unknown observer '5'"),
        (["predict", "colour", "sample:flat", "--illuminant", "E2"], "unknown illuminant 'E2'"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("goniolab: error:") and needle in err and err.count("\n") == 1
