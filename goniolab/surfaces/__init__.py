"""Surfaces: height-map files in and out, the synthetic sample library, ``sample:NAME``.

One module per file format (:mod:`~goniolab.surfaces.npy`, :mod:`~goniolab.surfaces.text`,
:mod:`~goniolab.surfaces.sdf`, :mod:`~goniolab.surfaces.sur`, :mod:`~goniolab.surfaces.gwy`),
chosen by suffix in :mod:`~goniolab.surfaces.registry`; the synthetic library of
:mod:`~goniolab.surfaces.synthetic`; :func:`resolve_map` for a spec naming either. The maths
on a map (levelling, slopes, statistics) lives in :mod:`goniolab.optics`.

The names below load from their modules on first use (PEP 562), so listing the sample
library (``goniolab samples``) does not import numpy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from goniolab.lazy_imports import lazy_exports

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


__getattr__, __dir__ = lazy_exports(__name__, _LAZY)

__all__ = [
    "SAMPLE_PREFIX",
    "HeightMap",
    "HeightMapError",
    "load_heightmap",
    "resolve_map",
    "save_heightmap",
]
