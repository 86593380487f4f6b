"""``goniolab gloss log`` output lines and its input errors (no instruments involved)."""

from __future__ import annotations

from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.commands.gloss import format_reading
from goniolab.scan.events import GlossRead


def test_reading_line_puts_the_prediction_beside_each_value() -> None:
    ev = GlossRead(
        run_id=1,
        timestamp=0.0,  # 1970-01-01T00:00:00 UTC
        values_gu={60: 58.7, 20: 55.9, 85: None},
        predicted_gu={20: 56.04, 60: 58.96, 85: 62.8},
        temperature_c=23.0,
    )
    assert format_reading(ev, 7) == (
        "   7  1970-01-01T00:00:00.000+00:00  G20   55.9 GU (pred   56.0)  "
        "G60   58.7 GU (pred   59.0)  G85     - GU (pred   62.8)  23.0 degC"
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--port", "{tmp}/ttyNONE"], "gloss log: --port {tmp}/ttyNONE: no such device"),
        (["--port", "/dev/null", "--interval", "-1"], "--interval must be >= 0 s, got -1.0"),
        (["--port", "/dev/null", "--timeout", "0"], "--timeout must be > 0 s, got 0.0"),
        (["--port", "/dev/null", "--config", "x.toml"], "--config and --port exclude each other"),
        (["--port", "/dev/null", "--angles", "45"], "angles must be a non-empty subset"),
    ],
)
def test_bad_gloss_input_is_one_line_with_exit_2(
    args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "s.sqlite"
    argv = ["gloss", "log", *(a.format(tmp=tmp_path) for a in args), "--store", str(store)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("goniolab: error: ") and err.count("\n") == 1
    assert message.format(tmp=tmp_path) in err
    assert not store.exists()


def test_a_port_that_is_no_serial_device_is_one_line_with_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # /dev/null opens but takes no serial settings: the driver's Disconnected names the port
    assert main(["gloss", "log", "--port", "/dev/null", "--store", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("goniolab: error: instrument error: glossmeter: ")
    assert "'/dev/null'" in err and err.count("\n") == 1


def test_gloss_log_records_the_run_identity(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # issue 22 item 4: a gloss session carries an operator, a physical sample id, notes
    # and tags like a scan does, and runs list finds it by them
    import json as _json

    from goniolab.cli import main as cli_main
    from goniolab.store import RunStore
    from tests.scan.test_integration import lab_config

    cfg = lab_config(tmp_path, sim={"noise_pct": "0.0"})
    store = str(tmp_path / "s.sqlite")
    argv = ["gloss", "log", "--config", str(cfg), "--count", "2", "--time-scale", "0",
            "--store", store, "--operator", "ada", "--sample-id", "LIMS-42",
            "--note", "second coat", "--tag", "panel", "--tag", "q3"]  # fmt: skip
    assert cli_main(argv) == 0
    capsys.readouterr()
    with RunStore(store, readonly=True) as s:
        run = s.get_run(1)
        assert (run.kind, run.operator, run.sample_id, run.notes, run.tags) == (
            "gloss",
            "ada",
            "LIMS-42",
            "second coat",
            ("panel", "q3"),
        )
    assert cli_main(["runs", "list", "--store", store, "--tag", "q3", "--json"]) == 0
    assert [r["id"] for r in _json.loads(capsys.readouterr().out)] == [1]
    assert cli_main(["runs", "list", "--store", store, "--operator", "bob", "--json"]) == 0
    assert _json.loads(capsys.readouterr().out) == []
