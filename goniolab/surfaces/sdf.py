"""ISO 25178-71 / Surfstand SDF height maps, ASCII and binary."""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from goniolab.optics.heightmap import HeightMap, HeightMapError, heightmap_error
from goniolab.surfaces._common import (
    ReadOptions,
    check_file_size,
    check_points,
    cstr,
    decode_text,
    make_heightmap,
    quantise,
    resolve_steps,
    snap,
    truncated_error,
)

__all__ = ["read_sdf", "write_sdf_ascii", "write_sdf_binary"]

# DataType codes, as in Gwyddion modules/file/sdfile.c (SDFDataType) and ISO 25178-71.
_SDF_DTYPES: dict[int, np.dtype[Any]] = {
    0: np.dtype("<u1"),
    1: np.dtype("<u2"),
    2: np.dtype("<u4"),
    3: np.dtype("<f4"),
    4: np.dtype("<i1"),
    5: np.dtype("<i2"),
    6: np.dtype("<i4"),
    7: np.dtype("<f8"),
}
# Invalid-point markers for signed integers (the type minimum), as SurfaceTopography does.
_SDF_INVALID: dict[int, int] = {5: -(2**15), 6: -(2**31)}
_SDF_BIN_HEADER = struct.Struct("<8s10s12s12sHHddddBBB")  # 81 bytes
_SDF_MAGICS = (b"aISO-1.0", b"aBCR-1.0", b"bISO-1.0", b"bBCR-1.0")
#: Most bytes a point of a text map may take (digits, sign, exponent, separators),
#: for the file-size bound read before a text file is read.
_TEXT_BYTES_PER_POINT = 64
_SDF_REQUIRED = ("NumPoints", "NumProfiles", "Xscale", "Yscale", "Zscale", "DataType")


def _sdf_check(name: str, info: Mapping[str, Any]) -> tuple[int, int, float, float, float]:
    nx, ny = int(info["NumPoints"]), int(info["NumProfiles"])
    if nx <= 0 or ny <= 0:
        raise heightmap_error(name, f"zero points: NumPoints={nx}, NumProfiles={ny}")
    for key in ("Xscale", "Yscale", "Zscale"):
        value = float(info[key])
        if not (math.isfinite(value) and value > 0.0):
            raise heightmap_error(name, f"{key} must be finite and > 0 (metres), got {value!r}")
    if int(info.get("Compression", 0)) != 0:
        raise heightmap_error(
            name, f"compressed SDF not supported (Compression={info['Compression']})"
        )
    if int(info.get("CheckType", 0)) != 0:
        raise heightmap_error(name, f"SDF checksums not supported (CheckType={info['CheckType']})")
    if int(info["DataType"]) not in _SDF_DTYPES:
        raise heightmap_error(name, f"unknown SDF DataType {info['DataType']} (known: 0..7)")
    return (
        nx,
        ny,
        snap(float(info["Xscale"]) * 1e6),
        snap(float(info["Yscale"]) * 1e6),
        float(info["Zscale"]) * 1e6,
    )


def read_sdf(path: Path, opts: ReadOptions) -> HeightMap:
    """Read an ISO 25178-71 SDF file, ASCII or binary (told apart by its first bytes)."""
    name = path.name
    size = path.stat().st_size
    with path.open("rb") as f:
        head = f.read(_SDF_BIN_HEADER.size)
        magic = head[:8]
        if magic not in _SDF_MAGICS:
            raise heightmap_error(
                name, f"not an SDF file: first bytes {magic!r}, expected aISO-1.0/bISO-1.0"
            )
        if magic[:1] == b"b":
            if len(head) == _SDF_BIN_HEADER.size:
                nx, ny = struct.unpack_from("<HH", head, 42)
                if nx > 0 and ny > 0:
                    check_points(name, nx, ny)  # before the data is read
                    # read only what the header declares (at most 8 bytes a point)
                    return _read_sdf_binary(name, head + f.read(nx * ny * 8), opts)
            return _read_sdf_binary(name, head + f.read(), opts)
        check_file_size(name, size, _TEXT_BYTES_PER_POINT, "ASCII SDF file")
        raw = head + f.read()
    return _read_sdf_ascii(name, raw, opts)


def _read_sdf_binary(name: str, raw: bytes, opts: ReadOptions) -> HeightMap:
    if len(raw) < _SDF_BIN_HEADER.size:
        raise heightmap_error(
            name,
            f"truncated: binary SDF header needs {_SDF_BIN_HEADER.size} bytes, file has {len(raw)}",
        )
    fields = _SDF_BIN_HEADER.unpack_from(raw)
    keys = [
        "Version",
        "ManufacID",
        "CreateDate",
        "ModDate",
        "NumPoints",
        "NumProfiles",
        "Xscale",
        "Yscale",
        "Zscale",
        "Zresolution",
        "Compression",
        "DataType",
        "CheckType",
    ]
    info = dict(zip(keys, fields, strict=True))
    nx, ny, dx_um, dy_um, zscale_um = _sdf_check(name, info)
    check_points(name, nx, ny)
    code = int(info["DataType"])
    dtype = _SDF_DTYPES[code]
    have = len(raw) - _SDF_BIN_HEADER.size
    if nx * ny * dtype.itemsize > have:
        raise truncated_error(name, ny, nx, dtype.itemsize, have)
    data = np.frombuffer(raw, dtype=dtype, count=nx * ny, offset=_SDF_BIN_HEADER.size)
    z = data.astype(np.float64).reshape(ny, nx)
    if code in _SDF_INVALID:
        z[data.reshape(ny, nx) == _SDF_INVALID[code]] = np.nan
    z[np.isinf(z)] = np.nan  # invalid float points; overflow of the scale is caught later
    z = z * zscale_um
    meta = {
        "format": "sdf-binary",
        "manufacturer": cstr(info["ManufacID"]),
        "create_date": cstr(info["CreateDate"]),
        "sdf_data_type": str(code),
    }
    if dtype.kind in "iu":
        meta["z_step_um"] = repr(zscale_um)
    dx, dy = resolve_steps(name, (dx_um, dy_um), opts.step_um)
    return make_heightmap(name, z, dx, dy, meta)


def _read_sdf_ascii(name: str, raw: bytes, opts: ReadOptions) -> HeightMap:
    text = decode_text(raw)
    lines = text.splitlines()
    info: dict[str, str] = {}
    i = 1
    while i < len(lines) and lines[i].strip() != "*":
        line = lines[i].strip()
        i += 1
        if not line or line.startswith(";"):
            continue
        if "=" not in line:
            raise heightmap_error(
                name, f"SDF header line {i}: expected 'Key = value', got {line[:40]!r}"
            )
        key, value = line.split("=", 1)
        info[key.strip()] = value.strip()
    if i >= len(lines):
        raise heightmap_error(name, "truncated: no '*' line ends the SDF header")
    missing = [k for k in _SDF_REQUIRED if k not in info]
    if missing:
        raise heightmap_error(name, f"SDF header lacks {', '.join(missing)}")
    try:
        nx, ny, dx_um, dy_um, zscale_um = _sdf_check(name, info)
    except ValueError as exc:
        if isinstance(exc, HeightMapError):
            raise
        raise heightmap_error(name, f"bad SDF header value: {exc}") from None
    check_points(name, nx, ny)
    start = i + 1
    end = start
    while end < len(lines) and lines[end].strip() != "*":
        end += 1
    if end >= len(lines):
        raise heightmap_error(name, "truncated: no '*' line ends the SDF data section")
    tokens = " ".join(lines[start:end]).split()
    if len(tokens) != nx * ny:
        raise heightmap_error(
            name,
            f"header says {nx}x{ny} = {nx * ny} points but the data section has {len(tokens)}",
        )
    values = np.empty(nx * ny, dtype=np.float64)
    for k, token in enumerate(tokens):
        if token.upper() in ("BAD", "NAN"):
            values[k] = np.nan
            continue
        try:
            values[k] = float(token)
        except ValueError:
            raise heightmap_error(
                name, f"SDF data value #{k + 1} is not a number: {token[:40]!r}"
            ) from None
    z = values.reshape(ny, nx)
    z[np.isinf(z)] = np.nan
    z = z * zscale_um
    meta = {
        "format": "sdf-ascii",
        "manufacturer": info.get("ManufacID", ""),
        "create_date": info.get("CreateDate", ""),
        "sdf_data_type": info["DataType"],
    }
    for line in lines[end + 1 :]:
        if "=" in line and line.strip() != "*":
            key, value = line.split("=", 1)
            meta[key.strip()] = value.strip()
    dx, dy = resolve_steps(name, (dx_um, dy_um), opts.step_um)
    return make_heightmap(name, z, dx, dy, meta)


def _sdf_date() -> str:
    return time.strftime("%d%m%Y%H%M", time.gmtime())


def write_sdf_ascii(hm: HeightMap, path: Path) -> None:
    """Write ``hm`` as an ASCII SDF file."""
    ny, nx = hm.shape
    date = _sdf_date()
    head = [
        "aISO-1.0",
        "ManufacID   = goniolab",
        f"CreateDate  = {date}",
        f"ModDate     = {date}",
        f"NumPoints   = {nx}",
        f"NumProfiles = {ny}",
        f"Xscale      = {hm.dx_um * 1e-6!r}",
        f"Yscale      = {hm.dy_um * 1e-6!r}",
        "Zscale      = 1e-06",
        "Zresolution = -1",
        "Compression = 0",
        "DataType    = 7",
        "CheckType   = 0",
        "*",
    ]
    body = [" ".join("BAD" if math.isnan(v) else repr(float(v)) for v in row) for row in hm.z_um]
    trailer = [f"{k} = {v}" for k, v in hm.meta.items() if _trailer_safe(k, v)]
    path.write_text("\n".join([*head, *body, "*", *trailer, "*"]) + "\n", encoding="utf-8")


def _trailer_safe(key: str, value: str) -> bool:
    return not any(c in s for s in (key, value) for c in "\n\r*=") and bool(key.strip())


def write_sdf_binary(hm: HeightMap, path: Path, code: int) -> None:
    """Write ``hm`` as a binary SDF file with data type ``code``."""
    ny, nx = hm.shape
    if nx > 0xFFFF or ny > 0xFFFF:
        raise heightmap_error(
            path.name, f"binary SDF holds at most 65535x65535 points, map is {nx}x{ny}"
        )
    z = np.asarray(hm.z_um)
    if code == 7:
        zscale_m = 1e-6  # data in micrometres: 1e-6 * 1e6 == 1.0 exactly, lossless
        zres_m = -1.0
        data = z.astype("<f8")
    else:
        n_max = 2**15 - 2 if code == 5 else 2**31 - 2
        ints, step_um, _ = quantise(z, n_max, offset=False)
        zscale_m = step_um * 1e-6
        # the reader multiplies by Zscale * 1e6: quantise with exactly that factor
        scale_um = zscale_m * 1e6
        valid = ~np.isnan(z)
        ints[valid] = np.clip(np.rint(z[valid] / scale_um), -n_max - 1, n_max + 1)
        ints[~valid] = _SDF_INVALID[code]
        zres_m = zscale_m
        data = ints.astype(_SDF_DTYPES[code])
    date = _sdf_date().encode()
    header = _SDF_BIN_HEADER.pack(
        b"bISO-1.0",
        b"goniolab",
        date,
        date,
        nx,
        ny,
        hm.dx_um * 1e-6,
        hm.dy_um * 1e-6,
        zscale_m,
        zres_m,
        0,
        code,
        0,
    )
    path.write_bytes(header + data.tobytes())
