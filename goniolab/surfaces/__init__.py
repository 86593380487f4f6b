"""Surfaces: height-map files in and out, the synthetic sample library, ``sample:NAME``.

One module per file format (:mod:`~goniolab.surfaces.npy`, :mod:`~goniolab.surfaces.text`,
:mod:`~goniolab.surfaces.sdf`, :mod:`~goniolab.surfaces.sur`, :mod:`~goniolab.surfaces.gwy`),
chosen by suffix in :mod:`~goniolab.surfaces.registry`; the synthetic library of
:mod:`~goniolab.surfaces.samples`; :func:`resolve_map` for a spec naming either. The maths
on a map (levelling, slopes, statistics) lives in :mod:`goniolab.optics`.

The names below load from their modules on first use (PEP 562), so listing the sample
library (``goniolab samples``) does not import numpy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from goniolab.optics.heightmap import HeightMap, HeightMapError
    from goniolab.surfaces.registry import load_heightmap, save_heightmap
    from goniolab.surfaces.resolve import SAMPLE_PREFIX, resolve_map

_LAZY: dict[str, str] = {
    "HeightMap": "goniolab.optics.heightmap",
    "HeightMapError": "goniolab.optics.heightmap",
    "SAMPLE_PREFIX": "goniolab.surfaces.resolve",
    "load_heightmap": "goniolab.surfaces.registry",
    "resolve_map": "goniolab.surfaces.resolve",
    "save_heightmap": "goniolab.surfaces.registry",
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'goniolab.surfaces' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "SAMPLE_PREFIX",
    "HeightMap",
    "HeightMapError",
    "load_heightmap",
    "resolve_map",
    "save_heightmap",
]
