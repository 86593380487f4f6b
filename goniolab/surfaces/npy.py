"""``.npy`` height maps with a JSON step sidecar."""

from __future__ import annotations

import json
import tokenize
from pathlib import Path

import numpy as np

from goniolab.optics.heightmap import HeightMap, HeightMapError, _fail
from goniolab.surfaces._common import (
    _make,
    _ReadOptions,
    _resolve_steps,
    _truncated,
)


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".json")


def _read_npy(path: Path, opts: _ReadOptions) -> HeightMap:
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
                raise _fail(name, f"heights must be a real numeric array, got dtype {dtype}")
            if len(shape) != 2:
                raise _fail(name, f"heights must be a 2-D array, got shape {shape}")
            if shape[0] * shape[1] == 0:
                raise _fail(name, f"height map has zero points (shape {shape})")
            have = size - f.tell()
            if shape[0] * shape[1] * dtype.itemsize > have:
                raise _truncated(name, shape[0], shape[1], dtype.itemsize, have)
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
        raise _fail(name, f"not a readable .npy file: {exc}") from None
    z = np.asarray(arr).astype(np.float64)
    z[np.isinf(z)] = np.nan
    meta: dict[str, str] = {"format": "npy"}
    file_steps: tuple[float, float] | None = None
    side = _sidecar(path)
    if side.exists():
        try:
            info = json.loads(side.read_text(encoding="utf-8"))
            file_steps = (float(info["dx_um"]), float(info["dy_um"]))
            extra = info.get("meta", {})
            if not isinstance(extra, dict):
                raise TypeError("meta is not an object")
            meta.update({str(k): str(v) for k, v in extra.items()})
        except (OSError, ValueError, KeyError, TypeError, RecursionError) as exc:
            raise _fail(side.name, f"bad step sidecar for {name}: {exc!r}") from None
    dx, dy = _resolve_steps(name, file_steps, opts.step_um, what=side.name)
    return _make(name, z, dx, dy, meta)


def _write_npy(hm: HeightMap, path: Path) -> None:
    np.save(path, np.asarray(hm.z_um, dtype=np.float64), allow_pickle=False)
    info = {"dx_um": hm.dx_um, "dy_um": hm.dy_um, "meta": hm.meta}
    _sidecar(path).write_text(json.dumps(info, indent=1, sort_keys=True) + "\n", encoding="utf-8")
