"""Stored strings reach the terminal without their control characters (issue 23, Low):
a sample named with an OSC title sequence and a screen clear, and a Trojan-Source bidi
override, are shown escaped by ``runs list`` and ``runs show``; JSON keeps them exact."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.scan.plans import BrdfPlan
from goniolab.store import RunStore
from goniolab.textsafe import printable

EVIL = "paint\x1b]0;owned\x07\x1b[2J\r\u202eevil\x9b"


def test_printable_escapes_controls_and_keeps_text() -> None:
    assert printable(EVIL) == "paint\\x1b]0;owned\\x07\\x1b[2J\\x0d\\u202eevil\\x9b"
    assert printable("Wittmann 3 µm, 45°\tok\n") == "Wittmann 3 µm, 45°\tok\n"


@pytest.fixture
def store(tmp_path: Path) -> Path:
    path = tmp_path / "s.sqlite"
    plan = BrdfPlan(45.0, (40.0,), sample=EVIL)
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample=EVIL,
                           model={}, version="t")  # fmt: skip
        s.set_status(rid, "failed", f"reason with {EVIL}")
    return path


@pytest.mark.parametrize("command", [["runs", "list"], ["runs", "show", "1"]])
def test_runs_list_and_show_escape_the_sample_name(
    store: Path, command: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*command, "--store", str(store)]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\x07" not in out and "\r" not in out and "\u202e" not in out
    assert "paint\\x1b]0;owned\\x07\\x1b[2J" in out


def test_json_keeps_the_exact_name(store: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["runs", "show", "1", "--json", "--store", str(store)]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out  # JSON escapes it as \u001b
    assert json.loads(out)["run"]["sample"] == EVIL
