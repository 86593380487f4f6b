"""The Python the docs ask a reader to type works against the real code (docs that cannot
go stale).

docs/HARDWARE_BRINGUP.md and docs/WIRE_SIM.md show ``$ [PYTHONPATH=$PWD] .venv/bin/python -c
"..."`` commands. Every one of them compiles, its imports exist, and every call of an
imported class, function or of a method on an object built from one binds to the real
signature (a renamed keyword or method fails here). Those that need no instrument and show
what they print (the interlock check of HARDWARE_BRINGUP.md, section 3) are run and their
output compared to the character; WIRE_SIM.md's, which need a running ``goniolab sim
serve``, are run by tests/test_docs_fresh.py.
"""

from __future__ import annotations

import ast
import enum
import importlib
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "docs" / "HARDWARE_BRINGUP.md", ROOT / "docs" / "WIRE_SIM.md"]
_CONSOLE = re.compile(r"^```console\n(.*?)^```", re.S | re.M)
_COMMAND = re.compile(
    r'^\$ (?:PYTHONPATH=\$PWD )?\.venv/bin/python -c "\n(?P<code>.*?)"\n(?P<out>.*?)(?=^\$ |\Z)',
    re.S | re.M,
)


def snippets(text: str) -> list[tuple[str, str]]:
    """The ``python -c`` programs of the console blocks and the lines each is shown printing."""
    found = []
    for block in _CONSOLE.findall(text):
        found += [(m["code"], m["out"]) for m in _COMMAND.finditer(block)]
    return found


ALL = [(doc.name, code, out) for doc in DOCS for code, out in snippets(doc.read_text())]


def test_the_docs_show_snippets() -> None:
    assert [d for d, _, _ in ALL].count("HARDWARE_BRINGUP.md") == 4
    assert [d for d, _, _ in ALL].count("WIRE_SIM.md") == 3
    assert any(out for _, _, out in ALL if out)


def _imported(tree: ast.Module) -> dict[str, Any]:
    names: dict[str, Any] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            module = importlib.import_module(node.module)
            for alias in node.names:
                assert hasattr(module, alias.name), f"{node.module} has no {alias.name}"
                names[alias.asname or alias.name] = getattr(module, alias.name)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                names[alias.asname or alias.name] = importlib.import_module(alias.name)
    return names


def _check_call(target: Any, call: ast.Call, where: str, *, method: bool = False) -> None:
    try:
        signature = inspect.signature(target)
    except (TypeError, ValueError):  # a builtin without a signature
        return
    if any(isinstance(a, ast.Starred) for a in call.args) or any(
        k.arg is None for k in call.keywords
    ):
        return
    try:
        signature.bind(
            *[None] * (len(call.args) + method), **{k.arg: None for k in call.keywords if k.arg}
        )
    except TypeError as exc:
        pytest.fail(
            f"{where}: {ast.unparse(call)} does not fit {target.__qualname__}{signature}: {exc}"
        )


def _callee(names: dict[str, Any], func: ast.expr) -> Any:
    """What ``Name(...)`` or ``module.Name(...)`` calls, when the snippet imported it."""
    if isinstance(func, ast.Name):
        return names.get(func.id)
    if isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name):
        module = names.get(func.value.id)
        return getattr(module, func.attr, None) if inspect.ismodule(module) else None
    return None


def check_calls(code: str, where: str) -> int:
    """Bind every call of an imported name, and of a method on a variable assigned from an
    imported class's constructor, to the real signature; the number of calls checked."""
    tree = ast.parse(code)
    names = _imported(tree)
    instances: dict[str, type] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
            made = _callee(names, node.value.func)
            if isinstance(made, type):
                instances.update({t.id: made for t in node.targets if isinstance(t, ast.Name)})
    checked = 0
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Name) and func.id in names and callable(names[func.id]):
            _check_call(names[func.id], node, where)
            checked += 1
        elif isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name):
            owner = func.value.id
            if owner in instances:
                cls = instances[owner]
                assert hasattr(cls, func.attr), f"{where}: {cls.__name__} has no {func.attr}()"
                plain = isinstance(
                    inspect.getattr_static(cls, func.attr), staticmethod | classmethod
                )
                _check_call(getattr(cls, func.attr), node, where, method=not plain)
                checked += 1
            elif inspect.ismodule(names.get(owner)):  # serial.Serial(...)
                module = names[owner]
                assert hasattr(module, func.attr), f"{where}: {owner} has no {func.attr}"
                _check_call(getattr(module, func.attr), node, where)
                checked += 1
    return checked


@pytest.mark.parametrize(
    ("doc", "code", "out"), ALL, ids=[f"{d}-{i}" for i, (d, _, _) in enumerate(ALL)]
)
def test_snippet_calls_fit_the_code(doc: str, code: str, out: str) -> None:
    assert check_calls(code, doc) >= 2


def test_check_calls_catches_a_renamed_keyword_or_method() -> None:
    code = "from drivers.glossmeter import Zgm1120\ng = Zgm1120(port='x', serial='1')\n"
    with pytest.raises(pytest.fail.Exception, match="serial"):
        check_calls(code, "t")
    code = "from drivers.glossmeter import Zgm1120\ng = Zgm1120(port='x')\ng.measure_gloss()\n"
    with pytest.raises(AssertionError, match="measure_gloss"):
        check_calls(code, "t")


OFFLINE = [(doc, code, out) for doc, code, out in ALL if doc == "HARDWARE_BRINGUP.md" and out]


@pytest.mark.parametrize(
    ("doc", "code", "out"), OFFLINE, ids=[f"{d}-{i}" for i, (d, _, _) in enumerate(OFFLINE)]
)
def test_offline_snippet_prints_what_the_doc_shows(doc: str, code: str, out: str) -> None:
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
        env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout == out, f"{doc} is stale: it shows\n{out}\nthe code prints\n{done.stdout}"


def test_an_offline_snippet_is_run() -> None:
    assert len(OFFLINE) == 1


def _call_defaults(sketch: str) -> tuple[str, dict[str, str]]:
    """``Name(pos, *, key=value, ...)`` -> ("Name", {key: value}) (positional names dropped)."""
    name, params = sketch.split("(", 1)
    found = dict(re.findall(r"(\w+)=([^,)]+)", params))
    return name.strip(), found


def test_protocols_md_library_notes_are_the_installed_pymodbus() -> None:
    """docs/PROTOCOLS.md, "Library notes": the pymodbus minor it names is the one pyproject
    pins and the one installed, and the client signatures it quotes have those defaults."""
    import pymodbus
    import pymodbus.client

    text = " ".join((ROOT / "docs" / "PROTOCOLS.md").read_text(encoding="utf-8").split())
    notes = text.split("## Library notes", 1)[1]
    version = re.search(r"pymodbus (\d+\.\d+):", notes)
    assert version, "docs/PROTOCOLS.md: the library notes name no pymodbus version"
    assert pymodbus.__version__.startswith(version[1] + ".")
    pyproject = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert f'"pymodbus>={version[1]},' in pyproject
    sketches = re.findall(r"`(Modbus(?:Tcp|Serial)Client\([^`]*\*, [^`]*\))`", notes)
    assert len(sketches) == 2, sketches
    for sketch in sketches:
        name, defaults = _call_defaults(sketch)
        real = inspect.signature(getattr(pymodbus.client, name)).parameters
        for key, value in defaults.items():
            default = real[key].default
            if isinstance(default, enum.Enum):
                shown = f"{type(default).__name__}.{default.name}"
            else:
                shown = repr(default)
            assert value.strip() == shown, (name, key, value, default)


def test_hardware_bringup_move_time_is_the_trapezoid() -> None:
    """docs/HARDWARE_BRINGUP.md's expected move time of the slow jog is what the drivers'
    trapezoid timing (also the dry run's and the twin's) gives."""
    from drivers.timing import trapezoid_duration_s

    text = " ".join((ROOT / "docs" / "HARDWARE_BRINGUP.md").read_text(encoding="utf-8").split())
    m = re.search(
        r"\((?P<d>[\d.]+) deg at (?P<v>[\d.]+) deg/s, (?P<a>[\d.]+) deg/s\^2: about (?P<t>[\d.]+) s\)",
        text,
    )
    assert m, "docs/HARDWARE_BRINGUP.md no longer states the jog's move time"
    t = trapezoid_duration_s(float(m["d"]), float(m["v"]), float(m["a"]))
    assert t == pytest.approx(float(m["t"]), abs=0.05)


def test_readme_python_blocks_fit_the_code() -> None:
    """The README's Python blocks (the notebook API, run by tests/test_api.py; the bluesky
    plan, which needs the bluesky extra to run) import what exists and call it with
    parameters the real signatures take."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 2
    for block in blocks:
        assert check_calls(block, "README.md") >= 3
