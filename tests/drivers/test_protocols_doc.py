"""docs/PROTOCOLS.md lists every value of every built-in profile (and every ZGM 1120
opcode of the driver) with its source and a confidence mark, and the marks agree with the
profiles' ``unconfirmed`` lists: a value is listed there exactly when it is not confirmed."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

import pytest

import drivers.glossmeter as glossmeter
from drivers.profiles import PROFILES_DIR

DOC = Path(__file__).resolve().parents[2] / "docs" / "PROTOCOLS.md"
MARKS = {"confirmed", "inferred", "unconfirmed"}
#: Keys that name or describe a profile, or are our own tuning, not device facts.
NOT_FACTS = {"kind", "name", "description", "move_style", "unconfirmed", "timeout_s",
             "exposure.default_us"}  # fmt: skip


def doc_table(marker: str) -> dict[str, tuple[Any, str, str]]:
    """Rows ``key -> (value, source, mark)`` of the table after ``<!-- marker -->``."""
    text = DOC.read_text(encoding="utf-8")
    start = text.find(f"<!-- {marker} -->")
    assert start >= 0, f"docs/PROTOCOLS.md has no section <!-- {marker} -->"
    rows: dict[str, tuple[Any, str, str]] = {}
    lines = text[start:].splitlines()[1:]
    assert lines[0].startswith("| key | value |"), lines[0]
    for line in lines[2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        assert len(cells) == 5, f"row {line!r}: expected 5 cells"
        key, value, _meaning, source, mark = cells
        literal = re.fullmatch(r"`(.*)`", value)
        assert literal, f"row {key!r}: value {value!r} is not a `TOML literal`"
        parsed = tomllib.loads(f"v = {literal.group(1)}")["v"]
        assert key not in rows, f"row {key!r} twice"
        assert source, f"row {key!r}: no source"
        rows[key] = (parsed, source, mark)
    return rows


def leaves(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in data.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(leaves(value, f"{dotted}."))
        elif dotted not in NOT_FACTS:
            out[dotted] = value
    return out


def listed(dotted: str, unconfirmed: list[str]) -> bool:
    """``dotted`` or one of its parent tables is in the profile's ``unconfirmed`` list."""
    parts = dotted.split(".")
    return any(".".join(parts[:n]) in unconfirmed for n in range(1, len(parts) + 1))


PROFILES = sorted(p.stem for p in PROFILES_DIR.glob("*.toml"))


def test_every_built_in_profile_is_covered() -> None:
    assert {"oriental-az", "applied-motion-stq", "applied-motion-mdx", "zgm1120",
            "stil-ruby", "line-gloss-example"} <= set(PROFILES)  # fmt: skip


@pytest.mark.parametrize("name", PROFILES)
def test_profile_values_appear_in_protocols_doc_with_a_mark(name: str) -> None:
    raw = tomllib.loads((PROFILES_DIR / f"{name}.toml").read_text(encoding="utf-8"))
    rows = doc_table(f"profile: {name}")
    values = leaves(raw)
    unconfirmed = list(raw.get("unconfirmed", []))
    assert values, name
    for key, value in values.items():
        assert key in rows, f"{name}: {key} = {value!r} is not in docs/PROTOCOLS.md"
        documented, _source, mark = rows[key]
        assert documented == value, f"{name}: {key} is {value!r}, the doc says {documented!r}"
        assert mark in MARKS, f"{name}: {key} has mark {mark!r}"
        if mark == "confirmed":
            assert not listed(key, unconfirmed), f"{name}: {key} is confirmed but listed"
        else:
            assert listed(key, unconfirmed), f"{name}: {key} is {mark} but not listed"
    stale = set(rows) - set(values)
    assert not stale, f"{name}: the doc lists keys the profile does not have: {sorted(stale)}"


def test_glossmeter_opcodes_appear_in_protocols_doc_as_confirmed() -> None:
    rows = doc_table("driver: drivers.glossmeter")
    opcodes = {k: v for k, v in vars(glossmeter).items() if k.startswith("OP_")}
    assert opcodes.keys() == rows.keys()
    for key, value in opcodes.items():
        assert rows[key][0] == value and rows[key][2] == "confirmed", key


def test_profiles_and_drivers_cite_the_repository_doc() -> None:
    """Comments point at docs/PROTOCOLS.md, a file in the repository, not at shared/."""
    root = DOC.parents[1]
    files = [*PROFILES_DIR.glob("*.toml"), *(root / "drivers").glob("*.py"),
             *(root / "sim" / "wire").glob("*.py"), root / "docs" / "WIRE_SIM.md"]  # fmt: skip
    for path in files:
        text = path.read_text(encoding="utf-8")
        assert "shared/PROTOCOLS" not in text, f"{path} cites shared/PROTOCOLS.md"
