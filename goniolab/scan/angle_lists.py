"""Angle lists of a plan: ``start:stop:step`` ranges and comma lists, and the error a bad
plan parameter raises.

Kept apart from :mod:`goniolab.scan.plans` (which re-exports them) so that a command that
only parses angles (``goniolab predict brdf --theta-r``) imports neither the plans'
dataclasses nor the drivers' constants.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["MAX_ANGLES", "PlanError", "angle_range", "parse_angles"]

#: Most detector angles one plan may hold (a 0.01 deg step over 90 deg is 9001).
MAX_ANGLES = 10_000


class PlanError(ValueError):
    """A plan parameter is invalid; the message names the parameter and the reason."""


def angle_range(
    start_deg: float, stop_deg: float, step_deg: float, *, name: str = "theta_r", spec: str = ""
) -> tuple[float, ...]:
    """The angles ``start_deg``, ``start_deg + step_deg``, ... up to ``stop_deg`` inclusive.

    The one expansion of an angle range (``parse_angles``, the CLI's ``--theta-r`` and the
    TUI's sweep form): ``n = floor((stop - start) / step + 1e-9) + 1`` angles (a stop
    within 1e-9 step of the grid is included), each ``start + k * step`` rounded to 1e-9
    deg so that float steps land on their grid (0.1 * 3 gives 0.3, not 0.30000000000000004).

    Raises
    ------
    PlanError
        Naming ``name`` and the range (``spec``, default ``start:stop:step``) when a value
        is not finite, ``step <= 0``, ``stop < start`` or the range holds more than
        ``MAX_ANGLES`` angles (checked before anything is expanded).
    """
    spec = spec or f"{start_deg:g}:{stop_deg:g}:{step_deg:g}"
    if not all(math.isfinite(v) for v in (start_deg, stop_deg, step_deg)):
        raise PlanError(f"{name}: range {spec!r} must be finite")
    if step_deg <= 0:
        raise PlanError(f"{name}: step must be > 0 in {spec!r}")
    if stop_deg < start_deg:
        raise PlanError(f"{name}: stop < start in {spec!r}")
    n = math.floor((stop_deg - start_deg) / step_deg + 1e-9) + 1
    if n > MAX_ANGLES:
        raise PlanError(
            f"{name}: range {spec!r} has {n} angles, more than the {MAX_ANGLES} a plan "
            "may hold (a 0.01 deg step over 90 deg is 9001): use a coarser step"
        )
    return tuple(round(start_deg + k * step_deg, 9) for k in range(n))


def parse_angles(spec: str | Sequence[float], *, name: str = "theta_r") -> tuple[float, ...]:
    """Parse an angle list: ``"start:stop:step"`` (stop inclusive), ``"a,b,c"`` or a sequence.

    Parameters
    ----------
    spec
        ``"0:70:1"`` gives 0, 1, ..., 70 (71 angles); ``"-10:10:2.5"`` gives 9 angles
        (:func:`angle_range`); ``"10,20,35"`` or ``[10, 20, 35]`` gives the listed angles
        in that order.
    name
        The parameter name used in error messages.

    Returns
    -------
    tuple of float
        The angles in degrees, rounded to 1e-9 deg so that float steps land on their grid.
    """
    if isinstance(spec, str):
        text = spec.strip()
        if not text:
            raise PlanError(f"{name}: empty angle list")
        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise PlanError(f"{name}: range {spec!r} must be start:stop:step")
            try:
                start, stop, step = (float(p) for p in parts)
            except ValueError as exc:
                raise PlanError(f"{name}: range {spec!r} has a non-numeric field") from exc
            return angle_range(start, stop, step, name=name, spec=spec)
        try:
            values = [float(p) for p in text.split(",") if p.strip()]
        except ValueError as exc:
            raise PlanError(f"{name}: list {spec!r} has a non-numeric entry") from exc
    else:
        values = [float(v) for v in spec]
    if not values:
        raise PlanError(f"{name}: empty angle list")
    if not all(math.isfinite(v) for v in values):
        raise PlanError(f"{name}: angles must be finite, got {values}")
    return tuple(round(v, 9) for v in values)
