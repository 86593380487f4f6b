"""Resolve a height-map spec: a file or ``sample:NAME``.

Every command, the lab and the TUI name a surface the same way: a path to a height-map file
(any format :func:`goniolab.surfaces.load_heightmap` reads) or ``sample:NAME`` for a
built-in synthetic sample (:mod:`goniolab.surfaces.synthetic`). Errors become :class:`goniolab.errors.UserError`
(exit code 2) with one line naming the file or sample and the reason.
"""

from __future__ import annotations

from pathlib import Path

from goniolab.errors import UserError
from goniolab.optics.heightmap import HeightMap, HeightMapError
from goniolab.surfaces.registry import load_heightmap

__all__ = ["SAMPLE_PREFIX", "one_line", "resolve_map"]

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
    text = str(spec)
    if text.startswith(SAMPLE_PREFIX):
        from goniolab.surfaces.synthetic import SampleError, make_sample

        try:
            return make_sample(text[len(SAMPLE_PREFIX) :], step_um=step_um)
        except SampleError as exc:
            raise UserError(one_line(str(exc))) from None
    if not text:
        raise UserError("no height map given (a file path or sample:NAME)")
    try:
        return load_heightmap(text, step_um=step_um)
    except HeightMapError as exc:
        raise UserError(one_line(str(exc))) from None
    except OSError as exc:
        raise UserError(one_line(f"{text}: cannot read: {exc}")) from None
