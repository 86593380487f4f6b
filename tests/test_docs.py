"""The physics reference the docstrings cite exists, with every section they name."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PHYSICS = ROOT / "docs" / "PHYSICS.md"

#: ``PHYSICS.md, "Section"``, ``PHYSICS.md "Section"``, ``PHYSICS.md ("Section")``, across a line break
CITATION = re.compile(r'PHYSICS\.md(?:,\s*\(?|\s+\(?|\()"([^"]+)"')  # not "docs/PHYSICS.md"


def _headings() -> set[str]:
    return {
        line.lstrip("#").strip()
        for line in PHYSICS.read_text(encoding="utf-8").splitlines()
        if line.startswith("## ")
    }


def test_every_cited_physics_section_exists() -> None:
    headings = _headings()
    cited: dict[str, list[str]] = {}
    for room in ("goniolab", "drivers", "sim", "tests", "bench", "README.md", "docs"):
        target = ROOT / room
        files = [target] if target.is_file() else sorted(target.rglob("*.py"))
        files += sorted(target.rglob("*.md")) if target.is_dir() else []
        for path in files:
            if path == Path(__file__).resolve():
                continue
            for title in CITATION.findall(path.read_text(encoding="utf-8")):
                title = " ".join(title.split())  # a title broken over two docstring lines
                cited.setdefault(title, []).append(str(path.relative_to(ROOT)))
    assert cited, "no citation of PHYSICS.md sections found: the pattern is out of date"
    missing = {title: where for title, where in cited.items() if title not in headings}
    assert missing == {}, f"cited sections missing from docs/PHYSICS.md: {missing}"


def test_in_page_links_of_physics_md_resolve() -> None:
    text = PHYSICS.read_text(encoding="utf-8")
    anchors = {re.sub(r"[^a-z0-9 -]", "", title.lower()).replace(" ", "-") for title in _headings()}
    links = re.findall(r"\]\(#([^)]+)\)", text)
    assert links
    assert sorted(set(links) - anchors) == []
