"""The README's "Try it" examples and docs/TUTORIAL.md's steps are run, and their printed
output compared (issue 27, item 4: docs that cannot go stale).

Each file of :data:`DOCS` is run in a scratch directory of its own.

A fenced ``sh`` block right after the line ``<!-- example: run -->`` is run with bash
(``set -euo pipefail``) in one scratch directory shared by all such blocks, in order (a
later block uses the files an earlier one wrote), with ``goniolab`` of this environment on
the PATH, its own store and log directory, and ``configs/`` linked in. A fenced ``text``
block right after ``<!-- example: output -->`` is what the run block before it must print
on stdout, to the character. When a change moves a number, the test fails; regenerate the
outputs with::

    .venv/bin/python -m tests.test_readme_examples --update

(every file of :data:`DOCS`; in a worktree put it first on the path: ``PYTHONPATH=$PWD``).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests._zygote import client_env, zygote

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: The files whose marked blocks are run and checked.
DOCS = (README, ROOT / "docs" / "TUTORIAL.md")
_BLOCK = re.compile(
    r"<!-- example: (?P<kind>run|output) -->\n```(?P<lang>\w*)\n(?P<body>.*?)```", re.S
)


@dataclass
class Example:
    """A run block and the output block that follows it (if any)."""

    script: str
    expected: str | None
    output_span: tuple[int, int] | None  # where the output block's body is in the README


def examples(text: str) -> list[Example]:
    """The README's run blocks with their expected outputs, in order."""
    found: list[Example] = []
    for m in _BLOCK.finditer(text):
        if m["kind"] == "run":
            if m["lang"] != "sh":
                raise ValueError(f"README: an example run block must be ```sh, got {m['lang']!r}")
            found.append(Example(m["body"], None, None))
        else:
            if not found or found[-1].expected is not None:
                raise ValueError("README: an example output block without its run block")
            found[-1].expected = m["body"]
            found[-1].output_span = m.span("body")
    return found


def run_examples(
    workdir: Path, found: list[Example], server: dict[str, str] | None = None
) -> list[str]:
    """Run every block in ``workdir``; return their stdouts (fails on a non-zero exit).
    ``server``: a running :func:`tests._zygote.zygote` (else one is started for the call)."""
    if server is None:
        with zygote(workdir) as started:
            return run_examples(workdir, found, started)
    (workdir / "configs").symlink_to(ROOT / "configs")
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "XDG_DATA_HOME": str(workdir / ".data"),
        "GONIOLAB_LOG_DIR": str(workdir / ".log"),
        "COLUMNS": "100",
        "NO_COLOR": "1",
    }
    outputs = []
    # each `goniolab` of a block is a process forked from a server that imported numpy,
    # colour-science, scipy and matplotlib once (tests/_zygote.py): its own argv, working
    # directory, environment, streams and exit status, without a second of imports each
    env = client_env(env, server)
    for ex in found:
        done = subprocess.run(
            ["bash", "-c", "set -euo pipefail\n" + ex.script],
            cwd=workdir, env=env, capture_output=True, text=True, timeout=600, check=False,
        )  # fmt: skip
        if done.returncode != 0:
            raise AssertionError(
                f"example failed (exit {done.returncode}):\n{ex.script}\n"
                f"stderr:\n{done.stderr[-3000:]}"
            )
        outputs.append(done.stdout)
    return outputs


@pytest.fixture(scope="module")
def goniolab_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, str]]:
    """One fork server for both docs' examples."""
    with zygote(tmp_path_factory.mktemp("zygote")) as server:
        yield server


#: How far a printed decimal may move: the twin's readings at an instant lab clock move by
#: up to ~1 % between a quiet machine and a loaded one (RMSE 0.250 vs 0.247 % seen in CI);
#: a changed model or formula moves them by far more (G85 42.4 -> 72.7 GU).
REL_TOL = 0.05

_NUMBER = re.compile(r"[-+]?\d+(?:\.(\d+))?")


def same_output(actual: str, expected: str) -> bool:
    """The printed output matches the doc's: the words exactly, each number within REL_TOL or
    two units of its last printed digit (integers exactly). The simulated lab's readings at an instant clock
    move in the third or fourth digit with the machine's load (a reading's virtual time
    depends on when worker threads finish; known, see the closing notes), so an exact
    compare failed at random; a changed model or formula moves numbers far more."""
    if _NUMBER.sub("#", actual) != _NUMBER.sub("#", expected):
        return False
    for a_m, e_m in zip(_NUMBER.finditer(actual), _NUMBER.finditer(expected), strict=True):
        if e_m.group(1) is None:  # integers (counts, run ids, years) are exact
            if a_m.group() != e_m.group():
                return False
            continue
        a, e = float(a_m.group()), float(e_m.group())
        if abs(a - e) > max(REL_TOL * abs(e), 2 * 10.0 ** -len(e_m.group(1))):
            return False
    return True


def test_same_output_tolerates_the_last_digits_only() -> None:
    assert same_output("RMSE 0.250 %\n", "RMSE 0.251 %\n")
    assert same_output("RMSE 0.247 %\n", "RMSE 0.250 %\n")  # seen between two CI runs
    assert not same_output("RMSE 0.300 %\n", "RMSE 0.251 %\n")
    assert not same_output("G85 72.7 GU, kirchhoff\n", "G85 42.4 GU, kirchhoff\n")
    assert not same_output("G85 42.4 GU, facet\n", "G85 42.4 GU, kirchhoff\n")
    assert same_output("run 1: done\n", "run 1: done\n")
    assert not same_output("run 2: done\n", "run 1: done\n")


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_doc_has_examples(doc: Path) -> None:
    found = examples(doc.read_text())
    assert len(found) >= 2 and any(ex.expected is not None for ex in found)


@pytest.mark.slow
@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_doc_examples_run_and_print_what_the_doc_says(
    tmp_path: Path, doc: Path, goniolab_server: dict[str, str]
) -> None:
    found = examples(doc.read_text())
    outputs = run_examples(tmp_path, found, goniolab_server)
    for ex, out in zip(found, outputs, strict=True):
        if ex.expected is not None:
            assert same_output(out, ex.expected), (
                f"{doc.name} output is stale for:\n{ex.script}\nregenerate with "
                "'.venv/bin/python -m tests.test_readme_examples --update'"
            )


def update() -> None:
    """Rewrite every doc's output blocks with what its run blocks print now."""
    for doc in DOCS:
        text = doc.read_text()
        found = examples(text)
        with tempfile.TemporaryDirectory() as tmp:
            outputs = run_examples(Path(tmp), found)
        for ex, out in reversed(list(zip(found, outputs, strict=True))):
            if ex.output_span is not None:
                a, b = ex.output_span
                text = text[:a] + out + text[b:]
        doc.write_text(text)


if __name__ == "__main__":
    if sys.argv[1:] != ["--update"]:
        sys.exit("usage: python -m tests.test_readme_examples --update")
    update()
