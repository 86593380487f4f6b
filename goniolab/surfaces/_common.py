"""Helpers shared by the height-map readers and writers: steps, units, quantisation, limits.

Size limits: a reader checks what a header declares against the file's size and against
:func:`max_map_points` (``GONIOLAB_MAX_MAP_POINTS``, default 8192 x 8192 points) *before*
allocating anything, and inflates compressed data (:func:`inflate`) in bounded steps that
stop as soon as a stream gives more than it claims, so a decompression bomb or a header
that lies fails with one clear error in milliseconds.
"""

from __future__ import annotations

import math
import os
import zlib
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics.heightmap import (
    FloatArray,
    HeightMap,
    HeightMapError,
    StepArg,
    heightmap_error,
    owning_base,
)

__all__ = [
    "DEFAULT_MAX_MAP_POINTS",
    "MAX_MAP_POINTS_ENV",
    "ZLIB_MAX_RATIO",
    "ReadOptions",
    "check_file_size",
    "check_points",
    "cstr",
    "decode_text",
    "inflate",
    "make_heightmap",
    "max_map_points",
    "quantise",
    "resolve_steps",
    "snap",
    "steps_from_arg",
    "truncated_error",
    "um_per_unit",
]


def steps_from_arg(name: str, step_um: StepArg) -> tuple[float, float] | None:
    """The ``step_um`` argument of a reader as ``(dx_um, dy_um)``, or None when not given."""
    if step_um is None:
        return None
    if isinstance(step_um, tuple):
        if len(step_um) != 2:
            raise heightmap_error(
                name, f"step_um must be a number or (dx_um, dy_um), got {step_um!r}"
            )
        dx, dy = step_um
    else:
        dx = dy = step_um
    try:
        dx_f, dy_f = float(dx), float(dy)
    except (TypeError, ValueError):
        raise heightmap_error(
            name, f"step_um must be a number or (dx_um, dy_um), got {step_um!r}"
        ) from None
    for value in (dx_f, dy_f):
        if not (math.isfinite(value) and value > 0.0):
            raise heightmap_error(name, f"step_um must be finite and > 0, got {step_um!r}")
    return dx_f, dy_f


def resolve_steps(
    name: str,
    file_steps: tuple[float, float] | None,
    step_um: StepArg,
    *,
    what: str = "the file",
) -> tuple[float, float]:
    """Combine the steps a file carries with the ``step_um`` option.

    The file's steps win; ``step_um`` fills in when the file carries none. A ``step_um``
    that contradicts the file is an error rather than a silent choice.
    """
    arg = steps_from_arg(name, step_um)
    if file_steps is None:
        if arg is None:
            raise heightmap_error(
                name, f"no lateral step in {what}: pass --step-um UM (step_um in Python)"
            )
        return arg
    for value in file_steps:
        if not (math.isfinite(value) and value > 0.0):
            raise heightmap_error(
                name, f"lateral step in {what} must be finite and > 0, got {value!r}"
            )
    if arg is not None and not np.allclose(arg, file_steps, rtol=1e-9, atol=0.0):
        raise heightmap_error(
            name,
            f"step_um={step_um!r} contradicts the step in {what} "
            f"(dx_um={file_steps[0]!r}, dy_um={file_steps[1]!r})",
        )
    return file_steps


def make_heightmap(
    name: str,
    z_um: ArrayLike,
    dx_um: float,
    dy_um: float,
    meta: dict[str, str],
    *,
    no_inf: bool = False,
) -> HeightMap:
    """A :class:`HeightMap` of a reader's heights, taking a fresh array without a copy
    (float32 heights stay float32: :class:`HeightMap` computes in float64 block by block).
    ``no_inf``: the reader has already turned every infinite height into NaN (the check
    for an overflowing scale is then skipped: a pass over the map)."""
    z = np.asarray(z_um)
    if z.dtype != np.float32:
        z = z.astype(np.float64, copy=False)
    if not no_inf and not math.isfinite(float(np.sum(z, dtype=np.float64))) and np.isinf(z).any():
        raise heightmap_error(
            name, "heights overflow to infinity after scaling: implausible z scale"
        )
    if z.flags.c_contiguous:
        base = None if z.flags.owndata else owning_base(z)
        if base is not None:
            base.setflags(write=False)  # np.load's reshaped read: the same, through its base
        if z.flags.owndata or base is not None:
            z.setflags(write=False)  # the reader's fresh array: the HeightMap takes it, no copy
    return HeightMap(z_um=z, dx_um=dx_um, dy_um=dy_um, source=name, meta=meta)


# Length units accepted in headers, as micrometres per unit. The micro sign appears as
# U+00B5 (latin-1 0xB5, Digital Surf and Gwyddion) or U+03BC; both normalise to "u".
_UM_PER_UNIT: dict[str, float] = {
    "m": 1e6,
    "mm": 1e3,
    "um": 1.0,
    "nm": 1e-3,
    "pm": 1e-6,
    "a": 1e-4,
    "å": 1e-4,
}


def um_per_unit(name: str, unit: str, what: str) -> float:
    """Micrometres per length ``unit`` of a header (m, mm, um, nm, pm, Angstrom)."""
    key = unit.strip().replace("\u00b5", "u").replace("\u03bc", "u").replace("&#181;", "u")
    key = key.lower()
    if key not in _UM_PER_UNIT:
        raise heightmap_error(name, f"unknown {what} unit {unit!r} (known: m, mm, um, nm, pm, A)")
    return _UM_PER_UNIT[key]


def snap(value: float) -> float:
    """Undo the last-digit noise of a unit conversion (e.g. 0.1e-6 m * 1e6 -> 0.1 um)."""
    return float(f"{value:.15g}")


def _mib(n_bytes: int) -> str:
    if n_bytes < 1024 * 1024:
        return f"{n_bytes} bytes"
    return f"{n_bytes / (1024 * 1024):.3g} MiB"


def truncated_error(name: str, ny: int, nx: int, item: int, have: int) -> HeightMapError:
    """The error of a file with fewer data bytes than its header declares."""
    need = ny * nx * item
    return heightmap_error(
        name,
        f"truncated: header says {nx}x{ny} points of {item} bytes ({_mib(need)}) "
        f"but file has {_mib(max(have, 0))} of data",
    )


def quantise(
    z_um: FloatArray, n_max: int, *, offset: bool
) -> tuple[NDArray[np.int64], float, float]:
    """Map heights to integers ``0..n_max`` (or ``-n_max..n_max`` without offset).

    Returns ``(raw, step_um, offset_um)`` with ``z ~= raw * step_um + offset_um`` and an error
    of at most ``step_um / 2`` (plus float rounding) on every valid point. Both numbers are
    representable in float32 so that the .sur header (float32 fields) stores them exactly.
    """
    valid = ~np.isnan(z_um)
    if valid.any():
        lo, hi = float(np.min(z_um[valid])), float(np.max(z_um[valid]))
    else:
        lo = hi = 0.0
    if offset:
        off = float(np.float32(lo))
        if off > lo:
            off = float(np.nextafter(np.float32(lo), np.float32(-np.inf)))
        span = hi - off
    else:
        off = 0.0
        span = max(abs(lo), abs(hi))
    step = span / n_max if span > 0 else 1e-6
    step32 = np.float32(step)
    if float(step32) < step:
        step32 = np.nextafter(step32, np.float32(np.inf))
    step = float(step32)
    raw = np.zeros(z_um.shape, dtype=np.int64)
    raw[valid] = np.rint((z_um[valid] - off) / step).astype(np.int64)
    return raw, step, off


def decode_text(raw: bytes) -> str:
    """A header's text: UTF-8 (with or without BOM), else latin-1."""
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def cstr(value: bytes) -> str:
    """A NUL-terminated latin-1 header field as a stripped string."""
    return value.split(b"\0", 1)[0].decode("latin-1").strip()


@dataclass(frozen=True)
class ReadOptions:
    """What a caller of :func:`~goniolab.surfaces.load_heightmap` asks of every reader."""

    step_um: StepArg
    missing_value: float | None


# --------------------------------------------------------------------------- size limits
#: Most points a height map may have unless ``GONIOLAB_MAX_MAP_POINTS`` says otherwise:
#: 8192 x 8192, 512 MiB as float64 (a map's heights, slopes and facets need a few times that).
DEFAULT_MAX_MAP_POINTS = 8192 * 8192
#: Environment variable that sets the most points a height map may have.
MAX_MAP_POINTS_ENV = "GONIOLAB_MAX_MAP_POINTS"
#: zlib's largest expansion (deflate's longest match, 258 bytes, in about 2 bits:
#: 1032:1); a stream that claims more cannot be valid.
ZLIB_MAX_RATIO = 1032
#: Bytes decompressed per step when inflating a stream.
_INFLATE_STEP = 1 << 20


def max_map_points() -> int:
    """The most points a height map may have: ``GONIOLAB_MAX_MAP_POINTS`` or the default.

    Raises
    ------
    HeightMapError
        The environment variable is set but not a positive integer.
    """
    raw = os.environ.get(MAX_MAP_POINTS_ENV, "").strip()
    if not raw:
        return DEFAULT_MAX_MAP_POINTS
    try:
        value = int(raw.replace("_", ""))
    except ValueError:
        value = 0
    if value <= 0:
        raise HeightMapError(f"{MAX_MAP_POINTS_ENV}={raw!r}: must be a positive integer")
    return value


def check_points(name: str, nx: int, ny: int, *, what: str = "header declares") -> None:
    """Refuse a map larger than :func:`max_map_points` before anything is allocated."""
    limit = max_map_points()
    if nx * ny > limit:
        raise heightmap_error(
            name,
            f"{what} {nx}x{ny} = {nx * ny} points, more than the limit of {limit} "
            f"(set {MAX_MAP_POINTS_ENV} to read larger maps)",
        )


def check_file_size(name: str, size: int, bytes_per_point: int, what: str) -> None:
    """Refuse a file larger than a map of :func:`max_map_points` points can need
    (``bytes_per_point`` per point plus 1 MiB of headers), before reading it."""
    limit = max_map_points()
    most = limit * bytes_per_point + (1 << 20)
    if size > most:
        raise heightmap_error(
            name,
            f"{what} of {_mib(size)} is more than a map within the limit of {limit} points "
            f"needs ({_mib(most)}; set {MAX_MAP_POINTS_ENV} to read larger maps)",
        )


def inflate(name: str, stream: bytes, raw_len: int, what: str) -> bytes:
    """Decompress one zlib ``stream`` that must give exactly ``raw_len`` bytes.

    The claim is checked against the stream's size first (:data:`ZLIB_MAX_RATIO`), then the
    stream is inflated step by step with ``max_length`` and stopped as soon as it gives
    more than claimed, so a decompression bomb costs at most ``raw_len`` bytes.
    """
    if raw_len > ZLIB_MAX_RATIO * len(stream) + 64:
        raise heightmap_error(
            name,
            f"{what} claims {_mib(raw_len)} from {_mib(len(stream))} of zlib data, more than "
            f"zlib can expand ({ZLIB_MAX_RATIO}:1): corrupt or malicious",
        )
    d = zlib.decompressobj()
    out = bytearray()
    data = stream
    try:
        while True:
            out += d.decompress(data, min(_INFLATE_STEP, raw_len - len(out) + 1))
            if len(out) > raw_len:
                raise heightmap_error(name, f"{what} gives more than the {_mib(raw_len)} it claims")
            data = d.unconsumed_tail
            if d.eof or not data:
                break
    except zlib.error as exc:
        raise heightmap_error(name, f"{what} is corrupt: {exc}") from None
    if len(out) != raw_len:
        raise heightmap_error(name, f"{what} gave {len(out)} bytes, expected {raw_len}")
    return bytes(out)
