"""The one direction of imports between the rooms of the house (docs/ARCHITECTURE.md).

Read statically from the source (every ``import`` and ``from ... import``, including those
inside functions, which the lazy-import rule puts there), so a forbidden import is caught
even on a code path no test runs.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: room -> module prefixes its files may not import (the lab wiring and ``sim serve`` are
#: the only doors from the application into the simulator).
FORBIDDEN: dict[str, tuple[str, ...]] = {
    "labtoml": ("goniolab", "drivers", "sim"),  # the one TOML loader, below every room
    "drivers": ("goniolab", "sim"),
    "goniolab/optics": (
        "sim", "drivers", "goniolab.surfaces", "goniolab.scan", "goniolab.store",
        "goniolab.session", "goniolab.lab_wiring", "goniolab.commands", "goniolab.tui", "textual",
    ),
    "goniolab/colour": (
        "sim", "drivers", "goniolab.surfaces", "goniolab.scan", "goniolab.store",
        "goniolab.session", "goniolab.lab_wiring", "goniolab.commands", "goniolab.tui", "textual",
    ),
    "goniolab/surfaces": (
        "sim", "drivers", "goniolab.scan", "goniolab.store", "goniolab.session",
        "goniolab.lab_wiring", "goniolab.commands", "goniolab.tui", "textual",
    ),
    "goniolab/scan": ("sim", "goniolab.session", "goniolab.commands", "goniolab.tui", "textual"),
    "goniolab/store": (
        "sim", "drivers", "goniolab.commands", "goniolab.api", "goniolab.tui", "textual",
        "goniolab.session", "goniolab.scan", "goniolab.lab_wiring", "goniolab.export",
        "goniolab.datasets",
    ),
    "goniolab/session.py": ("sim", "goniolab.commands", "goniolab.tui", "textual"),
    "goniolab/commands": ("sim", "goniolab.tui", "textual"),
    "goniolab/tui": ("sim", "goniolab.commands"),
    "goniolab/cli.py": ("sim", "goniolab.tui", "textual"),
    "sim": (
        "goniolab.scan", "goniolab.session", "goniolab.store", "goniolab.lab_wiring",
        "goniolab.commands", "goniolab.tui", "textual",
    ),
}  # fmt: skip

#: the only files of the application that may import the simulator
SIM_DOORS = {"goniolab/lab_wiring.py", "goniolab/commands/sim.py"}

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


#: The most lines a module of these rooms may have (issue 24: rooms of one job each).
MAX_MODULE_LINES = 800
#: Every room is held to :data:`MAX_MODULE_LINES`.
SIZED_ROOMS = ("goniolab", "drivers", "sim")
#: module -> why it may be longer for now. Temporary: each is split by another engineer this
#: round; the lead removes its entry after merging that split (a stale entry fails the test).
OVERSIZED_FOR_NOW: dict[str, str] = {}


def module_lines(room: str) -> dict[str, int]:
    """``path -> number of lines`` of every module of ``room``."""
    return {
        f.relative_to(ROOT).as_posix(): len(f.read_text(encoding="utf-8").splitlines())
        for f in _files(room)
    }


@pytest.mark.parametrize("room", SIZED_ROOMS)
def test_no_module_of_a_split_room_is_over_800_lines(room: str) -> None:
    lines = module_lines(room)
    assert len(lines) > 10, f"{room} has (almost) no Python files: the table is out of date"
    big = {
        name: n
        for name, n in lines.items()
        if n > MAX_MODULE_LINES and name not in OVERSIZED_FOR_NOW
    }
    assert big == {}, big


def test_the_oversized_exceptions_are_still_needed() -> None:
    lines = {name: n for room in SIZED_ROOMS for name, n in module_lines(room).items()}
    stale = sorted(n for n in OVERSIZED_FOR_NOW if lines.get(n, 0) <= MAX_MODULE_LINES)
    assert stale == [], f"split since (or gone): remove from OVERSIZED_FOR_NOW: {stale}"


def _names_from(path: Path, package: str) -> list[tuple[int, str, str]]:
    """``(line, module, name)`` of every ``from package[.x] import name`` in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    return [
        (node.lineno, node.module, alias.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module
        if _hit(node.module, (package,))
        for alias in node.names
    ]


def test_the_store_is_used_through_its_public_names() -> None:
    """Outside goniolab/store, a name comes from ``goniolab.store`` and is in its
    ``__all__`` (no ``_private`` name of one of its modules, no reach into a module that
    the package does not export from), so the rooms inside may move."""
    import goniolab.store as store

    outside = [
        f
        for top in ("goniolab", "drivers", "sim", "tests", "bench")
        for f in sorted((ROOT / top).rglob("*.py"))
        if not f.is_relative_to(ROOT / "goniolab" / "store")
    ]
    bad = [
        f"{f.relative_to(ROOT)}:{line}: from {mod} import {name}"
        for f in outside
        for line, mod, name in _names_from(f, "goniolab.store")
        if mod != "goniolab.store" or name not in store.__all__
    ]
    assert bad == [], "\n".join(bad)


#: what goniolab/optics may import besides the standard library and itself: the numerics,
#: colour-science (the CIE tables of goniolab/optics/iso2813_weighting.py, imported on use) and the
#: stdlib-only lazy-export helper of the package's __init__ (goniolab/lazy_imports.py)
OPTICS_MAY_IMPORT = (
    "numpy",
    "scipy",
    "numba",
    "colour",
    "goniolab.optics",
    "goniolab.lazy_imports",
)


def test_optics_imports_only_numerics_and_itself() -> None:
    bad = [
        f"{f.relative_to(ROOT)}:{line}: imports {mod}"
        for f in _files("goniolab/optics")
        for line, mod in imports_of(f)
        if mod.split(".")[0] not in sys.stdlib_module_names and not _hit(mod, OPTICS_MAY_IMPORT)
    ]
    assert bad == [], "\n".join(bad)


def test_optics_uses_no_relative_imports() -> None:
    # imports_of reads absolute imports only: a relative one would slip past the rules above
    bad = [
        f"{f.relative_to(ROOT)}:{node.lineno}"
        for f in _files("goniolab/optics")
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8")))
        if isinstance(node, ast.ImportFrom) and node.level > 0
    ]
    assert bad == [], bad


def test_the_optics_checker_catches_a_foreign_import(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text("import math\nimport numpy as np\nfrom goniolab.config import LabConfig\n")
    found = [
        m
        for _, m in imports_of(probe)
        if m.split(".")[0] not in sys.stdlib_module_names and not _hit(m, OPTICS_MAY_IMPORT)
    ]
    assert found == ["goniolab.config"]


# --------------------------------------------------------------------- names between modules
#: The packages whose module names are unique and whose ``_private`` names stay home (issue 24).
NAMED_ROOMS = ("goniolab", "drivers", "sim", "labtoml")


def repeated_module_names(paths: list[str]) -> dict[str, list[str]]:
    """Basename -> the paths sharing it, for every basename used twice (``__init__.py`` aside).

    ``goniolab/commands/<name>.py`` take part: a sub-command is found by its module name, so a
    library module may not wear a sub-command's name either.
    """
    by_name: dict[str, list[str]] = {}
    for path in paths:
        name = path.rsplit("/", 1)[-1]
        if name != "__init__.py":
            by_name.setdefault(name, []).append(path)
    return {name: sorted(where) for name, where in by_name.items() if len(where) > 1}


def _named_room_files() -> list[Path]:
    return [f for room in NAMED_ROOMS for f in sorted((ROOT / room).rglob("*.py"))]


def test_no_module_name_is_used_twice() -> None:
    paths = [f.relative_to(ROOT).as_posix() for f in _named_room_files()]
    assert len(paths) > 100, "the rooms were not found"
    assert repeated_module_names(paths) == {}


def test_the_name_checker_catches_a_repeat() -> None:
    paths = ["goniolab/__init__.py", "sim/__init__.py", "goniolab/commands/fit.py"]
    paths += ["goniolab/optics/fit.py", "goniolab/optics/psd.py", "sim/wire/modbus.py"]
    assert repeated_module_names(paths) == {
        "fit.py": ["goniolab/commands/fit.py", "goniolab/optics/fit.py"]
    }


#: ``file: module.name`` -> why it may import another module's ``_private`` name (none now:
#: what the faces shared became public names of the application layer, goniolab/app/).
PRIVATE_IMPORT_EXCEPTIONS: dict[str, str] = {}


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _is_module(dotted: str) -> bool:
    base = ROOT.joinpath(*dotted.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def _inside(package: str, parent: str) -> bool:
    return package == parent or package.startswith(parent + ".")


def private_imports(path: Path, module: str) -> list[tuple[int, str]]:
    """``(line, module.name)`` of every ``_private`` name of another module that ``path``
    (the module ``module``) imports or reads as an attribute of an imported module.

    A private *module* (``goniolab/optics/_kernels.py``, ``goniolab/surfaces/_common.py``) is
    its package's internals: modules inside that package may import it and its names, modules
    outside may not.
    """
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: list[tuple[int, str]] = []
    bound: dict[str, str] = {}  # local name -> the module of ours it is bound to

    def private_path(line: int, dotted: str) -> None:
        parts = dotted.split(".")
        for i, part in enumerate(parts):
            if _private(part) and not _inside(package, ".".join(parts[:i])):
                out.append((line, dotted))
                return

    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] not in NAMED_ROOMS:
                continue
            private_path(node.lineno, node.module)
            for alias in node.names:
                target = f"{node.module}.{alias.name}"
                if _is_module(target):
                    bound[alias.asname or alias.name] = target
                    private_path(node.lineno, target)
                elif _private(alias.name) and node.module != module:
                    out.append((node.lineno, target))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in NAMED_ROOMS:
                    private_path(node.lineno, alias.name)
                    top = alias.name.split(".")[0]
                    bound[alias.asname or top] = alias.name if alias.asname else top
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Attribute) and _private(node.attr)):
            continue
        chain: list[str] = []
        value: ast.expr = node.value
        while isinstance(value, ast.Attribute):
            chain.append(value.attr)
            value = value.value
        if not (isinstance(value, ast.Name) and value.id in bound):
            continue
        owner = ".".join([bound[value.id], *reversed(chain)])
        if not _is_module(owner) or owner == module:
            continue
        target = f"{owner}.{node.attr}"
        if _is_module(target):
            private_path(node.lineno, target)
        else:
            out.append((node.lineno, target))
    return sorted(set(out))


def _dotted(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_no_module_imports_another_modules_private_name() -> None:
    found = {
        f"{f.relative_to(ROOT).as_posix()}: {target}": line
        for f in _named_room_files()
        for line, target in private_imports(f, _dotted(f))
    }
    bad = [f"{where} (line {line})" for where, line in found.items()]
    bad = [b for b in bad if b.split(" (line")[0] not in PRIVATE_IMPORT_EXCEPTIONS]
    assert bad == [], "\n".join(bad)
    stale = sorted(set(PRIVATE_IMPORT_EXCEPTIONS) - set(found))
    assert stale == [], f"exceptions no longer needed (remove them): {stale}"
    assert len(PRIVATE_IMPORT_EXCEPTIONS) <= 6, "a handful of exceptions, no more"


def test_the_private_import_checker_catches_each_form(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text(
        "from goniolab.optics.psd import _helper, psd2\n"  # a private name of another module
        "from goniolab.optics import _kernels\n"  # a private module, from outside its package
        "import goniolab.optics.heightmap as hm\n"
        "hm._secret\n"  # a private attribute of an imported module
        "from goniolab.surfaces._common import ReadOptions\n"  # inside a private module
        "from goniolab.probe import _own\n"  # its own private name: fine
        "from goniolab.__init__ import __doc__\n"  # a dunder: fine
    )
    assert private_imports(probe, "goniolab.probe") == [
        (1, "goniolab.optics.psd._helper"),
        (2, "goniolab.optics._kernels"),
        (4, "goniolab.optics.heightmap._secret"),
        (5, "goniolab.surfaces._common"),
    ]
    # inside the package, its private module is its own business
    assert private_imports(probe, "goniolab.optics.probe") == [
        (1, "goniolab.optics.psd._helper"),
        (4, "goniolab.optics.heightmap._secret"),
        (5, "goniolab.surfaces._common"),
        (6, "goniolab.probe._own"),  # now another module's
    ]


# --------------------------------------------------------------------- faces over the use cases
#: The faces of the use cases on a lab (issue 24): they parse, call goniolab.app and present.
LAB_FACES = (
    "goniolab/commands/scan.py", "goniolab/commands/gloss.py", "goniolab/commands/calibrate.py",
    "goniolab/commands/lab.py", "goniolab/commands/sim.py", "goniolab/commands/tui.py",
    "goniolab/batch.py", "goniolab/bluesky_lab.py", "goniolab/tui/session_backend.py",
)  # fmt: skip
#: What a face may not import itself: the application layer loads the config, opens the
#: store, builds the plan and opens the session.
FACE_FORBIDDEN = ("goniolab.config", "goniolab.store", "goniolab.scan.plans", "goniolab.session")
#: ``file: module`` -> why that face imports it all the same.
FACE_IMPORT_EXCEPTIONS: dict[str, str] = {
    "goniolab/commands/scan.py: goniolab.scan.plans": "DEFAULT_REPEATS, the --repeats default "
    "shown at --help (stdlib-light; the TUI's form shows the same)",
    "goniolab/bluesky_lab.py: goniolab.scan.plans": "DEFAULT_REPEATS, inplane_scan's default "
    "repeats (the plan itself is built by goniolab.app.lab_setup.brdf_plan)",
    "goniolab/tui/session_backend.py: goniolab.session": "the TUI keeps one ScanSession and one "
    "GlossSession open while it runs (pause, resume, abort, coalesced gloss readings on the "
    "scan's lab): a long-lived session, not one use case",
    "goniolab/tui/session_backend.py: goniolab.scan.plans": "DEFAULT_REPEATS for the form, "
    "BrdfPlan.from_dict to replay a stored run, GlossPlan for one reading",
    "goniolab/tui/session_backend.py: goniolab.store": "RunMeta of the identity dialog; "
    "StoreError, a store failure during a run shown as an event",
}
#: The functions of goniolab/api.py that are a lab face (the rest of the notebook API is
#: another face's: predictions and stored runs).
API_LAB_FUNCTIONS = ("run_scan_async", "_run_blocking", "_blocking")


def _runtime_imports(tree: ast.AST) -> list[tuple[int, str]]:
    """Imports outside ``if TYPE_CHECKING:`` blocks (a type named in an annotation loads
    nothing and uses nothing)."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    out: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.lineno, node.module))
    return out


def face_imports(path: Path) -> list[tuple[int, str]]:
    """``(line, module)`` of the forbidden modules a lab face imports at run time."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    return [(line, mod) for line, mod in _runtime_imports(tree) if _hit(mod, FACE_FORBIDDEN)]


def test_lab_faces_leave_config_store_plans_and_session_to_the_app_layer() -> None:
    found: dict[str, int] = {}
    for name in LAB_FACES:
        for line, mod in face_imports(ROOT / name):
            top = next(p for p in FACE_FORBIDDEN if _hit(mod, (p,)))
            found.setdefault(f"{name}: {top}", line)
    api = ast.parse((ROOT / "goniolab" / "api.py").read_text(encoding="utf-8"))
    for node in api.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and (
            node.name in API_LAB_FUNCTIONS
        ):
            for line, mod in _runtime_imports(node):
                if _hit(mod, FACE_FORBIDDEN):
                    found.setdefault(f"goniolab/api.py: {mod}", line)
    bad = [f"{where} (line {line})" for where, line in found.items()
           if where not in FACE_IMPORT_EXCEPTIONS]  # fmt: skip
    assert bad == [], "\n".join(bad)
    stale = sorted(set(FACE_IMPORT_EXCEPTIONS) - set(found))
    assert stale == [], f"exceptions no longer needed (remove them): {stale}"


def test_the_face_checker_sees_runtime_imports_only(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from goniolab.store import RunStore\n"
        "def f():\n    from goniolab.config import load_lab_config\n"
        "    import goniolab.session\n    from goniolab.app.lab_setup import open_store\n"
    )
    assert face_imports(probe) == [(5, "goniolab.config"), (6, "goniolab.session")]


# --------------------------------------------------------------------- one TOML loader
#: The one module that parses TOML (issue 24: TOML was read three ways, each with its own
#: words for the same error); every other module calls :func:`labtoml.read_toml` or
#: :func:`labtoml.parse_toml`.
TOML_LOADER = "labtoml/__init__.py"
#: file -> why it may still import :mod:`tomllib` itself (temporary).
TOMLLIB_EXCEPTIONS: dict[str, str] = {}


def tomllib_importers() -> dict[str, int]:
    """``path -> line`` of every module of the house that imports :mod:`tomllib`."""
    found: dict[str, int] = {}
    for room in NAMED_ROOMS:
        for f in _files(room):
            for line, mod in imports_of(f):
                if _hit(mod, ("tomllib", "tomli", "toml")):
                    found.setdefault(f.relative_to(ROOT).as_posix(), line)
    return found


def test_toml_is_parsed_by_the_one_loader() -> None:
    found = tomllib_importers()
    assert TOML_LOADER in found, "the loader no longer imports tomllib: the table is stale"
    bad = sorted(f"{name}:{line}" for name, line in found.items() if name != TOML_LOADER)
    bad = [b for b in bad if b.split(":")[0] not in TOMLLIB_EXCEPTIONS]
    assert bad == [], "\n".join(bad)
    stale = sorted(set(TOMLLIB_EXCEPTIONS) - set(found))
    assert stale == [], f"exceptions no longer needed (remove them): {stale}"


def test_the_toml_loader_imports_only_the_standard_library() -> None:
    mods = [m for _, m in imports_of(ROOT / TOML_LOADER)]
    assert "tomllib" in mods
    assert [m for m in mods if m.split(".")[0] not in sys.stdlib_module_names] == []


# --------------------------------------------------------------------- faces call the app layer
#: The faces of the use cases without a lab (issue 24): they parse, call
#: :mod:`goniolab.app` and present; none opens a store, loads a config or builds a plan.
NO_LAB_FACES = tuple(
    f"goniolab/commands/{name}.py"
    for name in ("predict", "_colour", "runs", "plot", "render", "fit", "samples", "_surface_args")
)
#: What a face may not import: the store, the lab config, the plans (goniolab.app does that).
NO_LAB_FORBIDDEN = ("goniolab.store", "goniolab.config", "goniolab.scan.plans")
#: What a face may import from goniolab: the application layer, the one error family, its
#: fellow faces, and presentation helpers (JSON/text output, netCDF of a prediction) and the
#: registries whose names its options offer.
NO_LAB_MAY_IMPORT = (
    "goniolab.app", "goniolab.errors", "goniolab.commands", "goniolab.jsonout",
    "goniolab.textsafe", "goniolab.datasets", "goniolab.model_registry", "goniolab.export",
)  # fmt: skip
#: ``file: module`` -> why that face imports it beyond :data:`NO_LAB_MAY_IMPORT`.
NO_LAB_IMPORT_EXCEPTIONS: dict[str, str] = {
    "goniolab/commands/runs.py: goniolab.colour.difference": "the colour table's dL*..dE00 columns",
    "goniolab/commands/runs.py: goniolab.colour.multiangle": "the colour table's flop index line",
}
#: api.py's lab functions (run_scan and its helpers) belong to the other half of issue 24
#: (goniolab.app's scan use cases); the module-level imports they need are listed here.
API_LAB_NAMES = {
    "_ScanControl", "_run_blocking", "_ScanCall", "_scan_call", "_scan_in_this_thread",
    "run_scan", "run_scan_async", "_scan", "_angles", "_blocking",
}  # fmt: skip
API_MODULE_IMPORT_EXCEPTIONS: dict[str, str] = {
    "goniolab.store": "run_scan opens its store (RunMeta, RunStore); Run.record's type",
    "goniolab.scan.plans": "run_scan's default repeats (DEFAULT_REPEATS)",
}


def _goniolab_imports(nodes: list[ast.stmt]) -> list[tuple[int, str]]:
    """``(line, module)`` of every goniolab import in ``nodes`` (functions included;
    ``from goniolab import x`` as ``goniolab.x``)."""
    out: list[tuple[int, str]] = []
    for sub in (s for node in nodes for s in ast.walk(node)):
        if isinstance(sub, ast.Import):
            out += [(sub.lineno, a.name) for a in sub.names]
        elif isinstance(sub, ast.ImportFrom) and sub.level == 0 and sub.module == "goniolab":
            out += [(sub.lineno, f"goniolab.{a.name}") for a in sub.names]
        elif isinstance(sub, ast.ImportFrom) and sub.level == 0 and sub.module:
            out.append((sub.lineno, sub.module))
    return [(line, mod) for line, mod in out if mod.split(".")[0] == "goniolab"]


def test_the_faces_without_a_lab_import_the_app_layer_not_the_store() -> None:
    bad: list[str] = []
    seen: set[str] = set()
    for name in NO_LAB_FACES:
        tree = ast.parse((ROOT / name).read_text(encoding="utf-8"))
        for line, mod in _goniolab_imports(tree.body):
            key = f"{name}: {mod}"
            if key in NO_LAB_IMPORT_EXCEPTIONS:
                seen.add(key)
            elif _hit(mod, NO_LAB_FORBIDDEN) or not _hit(mod, NO_LAB_MAY_IMPORT):
                bad.append(f"{name}:{line}: imports {mod}")
    assert bad == [], "\n".join(bad)
    assert sorted(set(NO_LAB_IMPORT_EXCEPTIONS) - seen) == [], "exceptions no longer needed"
    # the notebook face: every function but the lab's calls the app layer
    tree = ast.parse((ROOT / "goniolab/api.py").read_text(encoding="utf-8"))
    own = [n for n in tree.body if isinstance(n, ast.FunctionDef | ast.ClassDef)
           and n.name not in API_LAB_NAMES]  # fmt: skip
    bad = [f"api.py:{line}: imports {mod}" for line, mod in _goniolab_imports(own)
           if _hit(mod, NO_LAB_FORBIDDEN) or _hit(mod, ("goniolab.commands",))]  # fmt: skip
    top = [n for n in tree.body if isinstance(n, ast.Import | ast.ImportFrom)]
    bad += [f"api.py:{line}: imports {mod}" for line, mod in _goniolab_imports(top)
            if _hit(mod, NO_LAB_FORBIDDEN) and mod not in API_MODULE_IMPORT_EXCEPTIONS]  # fmt: skip
    assert bad == [], "\n".join(bad)


def test_the_face_checker_sees_a_store_opened_in_a_function(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text(
        "def f():\n    from goniolab.store import RunStore\nimport goniolab.app\n"
        "from goniolab import config\n"
    )
    found = _goniolab_imports(ast.parse(probe.read_text()).body)
    assert found == [(2, "goniolab.store"), (3, "goniolab.app"), (4, "goniolab.config")]
    assert [m for _, m in found if _hit(m, NO_LAB_FORBIDDEN)] == [
        "goniolab.store",
        "goniolab.config",
    ]


#: Every module of the application layer.
APP_MODULES = tuple(
    sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "goniolab" / "app").glob("*.py"))
)


def test_the_app_layer_imports_no_face() -> None:
    faces = ("goniolab.commands", "goniolab.api", "goniolab.tui", "goniolab.cli", "textual", "sim")
    bad = [
        f"{name}:{line}: imports {mod}"
        for name in APP_MODULES
        for line, mod in imports_of(ROOT / name)
        if _hit(mod, faces)
    ]
    assert bad == [], "\n".join(bad)
