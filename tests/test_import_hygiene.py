"""Import rules of docs/ARCHITECTURE.md, checked in a fresh interpreter per rule
(harlequin's tests/unit_tests/test_import_hygiene.py style): import every module of a
package, then look at ``sys.modules``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: what every package imports on its way in: the ``goniolab`` package itself, its
#: stdlib-only lazy re-export helper (goniolab/lazy_imports.py, PEP 562) and the version constant
#: (goniolab/_version.py, one string)
PACKAGE_ROOT = ("goniolab", "goniolab.lazy_imports", "goniolab._version")

_PROBE = """
import importlib, json, pkgutil, sys
skip = {skip!r}
imported = []

def walk(name):
    if any(name == s or name.startswith(s + ".") for s in skip):
        return  # skipped before import: a package is never imported just to be walked
    module = importlib.import_module(name)
    imported.append(name)
    for info in pkgutil.iter_modules(getattr(module, "__path__", [])):
        walk(name + "." + info.name)

for pkg_name in {packages!r}:
    walk(pkg_name)
print(json.dumps({{"imported": imported, "modules": sorted(sys.modules)}}))
"""


def loaded_after_importing(
    packages: list[str], skip: tuple[str, ...] = ()
) -> tuple[list[str], set[str]]:
    code = _PROBE.format(packages=packages, skip=skip)
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    data = json.loads(out.stdout.strip().splitlines()[-1])
    return data["imported"], set(data["modules"])


def offenders(
    modules: set[str], forbidden: tuple[str, ...], allowed: tuple[str, ...] = ()
) -> list[str]:
    def hit(m: str, prefixes: tuple[str, ...]) -> bool:
        return any(m == p or m.startswith(p + ".") for p in prefixes)

    return sorted(m for m in modules if hit(m, forbidden) and not hit(m, allowed))


def test_optics_is_pure() -> None:
    imported, modules = loaded_after_importing(["goniolab.optics"])
    assert "goniolab.optics.facet" in imported  # the probe really walked the package
    # the bare ``goniolab`` package (its __init__) is the parent of optics, not a dependency
    bad = offenders(modules, ("goniolab", "drivers", "sim", "textual"), ("goniolab.optics",))
    assert [m for m in bad if m not in PACKAGE_ROOT] == [], bad


def test_drivers_import_no_goniolab_or_sim() -> None:
    imported, modules = loaded_after_importing(["drivers"])
    assert "drivers.modbus_stepper" in imported and "drivers.goniometer" in imported
    assert offenders(modules, ("goniolab", "sim", "textual")) == []


def test_sim_imports_only_physics_and_surfaces_from_goniolab() -> None:
    imported, modules = loaded_after_importing(["sim"])
    assert "sim.wire.lab_server" in imported and "sim.instruments" in imported
    allowed = ("goniolab.optics", "goniolab.colour", "goniolab.surfaces", "goniolab.errors")
    bad = offenders(modules, ("goniolab", "textual"), allowed)
    assert [m for m in bad if m not in PACKAGE_ROOT] == [], bad
    drivers_used = offenders(
        modules,
        ("drivers",),
        # drivers.protocols: the protocol tables, where sim.assembly registers the twin's
        # simulators (the standard library only; no driver I/O is loaded)
        (
            "drivers.base",
            "drivers.profiles",
            "drivers.protocols",
            "drivers.timing",
            "drivers.toml_schema",
        ),
    )
    assert drivers_used in ([], ["drivers"]), drivers_used


def test_textual_only_under_tui() -> None:
    imported, modules = loaded_after_importing(
        ["goniolab", "drivers", "sim"], skip=("goniolab.tui", "goniolab.__main__")
    )
    assert "goniolab.lab_wiring" in imported and "goniolab.commands.sim" in imported
    assert offenders(modules, ("textual", "textual_plot", "goniolab.tui")) == []


def test_scan_never_imports_tui() -> None:
    imported, modules = loaded_after_importing(["goniolab.scan"])
    assert len([m for m in imported if m.startswith("goniolab.scan.")]) >= 2
    assert offenders(modules, ("goniolab.tui", "textual")) == []


def test_colour_is_pure_and_imports_colour_science_lazily() -> None:
    imported, modules = loaded_after_importing(["goniolab.colour"])
    assert "goniolab.colour.paint" in imported and "goniolab.colour.spectral" in imported
    bad = offenders(
        modules, ("goniolab", "drivers", "sim", "textual"), ("goniolab.colour", "goniolab.optics")
    )
    assert [m for m in bad if m not in PACKAGE_ROOT] == [], bad
    assert "colour" not in modules  # colour-science is imported inside the functions
    # the CxF3 parser (optional extra goniolab[cxf]) only when a CxF3 file is read
    assert not {"colour_cxf", "xsdata"} & {m.split(".")[0] for m in modules}
