"""Multi-angle colour as the standards define it: aspecular angles and the flop index.

ASTM E2194 (metallic), ASTM E2539 (interference pigments) and DIN 6175-2 light the panel
at 45 deg and view at *aspecular* angles: the angle from the specular direction towards the
lamp, -15, 15, 25, 45, 75 and 110 deg (PHYSICS.md). In goniolab's signed in-plane frame
(theta_r > 0 on the specular side) the detector sits at ``theta_r = theta_i - aspecular``:
15 as -> 30 deg, 45 as -> 0 (the normal), 110 as -> -65 (lamp side).

The flop index (X-Rite; DuPont's formulation) from L* at 15, 45 and 110 deg aspecular:
``FI = 2.69 (L*15 - L*110)^1.11 / L*45^0.86``; solids read about 0-2, metallics 10-17.

References
----------
.. [1] ASTM E2194-14, Standard Practice for Multiangle Color Measurement of Metal Flake
   Pigmented Materials; ASTM E2539-14 (interference pigments); DIN 6175-2:2001.
.. [2] X-Rite, "A guide to understanding color" / MA-T multi-angle instrument manuals:
   flop index definition.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

__all__ = [
    "E2194_ASPECULAR_DEG",
    "E2194_INCIDENCE_DEG",
    "aspecular_deg",
    "flop_index",
    "flop_index_note",
    "flop_of_rows",
    "theta_r_for_aspecular",
]

#: Incidence of the multi-angle standards.
E2194_INCIDENCE_DEG = 45.0
#: Aspecular viewing angles of ASTM E2194 / E2539 / DIN 6175-2.
E2194_ASPECULAR_DEG: tuple[float, ...] = (-15.0, 15.0, 25.0, 45.0, 75.0, 110.0)


def theta_r_for_aspecular(aspecular: float, theta_i_deg: float = E2194_INCIDENCE_DEG) -> float:
    """Signed detector angle (> 0 specular side) of an aspecular angle."""
    return float(theta_i_deg - aspecular)


def aspecular_deg(theta_r_deg: float, theta_i_deg: float = E2194_INCIDENCE_DEG) -> float:
    """Aspecular angle of a signed in-plane detector angle (inverse of the above)."""
    return float(theta_i_deg - theta_r_deg)


def flop_index(l_star: Mapping[float, float]) -> float:
    """``2.69 (L*15 - L*110)^1.11 / L*45^0.86`` from L* keyed by aspecular angle.

    Raises
    ------
    ValueError
        When 15, 45 or 110 deg is missing, or L*45 <= 0. A negative difference
        L*15 - L*110 (darker near specular) gives a negative index (sign kept).
    """
    missing = [a for a in (15.0, 45.0, 110.0) if a not in l_star]
    if missing:
        raise ValueError(
            "flop index needs L* at 15, 45 and 110 deg aspecular; missing "
            + ", ".join(f"{a:g}" for a in missing)
        )
    d = l_star[15.0] - l_star[110.0]
    l45 = l_star[45.0]
    if not l45 > 0:
        raise ValueError(f"flop index needs L*45 > 0, got {l45:g}")
    return math.copysign(2.69 * abs(d) ** 1.11 / l45**0.86, d)


def aspecular_table(theta_r_deg: Sequence[float], theta_i_deg: float) -> dict[float, int]:
    """``{aspecular: index}`` for the plan angles that are a standard aspecular angle."""
    out: dict[float, int] = {}
    for k, tr in enumerate(theta_r_deg):
        a = aspecular_deg(tr, theta_i_deg)
        for std in E2194_ASPECULAR_DEG:
            if abs(a - std) < 1e-6:
                out[std] = k
    return out


def flop_index_note(theta_i_deg: float) -> str:
    """Why there is no flop index at this incidence ('' at 45 deg): the index is defined on
    L* at 15, 45 and 110 deg aspecular of a 45 deg illumination (ASTM E2194, X-Rite);
    the same aspecular angles at another incidence are other geometries."""
    if abs(float(theta_i_deg) - E2194_INCIDENCE_DEG) < 1e-6:
        return ""
    return (
        f"no flop index at theta_i {float(theta_i_deg):g} deg: it is defined for "
        f"{E2194_INCIDENCE_DEG:g} deg incidence only (ASTM E2194)"
    )


def flop_of_rows(
    rows: Sequence[Mapping[str, object]], theta_i_deg: float, key: str = "L"
) -> float | None:
    """Flop index of per-geometry rows (``aspecular_deg`` and ``key`` = L*), ``None`` when
    the incidence is not 45 deg (:func:`flop_index_note`) or 15/45/110 is missing."""
    if flop_index_note(theta_i_deg):
        return None
    ls: dict[float, float] = {}
    for r in rows:
        v = r.get(key)
        if isinstance(v, int | float) and math.isfinite(float(v)):
            ls[round(float(r["aspecular_deg"]), 6)] = float(v)  # type: ignore[arg-type]
    try:
        return flop_index(ls)
    except ValueError:
        return None
