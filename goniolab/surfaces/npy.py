"""``.npy`` height maps with a JSON step sidecar."""

from __future__ import annotations

import json
import math
import tokenize
import warnings
from pathlib import Path

import numpy as np

from goniolab.optics.heightmap import HeightMap, HeightMapError, heightmap_error
from goniolab.surfaces._common import (
    ReadOptions,
    check_points,
    make_heightmap,
    resolve_steps,
    snap,
    truncated_error,
    um_per_unit,
)

__all__ = ["read_npy", "write_npy"]


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".json")


def read_npy(path: Path, opts: ReadOptions) -> HeightMap:
    """Read a ``.npy`` height map and its JSON step sidecar."""
    name = path.name
    size = path.stat().st_size
    try:
        with path.open("rb") as f:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(f)
            elif version in ((2, 0), (3, 0)):
                shape, _, dtype = np.lib.format.read_array_header_2_0(f)
            else:
                raise ValueError(f"unsupported .npy version {version}")
            if dtype.hasobject or dtype.kind not in "iuf":
                raise heightmap_error(
                    name, f"heights must be a real numeric array, got dtype {dtype}"
                )
            if len(shape) != 2:
                raise heightmap_error(name, f"heights must be a 2-D array, got shape {shape}")
            if shape[0] * shape[1] == 0:
                raise heightmap_error(name, f"height map has zero points (shape {shape})")
            check_points(name, shape[1], shape[0], what="array header declares")
            have = size - f.tell()
            if shape[0] * shape[1] * dtype.itemsize > have:
                raise truncated_error(name, shape[0], shape[1], dtype.itemsize, have)
            f.seek(0)
            arr = np.load(f, allow_pickle=False)
    except HeightMapError:
        raise
    except (
        ValueError,
        EOFError,
        SyntaxError,
        TypeError,
        OverflowError,
        tokenize.TokenError,  # numpy tokenises the header dict to repair old files
    ) as exc:
        raise heightmap_error(name, f"not a readable .npy file: {exc}") from None
    # a float64 or float32 file is read once, no copy: float32 heights stay float32 (half
    # the memory; HeightMap computes in float64 block by block). The file is read, not
    # memory-mapped: the slopes touch every page, so a mapping would cost the same resident
    # memory, and a mapped file rewritten while a cached model still reads it would crash
    # the process (SIGBUS) instead of giving the old or the new heights.
    z = np.asarray(arr)
    if z.dtype != np.float32:
        z = z.astype(np.float64, copy=False)
    if not np.isfinite(np.sum(z, dtype=np.float64)):
        z[np.isinf(z)] = np.nan  # then no height is infinite, unless scaled below
    meta: dict[str, str] = {"format": "npy"}
    file_steps: tuple[float, float] | None = None
    side = _sidecar(path)
    scaled = False
    if side.exists():
        file_steps, z_um_per, extra = _read_sidecar(side, name)
        if z_um_per != 1.0:  # scaled in float64, as a float64 file is
            z = z.astype(np.float64, copy=False) * z_um_per
            scaled = True
        meta.update(extra)
    # name the sidecar only when there is one (issue 27: the message named a missing file)
    what = side.name if side.exists() else f"the file (it has no sidecar {side.name})"
    dx, dy = resolve_steps(name, file_steps, opts.step_um, what=what)
    hm = make_heightmap(name, z, dx, dy, meta, no_inf=not scaled)
    _warn_if_nm(hm)
    return hm


#: Keys a ``.npy.json`` sidecar may hold.
_SIDECAR_KEYS = ("dx_um", "dy_um", "step_um", "z_unit", "z_scale", "meta")


def _read_sidecar(side: Path, name: str) -> tuple[tuple[float, float], float, dict[str, str]]:
    """Steps, heights' micrometres per stored unit, and metadata of a ``.npy.json`` sidecar.

    ``{"dx_um": 0.5, "dy_um": 0.5}`` or ``{"step_um": 0.5}`` (``dy_um`` defaults to
    ``dx_um``, as the CSV header's ``dx_um``); ``"z_unit": "nm"`` (m, mm, um, nm, pm, A;
    default um) and ``"z_scale": 2.0`` (a factor applied first) convert the stored heights
    to micrometres; ``"meta"`` is free text.
    """

    def bad(reason: str) -> HeightMapError:
        return heightmap_error(side.name, f"bad sidecar for {name}: {reason}")

    try:
        info = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        raise bad(f"not readable JSON ({exc})") from None
    if not isinstance(info, dict):
        raise bad('must be a JSON object like {"dx_um": 0.5, "dy_um": 0.5}')
    unknown = sorted(set(info) - set(_SIDECAR_KEYS))
    if unknown:
        raise bad(f"unknown key {unknown[0]!r} (known: {', '.join(_SIDECAR_KEYS)})")

    def number(key: str) -> float:
        value = info[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise bad(f"{key} must be a number, got {value!r}")
        return float(value)

    if "dy_um" in info and "dx_um" not in info:
        raise bad("dy_um needs dx_um (or give step_um alone)")
    if "dx_um" in info:
        if "step_um" in info:
            raise bad("give dx_um (and dy_um) or step_um, not both")
        dx = number("dx_um")
        dy = number("dy_um") if "dy_um" in info else dx
    elif "step_um" in info:
        dx = dy = number("step_um")
    else:
        raise bad("no lateral step: give dx_um (and dy_um, default dx_um) or step_um")
    scale = number("z_scale") if "z_scale" in info else 1.0
    if not (math.isfinite(scale) and scale > 0):
        raise bad(f"z_scale must be finite and > 0, got {scale!r}")
    unit = info.get("z_unit", "um")
    if not isinstance(unit, str):
        raise bad(f'z_unit must be a unit name like "nm", got {unit!r}')
    um_per = um_per_unit(side.name, unit, "z")
    extra = info.get("meta", {})
    if not isinstance(extra, dict):
        raise bad("meta must be an object of text values")
    meta = {str(k): str(v) for k, v in extra.items()}
    if unit != "um" or scale != 1.0:
        meta["z_stored_unit"] = f"{scale:g} {unit}" if scale != 1.0 else unit
    return (dx, dy), snap(scale * um_per), meta


#: A map whose heights look like nanometres read as micrometres (rms slope and rms height
#: no coating has): warned about, not refused.
NM_SUSPECT_SDQ = 5.0
NM_SUSPECT_SQ_UM = 50.0


#: Most row pairs the nanometre check reads (spread over the map; all of a smaller map).
_NM_CHECK_ROWS = 256
#: The nanometre check's blocks of rows hold at most 1/_NM_CHECK_BLOCKS of the map.
_NM_CHECK_BLOCKS = 64


def _warn_if_nm(hm: HeightMap) -> None:
    """Warn when heights read as micrometres look like nanometres (Sq and rms slope both
    implausibly large). Sq and Sdq (forward differences) come from up to
    :data:`_NM_CHECK_ROWS` pairs of adjacent rows spread over the map, in blocks of at most
    1/:data:`_NM_CHECK_BLOCKS` of the map, so the check adds no full-size temporaries to the
    read (it made five, and set the peak memory of a 2048^2 read-to-curve at 3.25 x the
    map) and few numpy calls (row by row it took 60 ms of a 2048^2 read); the slopes are
    read only when Sq is suspect."""
    z = hm.z_um  # float64, or float32 (the rows read are cast below)
    ny, nx = z.shape
    if ny < 2 or nx < 2:
        return
    rows = np.linspace(0, ny - 2, min(ny - 1, _NM_CHECK_ROWS)).astype(np.intp)
    rows = rows[np.concatenate(([True], np.diff(rows) > 0))]  # sorted: np.unique's rows
    per_block = max(1, ny // _NM_CHECK_BLOCKS)
    spans = [rows[k : k + per_block] for k in range(0, rows.size, per_block)]
    n = 0
    s1 = s2 = 0.0
    for block in spans:  # temporaries of a block of rows only
        vals = z[block].astype(np.float64, copy=False)
        vals = vals[np.isfinite(vals)]
        n += vals.size
        s1 += float(vals.sum())
        s2 += float(np.dot(vals, vals))
    if n == 0:
        return
    mean = s1 / n
    sq = math.sqrt(max(s2 / n - mean * mean, 0.0))
    if not sq > NM_SUSPECT_SQ_UM:
        return  # the slopes are read only for a map whose Sq is suspect
    n_g = 0
    g2 = 0.0
    for block in spans:
        top = z[block].astype(np.float64, copy=False)
        below = z[block + 1].astype(np.float64, copy=False)
        g = (np.diff(top, axis=1) / hm.dx_um) ** 2 + ((below - top)[:, :-1] / hm.dy_um) ** 2
        good = g[np.isfinite(g)]
        n_g += good.size
        g2 += float(good.sum())
    if n_g == 0:
        return
    sdq = math.sqrt(g2 / n_g)
    if sdq > NM_SUSPECT_SDQ:
        warnings.warn(
            f"{hm.source}: heights read as micrometres give Sq = {sq:.3g} um and Sdq = "
            f'{sdq:.3g}; if they are nanometres, put "z_unit": "nm" in the .npy.json '
            "sidecar",
            HeightUnitsWarning,
            stacklevel=2,
        )


class HeightUnitsWarning(UserWarning):
    """Heights that look like they are in the wrong unit (nm read as um)."""


def write_npy(hm: HeightMap, path: Path) -> None:
    """Write ``hm`` as ``.npy`` heights and a JSON step sidecar."""
    np.save(path, np.asarray(hm.z_um, dtype=np.float64), allow_pickle=False)
    info = {"dx_um": hm.dx_um, "dy_um": hm.dy_um, "meta": hm.meta}
    _sidecar(path).write_text(json.dumps(info, indent=1, sort_keys=True) + "\n", encoding="utf-8")
