"""The README's speed summary, generated from bench/README.md's issue-26 table.

Run:  python bench/speed_summary.py            (print the block)
      python bench/speed_summary.py --write    (rewrite it in README.md)

bench/README.md keeps each figure of issue 26 with its before / now / target / command and
the load it was taken at; its ``in short`` column is the one-line statement a reader of the
README needs (the figure, the target and whether it is met). This script copies that
column, the target and the command into README.md between the markers
``<!-- generated: bench/speed_summary.py -->`` and ``<!-- end generated -->``, so the
README never says other than bench/README.md (``tests/test_docs_fresh.py`` checks the block
is this script's output). No figure is measured here: each comes from its command, rerun
by hand and written into bench/README.md with its load.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench" / "README.md"
README = ROOT / "README.md"
START = "<!-- generated: bench/speed_summary.py -->"
END = "<!-- end generated -->"
#: The issue-26 table's heading in bench/README.md, and the columns the summary copies.
SECTION = "## Issue 26: the figures a user feels"
COLUMNS = ("in short", "target", "command")


def _cells(line: str) -> list[str]:
    """A markdown table row's cells (``\\|`` inside a cell is not a separator)."""
    return [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]


def table_rows(text: str) -> list[dict[str, str]]:
    """The rows of the first table after :data:`SECTION`, as column -> cell."""
    if SECTION not in text:
        raise SystemExit(f"{BENCH}: the heading {SECTION!r} is gone")
    lines = text.split(SECTION, 1)[1].splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("|"))
    header = _cells(lines[start])
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise SystemExit(f"{BENCH}: the issue-26 table has no column {missing[0]!r}")
    rows = []
    for ln in lines[start + 2 :]:
        if not ln.startswith("|"):
            break
        cells = _cells(ln)
        if len(cells) != len(header):
            raise SystemExit(f"{BENCH}: a row of {len(cells)} cells, not {len(header)}: {ln[:80]}")
        rows.append(dict(zip(header, cells, strict=True)))
    return rows


def block(text: str) -> str:
    """The README's summary table (its lines between the markers)."""
    out = ["| figure | target | command |", "|---|---|---|"]
    for row in table_rows(text):
        if row["in short"] in ("", "-"):
            continue
        out.append(f"| {row['in short']} | {row['target']} | {row['command']} |")
    return "\n".join(out) + "\n"


def written(readme: str) -> str:
    """The block README.md holds now."""
    m = re.search(re.escape(START) + r"\n(.*?)" + re.escape(END), readme, re.S)
    if not m:
        raise SystemExit(f"{README}: the markers {START!r} ... {END!r} are gone")
    return m.group(1)


def main(argv: list[str]) -> int:
    new = block(BENCH.read_text(encoding="utf-8"))
    if "--write" not in argv:
        print(new, end="")
        return 0
    readme = README.read_text(encoding="utf-8")
    old = written(readme)
    README.write_text(readme.replace(START + "\n" + old, START + "\n" + new, 1), encoding="utf-8")
    print(f"{README}: {'unchanged' if old == new else 'rewritten'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
