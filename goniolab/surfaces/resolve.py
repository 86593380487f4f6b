"""Resolve a height-map spec: a file or ``sample:NAME``.

Every command, the lab and the TUI name a surface the same way: a path to a height-map file
(any format :func:`goniolab.surfaces.load_heightmap` reads) or ``sample:NAME`` for a
built-in synthetic sample (:mod:`goniolab.surfaces.synthetic`). Errors become :class:`goniolab.errors.UserError`
(exit code 2) with one line naming the file or sample and the reason.
"""

from __future__ import annotations

import threading
import weakref
from pathlib import Path

from goniolab.errors import UserError
from goniolab.optics.heightmap import HeightMap, HeightMapError
from goniolab.surfaces.registry import load_heightmap

__all__ = ["SAMPLE_PREFIX", "CoarseStepWarning", "one_line", "resolve_map"]


class CoarseStepWarning(UserWarning):
    """A lateral step larger than the surface's correlation length: neighbouring points are
    nearly uncorrelated, so slopes from differences are not the surface's."""


#: Prefix of a built-in sample spec, e.g. ``sample:wittmann-3``.
SAMPLE_PREFIX = "sample:"


def one_line(text: str) -> str:
    return " ".join(str(text).split())


def resolve_map(spec: str | Path, *, step_um: float | None = None) -> HeightMap:
    """The height map named by ``spec``.

    Parameters
    ----------
    spec
        ``sample:NAME`` (a built-in sample, see ``goniolab samples``) or a file path.
    step_um
        Lateral step in micrometres for files that carry none (``.npy`` without sidecar,
        bare text matrices); for a sample, the step to generate it at.

    Raises
    ------
    UserError
        Unknown sample (lists the known ones), unreadable or malformed file (names it).
    """
    hm = _resolve(str(spec), step_um)
    if step_um is not None:
        _warn_if_coarse(hm, str(spec), step_um)
    return hm


def _warn_if_coarse(hm: HeightMap, name: str, step_um: float) -> None:
    """Warn when neighbouring points of a map read at a step the user gave are nearly
    uncorrelated: their lag-1 autocorrelation below 1/e means the step exceeds the
    correlation length (the 1/e fall of the autocorrelation, docs/PHYSICS.md), and every
    facet slope is a difference of unrelated heights (issue 27: ``--step-um 500`` passed
    silently)."""
    import math
    import warnings

    import numpy as np

    z = np.asarray(hm.z_um, dtype=np.float64)
    if z.ndim != 2 or min(z.shape) < 3:
        return
    z = np.nan_to_num(z - np.nanmean(z))
    power = float(np.sum(z * z))
    if not power > 0.0:
        return
    rho = min(
        float(np.sum(z[:, :-1] * z[:, 1:])) / power,
        float(np.sum(z[:-1, :] * z[1:, :])) / power,
    )
    if rho < math.exp(-1.0):
        warnings.warn(
            f"{name}: at --step-um {step_um:g} neighbouring points are nearly uncorrelated "
            f"(lag-1 autocorrelation {rho:.2f} < 1/e): the step is larger than the surface's "
            "correlation length, so its slopes (and the facet prediction) are not the "
            "surface's; check the step",
            CoarseStepWarning,
            stacklevel=3,
        )


def _resolve(text: str, step_um: float | None) -> HeightMap:
    if text.startswith(SAMPLE_PREFIX):
        from goniolab.surfaces.synthetic import SampleError, make_sample

        try:
            return make_sample(text[len(SAMPLE_PREFIX) :], step_um=step_um)
        except SampleError as exc:
            raise UserError(one_line(str(exc))) from None
    if not text:
        raise UserError("no height map given (a file path or sample:NAME)")
    try:
        key = _file_key(text, step_um)
        with _lock:
            hm = _read.get(key) if key is not None else None
        if hm is None:
            hm = load_heightmap(text, step_um=step_um)
            if key is not None:
                with _lock:
                    _read[key] = hm
        return hm
    except HeightMapError as exc:
        raise UserError(one_line(str(exc))) from None
    except OSError as exc:
        raise UserError(one_line(f"{text}: cannot read: {exc}")) from None


#: The maps read from files and still held by someone (a model, a command), by file
#: version: the ``auto`` model and the facet model it shares read one map, not two (an
#: 8192^2 float32 map read twice cost 256 MB more). Weak: a map nobody holds is dropped.
_read: weakref.WeakValueDictionary[tuple[str, int, int, float | None], HeightMap] = (
    weakref.WeakValueDictionary()
)
_lock = threading.Lock()


def _file_key(text: str, step_um: float | None) -> tuple[str, int, int, float | None] | None:
    """The file's resolved path, mtime and size, and the step asked for; None when it cannot
    be read (the reader reports why)."""
    try:
        path = Path(text).expanduser().resolve()
        st = path.stat()
    except (OSError, RuntimeError, ValueError):
        return None
    return str(path), st.st_mtime_ns, st.st_size, step_um
