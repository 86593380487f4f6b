"""Surfaces: height-map files in and out, the synthetic sample library, ``sample:NAME``.

One module per file format (:mod:`~goniolab.surfaces.npy`, :mod:`~goniolab.surfaces.text`,
:mod:`~goniolab.surfaces.sdf`, :mod:`~goniolab.surfaces.sur`, :mod:`~goniolab.surfaces.gwy`),
chosen by suffix in :mod:`~goniolab.surfaces.registry`; the synthetic library of
:mod:`~goniolab.surfaces.samples`; :func:`resolve_map` for a spec naming either. The maths
on a map (levelling, slopes, statistics) lives in :mod:`goniolab.optics`.
"""

from goniolab.optics.heightmap import HeightMap, HeightMapError
from goniolab.surfaces.registry import load_heightmap, save_heightmap
from goniolab.surfaces.resolve import SAMPLE_PREFIX, resolve_map

__all__ = [
    "SAMPLE_PREFIX",
    "HeightMap",
    "HeightMapError",
    "load_heightmap",
    "resolve_map",
    "save_heightmap",
]
