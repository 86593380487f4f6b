"""Resolve a height-map spec (a file or ``sample:NAME``) and build its cached facet model.

Every command, the lab and the TUI name a surface the same way: a path to a height-map file
(any format :func:`goniolab.optics.heightmap.load_heightmap` reads) or ``sample:NAME`` for a
built-in synthetic sample (:mod:`sim.samples`). Errors become :class:`goniolab.errors.UserError`
(exit code 2) with one line naming the file or sample and the reason.
"""

from __future__ import annotations

import functools
from pathlib import Path

from goniolab.errors import UserError
from goniolab.optics.facet import FacetModel, Weighting
from goniolab.optics.heightmap import HeightMap, HeightMapError, load_heightmap
from goniolab.optics.surface import SlopeMethod, Surface

__all__ = ["SAMPLE_PREFIX", "model_for", "resolve_map"]

#: Prefix of a built-in sample spec, e.g. ``sample:wittmann-3``.
SAMPLE_PREFIX = "sample:"


def _one_line(text: str) -> str:
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
        from sim.samples import SampleError, make_sample

        try:
            return make_sample(text[len(SAMPLE_PREFIX) :], step_um=step_um)
        except SampleError as exc:
            raise UserError(_one_line(str(exc))) from None
    if not text:
        raise UserError("no height map given (a file path or sample:NAME)")
    try:
        return load_heightmap(text, step_um=step_um)
    except HeightMapError as exc:
        raise UserError(_one_line(str(exc))) from None
    except OSError as exc:
        raise UserError(_one_line(f"{text}: cannot read: {exc}")) from None


def _spec_key(spec: str | Path) -> tuple[str, int, int]:
    """Cache key: the sample spec, or the resolved path with its mtime and size."""
    text = str(spec)
    if text.startswith(SAMPLE_PREFIX):
        return text, 0, 0
    path = Path(text).expanduser()
    try:
        st = path.stat()
    except OSError:
        return text, -1, -1  # resolve_map reports the missing file
    return str(path.resolve()), st.st_mtime_ns, st.st_size


@functools.lru_cache(maxsize=16)
def _model(
    key: tuple[str, int, int],
    spec: str,
    n: complex,
    step_um: float | None,
    slope_method: SlopeMethod,
    weighting: Weighting,
    masking: bool,
) -> FacetModel:
    hm = resolve_map(spec, step_um=step_um)
    try:
        surface = Surface.from_heightmap(hm, slope_method=slope_method)
        return FacetModel(surface, n=n, weighting=weighting, masking=masking)
    except ValueError as exc:
        raise UserError(_one_line(f"{spec}: {exc}")) from None


def model_for(
    spec: str | Path,
    *,
    n: complex | float = 1.55,
    step_um: float | None = None,
    slope_method: SlopeMethod = "forward",
    weighting: Weighting = "radiometric",
    masking: bool = False,
) -> FacetModel:
    """The facet model of a height map (cached per spec, file version and options).

    Parameters
    ----------
    spec, step_um
        As in :func:`resolve_map`.
    n
        Refractive index; complex ``n + ik`` for conductors.
    slope_method, weighting, masking
        Passed to :meth:`Surface.from_heightmap` and :class:`FacetModel`.

    Raises
    ------
    UserError
        Bad spec or file (see :func:`resolve_map`), or a map with no usable facets.
    """
    key = _spec_key(spec)
    return _model(key, str(spec), complex(n), step_um, slope_method, weighting, bool(masking))
