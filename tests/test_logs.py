"""The log file: every command writes it, --log-level filters it, passwords never reach it."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.logs import redact


def test_a_command_and_its_error_land_in_the_log(
    _log_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["runs", "show", "7", "--store", str(tmp_path / "none.sqlite")]) == 2
    text = (_log_dir / "goniolab.log").read_text()
    assert "INFO goniolab: goniolab " in text and "runs show 7" in text
    assert "ERROR goniolab: error: store " in text and "no such file" in text
    assert capsys.readouterr().err.startswith("goniolab: error: store ")


def test_log_level_filters(_log_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--log-level", "warning", "samples", "--json"]) == 0
    assert main(["--log-level", "DEBUG", "samples", "--json"]) == 0
    capsys.readouterr()
    logging.getLogger("goniolab.test").debug("a debug line")
    lines = (_log_dir / "goniolab.log").read_text().splitlines()
    commands = [ln for ln in lines if "samples --json" in ln]
    assert len(commands) == 1 and "--log-level DEBUG" in commands[0]  # WARNING kept INFO out
    assert any("DEBUG goniolab.test: a debug line" in ln for ln in lines)


def test_version_names_store_config_and_log(
    _log_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    with pytest.raises(SystemExit) as ex:
        main(["--version"])
    assert ex.value.code == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("goniolab ")
    from goniolab.store import default_store_path

    assert out[1].startswith(f"store:  {default_store_path()} ")
    assert out[2].startswith("config:")
    assert out[3] == f"log:    {_log_dir / 'goniolab.log'}"


def test_redact_blanks_url_and_keyword_passwords_never_env_text(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # issue 23.7: $PGPASSWORD used to be replaced as plain text ("lab" -> configs/***-sim.toml);
    # redaction parses connection strings instead, and leaves other text alone
    monkeypatch.setenv("PGPASSWORD", "lab")
    text = "postgresql://lab:hunter2@db.example:5432/runs password=abc configs/lab-sim.toml"
    assert (
        redact(text)
        == "postgresql://lab:***@db.example:5432/runs password=*** configs/lab-sim.toml"
    )


def test_the_log_file_rotates_as_the_standard_rotating_handler(tmp_path: Path) -> None:
    """The same files as logging.handlers.RotatingFileHandler(maxBytes=300, backupCount=2)
    given the same records: goniolab.log, .1 and .2, none beyond, each under the limit."""
    import logging.handlers

    from goniolab.logs import _RotatingFile

    ours, ref = tmp_path / "ours", tmp_path / "ref"
    ours.mkdir()
    ref.mkdir()
    handlers = [
        _RotatingFile(ours / "goniolab.log", 300, 2),
        logging.handlers.RotatingFileHandler(ref / "goniolab.log", maxBytes=300, backupCount=2),
    ]
    for i in range(40):
        record = logging.LogRecord(
            "goniolab", logging.INFO, __file__, 1, "line %03d of the log", (i,), None
        )
        for h in handlers:
            h.handle(record)
    for h in handlers:
        h.close()
    names = sorted(p.name for p in ours.iterdir())
    assert names == ["goniolab.log", "goniolab.log.1", "goniolab.log.2"]
    for name in names:
        assert (ours / name).read_text() == (ref / name).read_text()
        assert len((ours / name).read_bytes()) < 300
