"""The one direction of imports between the rooms of the house (docs/ARCHITECTURE.md).

Read statically from the source (every ``import`` and ``from ... import``, including those
inside functions, which the lazy-import rule puts there), so a forbidden import is caught
even on a code path no test runs.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: room -> module prefixes its files may not import (the lab wiring and ``sim serve`` are
#: the only doors from the application into the simulator).
FORBIDDEN: dict[str, tuple[str, ...]] = {
    "drivers": ("goniolab", "sim"),
    "goniolab/optics": (
        "sim", "drivers", "goniolab.surfaces", "goniolab.scan", "goniolab.store",
        "goniolab.session", "goniolab.lab", "goniolab.commands", "goniolab.tui", "textual",
    ),
    "goniolab/colour": (
        "sim", "drivers", "goniolab.surfaces", "goniolab.scan", "goniolab.store",
        "goniolab.session", "goniolab.lab", "goniolab.commands", "goniolab.tui", "textual",
    ),
    "goniolab/surfaces": (
        "sim", "drivers", "goniolab.scan", "goniolab.store", "goniolab.session",
        "goniolab.lab", "goniolab.commands", "goniolab.tui", "textual",
    ),
    "goniolab/scan": ("sim", "goniolab.session", "goniolab.commands", "goniolab.tui", "textual"),
    "goniolab/store.py": ("sim", "goniolab.commands", "goniolab.tui", "textual"),
    "goniolab/session.py": ("sim", "goniolab.commands", "goniolab.tui", "textual"),
    "goniolab/commands": ("sim", "goniolab.tui", "textual"),
    "goniolab/tui": ("sim", "goniolab.commands"),
    "goniolab/cli.py": ("sim", "goniolab.tui", "textual"),
    "sim": (
        "goniolab.scan", "goniolab.session", "goniolab.store", "goniolab.lab",
        "goniolab.commands", "goniolab.tui", "textual",
    ),
}  # fmt: skip

#: the only files of the application that may import the simulator
SIM_DOORS = {"goniolab/lab.py", "goniolab/commands/sim.py"}

#: file -> prefixes it may import although its room may not: the doors between rooms
DOORS: dict[str, tuple[str, ...]] = {
    **dict.fromkeys(SIM_DOORS, ("sim",)),
    "goniolab/commands/tui.py": ("goniolab.tui",),  # `goniolab tui` starts the app
}


def imports_of(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.lineno, node.module))
    return out


def _hit(module: str, prefixes: tuple[str, ...]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def _files(room: str) -> list[Path]:
    target = ROOT / room
    return [target] if target.suffix == ".py" else sorted(target.rglob("*.py"))


@pytest.mark.parametrize("room", sorted(FORBIDDEN))
def test_room_imports_point_one_way(room: str) -> None:
    files = _files(room)
    assert files, f"{room} has no Python files: the table is out of date"
    bad = [
        f"{f.relative_to(ROOT)}:{line}: imports {mod}"
        for f in files
        for line, mod in imports_of(f)
        if _hit(mod, FORBIDDEN[room]) and not _hit(mod, DOORS.get(str(f.relative_to(ROOT)), ()))
    ]
    assert bad == [], "\n".join(bad)


def test_only_the_lab_wiring_imports_the_simulator() -> None:
    bad = [
        f"{f.relative_to(ROOT)}:{line}: imports {mod}"
        for f in sorted((ROOT / "goniolab").rglob("*.py"))
        if str(f.relative_to(ROOT)) not in SIM_DOORS
        for line, mod in imports_of(f)
        if _hit(mod, ("sim",))
    ]
    assert bad == [], "\n".join(bad)


#: what the doors take from the simulator: the twin as ``sim/assembly.py`` assembles it, and
#: the wire server it runs (the lab only chooses; it builds no simulated device itself)
SIM_DOOR_MODULES = ("sim.assembly", "sim.wire")


def test_the_lab_takes_the_twin_as_sim_assembles_it() -> None:
    bad = [
        f"{name}:{line}: imports {mod}"
        for name in sorted(SIM_DOORS)
        for line, mod in imports_of(ROOT / name)
        if _hit(mod, ("sim",)) and not _hit(mod, SIM_DOOR_MODULES)
    ]
    assert bad == [], "\n".join(bad)


def test_the_checker_sees_imports_inside_functions(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from sim.motion import SimMotor\n    import textual.app\n")
    assert imports_of(probe) == [(2, "sim.motion"), (3, "textual.app")]


#: rooms whose modules stay under :data:`MAX_MODULE_LINES` lines (issue 24: rooms of one job)
SIZED_ROOMS = ("drivers",)
MAX_MODULE_LINES = 800


def oversized(files: list[Path]) -> dict[str, int]:
    """``{file: lines}`` of the files longer than :data:`MAX_MODULE_LINES` lines."""
    out: dict[str, int] = {}
    for f in files:
        n = len(f.read_text(encoding="utf-8").splitlines())
        if n > MAX_MODULE_LINES:
            out[str(f.relative_to(ROOT)) if f.is_relative_to(ROOT) else f.name] = n
    return out


@pytest.mark.parametrize("room", SIZED_ROOMS)
def test_no_module_is_over_the_size_limit(room: str) -> None:
    files = _files(room)
    assert files, f"{room} has no Python files: the table is out of date"
    assert oversized(files) == {}, f"modules over {MAX_MODULE_LINES} lines"


def test_the_size_check_sees_a_long_module(tmp_path: Path) -> None:
    long, short = tmp_path / "long.py", tmp_path / "short.py"
    long.write_text("x = 1\n" * (MAX_MODULE_LINES + 1))
    short.write_text("x = 1\n" * MAX_MODULE_LINES)
    assert oversized([long, short]) == {"long.py": MAX_MODULE_LINES + 1}
