"""Help that teaches (issue 27, item 2): every command's ``--help`` has examples that parse,
shows every default, and a config key typo suggests the key.

The walk covers every parser the CLI builds, so a new command without examples, or an
example naming an option that was renamed, fails here.
"""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from goniolab.cli import build_parser, main
from goniolab.commands._help import EXAMPLES, walk
from goniolab.config import ConfigError, load_lab_config

ROOT = Path(__file__).resolve().parents[1]
PARSERS = list(walk(build_parser()))


def _help(words: str, capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as done:
        main([*words.split(), "--help"])
    assert done.value.code == 0
    return capsys.readouterr().out


def _examples(text: str) -> list[str]:
    """The commands of the ``examples:`` section of a help text (comments dropped)."""
    section = text.split("\nexamples:\n", 1)[1]
    return [line.split("  #")[0].strip() for line in section.splitlines() if line.strip()]


@pytest.mark.parametrize("words", [w for w, _ in PARSERS], ids=lambda w: w or "goniolab")
def test_every_help_has_examples_that_parse(words: str, capsys: pytest.CaptureFixture[str]) -> None:
    text = _help(words, capsys)
    assert "\nexamples:\n" in text
    found = _examples(text)
    assert 2 <= len(found) <= 3
    for example in found:
        argv = shlex.split(example.split("|")[0].split(">")[0])
        assert argv[0] == "goniolab"
        # the real parser takes it: the command exists and so does every option
        args = build_parser().parse_args(argv[1:])
        assert getattr(args, "func", None) is not None, example
        if words:  # an example of "runs export" runs "runs export"
            assert " ".join(argv[1:]).startswith(words.split()[0]), example


def test_examples_table_names_only_real_commands() -> None:
    assert set(EXAMPLES) == {w for w, _ in PARSERS}


@pytest.mark.parametrize("words", [w for w, _ in PARSERS], ids=lambda w: w or "goniolab")
def test_every_default_is_shown(words: str, capsys: pytest.CaptureFixture[str]) -> None:
    parser = dict(PARSERS)[words]
    options = _help(words, capsys).split("\noptions:\n")[1].split("\n\n")[0]
    # one entry per option: its line "  --opt ..." and the indented lines under it
    entries = {
        m["names"]: " ".join(m["text"].split())
        for m in re.finditer(r"(?m)^  (?P<names>-\S.*?)(?:  +|\n)(?P<text>(?:.*\n?)*?)(?=^  -|\Z)",
                             options)
    }  # fmt: skip
    for action in parser._actions:
        if not action.option_strings or action.nargs == 0 or action.default is None:
            continue
        if action.default is argparse.SUPPRESS:
            continue
        option = action.option_strings[-1]
        (text,) = [t for names, t in entries.items() if option in names.replace(",", " ").split()]
        assert "(default: " in text, f"{words} {option}: default not shown in {text!r}"


def test_the_defaults_the_issue_named(capsys: pytest.CaptureFixture[str]) -> None:
    def one_line(words: str) -> str:
        return " ".join(_help(words, capsys).split())

    assert "settling time after each move, s (default: 0)" in one_line("scan")
    assert "lamp cone, full angle, deg (default: 6)" in one_line("predict brdf")
    render = one_line("render")
    assert "(default: 512)" in render and "key and fill lamp (default: 1)" in render
    assert "pause between readings, s (default: 0)" in one_line("gloss log")
    # complex and list defaults as a user types them
    assert "0.27+3.41j (default: 1.55)" in one_line("predict gloss")
    assert "geometries, deg (default: 20 60 85)" in one_line("gloss log")


def test_scan_usage_shows_resume_as_optional(capsys: pytest.CaptureFixture[str]) -> None:
    usage = _help("scan", capsys).split("\n\n")[0]
    assert "[resume ...]" in usage
    assert not re.search(r"(?<!\[)resume \.\.\.", usage)


def test_every_run_argument_has_help(capsys: pytest.CaptureFixture[str]) -> None:
    for words, parser in PARSERS:
        for action in parser._actions:
            if action.dest == "run" and not action.option_strings:
                assert action.help, words
                assert "RUN  " in " ".join(_help(words, capsys).split("\n"))


def test_store_says_sqlite_or_postgresql(capsys: pytest.CaptureFixture[str]) -> None:
    for words, parser in PARSERS:
        if any("--store" in a.option_strings for a in parser._actions):
            text = " ".join(_help(words, capsys).split())
            assert "SQLite file or postgresql:// URL" in text, words


def test_predict_help_names_every_action_without_rst(capsys: pytest.CaptureFixture[str]) -> None:
    text = _help("predict", capsys)
    assert "``" not in text and ":func:" not in text
    head = text.split("positional arguments:")[0]
    for action in ("stats", "gloss", "brdf", "albedo", "colour"):
        assert action in head


def test_no_help_shows_rst_markup(capsys: pytest.CaptureFixture[str]) -> None:
    for words, _ in PARSERS:
        text = _help(words, capsys)
        assert "``" not in text and not re.search(r":\w+:`", text), words


def test_tui_help_lists_every_key_of_the_app(capsys: pytest.CaptureFixture[str]) -> None:
    from goniolab.tui.app import GonioApp

    text = _help("tui", capsys)
    listed = set(re.findall(r"^  (\S+)  ", text.split("\nkeys:\n")[1].split("\n\n")[0], re.M))
    keys = {key for b in GonioApp.BINDINGS for key in b.key.split(",")}  # type: ignore[union-attr]
    assert keys <= listed, keys - listed
    for key in ("a", "h", "c", "f"):
        assert key in listed


def _config_with(tmp_path: Path, old: str, new: str) -> Path:
    text = (ROOT / "configs" / "lab-sim.toml").read_text()
    assert re.search(rf"(?m)^{re.escape(old)}", text)
    path = tmp_path / "lab.toml"
    path.write_text(re.sub(rf"(?m)^{re.escape(old)}", new, text, count=1))
    return path


@pytest.mark.parametrize(
    ("old", "typo", "key", "guess"),
    [
        ("time_scale", "time_scael", "lab.time_scael", "time_scale"),
        ("min_separation_deg", "min_seperation_deg", "goniometer.min_seperation_deg",
         "min_separation_deg"),
    ],
)  # fmt: skip
def test_config_key_typo_suggests_the_key(
    tmp_path: Path, old: str, typo: str, key: str, guess: str
) -> None:
    with pytest.raises(ConfigError) as exc:
        load_lab_config(_config_with(tmp_path, old, typo))
    assert exc.value.key == key
    assert exc.value.reason == f"unknown key (typo?); did you mean {guess!r}?"


def test_config_key_far_from_any_suggests_nothing(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as exc:
        load_lab_config(_config_with(tmp_path, "time_scale", "zzzz_qqqq"))
    assert exc.value.reason == "unknown key (typo?)"
