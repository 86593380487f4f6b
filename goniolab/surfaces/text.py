"""Text matrices (.csv .txt .asc .dat), including Gwyddion's "ASCII data matrix" export."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from goniolab.optics.heightmap import HeightMap, heightmap_error
from goniolab.surfaces._common import (
    ReadOptions,
    check_file_size,
    check_points,
    decode_text,
    make_heightmap,
    max_map_points,
    resolve_steps,
    um_per_unit,
)

__all__ = ["read_text_map", "write_text_map"]

#: Most bytes a point of a text map may take (digits, sign, exponent, separators), for the
#: file-size bound checked before the file is read.
_TEXT_BYTES_PER_POINT = 64
_MISSING_TOKENS = frozenset({"", "nan", "-", "bad"})
_GWY_EXTENT = re.compile(r"^\s*([-+0-9.eE]+)\s*(\S+)\s*$")


def _parse_header_line(line: str) -> tuple[str, str] | None:
    """``# key = value`` or Gwyddion's ``# Key: value``; returns (lower-case key, value)."""
    body = line.lstrip("#% \t")
    for sep in ("=", ":"):
        if sep in body:
            key, value = body.split(sep, 1)
            return key.strip().lower(), value.strip()
    return None


def _sniff_delimiter(line: str) -> str | None:
    for delim in ("\t", ";", ","):
        if delim in line:
            return delim
    return None  # runs of whitespace


def _parse_row(
    name: str, lineno: int, line: str, delim: str | None, missing_value: float | None
) -> list[float]:
    cells = line.split(delim) if delim is not None else line.split()
    if delim == ";":
        cells = [c.replace(",", ".") for c in cells]  # decimal comma goes with ';'
    out: list[float] = []
    for col, cell in enumerate(cells, 1):
        token = cell.strip()
        if token.lower() in _MISSING_TOKENS:
            out.append(math.nan)
            continue
        try:
            value = float(token)
        except ValueError:
            raise heightmap_error(
                name, f"line {lineno}, column {col}: non-numeric cell {token[:40]!r}"
            ) from None
        if not math.isfinite(value) or (missing_value is not None and value == missing_value):
            value = math.nan
        out.append(value)
    return out


def read_text_map(path: Path, opts: ReadOptions) -> HeightMap:
    """Read a text matrix of heights (rows = y, columns = x)."""
    name = path.name
    check_file_size(name, path.stat().st_size, _TEXT_BYTES_PER_POINT, "text file")
    limit = max_map_points()
    text = decode_text(path.read_bytes())
    header: dict[str, str] = {}
    rows: list[list[float]] = []
    delim: str | None = None
    width = 0
    missing_value = opts.missing_value
    for lineno, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped[0] in "#%":
            if rows:
                continue  # trailing comments
            parsed = _parse_header_line(stripped)
            if parsed is not None:
                header[parsed[0]] = parsed[1]
                if parsed[0] == "missing_value" and missing_value is None:
                    try:
                        missing_value = float(parsed[1])
                    except ValueError:
                        raise heightmap_error(name, f"bad missing_value {parsed[1]!r}") from None
            continue
        if not rows:
            delim = _sniff_delimiter(stripped)
        row = _parse_row(name, lineno, stripped if delim is None else line, delim, missing_value)
        if rows and len(row) != width:
            raise heightmap_error(
                name, f"ragged rows: line {lineno} has {len(row)} values, expected {width}"
            )
        width = len(row)
        rows.append(row)
        if width * len(rows) > limit:
            check_points(name, width, len(rows), what=f"the data up to line {lineno} holds")
    if not rows:
        raise heightmap_error(name, "zero points: no data rows")
    z = np.array(rows, dtype=np.float64)
    ny, nx = z.shape

    z_unit = header.get("z_unit", header.get("value units", "um"))
    z = z * um_per_unit(name, z_unit, "z")
    file_steps = _text_steps(name, header, nx, ny)
    dx, dy = resolve_steps(name, file_steps, opts.step_um, what="the file header")
    meta = {"format": "text", "z_unit_in_file": z_unit}
    for key, value in header.items():
        if key.startswith("meta."):
            try:
                meta[key[5:]] = str(json.loads(value))
            except (ValueError, RecursionError):
                meta[key[5:]] = value
        elif key == "channel":
            meta["channel"] = value
    return make_heightmap(name, z, dx, dy, meta)


def _float_key(name: str, header: Mapping[str, str], key: str) -> float | None:
    if key not in header:
        return None
    try:
        return float(header[key])
    except ValueError:
        raise heightmap_error(name, f"header {key} = {header[key]!r} is not a number") from None


def _text_steps(
    name: str, header: Mapping[str, str], nx: int, ny: int
) -> tuple[float, float] | None:
    step = _float_key(name, header, "step_um")
    dx = _float_key(name, header, "dx_um")
    dy = _float_key(name, header, "dy_um")
    if dx is None and dy is None and step is None and "width" in header:
        # Gwyddion ASCII export: "# Width: 5.000 µm" / "# Height: 5.000 µm" (extents).
        extents = []
        for key, n in (("width", nx), ("height", ny)):
            match = _GWY_EXTENT.match(header.get(key, ""))
            if match is None:
                raise heightmap_error(
                    name, f"cannot read Gwyddion header {key}: {header.get(key)!r}"
                )
            try:
                extent = float(match.group(1))
            except ValueError:
                raise heightmap_error(
                    name, f"cannot read Gwyddion header {key}: {header[key]!r}"
                ) from None
            extents.append(extent * um_per_unit(name, match.group(2), "lateral") / n)
        return extents[0], extents[1]
    dx = dx if dx is not None else step
    dy = dy if dy is not None else (step if step is not None else dx)
    if dx is None and dy is not None:
        dx = dy
    if dx is None or dy is None:
        return None
    return dx, dy


def write_text_map(hm: HeightMap, path: Path, delimiter: str) -> None:
    """Write ``hm`` as a text matrix with ``delimiter`` between columns."""
    lines = [
        "# goniolab height map (rows = y, columns = x; nan = missing point)",
        f"# dx_um = {hm.dx_um!r}",
        f"# dy_um = {hm.dy_um!r}",
        "# z_unit = um",
    ]
    lines += [f"# meta.{k} = {json.dumps(v)}" for k, v in hm.meta.items() if "\n" not in k]
    with path.open("w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(lines) + "\n")
        np.savetxt(f, hm.z_um, fmt="%.17g", delimiter=delimiter)
