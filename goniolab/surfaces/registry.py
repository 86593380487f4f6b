"""Height-map files: the registry of formats by suffix, :func:`load_heightmap` and :func:`save_heightmap`.

A :class:`HeightMap` is a regular grid of surface heights ``z_um`` (micrometres; rows are y,
columns are x; NaN marks a missing or invalid point) with lateral steps ``dx_um`` and
``dy_um``. Wittmann et al. (2021, sec. 3.1) compute facet slopes from such a map after
subtracting the best-fitting plane; :func:`level_plane` does that, NaN-aware, and
:func:`fill_missing` fills missing points only when asked to.

File formats (:func:`load_heightmap`, :func:`save_heightmap`):

``.npy``
    A 2-D numpy array of heights in micrometres, read with ``allow_pickle=False``. The steps
    live in a JSON sidecar ``<file>.npy.json`` (``{"dx_um": .., "dy_um": .., "meta": {..}}``)
    that :func:`save_heightmap` always writes; without a sidecar, ``step_um`` is required.
``.csv`` ``.txt`` ``.asc`` ``.dat``
    A text matrix, one row of the map per line. The delimiter is sniffed from the first data
    line (tab, then ``;`` -- which also allows a decimal comma --, then ``,``, else runs of
    whitespace). Comment lines (``#``, ``%``) before the data carry ``key = value``
    or ``Key: value`` settings: ``dx_um``, ``dy_um``, ``step_um`` (dy defaults to dx),
    ``z_unit`` (m, mm, um, nm, pm, A; default um), ``missing_value``, and Gwyddion's
    "ASCII data matrix" export header (``# Width: 5.000 µm``, ``# Height: ...`` are the
    x and y extents, ``# Value units: m``; Gwyddion modules/file/asciiexport.c). Missing
    points: empty cell, ``nan``, ``-``, ``BAD`` or the missing value. Ragged rows are an
    error.
``.sdf``
    ISO 25178-71 / Surfstand SDF, ASCII (``aISO-1.0``, ``aBCR-1.0``) or binary (``bISO-1.0``,
    ``bBCR-1.0``): header keys ManufacID, CreateDate, ModDate, NumPoints, NumProfiles,
    Xscale, Yscale, Zscale (metres per unit), Zresolution, Compression, DataType, CheckType.
    Binary header: 81 bytes, little-endian ``8s 10s 12s 12s uint16 uint16 4*float64
    3*uint8``, then NumProfiles rows of NumPoints values. DataType 0 uint8, 1 uint16,
    2 uint32, 3 float32, 4 int8, 5 int16, 6 int32, 7 float64 (Gwyddion
    modules/file/sdfile.c). ASCII: ``Key = value`` lines, ``*``, the values, ``*``, an
    optional trailer, ``*``. Invalid points: ``BAD`` in ASCII, NaN in floats, the type
    minimum in int16/int32 (the convention of SurfaceTopography's SDF reader).
    Compression and checksums are rejected with a clear error.
``.sur``
    Digital Surf (MountainsMap, STIL exports): a 512-byte little-endian header starting
    ``DIGITAL SURF`` (or ``DSCOMPRESSED``), the comment zone, the private zone, then
    int16/int32 points, row by row. Field offsets are those of Gwyddion
    modules/file/surffile.c (``surffile_load`` and its ``SurfWriter``), confirmed against
    RosettaSciIO rsciio/digitalsurf/_api.py, which also gives the DSCOMPRESSED layout
    (stream directory + zlib streams) and the non-measured value ``zmin - 2`` when the
    "special points" flag (offset 86) is 1. Heights are ``point * dz + z_offset`` in the
    z step unit, as Gwyddion computes them (RosettaSciIO subtracts ``zmin`` first; goniolab
    writes ``zmin = 0`` so its files read the same either way). Only the first object of
    a multi-object file is read.
``.gwy``
    Gwyddion native files: the first GwyDataField ``/N/data`` of the container, ``xreal``
    and ``yreal`` with ``si_unit_xy``, values with ``si_unit_z`` (metres by default); a
    mask ``/N/mask`` marks points that become NaN. Written with the ``gwyfile`` package;
    read with a bounded parser of the documented serialisation (``gwyfile``'s parser can
    loop forever on a malformed component).

Size: a map may have at most :func:`goniolab.surfaces._common.max_map_points` points
(``GONIOLAB_MAX_MAP_POINTS``, default 8192 x 8192); every reader checks what a header
declares against that limit and against the file's size before reading or inflating the
data (compressed ``.sur`` streams are inflated in bounded steps).

Heights are returned in micrometres whatever the unit in the file; ``meta['format']`` names
the format read and integer formats report their z quantisation step as
``meta['z_step_um']``.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 3.1.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from goniolab.optics.heightmap import HeightMap, HeightMapError, heightmap_error
from goniolab.surfaces._common import (
    ReadOptions,
    StepArg,
    steps_from_arg,
)
from goniolab.surfaces.gwy import read_gwy, write_gwy
from goniolab.surfaces.npy import read_npy, write_npy
from goniolab.surfaces.sdf import read_sdf, write_sdf_ascii, write_sdf_binary
from goniolab.surfaces.sur import read_sur, write_sur
from goniolab.surfaces.text import read_text_map, write_text_map

__all__ = ["load_heightmap", "save_heightmap"]

Reader = Callable[[Path, ReadOptions], HeightMap]
Writer = Callable[[HeightMap, Path], None]

_READERS: dict[str, Reader] = {
    "npy": read_npy,
    "csv": read_text_map,
    "txt": read_text_map,
    "sdf": read_sdf,
    "sur": read_sur,
    "gwy": read_gwy,
}
_WRITERS: dict[str, Writer] = {
    "npy": write_npy,
    "csv": lambda hm, p: write_text_map(hm, p, ","),
    "txt": lambda hm, p: write_text_map(hm, p, "\t"),
    "sdf": lambda hm, p: write_sdf_binary(hm, p, 7),
    "sdf-int16": lambda hm, p: write_sdf_binary(hm, p, 5),
    "sdf-int32": lambda hm, p: write_sdf_binary(hm, p, 6),
    "sdf-ascii": write_sdf_ascii,
    "sur": lambda hm, p: write_sur(hm, p, 32),
    "sur-int16": lambda hm, p: write_sur(hm, p, 16),
    "gwy": write_gwy,
}
_ALIASES: dict[str, str] = {
    "csv": "csv",
    "txt": "txt",
    "asc": "txt",
    "dat": "txt",
    "text": "txt",
    "npy": "npy",
    "sdf": "sdf",
    "sur": "sur",
    "gwy": "gwy",
}
_READ_ALIASES: dict[str, str] = {
    "sdf-int16": "sdf",
    "sdf-int32": "sdf",
    "sdf-ascii": "sdf",
    "sur-int16": "sur",
}


def _format_for(path: Path, fmt: str | None, table: Mapping[str, object]) -> str:
    if fmt is not None:
        key = fmt.lower().lstrip(".")
        key = _ALIASES.get(key, key)
        if table is _READERS:
            key = _READ_ALIASES.get(key, key)
        if key not in table:
            raise heightmap_error(
                path.name, f"unknown height-map format {fmt!r} (known: {sorted(table)})"
            )
        return key
    ext = path.suffix.lower().lstrip(".")
    if ext not in _ALIASES:
        known = sorted("." + e for e in _ALIASES if e != "text")
        raise heightmap_error(
            path.name, f"unknown height-map extension {path.suffix!r} (known: {known})"
        )
    return _ALIASES[ext]


def load_heightmap(
    path: str | Path,
    *,
    step_um: StepArg = None,
    fmt: str | None = None,
    missing_value: float | None = None,
) -> HeightMap:
    """Read a height map; heights are returned in micrometres whatever the file's unit.

    Parameters
    ----------
    path
        The file.
    step_um
        Lateral step in micrometres (one number, or ``(dx_um, dy_um)``), used when the file
        carries none (``.npy`` without sidecar, text matrices without a step header). If the
        file has a step and ``step_um`` contradicts it, :class:`HeightMapError` is raised.
    fmt
        Format name overriding the extension: ``npy``, ``csv``, ``txt`` (also ``asc``,
        ``dat``), ``sdf``, ``sur``, ``gwy``.
    missing_value
        Text matrices only: a number that marks a missing point (besides empty cells,
        ``nan``, ``-`` and ``BAD``); a ``# missing_value = ...`` header line does the same.

    Returns
    -------
    HeightMap
        ``source`` is the file name; ``meta['format']`` names the format read.

    Raises
    ------
    HeightMapError
        Missing file, directory, unknown format, malformed or truncated content; the message
        names the file and the problem.
    """
    p = Path(path)
    kind = _format_for(p, fmt, _READERS)
    steps_from_arg(p.name, step_um)
    if missing_value is not None and not math.isfinite(missing_value):
        raise heightmap_error(p.name, f"missing_value must be finite, got {missing_value!r}")
    if not p.exists():
        raise heightmap_error(p.name, f"no such file ({p})")
    if p.is_dir():
        raise heightmap_error(p.name, f"is a directory, not a height-map file ({p})")
    try:
        # an absurd scale in a header overflows to inf, which make_heightmap reports: no warnings
        with np.errstate(over="ignore", invalid="ignore"):
            return _READERS[kind](p, ReadOptions(step_um, missing_value))
    except HeightMapError:
        raise
    except OSError as exc:
        raise heightmap_error(p.name, f"cannot read: {exc.strerror or exc}") from None


def save_heightmap(hm: HeightMap, path: str | Path, *, fmt: str | None = None) -> None:
    """Write a height map in the format given by ``fmt`` or the extension of ``path``.

    Every format :func:`load_heightmap` reads is written so that it reads back to the same
    map: exactly for ``npy``, ``csv``/``txt``, ``sdf`` (binary double) and ``sdf-ascii``;
    to 1 ulp for ``gwy`` (metres on disk); within half the z step stored in the file for
    the integer formats ``sur`` (int32), ``sur-int16``, ``sdf-int32`` and ``sdf-int16``
    (that step is returned on reading as ``meta['z_step_um']``).

    Parameters
    ----------
    hm
        The map.
    path
        Destination; ``.npy`` also writes ``<path>.json`` with the steps and metadata.
    fmt
        ``npy``, ``csv``, ``txt``, ``sdf`` (binary, double), ``sdf-ascii``, ``sdf-int16``,
        ``sdf-int32``, ``sur`` (int32), ``sur-int16``, ``gwy``; default from the extension.

    Raises
    ------
    HeightMapError
        Unknown format, a map the format cannot hold, or an I/O error.
    """
    p = Path(path)
    kind = _format_for(p, fmt, _WRITERS)
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # float32 overflow is checked
            _WRITERS[kind](hm, p)
    except OSError as exc:
        raise heightmap_error(p.name, f"cannot write: {exc.strerror or exc}") from None
