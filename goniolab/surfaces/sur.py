"""Digital Surf ``.sur`` height maps (MountainsMap, STIL exports), plain and DSCOMPRESSED."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np

from goniolab.optics.heightmap import HeightMap, heightmap_error
from goniolab.surfaces._common import (
    ReadOptions,
    check_points,
    cstr,
    inflate,
    make_heightmap,
    quantise,
    resolve_steps,
    truncated_error,
    um_per_unit,
)

__all__ = ["read_sur", "write_sur"]

_SUR_HEADER_SIZE = 512
# (name, struct code, byte offset) of the fields goniolab reads and writes; offsets from
# Gwyddion modules/file/surffile.c (surffile_load / SurfWriter) and RosettaSciIO
# rsciio/digitalsurf/_api.py. All little-endian.
_SUR_FIELDS: tuple[tuple[str, str, int], ...] = (
    ("signature", "12s", 0),
    ("format", "h", 12),
    ("n_objects", "H", 14),
    ("version", "h", 16),
    ("object_type", "h", 18),
    ("object_name", "30s", 20),
    ("operator_name", "30s", 50),
    ("material_code", "h", 80),
    ("acquisition", "h", 82),
    ("range", "h", 84),
    ("special_points", "h", 86),
    ("absolute", "h", 88),
    ("gauge_resolution", "f", 90),
    ("w_size", "i", 94),
    ("point_size", "h", 98),
    ("zmin", "i", 100),
    ("zmax", "i", 104),
    ("xres", "i", 108),
    ("yres", "i", 112),
    ("n_points", "i", 116),
    ("dx", "f", 120),
    ("dy", "f", 124),
    ("dz", "f", 128),
    ("x_axis", "16s", 132),
    ("y_axis", "16s", 148),
    ("z_axis", "16s", 164),
    ("dx_unit", "16s", 180),
    ("dy_unit", "16s", 196),
    ("dz_unit", "16s", 212),
    ("x_length_unit", "16s", 228),
    ("y_length_unit", "16s", 244),
    ("z_length_unit", "16s", 260),
    ("x_unit_ratio", "f", 276),
    ("y_unit_ratio", "f", 280),
    ("z_unit_ratio", "f", 284),
    ("imprint", "h", 288),
    ("inversion", "h", 290),
    ("leveling", "h", 292),
    ("seconds", "h", 306),
    ("minutes", "h", 308),
    ("hours", "h", 310),
    ("day", "h", 312),
    ("month", "h", 314),
    ("year", "h", 316),
    ("day_of_week", "h", 318),
    ("duration", "f", 320),
    ("compressed_size", "I", 324),
    ("comment_size", "H", 334),
    ("private_size", "H", 336),
    ("client_zone", "128s", 338),
    ("x_offset", "f", 466),
    ("y_offset", "f", 470),
    ("z_offset", "f", 474),
)
_SUR_ACQUISITION = {
    0: "unknown",
    1: "contact stylus",
    2: "scanning optical gauge",
    3: "thermocouple",
    4: "unknown",
    5: "contact stylus with skid",
    6: "AFM",
    7: "STM",
    8: "video",
    9: "interferometer",
    10: "structured light projection",
}


def _sur_unpack(raw: bytes) -> dict[str, Any]:
    return {
        key: struct.unpack_from("<" + code, raw, offset)[0] for key, code, offset in _SUR_FIELDS
    }


def read_sur(path: Path, opts: ReadOptions) -> HeightMap:
    """Read a Digital Surf ``.sur`` file, plain or DSCOMPRESSED."""
    name = path.name
    with path.open("rb") as f:
        head = f.read(_SUR_HEADER_SIZE)
        magic = head[:12]
        if magic not in (b"DIGITAL SURF", b"DSCOMPRESSED"):
            raise heightmap_error(name, f"not a Digital Surf file: first bytes {magic!r}")
        if len(head) < _SUR_HEADER_SIZE:
            raise heightmap_error(
                name, f"truncated: header needs {_SUR_HEADER_SIZE} bytes, file has {len(head)}"
            )
        h = _sur_unpack(head)
        nx, ny = int(h["xres"]), int(h["yres"])
        if nx > 0 and ny > 0:
            check_points(name, nx, ny)  # before the data is read, let alone inflated
        f.seek(0)
        raw = f.read()  # one buffer, not head + rest (a copy of the file)
    h = _sur_unpack(raw)
    if h["format"] != 0:
        raise heightmap_error(
            name, f"Digital Surf format {h['format']} (Macintosh byte order) not supported"
        )
    if h["object_type"] not in (1, 2):
        raise heightmap_error(
            name, f"object type {h['object_type']} is not a profile (1) or surface (2) height map"
        )
    nx, ny = int(h["xres"]), int(h["yres"])
    if nx <= 0 or ny <= 0:
        raise heightmap_error(name, f"zero points: header says {nx}x{ny}")
    if h["n_points"] != nx * ny:
        raise heightmap_error(name, f"header total points {h['n_points']} != {nx}x{ny}")
    if h["point_size"] not in (16, 32):
        raise heightmap_error(name, f"unsupported point size {h['point_size']} bits (16 or 32)")
    item = h["point_size"] // 8
    for key in ("dx", "dy", "dz", "z_offset"):
        if not math.isfinite(h[key]):
            raise heightmap_error(name, f"header {key} is not finite ({h[key]!r})")
    if h["dx"] == 0.0 or h["dy"] == 0.0 or h["dz"] == 0.0:
        raise heightmap_error(
            name, f"zero spacing in header (dx={h['dx']}, dy={h['dy']}, dz={h['dz']})"
        )
    dx_um = abs(h["dx"]) * um_per_unit(name, cstr(h["dx_unit"]), "x step")
    dy_um = abs(h["dy"]) * um_per_unit(name, cstr(h["dy_unit"]), "y step")
    z_um_per = um_per_unit(name, cstr(h["dz_unit"]), "z step")
    start = _SUR_HEADER_SIZE + h["comment_size"] + h["private_size"]
    if start > len(raw):
        raise heightmap_error(
            name,
            f"truncated: comment and private zones end at byte {start}, file has {len(raw)}",
        )
    comment = raw[_SUR_HEADER_SIZE : _SUR_HEADER_SIZE + h["comment_size"]].decode("latin-1")
    need = nx * ny * item
    body: bytes | memoryview
    if magic == b"DSCOMPRESSED":
        body = _sur_decompress(name, raw, start, need)
    else:
        body = memoryview(raw)[start : start + need]  # no copy of the data
        if len(body) < need:
            raise truncated_error(name, ny, nx, item, len(raw) - start)
    ints = np.frombuffer(body, dtype="<i2" if item == 2 else "<i4", count=nx * ny)
    ints = ints.reshape(ny, nx)
    z = ints.astype(np.float64)  # scaled in place: one float64 array, no temporaries
    z *= float(h["dz"]) * z_um_per
    z += float(h["z_offset"]) * z_um_per
    if h["special_points"] == 1:
        z[ints == int(h["zmin"]) - 2] = np.nan
    # Inversion codes as in Gwyddion surffile.c: 1 = invert z, 2 = flip (mirror x) and
    # invert z, 3 = flop (mirror y) and invert z.
    if h["inversion"] in (1, 2, 3):
        z = -z
        if h["inversion"] == 2:
            z = z[:, ::-1]
        elif h["inversion"] == 3:
            z = z[::-1, :]
    meta = {
        "format": "sur",
        "object_name": cstr(h["object_name"]),
        "operator_name": cstr(h["operator_name"]),
        "acquisition": _SUR_ACQUISITION.get(h["acquisition"], str(h["acquisition"])),
        "z_step_um": repr(abs(float(h["dz"]) * z_um_per)),
    }
    if h["year"] > 0:
        meta["date"] = f"{h['year']:04d}-{h['month']:02d}-{h['day']:02d}"
    if h["n_objects"] > 1:
        meta["note"] = f"file holds {h['n_objects']} objects; the first was read"
    exact = _sur_parse_comment(comment, meta)
    if exact is not None and all(
        math.isclose(a, b, rel_tol=1e-6) for a, b in zip(exact, (dx_um, dy_um), strict=True)
    ):
        dx_um, dy_um = exact  # goniolab's own full-precision steps (header floats are float32)
    dx, dy = resolve_steps(name, (dx_um, dy_um), opts.step_um)
    return make_heightmap(name, z, dx, dy, meta)


def _sur_decompress(name: str, raw: bytes, start: int, need: int) -> bytes:
    """DSCOMPRESSED data: uint32 stream count, (raw length, zipped length) uint32 pairs,
    then the zlib streams (RosettaSciIO rsciio/digitalsurf/_api.py, ``_unpack_data``)."""
    if start + 4 > len(raw):
        raise heightmap_error(name, "truncated: compressed SUR stream directory missing")
    (count,) = struct.unpack_from("<I", raw, start)
    if not 1 <= count <= 1024:
        raise heightmap_error(name, f"compressed SUR: implausible stream count {count}")
    pos = start + 4
    if pos + 8 * count > len(raw):
        raise heightmap_error(name, "truncated: compressed SUR stream directory cut short")
    sizes = [struct.unpack_from("<II", raw, pos + 8 * k) for k in range(count)]
    pos += 8 * count
    total = sum(raw_len for raw_len, _ in sizes)
    if total != need:
        raise heightmap_error(
            name, f"compressed SUR stream directory claims {total} bytes, header implies {need}"
        )
    out = bytearray()
    for k, (raw_len, zip_len) in enumerate(sizes, 1):
        chunk = raw[pos : pos + zip_len]
        if len(chunk) < zip_len:
            raise heightmap_error(name, f"truncated: compressed SUR stream needs {zip_len} bytes")
        pos += zip_len
        out += inflate(name, chunk, raw_len, f"compressed SUR stream {k} of {count}")
    return bytes(out)


def _sur_parse_comment(comment: str, meta: dict[str, str]) -> tuple[float, float] | None:
    """goniolab writes ``$goniolab.dx_um = ...`` lines (MountainsMap's ``$key = value``
    comment style); other comments are kept whole in ``meta['comment']``."""
    steps: dict[str, float] = {}
    other: list[str] = []
    for line in comment.splitlines():
        if line.startswith("$goniolab.") and "=" in line:
            key, value = line[len("$goniolab.") :].split("=", 1)
            key = key.strip()
            try:
                if key in ("dx_um", "dy_um"):
                    steps[key] = float(value)
                elif key.startswith("meta."):
                    meta[key[5:]] = str(json.loads(value))
            except (ValueError, RecursionError):
                other.append(line)
        elif line.strip():
            other.append(line)
    if other:
        meta["comment"] = "\n".join(other)
    if "dx_um" in steps and "dy_um" in steps:
        return steps["dx_um"], steps["dy_um"]
    return None


def write_sur(hm: HeightMap, path: Path, bits: int) -> None:
    """Write ``hm`` as a Digital Surf ``.sur`` file of ``bits``-bit integers."""
    ny, nx = hm.shape
    n_max = 2 ** (bits - 1) - 16
    ints, step_um, off_um = quantise(np.asarray(hm.z_um), n_max, offset=True)
    for what, value in (("dx_um", hm.dx_um), ("dy_um", hm.dy_um), ("z", step_um), ("z", off_um)):
        if not np.isfinite(np.float32(value)) or (value != 0.0 and np.float32(value) == 0.0):
            raise heightmap_error(
                path.name, f"{what} = {value!r} does not fit the float32 .sur header"
            )
    missing = np.isnan(hm.z_um)
    ints[missing] = -2  # non-measured value: zmin - 2 with zmin = 0
    comment_lines = [f"$goniolab.dx_um = {hm.dx_um!r}", f"$goniolab.dy_um = {hm.dy_um!r}"]
    comment_lines += [
        f"$goniolab.meta.{k} = {json.dumps(v)}" for k, v in hm.meta.items() if "\n" not in k
    ]
    comment = ("\n".join(comment_lines) + "\n").encode("latin-1", errors="replace")
    if len(comment) > 0xFFFF:
        comment = ("\n".join(comment_lines[:2]) + "\n").encode("latin-1")
    values: dict[str, Any] = {
        "signature": b"DIGITAL SURF",
        "format": 0,
        "n_objects": 1,
        "version": 1,
        "object_type": 2 if ny > 1 else 1,
        "object_name": hm.source.encode("latin-1", errors="replace")[:30],
        "operator_name": b"goniolab",
        "material_code": 0,
        "acquisition": 0,
        "range": 0,
        "special_points": 1 if missing.any() else 0,
        "absolute": 1,
        "gauge_resolution": 0.0,
        "w_size": 0,
        "point_size": bits,
        "zmin": 0,
        "zmax": int(ints.max(initial=0)),
        "xres": nx,
        "yres": ny,
        "n_points": nx * ny,
        "dx": hm.dx_um,
        "dy": hm.dy_um,
        "dz": step_um,
        "x_axis": b"X",
        "y_axis": b"Y",
        "z_axis": b"Z",
        "dx_unit": b"\xb5m",
        "dy_unit": b"\xb5m",
        "dz_unit": b"\xb5m",
        "x_length_unit": b"\xb5m",
        "y_length_unit": b"\xb5m",
        "z_length_unit": b"\xb5m",
        "x_unit_ratio": 1.0,
        "y_unit_ratio": 1.0,
        "z_unit_ratio": 1.0,
        "imprint": 0,
        "inversion": 0,
        "leveling": 0,
        "seconds": 0,
        "minutes": 0,
        "hours": 0,
        "day": 0,
        "month": 0,
        "year": 0,
        "day_of_week": 0,
        "duration": 0.0,
        "compressed_size": 0,
        "comment_size": len(comment),
        "private_size": 0,
        "client_zone": b"",
        "x_offset": 0.0,
        "y_offset": 0.0,
        "z_offset": off_um,
    }
    header = bytearray(_SUR_HEADER_SIZE)
    for key, code, offset in _SUR_FIELDS:
        struct.pack_into("<" + code, header, offset, values[key])
    dtype = "<i2" if bits == 16 else "<i4"
    path.write_bytes(bytes(header) + comment + ints.astype(dtype).tobytes())
