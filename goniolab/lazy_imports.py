"""Lazy re-exports for a package's ``__init__`` (PEP 562), so importing it stays cheap.

``goniolab.optics`` and ``goniolab.surfaces`` offer their public names at package level,
but ``goniolab --help`` and ``goniolab samples`` must not import numpy, scipy or numba
(issue 13): each name is imported from its module on first use and cached in the package.
"""

from __future__ import annotations

import importlib
import sys
import threading
import types
from collections.abc import Callable
from typing import Any


def lazy_exports(
    package: str, table: dict[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Return the ``__getattr__`` and ``__dir__`` of a package whose names load on first use.

    Parameters
    ----------
    package
        The package's ``__name__``.
    table
        Public name -> the module (dotted path) that defines it.

    Returns
    -------
    tuple
        ``(__getattr__, __dir__)`` to assign at the package's top level.
    """

    def __getattr__(name: str) -> Any:
        module = table.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(table))

    return __getattr__, __dir__


class _DeferredSubmodule(types.ModuleType):
    """Stands in ``sys.modules`` for a submodule until an attribute of it is used; then the
    real submodule is imported, replaces the stand-in, and answers."""

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        full = self.__name__
        if sys.modules.get(full) is self:
            del sys.modules[full]
        real = importlib.import_module(full)
        parent, _, child = full.rpartition(".")
        setattr(sys.modules[parent], child, real)
        return getattr(real, name)


def import_colour() -> Any:
    """colour-science, imported without its plotting package until that is used.

    ``import colour`` (0.4) imports ``colour.plotting`` whenever matplotlib is installed --
    matplotlib, pyplot and the plotting datasets: 2.5-3.5 s of the 3.7 s the import
    costs (``python -X importtime``), paid by every scan that computes a colour. The
    plotting package is put in ``sys.modules`` as a stand-in that imports the real one on
    its first attribute access, so ``colour.plotting.plot_...`` still works. Its optional-
    dependency notices ("Matplotlib not available" and similar) are silenced.
    """
    module = sys.modules.get("colour")
    if module is not None and not _initializing(module):
        return module
    with _COLOUR_IMPORT:
        # A scan imports colour first in a worker thread (the twin's spectrum, the model's
        # colour) while others start. ``sys.modules`` holds the module from the first line
        # of its import: another thread must wait for the import, not take the half-built
        # module (that was an AttributeError on ``colour.MSDS_CMFS`` that ended scans).
        module = sys.modules.get("colour")
        if module is not None and not _initializing(module):
            return module
        import warnings

        sys.modules.setdefault("colour.plotting", _DeferredSubmodule("colour.plotting"))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # waits on the module's import lock when another thread imports it directly
            return importlib.import_module("colour")


#: Serialises :func:`import_colour`: one thread imports, the others wait for the result.
_COLOUR_IMPORT = threading.Lock()


def _initializing(module: types.ModuleType) -> bool:
    """Whether ``module`` is still being executed by an import (``sys.modules`` has it
    from the start; :mod:`importlib` marks the spec until the import ends)."""
    return bool(getattr(getattr(module, "__spec__", None), "_initializing", False))
