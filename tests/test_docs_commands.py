"""Every command and path the README and docs/ show works as written (docs that cannot go
stale): a ``goniolab ...`` line of a fenced ``sh``/``console`` block parses with the real
argparse parser (no execution: a renamed option or a removed command fails here); a
``goniolab ...`` code span in the prose names a real command and only its real options; and
every repository path the docs name (``tests/...py``, ``bench/...py``, ``configs/...``,
``goniolab/...``) exists.

The shorthand of the docs is read as a reader reads it: ``RUN`` is a run id, ``[--opt X]``
is an option that may be given, ``a|b`` a choice (the first is parsed), ``...`` "and the
rest", ``# ...`` a comment, ``> file`` a redirection.
"""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from goniolab.cli import build_parser
from goniolab.commands._help import walk

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: fenced blocks whose lines are commands (bare fences hold program output: timings tables)
_FENCE = re.compile(r"^```(?P<lang>[^\n]*)\n(?P<body>.*?)^```", re.S | re.M)
_COMMAND_LANGS = {"sh", "bash", "console"}
_SPAN = re.compile(r"(?<!`)`(goniolab(?: [a-zA-Z-][^`]*)?)`(?!`)")  # not the TUI's title


def fenced_commands(text: str) -> list[str]:
    """The ``goniolab`` command lines of the command blocks (continuations joined)."""
    found = []
    for m in _FENCE.finditer(text):
        if m["lang"].strip() not in _COMMAND_LANGS:
            continue
        for line in m["body"].replace("\\\n", " ").splitlines():
            line = line.strip().removeprefix("$ ").removeprefix(".venv/bin/")
            if line == "goniolab" or line.startswith("goniolab "):
                found.append(" ".join(line.split()))
    return found


def prose_commands(text: str) -> list[str]:
    """The ``goniolab ...`` code spans outside fenced blocks (a span may break a line)."""
    return [" ".join(m[1].split()) for m in _SPAN.finditer(_FENCE.sub("", text))]


def argv_of(command: str) -> list[str]:
    """The arguments a reader types for a documented command line (see the module doc)."""
    command = re.sub(r"\s#.*$", "", command)  # a comment
    command = command.split(" | ")[0]  # a pipe, or "cmd | other cmd" alternatives
    command = re.sub(r"\s\d?>>?\s*\S+", "", command)  # redirections
    command = command.replace("[", " ").replace("]", " ")
    argv = []
    for word in shlex.split(command)[1:]:
        if word in ("...", "RUN"):
            word = {"...": "", "RUN": "1"}[word]
        if "|" in word:
            word = word.split("|")[0]
        if word:
            argv.append(word)
    return argv


def test_argv_of_reads_the_shorthand() -> None:
    assert argv_of("goniolab runs export RUN --format csv|json [-o FILE]   # note") == [
        "runs", "export", "1", "--format", "csv", "-o", "FILE"
    ]  # fmt: skip
    assert argv_of("goniolab predict gloss maps/*.sur --json > gloss.jsonl") == [
        "predict", "gloss", "maps/*.sur", "--json"
    ]  # fmt: skip
    assert argv_of("goniolab runs list [--tag T] | runs show RUN") == ["runs", "list", "--tag", "T"]
    assert argv_of("goniolab scan --store postgresql://lab@db/g ...") == [
        "scan", "--store", "postgresql://lab@db/g"
    ]  # fmt: skip


def _all(kind: str) -> list[tuple[str, str]]:
    pick = fenced_commands if kind == "fenced" else prose_commands
    return [(doc.name, c) for doc in DOCS for c in pick(doc.read_text(encoding="utf-8"))]


FENCED = _all("fenced")
PROSE = _all("prose")
PARSERS = dict(walk(build_parser()))


def test_a_stale_command_is_refused() -> None:
    with pytest.raises(_Refused, match="--theta"):
        _parse(argv_of("goniolab scan --config c.toml --theta 45"))
    with pytest.raises(_Refused):
        _parse(argv_of("goniolab runs export RUN --format xlsx"))


def test_the_docs_show_commands() -> None:
    """The collection is not silently empty (a changed fence style would make it so)."""
    assert len(FENCED) > 40 and len(PROSE) > 30
    assert {doc for doc, _ in FENCED} >= {"README.md", "TUTORIAL.md", "WIRE_SIM.md"}


class _Refused(Exception):
    pass


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = build_parser()
    for _, p in walk(parser):  # an error raises here instead of printing and exiting
        p.error = lambda message: (_ for _ in ()).throw(_Refused(message))  # type: ignore[method-assign]
    return parser.parse_args(argv)


@pytest.mark.parametrize(("doc", "command"), FENCED, ids=[f"{d}:{c[:60]}" for d, c in FENCED])
def test_fenced_command_parses(doc: str, command: str) -> None:
    argv = argv_of(command)
    try:
        args = _parse(argv)
    except _Refused as exc:
        pytest.fail(f"{doc}: {command!r} is refused by goniolab's parser: {exc}")
    except SystemExit:  # --help / --version
        assert argv[-1] in ("--help", "--version"), command
        return
    assert getattr(args, "func", None) is not None or argv == [], f"{doc}: {command!r}"


def _command_words(argv: list[str]) -> str:
    """The longest run of leading words that names a parser (``runs export``)."""
    words = ""
    for word in argv:
        longer = f"{words} {word}".strip()
        if longer not in PARSERS:
            break
        words = longer
    return words


@pytest.mark.parametrize(("doc", "command"), PROSE, ids=[f"{d}:{c[:60]}" for d, c in PROSE])
def test_prose_command_names_real_options(doc: str, command: str) -> None:
    argv = argv_of(command)
    words = _command_words(argv)
    rest = argv[len(words.split()) :] if words else argv
    if rest and not rest[0].startswith("-"):
        # "goniolab COMMAND --help": a placeholder; otherwise a positional of the command
        assert words or rest[0].isupper(), f"{doc}: {command!r}: no command {rest[0]!r}"
    parser = PARSERS[words]
    known = {s for a in parser._actions for s in a.option_strings}
    known |= {s for a in PARSERS[""]._actions for s in a.option_strings}
    unknown = [w.split("=")[0] for w in rest if w.startswith("--") and w.split("=")[0] not in known]
    assert unknown == [], f"{doc}: {command!r}: 'goniolab {words}' has no option {unknown}"


#: a repository path: a top-level room, then a path (a trailing ``/`` names a folder)
_PATH = re.compile(
    r"(?<![\w./~-])((?:goniolab|drivers|sim|tests|bench|configs|docs|\.ci)/[\w.*/-]*[\w*/])"
)


#: paths of a "how to add one" example, which a reader creates (docs/ARCHITECTURE.md)
EXAMPLE_PATHS = {"drivers/acme_gloss.py", "goniolab/optics/lambert.py"}


def referenced_paths(text: str) -> set[str]:
    return set(_PATH.findall(text))


def test_referenced_paths_exist() -> None:
    missing = {}
    for doc in DOCS:
        for path in sorted(referenced_paths(doc.read_text(encoding="utf-8"))):
            if path in EXAMPLE_PATHS:
                assert doc.name == "ARCHITECTURE.md" and not (ROOT / path).exists(), path
                continue
            if not (any(ROOT.glob(path)) if "*" in path else (ROOT / path).exists()):
                missing.setdefault(doc.name, []).append(path)
    assert missing == {}, f"paths the docs name that are not in the repository: {missing}"


def test_referenced_paths_finds_what_a_reader_sees() -> None:
    text = "see `tests/sim/test_soak.py`, bench/bench_fit.py and /tmp/goniolab-sim/spectro, "
    text += "~/.local/share/goniolab/goniolab.sqlite or configs/profiles/."
    assert referenced_paths(text) == {
        "tests/sim/test_soak.py",
        "bench/bench_fit.py",
        "configs/profiles/",
    }


FIGURES = ROOT / "docs" / "figures.sh"


def test_every_figure_is_made_by_docs_figures_sh() -> None:
    """Every PNG in docs/ is written by docs/figures.sh, every image the docs show is one of
    them, and the README names the script beside each figure (render-example.png was made by
    hand, from a command the README did not give in full)."""
    script = FIGURES.read_text(encoding="utf-8")
    pngs = {p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.png")}
    assert pngs and {p for p in pngs if p not in script} == set()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    shown = set()
    for doc in DOCS:
        shown |= set(re.findall(r"!\[[^\]]*\]\(([^)]+)\)", doc.read_text(encoding="utf-8")))
    assert shown == pngs
    for png in pngs:
        before = readme[: readme.index(f"]({png})")]
        assert "docs/figures.sh" in before[-600:], f"README: no 'sh docs/figures.sh' beside {png}"


def test_docs_figures_sh_commands_parse() -> None:
    lines = script_commands(FIGURES.read_text(encoding="utf-8"))
    assert len(lines) == 4
    for command in lines:
        args = _parse(argv_of(command))
        assert getattr(args, "func", None) is not None, command


def script_commands(script: str) -> list[str]:
    """The ``goniolab`` lines of a shell script (continuations joined, ``"$tmp/x"`` kept)."""
    joined = script.replace("\\\n", " ")
    return [" ".join(line.split()) for line in joined.splitlines() if line.startswith("goniolab ")]


def layout_entries() -> list[tuple[str, set[str]]]:
    """README "Layout": (path of each listed entry, the ``*.py`` names its description gives)."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"## Layout\n+```\n(.*?)```", readme, re.S)
    assert block, "README: the Layout block is gone"
    entries: list[tuple[str, set[str]]] = []
    top = ""
    for line in block[1].splitlines():
        m = re.match(r"^( {0,2})([\w.]+/?)\s", line + " ")
        if m and (m[2].endswith("/") or m[2].endswith(".py")):
            path = m[2] if not m[1] else top + m[2]
            top = m[2] if not m[1] else top
            entries.append((path, set()))
            line = line[m.end() :]
        entries[-1][1].update(re.findall(r"\b(\w+\.py)\b", line))
    return entries


def test_readme_layout_lists_what_is_there() -> None:
    entries = layout_entries()
    assert len(entries) >= 15
    missing = [path for path, _ in entries if not (ROOT / path).exists()]
    assert missing == [], f"README Layout lists what is not in the repository: {missing}"
    for path, names in entries:
        room = ROOT / path.split("/")[0]  # a file named under goniolab/store/ may live in goniolab/
        absent = sorted(n for n in names if not any(room.rglob(n)))
        assert absent == [], f"README Layout, {path}: no {absent} under {room.name}/"
