"""Gwyddion native ``.gwy`` height maps."""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from goniolab.optics.heightmap import HeightMap, HeightMapError, heightmap_error
from goniolab.surfaces._common import (
    ReadOptions,
    check_file_size,
    check_points,
    make_heightmap,
    resolve_steps,
    snap,
    um_per_unit,
)

__all__ = ["read_gwy", "write_gwy"]


class _GwyParser:
    """Bounded reader of the Gwyddion native serialisation (GWYP).

    Layout from the Gwyddion user guide, "Gwyddion Native File Format" (gwyfile-format):
    an object is a NUL-terminated type name, a uint32 LE size, then components; a component
    is a NUL-terminated name, a one-byte type code (b c i q d s o; arrays C I Q D S O with a
    uint32 count) and the value. Every length is checked against the buffer, so malformed
    files end in :class:`HeightMapError` (``gwyfile``'s own parser can loop forever on a
    zero-length component).
    """

    _SCALAR: ClassVar[dict[str, str]] = {"b": "<?", "c": "<c", "i": "<i", "q": "<q", "d": "<d"}
    _ARRAY: ClassVar[dict[str, str]] = {"C": "<u1", "I": "<i4", "Q": "<i8", "D": "<f8"}

    def __init__(self, name: str, buf: bytes) -> None:
        self.name = name
        self.buf = buf

    def _err(self, pos: int, what: str) -> HeightMapError:
        return heightmap_error(self.name, f"corrupt or truncated .gwy at byte {pos}: {what}")

    def cstring(self, pos: int, end: int) -> tuple[str, int]:
        stop = self.buf.find(b"\0", pos, end)
        if stop < 0:
            raise self._err(pos, "unterminated string")
        return self.buf[pos:stop].decode("utf-8", errors="replace"), stop + 1

    def uint32(self, pos: int, end: int) -> int:
        if pos + 4 > end:
            raise self._err(pos, "length field cut short")
        return int(struct.unpack_from("<I", self.buf, pos)[0])

    def obj(self, pos: int, end: int, depth: int = 0) -> tuple[dict[str, Any], int]:
        if depth > 32:
            raise self._err(pos, "objects nested too deeply")
        type_name, pos = self.cstring(pos, end)
        size = self.uint32(pos, end)
        pos += 4
        stop = pos + size
        if stop > end:
            raise self._err(pos, f"object {type_name!r} claims {size} bytes past the end")
        out: dict[str, Any] = {"__type__": type_name}
        while pos < stop:
            key, pos = self.cstring(pos, stop)
            if pos >= stop:
                raise self._err(pos, f"component {key!r} has no type code")
            code = chr(self.buf[pos])
            pos += 1
            out[key], pos = self.value(code, pos, stop, depth)
        return out, stop

    def value(self, code: str, pos: int, end: int, depth: int) -> tuple[Any, int]:
        if code in self._SCALAR:
            size = struct.calcsize(self._SCALAR[code])
            if pos + size > end:
                raise self._err(pos, "value cut short")
            return struct.unpack_from(self._SCALAR[code], self.buf, pos)[0], pos + size
        if code == "s":
            return self.cstring(pos, end)
        if code == "o":
            return self.obj(pos, end, depth + 1)
        if code in self._ARRAY:
            count = self.uint32(pos, end)
            pos += 4
            dtype = np.dtype(self._ARRAY[code])
            if pos + count * dtype.itemsize > end:
                raise self._err(pos, f"array of {count} items runs past the end")
            arr = np.frombuffer(self.buf, dtype=dtype, count=count, offset=pos)
            return arr, pos + count * dtype.itemsize
        if code in "SO":
            count = self.uint32(pos, end)
            pos += 4
            if count > end - pos:
                raise self._err(pos, f"list of {count} items runs past the end")
            items: list[Any] = []
            for _ in range(count):
                if code == "S":
                    text, pos = self.cstring(pos, end)
                    items.append(text)
                else:
                    child, pos = self.obj(pos, end, depth + 1)
                    items.append(child)
            return items, pos
        raise self._err(pos - 1, f"unknown type code {code!r}")


def _gwy_field(name: str, container: Mapping[str, Any], key: str) -> dict[str, Any] | None:
    field_obj = container.get(key)
    if not isinstance(field_obj, dict) or field_obj.get("__type__") != "GwyDataField":
        return None
    xres, yres = field_obj.get("xres"), field_obj.get("yres")
    data = field_obj.get("data")
    if not isinstance(xres, int) or not isinstance(yres, int) or not isinstance(data, np.ndarray):
        raise heightmap_error(name, f"{key}: GwyDataField lacks xres/yres/data")
    if xres <= 0 or yres <= 0:
        raise heightmap_error(name, f"{key}: zero points ({xres}x{yres})")
    check_points(name, xres, yres, what=f"{key} declares")
    if data.dtype != np.float64 or data.size != xres * yres:
        raise heightmap_error(name, f"{key}: data has {data.size} values, expected {xres}x{yres}")
    return field_obj


def _gwy_unit(field_obj: Mapping[str, Any], key: str) -> str:
    unit = field_obj.get(key)
    if isinstance(unit, dict):
        return str(unit.get("unitstr", ""))
    return ""


def read_gwy(path: Path, opts: ReadOptions) -> HeightMap:
    """Read the first data field (and its mask) of a Gwyddion ``.gwy`` file."""
    name = path.name
    # a map and its mask, float64 each, plus 1 MiB of metadata (checked before reading)
    check_file_size(name, path.stat().st_size, 16, "Gwyddion file")
    buf = path.read_bytes()
    if buf[:4] != b"GWYP":
        raise heightmap_error(
            name, f"not a Gwyddion .gwy file: first bytes {buf[:4]!r}, expected b'GWYP'"
        )
    parser = _GwyParser(name, buf)
    top, _ = parser.obj(4, len(buf))
    if top["__type__"] != "GwyContainer":
        raise heightmap_error(name, f"top object is {top['__type__']!r}, expected GwyContainer")
    channels = sorted(int(k[1:-5]) for k in top if re.fullmatch(r"/\d{1,9}/data", k) is not None)
    field_obj = None
    channel = -1
    for channel in channels:
        field_obj = _gwy_field(name, top, f"/{channel}/data")
        if field_obj is not None:
            break
    if field_obj is None:
        raise heightmap_error(name, "no GwyDataField (/N/data) in the container")
    xres, yres = field_obj["xres"], field_obj["yres"]
    z = np.array(field_obj["data"], dtype=np.float64).reshape(yres, xres)
    z_unit = _gwy_unit(field_obj, "si_unit_z") or "m"
    xy_unit = _gwy_unit(field_obj, "si_unit_xy") or "m"
    z[np.isinf(z)] = np.nan
    z = z * um_per_unit(name, z_unit, "z")
    xy_um = um_per_unit(name, xy_unit, "lateral")
    xreal, yreal = field_obj.get("xreal", 1.0), field_obj.get("yreal", 1.0)
    if not all(isinstance(v, float) and math.isfinite(v) and v > 0 for v in (xreal, yreal)):
        raise heightmap_error(name, f"xreal/yreal must be finite and > 0, got {xreal!r}, {yreal!r}")
    mask_obj = _gwy_field(name, top, f"/{channel}/mask")
    if mask_obj is not None:
        if (mask_obj["xres"], mask_obj["yres"]) != (xres, yres):
            raise heightmap_error(name, f"/{channel}/mask shape differs from the data")
        z[np.asarray(mask_obj["data"]).reshape(yres, xres) > 0.5] = np.nan
    meta = {"format": "gwy", "channel": str(channel)}
    title = top.get(f"/{channel}/data/title")
    if isinstance(title, str):
        meta["title"] = title
    gmeta = top.get(f"/{channel}/meta")
    if isinstance(gmeta, dict):
        for key, value in gmeta.items():
            if key != "__type__" and isinstance(value, (str, bytes)):
                meta[key] = value if isinstance(value, str) else value.decode("latin-1")
    dx = snap(xreal * xy_um / xres)
    dy = snap(yreal * xy_um / yres)
    dx, dy = resolve_steps(name, (dx, dy), opts.step_um)
    return make_heightmap(name, z, dx, dy, meta)


def write_gwy(hm: HeightMap, path: Path) -> None:
    """Write ``hm`` as a Gwyddion ``.gwy`` file (missing points as a mask)."""
    from gwyfile.objects import GwyContainer, GwyDataField, GwySIUnit

    ny, nx = hm.shape
    missing = np.isnan(hm.z_um)
    z_m = np.where(missing, 0.0, hm.z_um) / 1e6
    field_obj = GwyDataField(
        np.ascontiguousarray(z_m, dtype=np.float64),
        xreal=nx * hm.dx_um / 1e6,
        yreal=ny * hm.dy_um / 1e6,
        si_unit_xy=GwySIUnit(unitstr="m"),
        si_unit_z=GwySIUnit(unitstr="m"),
    )
    container = GwyContainer()
    container["/0/data"] = field_obj
    container["/0/data/title"] = hm.meta.get("title", "Height")
    if missing.any():
        container["/0/mask"] = GwyDataField(
            missing.astype(np.float64),
            xreal=nx * hm.dx_um / 1e6,
            yreal=ny * hm.dy_um / 1e6,
            si_unit_xy=GwySIUnit(unitstr="m"),
            si_unit_z=GwySIUnit(unitstr=""),
        )
    meta = {k: v for k, v in hm.meta.items() if k not in ("format", "channel", "title")}
    if meta:
        container["/0/meta"] = GwyContainer(meta, typecodes=dict.fromkeys(meta, "s"))
    container.tofile(str(path))
