"""Colour differences a paint lab reports, vectorised: dL*, dC*, dH*, dE*ab, dE94, dE00, CMC.

Every function takes the *reference* (the standard: a panel's measured colour, a master
run) first and the *sample* second, as ``(..., 3)`` L*a*b* arrays; the signed components are
sample minus reference (a positive dL* = the sample is lighter).

- CIE 1976 (CIE 15:2004 eqs. 8.5-8.9): ``dE*ab = |Lab_2 - Lab_1|``; ``dC*ab = C2 - C1``;
  the signed hue difference ``dH*ab = 2 sqrt(C1 C2) sin(dh/2)`` (``dh = h2 - h1`` wrapped into
  [-180, 180]) whose square is ``dE*ab^2 - dL*^2 - dC*^2`` (CIE 15:2004 eq. 8.9).
- CIE 1994 (CIE 116-1995, graphic-arts weights): ``kL = kC = kH = 1``, ``S_L = 1``,
  ``S_C = 1 + 0.045 C1``, ``S_H = 1 + 0.015 C1`` (C1 of the reference).
- CIEDE2000 (CIE 142-2001; G. Sharma, W. Wu, E. N. Dalal, Color Res. Appl. 30 (2005) 21,
  eqs. 1-22 and their implementation notes): ``kL = kC = kH = 1``.
- CMC(l:c) (BS 6923:1988, ISO 105-J03; F. J. J. Clarke, R. McDonald, B. Rigg, JSDC 100 (1984)
  128): the ellipsoid at the reference, l = 2, c = 1 for acceptability by default.

Written with numpy (one call per table, no per-pair overhead); tests/colour/test_difference.py
holds each against colour-science's ``colour.delta_E`` and Sharma's 34 published pairs.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DIFFERENCE_METHODS",
    "components",
    "delta_e_cie1976",
    "delta_e_cie1994",
    "delta_e_cie2000",
    "delta_e_cmc",
    "differences",
]

FloatArray = NDArray[np.float64]

#: The dE formulas by the names colour-science uses (plus "CMC" with l, c).
DIFFERENCE_METHODS: tuple[str, ...] = ("CIE 1976", "CIE 1994", "CIE 2000", "CMC")


def _lab(x: ArrayLike) -> FloatArray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"L*a*b* arrays need a last axis of 3, got shape {a.shape}")
    return a


def components(reference: ArrayLike, sample: ArrayLike) -> FloatArray:
    """``(..., 3)``: dL*, dC*ab, dH*ab (signed, sample - reference; CIE 15:2004 eqs. 8.6-8.9)."""
    r, s = _lab(reference), _lab(sample)
    c1 = np.hypot(r[..., 1], r[..., 2])
    c2 = np.hypot(s[..., 1], s[..., 2])
    h1 = np.arctan2(r[..., 2], r[..., 1])
    h2 = np.arctan2(s[..., 2], s[..., 1])
    dh = np.angle(np.exp(1j * (h2 - h1)))  # wrapped into [-pi, pi]
    d_h = 2.0 * np.sqrt(c1 * c2) * np.sin(dh / 2.0)
    out: FloatArray = np.stack([s[..., 0] - r[..., 0], c2 - c1, d_h], axis=-1)
    return out


def delta_e_cie1976(reference: ArrayLike, sample: ArrayLike) -> FloatArray:
    """CIE 1976 dE*ab (CIE 15:2004 eq. 8.5)."""
    out: FloatArray = np.linalg.norm(_lab(sample) - _lab(reference), axis=-1)
    return out


def delta_e_cie1994(reference: ArrayLike, sample: ArrayLike) -> FloatArray:
    """CIE 1994 dE94 with the graphic-arts weights (CIE 116-1995; C1 of the reference)."""
    r, s = _lab(reference), _lab(sample)
    c1 = np.hypot(r[..., 1], r[..., 2])
    dl, dc, _ = np.moveaxis(components(r, s), -1, 0)
    dh2 = np.maximum(np.sum((s - r)[..., 1:] ** 2, axis=-1) - dc**2, 0.0)
    s_c = 1.0 + 0.045 * c1
    s_h = 1.0 + 0.015 * c1
    out: FloatArray = np.sqrt(dl**2 + (dc / s_c) ** 2 + dh2 / s_h**2)
    return out


def delta_e_cmc(
    reference: ArrayLike,
    sample: ArrayLike,
    l: float = 2.0,  # noqa: E741 (CMC's own name)
    c: float = 1.0,
) -> FloatArray:
    """CMC(l:c) (BS 6923; Clarke, McDonald, Rigg 1984), the ellipsoid at the reference."""
    r, s = _lab(reference), _lab(sample)
    l1 = r[..., 0]
    c1 = np.hypot(r[..., 1], r[..., 2])
    h1 = np.degrees(np.arctan2(r[..., 2], r[..., 1])) % 360.0
    dl, dc, _ = np.moveaxis(components(r, s), -1, 0)
    dh2 = np.maximum(np.sum((s - r)[..., 1:] ** 2, axis=-1) - dc**2, 0.0)
    s_l = np.where(l1 < 16.0, 0.511, 0.040975 * l1 / (1.0 + 0.01765 * l1))
    s_c = 0.0638 * c1 / (1.0 + 0.0131 * c1) + 0.638
    f = np.sqrt(c1**4 / (c1**4 + 1900.0))
    t = np.where(
        (h1 >= 164.0) & (h1 <= 345.0),
        0.56 + np.abs(0.2 * np.cos(np.radians(h1 + 168.0))),
        0.36 + np.abs(0.4 * np.cos(np.radians(h1 + 35.0))),
    )
    s_h = s_c * (f * t + 1.0 - f)
    out: FloatArray = np.sqrt((dl / (l * s_l)) ** 2 + (dc / (c * s_c)) ** 2 + dh2 / s_h**2)
    return out


def delta_e_cie2000(reference: ArrayLike, sample: ArrayLike) -> FloatArray:
    """CIEDE2000 (CIE 142-2001) as Sharma, Wu & Dalal (2005) write it, kL = kC = kH = 1."""
    r, s = _lab(reference), _lab(sample)
    l1, a1, b1 = np.moveaxis(r, -1, 0)
    l2, a2, b2 = np.moveaxis(s, -1, 0)
    c_bar = 0.5 * (np.hypot(a1, b1) + np.hypot(a2, b2))
    g = 0.5 * (1.0 - np.sqrt(c_bar**7 / (c_bar**7 + 25.0**7)))
    a1p, a2p = (1.0 + g) * a1, (1.0 + g) * a2
    c1p, c2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.where((a1p == 0) & (b1 == 0), 0.0, np.degrees(np.arctan2(b1, a1p)) % 360.0)
    h2p = np.where((a2p == 0) & (b2 == 0), 0.0, np.degrees(np.arctan2(b2, a2p)) % 360.0)
    d_lp = l2 - l1
    d_cp = c2p - c1p
    zero = c1p * c2p == 0
    dh = h2p - h1p
    dhp = np.where(dh > 180.0, dh - 360.0, np.where(dh < -180.0, dh + 360.0, dh))
    dhp = np.where(zero, 0.0, dhp)
    d_hp = 2.0 * np.sqrt(c1p * c2p) * np.sin(np.radians(dhp / 2.0))
    l_bar = 0.5 * (l1 + l2)
    c_bar_p = 0.5 * (c1p + c2p)
    hsum = h1p + h2p
    h_bar = np.where(
        zero,
        hsum,
        np.where(
            np.abs(h1p - h2p) <= 180.0,
            0.5 * hsum,
            np.where(hsum < 360.0, 0.5 * (hsum + 360.0), 0.5 * (hsum - 360.0)),
        ),
    )
    t = (
        1.0
        - 0.17 * np.cos(np.radians(h_bar - 30.0))
        + 0.24 * np.cos(np.radians(2.0 * h_bar))
        + 0.32 * np.cos(np.radians(3.0 * h_bar + 6.0))
        - 0.20 * np.cos(np.radians(4.0 * h_bar - 63.0))
    )
    d_theta = 30.0 * np.exp(-(((h_bar - 275.0) / 25.0) ** 2))
    r_c = 2.0 * np.sqrt(c_bar_p**7 / (c_bar_p**7 + 25.0**7))
    s_l = 1.0 + 0.015 * (l_bar - 50.0) ** 2 / np.sqrt(20.0 + (l_bar - 50.0) ** 2)
    s_c = 1.0 + 0.045 * c_bar_p
    s_h = 1.0 + 0.015 * c_bar_p * t
    r_t = -np.sin(np.radians(2.0 * d_theta)) * r_c
    out: FloatArray = np.sqrt(
        (d_lp / s_l) ** 2
        + (d_cp / s_c) ** 2
        + (d_hp / s_h) ** 2
        + r_t * (d_cp / s_c) * (d_hp / s_h)
    )
    return out


def differences(
    reference: ArrayLike,
    sample: ArrayLike,
    *,
    cmc_l: float = 2.0,
    cmc_c: float = 1.0,
) -> dict[str, FloatArray]:
    """Every difference of a pair (arrays): ``dL``, ``dC``, ``dH`` (signed, sample -
    reference), ``dE76``, ``dE94``, ``dE00`` and ``dE_CMC`` (l:c as given)."""
    comp = components(reference, sample)
    return {
        "dL": comp[..., 0],
        "dC": comp[..., 1],
        "dH": comp[..., 2],
        "dE76": delta_e_cie1976(reference, sample),
        "dE94": delta_e_cie1994(reference, sample),
        "dE00": delta_e_cie2000(reference, sample),
        "dE_CMC": delta_e_cmc(reference, sample, cmc_l, cmc_c),
    }
