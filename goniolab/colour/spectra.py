"""Spectra to colour: CIE XYZ, L*a*b*, L*C*h and colour differences (colour-science).

A reflectance spectrum R(lambda) (a factor, 1 = the perfect reflecting diffuser) becomes
tristimulus values by CIE 15:2004 sec. 7 (``X = k sum S R xbar``, ``k = 100 / sum S ybar``),
with the ASTM E308 weighting tables by default (``colour.sd_to_XYZ(method="ASTM E308")``),
then CIE 1976 L*a*b* with the illuminant's white point (CIE 15:2004 eqs. 8.1-8.3) and
L*C*h (eq. 8.4). Defaults as PHYSICS.md, "Colour and the paint layer": illuminant D65 and
the CIE 1964 10 deg standard observer.

The integration is linear in R, so for one wavelength grid it is a 3 x N matrix:
:func:`xyz_weights` builds it once from ``colour.sd_to_XYZ`` applied to the unit spectra
of the grid (exactly what ``sd_to_XYZ`` does to any spectrum on that grid) and caches it;
renders and fits then convert thousands of spectra with one matrix product.

colour-science is imported inside the functions (it takes seconds to import).

References
----------
.. [1] CIE 15:2004, Colorimetry, 3rd ed., secs. 7-8.
.. [2] ASTM E308-18, Standard Practice for Computing the Colors of Objects by Using the
   CIE System.
.. [3] R. Durikovic et al., "Prediction of optical properties of paints", Cent. Eur. J.
   Phys. 5 (2007) 416, sec. 7 (D65 rendering); A. Mihalik, R. Durikovic, "Virtual
   gonio-spectrophotometer", sec. 2.1 (D65 as the virtual instrument's source).
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DELTA_E_METHODS",
    "E308_LIMITS_NM",
    "ILLUMINANT_ALIASES",
    "OBSERVERS",
    "VISIBLE_NM",
    "ColourError",
    "ColourSettings",
    "ColourValues",
    "check_spectrum",
    "colour_module",
    "delta_e",
    "lab_to_srgb",
    "range_note",
    "resolve_illuminant",
    "spectra_to_xyz",
    "spectrum_to_colour",
    "standard_grid_nm",
    "white_xyz",
    "xyz_to_colour",
    "xyz_to_colour_of_white",
    "xyz_weights",
]

FloatArray = NDArray[np.float64]

#: The range the ASTM E308 weighting tables span (360-780 nm) and CIE 15's CMFs reach (830 nm):
#: a measured grid must lie inside it.
E308_LIMITS_NM: tuple[float, float] = (360.0, 830.0)
#: The range a spectrum must at least cover: 400-700 nm, the range of most multi-angle
#: instruments (BYK-mac, X-Rite MA-T), which ASTM E308-18 sec. 7.3 handles by holding the
#: end readings over the unmeasured ends of the tables (what colour-science's ``sd_to_XYZ``
#: does: constant extrapolation). The standard grid the models predict on is 380-780 nm.
VISIBLE_NM: tuple[float, float] = (400.0, 700.0)
#: The standard range of a prediction (CIE 15's 380-780 nm).
STANDARD_NM: tuple[float, float] = (380.0, 780.0)

#: Observers accepted by name (colour-science's ``MSDS_CMFS`` keys), with short aliases.
OBSERVERS: dict[str, str] = {
    "CIE 1964 10 Degree Standard Observer": "CIE 1964 10 Degree Standard Observer",
    "CIE 1931 2 Degree Standard Observer": "CIE 1931 2 Degree Standard Observer",
    "10": "CIE 1964 10 Degree Standard Observer",
    "2": "CIE 1931 2 Degree Standard Observer",
}

#: Colour-difference formulas offered (colour-science ``delta_E`` method names).
DELTA_E_METHODS: tuple[str, ...] = ("CIE 1976", "CIE 1994", "CIE 2000")

Method = Literal["ASTM E308", "Integration"]

#: Illuminants colour-science 0.4 has spectra and white points of for both observers: a
#: config naming one of them is valid without importing colour-science (1.5-10 s, as it
#: imports its plotting package); other names are checked against colour-science itself.
#: tests/colour/test_spectra.py keeps this list a subset of colour-science's tables.
COMMON_ILLUMINANTS: frozenset[str] = frozenset(
    {"A", "B", "C", "D50", "D55", "D60", "D65", "D75", "E", "ID50", "ID65"}
    | {f"FL{k}" for k in range(1, 13)}
    | {f"FL3.{k}" for k in range(1, 16)}
    | {f"HP{k}" for k in range(1, 6)}
    | {f"LED-B{k}" for k in range(1, 6)}
    | {"LED-BH1", "LED-RGB1", "LED-V1", "LED-V2"}
)

#: Common names of CIE illuminants -> colour-science's key. CIE 15:2004 table T.6 names the
#: fluorescent illuminants F1..F12 (colour-science spells them FL1..FL12); TL84 and CWF are
#: the trade names of the lamps F11 and F2 stand for (X-Rite / BYK light booths); "LED" is
#: CIE 15:2018's LED-B3 (phosphor-type, 4103 K, the white LED of the metamerism table).
ILLUMINANT_ALIASES: dict[str, str] = {
    **{f"F{k}": f"FL{k}" for k in range(1, 13)},
    **{f"F3.{k}": f"FL3.{k}" for k in range(1, 16)},
    "TL84": "FL11",
    "CWF": "FL2",
    "LED": "LED-B3",
    "ILLUMINANT A": "A",
    "CIE A": "A",
}


def resolve_illuminant(name: str) -> str:
    """colour-science's key of an illuminant name or alias (case-insensitive): ``"F11"``,
    ``"f11"``, ``"TL84"`` -> ``"FL11"``; ``"d65"`` -> ``"D65"``; unknown names unchanged."""
    text = str(name).strip()
    up = text.upper()
    if up in ILLUMINANT_ALIASES:
        return ILLUMINANT_ALIASES[up]
    for known in COMMON_ILLUMINANTS:
        if known.upper() == up:
            return known
    return text


class ColourError(ValueError):
    """A spectrum or a colour setting is unusable; the message names what is wrong."""


def colour_module() -> Any:
    """colour-science, imported on first use with its optional-dependency notices silenced
    and its plotting package deferred (:func:`goniolab.lazy_imports.import_colour`)."""
    from goniolab.lazy_imports import import_colour

    return import_colour()


@dataclass(frozen=True, slots=True)
class ColourSettings:
    """How spectra become colour: illuminant, observer and weighting method.

    Parameters
    ----------
    illuminant
        A ``colour.SDS_ILLUMINANTS`` name (``"D65"``, ``"A"``, ``"C"``, ``"D50"``, ``"FL11"``...)
        or a common alias (``"F11"``, ``"TL84"``, ``"LED"``: :data:`ILLUMINANT_ALIASES`).
    observer
        ``"CIE 1964 10 Degree Standard Observer"`` (default, alias ``"10"``) or
        ``"CIE 1931 2 Degree Standard Observer"`` (alias ``"2"``).
    method
        ``"ASTM E308"`` (weighting tables, default) or ``"Integration"`` (CIE 15 plain sum).
    """

    illuminant: str = "D65"
    observer: str = "CIE 1964 10 Degree Standard Observer"
    method: Method = "ASTM E308"

    def validated(self) -> ColourSettings:
        """The settings with the observer alias resolved; :class:`ColourError` when unknown.

        Cached: colour-science's tables are case- and punctuation-insensitive mappings whose
        every lookup slugifies all their keys (~3 ms), once per reading before."""
        return _validated(self.illuminant, self.observer, self.method)

    @property
    def white_xy(self) -> FloatArray:
        """The illuminant's chromaticity for the observer (``colour.CCS_ILLUMINANTS``)."""
        s = self.validated()
        return _white_xy(s.observer, s.illuminant)


@functools.lru_cache(maxsize=64)
def _validated(illuminant: str, observer_name: str, method: str) -> ColourSettings:
    observer = OBSERVERS.get(observer_name)
    if observer is None:
        known = ", ".join(k for k in OBSERVERS if len(k) > 2)
        raise ColourError(f"unknown observer {observer_name!r} (known: {known}, or 2 / 10)")
    if method not in ("ASTM E308", "Integration"):
        raise ColourError(f"unknown weighting method {method!r} (ASTM E308 or Integration)")
    given = illuminant
    illuminant = resolve_illuminant(illuminant)
    colour = colour_module()
    if illuminant not in colour.SDS_ILLUMINANTS:
        raise ColourError(
            f"unknown illuminant {given!r} (e.g. D65, D50, A, C, F2 = FL2, F11 = FL11 = TL84, "
            "LED = LED-B3)"
        )
    if illuminant not in colour.CCS_ILLUMINANTS[observer]:
        raise ColourError(f"illuminant {illuminant!r} has no white point for the {observer}")
    return ColourSettings(illuminant, observer, method)  # type: ignore[arg-type]


@functools.lru_cache(maxsize=64)
def _white_xy(observer: str, illuminant: str) -> FloatArray:
    white = np.asarray(colour_module().CCS_ILLUMINANTS[observer][illuminant], dtype=float)
    white.setflags(write=False)
    return white


@dataclass(frozen=True, slots=True)
class ColourValues:
    """One colour: CIE XYZ (Y = 100 for the perfect reflecting diffuser), L*a*b*, L*C*h."""

    X: float
    Y: float
    Z: float
    L: float
    a: float
    b: float
    C: float
    h_deg: float

    @property
    def lab(self) -> tuple[float, float, float]:
        """``(L*, a*, b*)``."""
        return (self.L, self.a, self.b)

    def as_dict(self) -> dict[str, float]:
        """Plain dict with the column names used by the store and the exports."""
        return {
            "X": self.X,
            "Y": self.Y,
            "Z": self.Z,
            "L": self.L,
            "a": self.a,
            "b": self.b,
            "C": self.C,
            "h_deg": self.h_deg,
        }


def standard_grid_nm(step_nm: float = 10.0) -> FloatArray:
    """380..780 nm in ``step_nm`` steps (the default 10 nm gives 41 wavelengths)."""
    if not (math.isfinite(step_nm) and 0 < step_nm <= 100 and (400.0 / step_nm).is_integer()):
        raise ColourError(f"wavelength step {step_nm} nm must divide 400 nm (e.g. 5, 10, 20)")
    return np.linspace(380.0, 780.0, round(400.0 / step_nm) + 1)


def check_spectrum(
    wavelengths_nm: ArrayLike,
    values: ArrayLike,
    *,
    what: str = "spectrum",
    noise_floor: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Validate a measured spectrum; return it as float arrays.

    ``noise_floor``: a value down to ``-noise_floor`` is detector noise around zero (what a
    dark-subtracted reading of a dark sample shows) and is returned as 0; anything lower is
    refused as negative.

    Raises
    ------
    ColourError
        Naming the problem: not 1-D, lengths differ, fewer than 3 wavelengths, a NaN or
        infinite value or wavelength, a negative value (below the noise floor), wavelengths
        not ascending and evenly spaced, a grid reaching outside 360-830 nm or one that does
        not cover 400-700 nm (ASTM E308-18 sec. 7.3: shorter ranges are completed by
        holding the end readings, :func:`range_note`).
    """
    try:
        wl = np.asarray(wavelengths_nm, dtype=np.float64)
        r = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ColourError(f"{what}: not numeric ({exc})") from None
    if wl.ndim != 1 or r.ndim != 1:
        raise ColourError(f"{what}: wavelengths and values must be 1-D lists")
    if wl.size != r.size:
        raise ColourError(
            f"{what}: {r.size} values for {wl.size} wavelengths (the lengths must match)"
        )
    _check_grid(wl.tobytes(), what)  # one instrument's grid: checked once
    r_min = float(r.min())
    if not math.isfinite(r_min) or not math.isfinite(float(r.max())):
        bad = ~np.isfinite(r)
        k = int(np.argmax(bad))
        raise ColourError(f"{what}: value at {wl[k]:g} nm is {r[k]} (NaN or infinite)")
    if r_min < -abs(noise_floor):
        k = int(np.argmax(r < -abs(noise_floor)))
        floor = f", below the noise floor -{abs(noise_floor):g}" if noise_floor else ""
        raise ColourError(f"{what}: value at {wl[k]:g} nm is negative ({r[k]:g}{floor})")
    if r_min < 0.0:
        r = np.maximum(r, 0.0)
    return wl, r


@functools.lru_cache(maxsize=32)
def _check_grid_cached(wl_bytes: bytes) -> str:
    """The problem with a wavelength grid ('' when it is fine), cached per grid."""
    wl = np.frombuffer(wl_bytes, dtype=np.float64)
    if wl.size < 3:
        return f"{wl.size} wavelengths, need at least 3"
    if not np.all(np.isfinite(wl)):
        return "a wavelength is NaN or infinite"
    steps = np.diff(wl)
    if np.any(steps <= 0):
        return "wavelengths must be ascending"
    if np.ptp(steps) > 1e-6 * max(1.0, float(steps.mean())):
        return "wavelengths must be evenly spaced"
    lo, hi = VISIBLE_NM
    if wl[0] > lo + 1e-9 or wl[-1] < hi - 1e-9:
        return f"wavelengths {wl[0]:g}-{wl[-1]:g} nm do not cover {lo:g}-{hi:g} nm"
    e_lo, e_hi = E308_LIMITS_NM
    if wl[0] < e_lo - 1e-9 or wl[-1] > e_hi + 1e-9:
        return (
            f"wavelengths {wl[0]:g}-{wl[-1]:g} nm reach outside {e_lo:g}-{e_hi:g} nm "
            "(the CIE observers' range; trim the grid)"
        )
    return ""


def range_note(wavelengths_nm: ArrayLike) -> str:
    """How a grid short of 360-780 nm is completed ('' when it covers 380-780 nm): the text
    every face prints beside colours computed from it (no silent extrapolation)."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64).ravel()
    if wl.size == 0:
        return ""
    lo, hi = STANDARD_NM
    if wl[0] <= lo + 1e-9 and wl[-1] >= hi - 1e-9:
        return ""
    return (
        f"spectra cover {wl[0]:g}-{wl[-1]:g} nm: the end readings are held over the rest of "
        "360-780 nm (ASTM E308-18 sec. 7.3)"
    )


def _check_grid(wl_bytes: bytes, what: str) -> None:
    problem = _check_grid_cached(wl_bytes)
    if problem:
        raise ColourError(f"{what}: {problem}")


@functools.lru_cache(maxsize=32)
def _weights(wl_bytes: bytes, settings: ColourSettings) -> FloatArray:
    colour = colour_module()
    s = settings.validated()
    cmfs = colour.MSDS_CMFS[s.observer]
    illuminant = colour.SDS_ILLUMINANTS[s.illuminant]
    wl_arr = np.frombuffer(wl_bytes, dtype=np.float64).copy()
    out = np.empty((3, wl_arr.size))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # colour warns when it interpolates/extrapolates
        for k in range(wl_arr.size):
            unit = np.zeros(wl_arr.size)
            unit[k] = 1.0
            sd = colour.SpectralDistribution(unit, wl_arr)
            out[:, k] = colour.sd_to_XYZ(sd, cmfs, illuminant, method=s.method)
    out.setflags(write=False)
    return out


def xyz_weights(wavelengths_nm: ArrayLike, settings: ColourSettings | None = None) -> FloatArray:
    """The 3 x N matrix W with ``XYZ = W @ R`` for reflectance factors R on this grid.

    Built from ``colour.sd_to_XYZ`` on each unit spectrum of the grid (its integration,
    ASTM E308 tables included, is linear in R), cached per grid and settings.
    """
    s = (settings or ColourSettings()).validated()
    return _weights(np.asarray(wavelengths_nm, dtype=np.float64).ravel().tobytes(), s)


def spectra_to_xyz(
    wavelengths_nm: ArrayLike, factors: ArrayLike, settings: ColourSettings | None = None
) -> FloatArray:
    """CIE XYZ (Y = 100 for R = 1) of reflectance factors ``(..., N)``; returns ``(..., 3)``."""
    w = xyz_weights(wavelengths_nm, settings)
    r = np.asarray(factors, dtype=np.float64)
    out: FloatArray = r @ w.T
    return out


def white_xyz(settings: ColourSettings | None = None) -> FloatArray:
    """The illuminant's white for the observer, XYZ on the Y = 100 scale (the ``X_n, Y_n,
    Z_n`` of CIE 15:2004 eqs. 8.1-8.3)."""
    s = (settings or ColourSettings()).validated()
    x_w, y_w = _white_xy(s.observer, s.illuminant)
    return np.array([x_w / y_w, 1.0, (1.0 - x_w - y_w) / y_w]) * 100.0


def xyz_to_colour(xyz: ArrayLike, settings: ColourSettings | None = None) -> FloatArray:
    """``(..., 3)`` XYZ (Y = 100 scale) to ``(..., 8)``: X, Y, Z, L*, a*, b*, C*, h (deg),
    relative to the white of ``settings`` (:func:`xyz_to_colour_of_white`)."""
    return xyz_to_colour_of_white(xyz, white_xyz(settings))


def xyz_to_colour_of_white(xyz: ArrayLike, white: ArrayLike) -> FloatArray:
    """``(..., 3)`` XYZ to ``(..., 8)``: X, Y, Z, L*, a*, b*, C*, h (deg) relative to the
    white ``white`` (XYZ, same scale).

    CIE 1976 L*a*b* (CIE 15:2004 eqs. 8.1-8.3, ``f(t) = t^(1/3)`` above ``(6/29)^3``, else
    ``t / (3 (6/29)^2) + 4/29``) and L*C*h (eq. 8.4). Written out rather than called
    through ``colour.XYZ_to_Lab``, whose argument handling cost ~1 ms per reading;
    tests/colour/test_spectra.py checks it against colour-science.
    """
    xyz_a = np.asarray(xyz, dtype=np.float64)
    t = xyz_a / np.asarray(white, dtype=np.float64)
    delta = 6.0 / 29.0
    f = np.where(t > delta**3, np.cbrt(t), t / (3.0 * delta**2) + 4.0 / 29.0)
    big_l = 116.0 * f[..., 1] - 16.0
    a = 500.0 * (f[..., 0] - f[..., 1])
    b = 200.0 * (f[..., 1] - f[..., 2])
    c = np.hypot(a, b)
    h = np.degrees(np.arctan2(b, a)) % 360.0
    out: FloatArray = np.concatenate([xyz_a, np.stack([big_l, a, b, c, h], axis=-1)], axis=-1)
    return out


def _values(row: Sequence[float]) -> ColourValues:
    return ColourValues(*(float(v) for v in row))


def spectrum_to_colour(
    wavelengths_nm: ArrayLike,
    factors: ArrayLike,
    settings: ColourSettings | None = None,
    *,
    what: str = "spectrum",
) -> ColourValues:
    """Colour of one reflectance-factor spectrum (validated by :func:`check_spectrum`).

    Parameters
    ----------
    wavelengths_nm
        Ascending, evenly spaced wavelengths inside 360-830 nm covering 400-700 nm.
    factors
        Reflectance factor per wavelength (1 = perfect reflecting diffuser; a gloss peak
        can exceed 1).
    settings
        Illuminant, observer and method (default D65, CIE 1964 10 deg, ASTM E308).
    """
    wl, r = check_spectrum(wavelengths_nm, factors, what=what)
    xyz = spectra_to_xyz(wl, r, settings)
    return _values(xyz_to_colour(xyz, settings).tolist())


def delta_e(lab_1: ArrayLike, lab_2: ArrayLike, method: str = "CIE 2000") -> FloatArray:
    """Colour difference between L*a*b* arrays (``colour.delta_E``): dE*ab (``"CIE 1976"``),
    dE94 (``"CIE 1994"``, graphic arts weights) or dE2000 (``"CIE 2000"``)."""
    if method not in DELTA_E_METHODS:
        raise ColourError(f"unknown colour difference {method!r} (one of {DELTA_E_METHODS})")
    colour = colour_module()
    out: FloatArray = np.asarray(
        colour.delta_E(np.asarray(lab_1, float), np.asarray(lab_2, float), method=method),
        dtype=np.float64,
    )
    return out


def lab_to_srgb(lab: ArrayLike, settings: ColourSettings | None = None) -> FloatArray:
    """Display sRGB in [0, 1] of L*a*b* colours (for swatches): ``colour.XYZ_to_sRGB`` with
    chromatic adaptation from the illuminant's white point, clipped to the gamut."""
    colour = colour_module()
    s = (settings or ColourSettings()).validated()
    white = np.asarray(colour.CCS_ILLUMINANTS[s.observer][s.illuminant], dtype=float)
    xyz = colour.Lab_to_XYZ(np.asarray(lab, dtype=float), white)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rgb = colour.XYZ_to_sRGB(xyz, white)
    out: FloatArray = np.clip(np.nan_to_num(rgb), 0.0, 1.0)
    return out
