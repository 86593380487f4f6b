"""docs/ARCHITECTURE.md's API sketch and config example are the code's (docs that cannot go
stale).

- "goniolab.optics (public API ...)" and "goniolab.surfaces": every ``def``/``class`` line names a real function or
  class of the module its ``# module.py`` header names, with parameters the real signature
  has (and every parameter it requires, unless the line says ``...``); a dataclass's field
  list is its fields; the constants (``GONIO_CONE = Cone(6.0)``, the ISO 2813 apertures and
  black-glass index) equal the code's.
- "goniolab.colour": every module it names exists and holds the names given under it.
- "Lab config": the TOML block loads with the real loader.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")


def _block(heading: str, lang: str) -> str:
    m = re.search(rf"^## {re.escape(heading)}.*?\n```{lang}\n(.*?)^```", DOC, re.S | re.M)
    assert m, f"docs/ARCHITECTURE.md: no {lang} block under {heading!r}"
    return m[1]


def _names(params: str) -> tuple[list[str], bool]:
    """The parameter names of a sketched parameter list (the text after ``def name(``, up to
    its closing parenthesis), and whether it ends in ``...``."""
    depth, parts, word = 0, [], ""
    for ch in params:
        depth += ch in "([{"
        depth -= ch in ")]}"
        if depth < 0:
            break
        if ch == "," and depth == 0:
            parts.append(word)
            word = ""
        else:
            word += ch
    parts.append(word)
    names = [m[1] for p in parts if (m := re.match(r"\s*\**(\w+)", p))]
    return [n for n in names if n not in ("self", "cls")], "..." in parts[-1]


def _check_signature(target: Any, params: str, where: str) -> None:
    names, more = _names(params)
    real = inspect.signature(target).parameters
    unknown = [n for n in names if n not in real]
    assert unknown == [], f"{where}: {unknown} not parameters of {inspect.signature(target)}"
    if not more:
        required = [
            n for n, p in real.items()
            if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
            and n not in ("self", "cls")
        ]  # fmt: skip
        assert set(required) <= set(names), (
            f"{where}: {inspect.signature(target)} requires {required}"
        )


_MODULE = re.compile(r"^# (\w+)\.py\b")
_DEF = re.compile(r"^(?P<indent> *)(?:@\w+ )?def (?P<name>\w+)\((?P<params>.*)")
_CLASS = re.compile(
    r"^(?:@dataclass\(frozen=True\) )?class (?P<name>\w+)(?:\((?P<base>\w+)\))?(?::(?P<fields>[^#]*))?"
)
_CONST = re.compile(r"^[A-Z0-9_]+ = ")


#: the sketched packages: heading of the section, package
SKETCHES = {"goniolab.optics": "goniolab.optics", "goniolab.surfaces": "goniolab.surfaces"}


def sketch_items() -> list[tuple[str, str]]:
    """(package.module, line) for every def, class and constant line of the API sketches."""
    items: list[tuple[str, str]] = []
    for heading, package in SKETCHES.items():
        items += _items(_block(heading, "python"), package)
    return items


def _items(block: str, package: str) -> list[tuple[str, str]]:
    items, module = [], ""
    for line in block.splitlines():
        if m := _MODULE.match(line):
            module = f"{package}.{m[1]}"
        elif _DEF.match(line) or _CLASS.match(line) or _CONST.match(line):
            items.append((module, line))
    return items


ITEMS = sketch_items()


def test_the_sketch_is_read() -> None:
    modules = {m.rsplit(".", 1)[1] for m, _ in ITEMS}
    assert {"heightmap", "surface", "fresnel", "apertures", "facet", "gloss_standards"} <= modules
    assert {"registry", "resolve", "synthetic"} <= modules
    assert len(ITEMS) >= 40


def _module(name: str) -> ModuleType:
    """``goniolab.optics.facet``, or a bare ``kirchhoff`` (a class line's comment) in optics."""
    return importlib.import_module(name if "." in name else f"goniolab.optics.{name}")


@pytest.mark.parametrize(
    ("module", "line"), ITEMS, ids=[f"{m.rsplit('.', 1)[1]}:{ln.strip()[:50]}" for m, ln in ITEMS]
)
def test_sketch_line_is_the_code(module: str, line: str) -> None:
    where = f"docs/ARCHITECTURE.md, {module}: {line.strip()}"
    mod = _module(module)
    if _CONST.match(line):
        for statement in line.split(";"):
            name, value = (s.strip() for s in statement.split("=", 1))
            assert eval(value, vars(mod)) == getattr(mod, name), where
        return
    if c := _CLASS.match(line):
        cls = getattr(mod, c["name"], None)
        if cls is None and "#" in line:  # "class X(Base)   # kirchhoff.py: ..." names its module
            cls = getattr(_module(line.split("#")[1].split(".py")[0].strip()), c["name"])
        assert inspect.isclass(cls), where
        if c["base"]:
            assert c["base"] in [b.__name__ for b in cls.__mro__], where
        sketched = [f.strip() for f in (c["fields"] or "").split(",") if f.strip()]
        if sketched and dataclasses.is_dataclass(cls):
            assert sketched == [f.name for f in dataclasses.fields(cls)], where
        elif sketched:  # a Protocol's members
            assert [f for f in sketched if not hasattr(cls, f)] == [], where
        return
    d = _DEF.match(line)
    assert d
    if d["indent"]:  # a method of the class above it in the sketch
        owner = _owner_of(module, line)
        _check_signature(getattr(owner, d["name"]), d["params"], where)
    else:
        _check_signature(getattr(mod, d["name"]), d["params"], where)


def _owner_of(module: str, line: str) -> type:
    """The class a sketched method line belongs to: the last class line above it."""
    owner = None
    for m, ln in ITEMS:
        if ln == line and m == module:
            break
        if (c := _CLASS.match(ln)) and not ln.startswith(" "):
            found = getattr(_module(m), c["name"], None)
            if found is None and "#" in ln:
                found = getattr(_module(ln.split("#")[1].split(".py")[0].strip()), c["name"])
            owner = found
    assert inspect.isclass(owner), line
    return owner


def test_signature_check_catches_a_renamed_parameter() -> None:
    from goniolab.optics.heightmap import fill_missing

    _check_signature(fill_missing, 'hm, method="nearest"|"mean"', "ok")
    with pytest.raises(AssertionError, match="mode"):
        _check_signature(fill_missing, 'hm, mode="nearest"', "renamed")


def test_lab_config_example_loads(tmp_path: Path) -> None:
    from goniolab.config import load_lab_config

    path = tmp_path / "lab.toml"
    path.write_text(_block("Lab config", "toml"), encoding="utf-8")
    config = load_lab_config(path)
    assert config.sample.map == "sample:wittmann-3"


def colour_names() -> list[tuple[str, str]]:
    """docs/ARCHITECTURE.md, "goniolab.colour": (module, name) for every backticked name the
    text gives under a module label `` `module`: ``."""
    section = DOC.split("## goniolab.colour", 1)[1].split("\n## ", 1)[0]
    section = " ".join(section.split())
    found = []
    parts = re.split(r"`(\w+)`:", section)  # [before, module, text, module, text, ...]
    for module, text in zip(parts[1::2], parts[2::2], strict=True):
        for token in re.findall(r"`([^`]+)`", text):
            m = re.fullmatch(r"(?:(\w+)\.)?(\w+)(?:\(.*\))?", token)
            if m is None or token.startswith("goniolab."):
                continue  # an expression, a path, an option, a key
            owner, name = m[1], m[2]
            if owner is not None and owner not in parts[1::2]:
                continue  # colour.sd_to_XYZ: the library's
            found.append((owner or module, name))
    return found


COLOUR_NAMES = colour_names()


def test_colour_section_is_read() -> None:
    assert len(COLOUR_NAMES) >= 25
    assert ("spectra", "check_spectrum") in COLOUR_NAMES


@pytest.mark.parametrize(
    ("module", "name"), COLOUR_NAMES, ids=[f"{m}.{n}" for m, n in COLOUR_NAMES]
)
def test_colour_section_names_exist(module: str, name: str) -> None:
    try:
        mod = importlib.import_module(f"goniolab.colour.{module}")
    except ModuleNotFoundError:
        pytest.fail(f"docs/ARCHITECTURE.md, goniolab.colour: there is no module {module!r}")
    if hasattr(mod, name):
        return
    # a method, written after its class: `Paint(...)`; `subsurface_brdf(...)`
    classes = [getattr(mod, n) for m, n in COLOUR_NAMES if m == module and hasattr(mod, n)]
    assert any(inspect.isclass(c) and hasattr(c, name) for c in classes), (
        f"docs/ARCHITECTURE.md: goniolab.colour.{module} has no {name}"
    )
