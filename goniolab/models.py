"""The reflectance model of a surface spec, built once and cached.

Every command, the lab and the TUI name a surface the same way (a height-map file or
``sample:NAME``, :func:`goniolab.surfaces.resolve_map`); :func:`model_for` turns it into the
model that predicts it, cached per spec, file version and options. Errors become
:class:`goniolab.errors.UserError` (exit code 2) naming the file or sample and the reason.
"""

from __future__ import annotations

import functools
from pathlib import Path

from goniolab.errors import UserError
from goniolab.optics.facet import FacetModel, Weighting
from goniolab.optics.surface import SlopeMethod, Surface
from goniolab.surfaces.resolve import SAMPLE_PREFIX, one_line, resolve_map

__all__ = ["model_for"]


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
        raise UserError(one_line(f"{spec}: {exc}")) from None


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
