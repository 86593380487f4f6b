"""Colour of each spectro reading, measured and predicted (issue 11).

:class:`PointColour` turns one stored reading's spectrum into CIE XYZ, L*a*b* and L*C*h with
the lab's ``[colour]`` settings (:mod:`goniolab.colour.spectra`): the spectrum (in % of the
instrument's reference, rescaled by the run's mirror level like the luminance) becomes a
reflectance factor through the detector cone (:func:`goniolab.colour.spectral.reflectance_factor_scale`)
and is integrated with the illuminant and observer (ASTM E308). A bad spectrum (wrong
length, NaN, negative beyond the noise floor :data:`NOISE_FLOOR_PCT`, a grid short of
380-780 nm) raises
:class:`goniolab.colour.spectra.ColourError` naming the problem; the runner then stores the
reading without colour and says why (nothing is lost).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from goniolab.colour.spectra import ColourSettings, ColourValues, spectrum_to_colour
from goniolab.colour.spectral import Scale, reflectance_factor_scale
from goniolab.config import LabConfig
from goniolab.scan.exposure import EXCLUDED_QUALITY, quality_of_raw
from goniolab.store import PointRow, PredictedColour

__all__ = ["NOISE_FLOOR_PCT", "PointColour", "colour_rows", "compare_rows", "flop_of_rows"]

#: Spectral values down to -0.05 % of the instrument's reference are detector noise around
#: zero after dark subtraction (a dark sample's blue end, where lamp and silicon are weak) and
#: are read as 0; a lower value makes the spectrum unusable (named, the reading kept).
NOISE_FLOOR_PCT = 0.05


@dataclass(frozen=True, slots=True)
class PointColour:
    """Settings of the per-point colour: illuminant/observer/method, scale, detector cone."""

    settings: ColourSettings = ColourSettings()  # noqa: RUF009 -- frozen dataclass, safe default
    scale: Scale = "diffuser"
    detector_cone_deg: float = 6.0

    @classmethod
    def from_snapshot(cls, config: Mapping[str, Any]) -> PointColour:
        """From a run's stored config snapshot (its ``colour`` and ``spectro`` tables);
        the defaults where a key is absent (a store that predates them)."""
        c = config.get("colour") or {}
        d = ColourSettings()
        return cls(
            ColourSettings(
                str(c.get("illuminant", d.illuminant)),
                str(c.get("observer", d.observer)),
                "Integration" if c.get("method") == "Integration" else "ASTM E308",
            ),
            c.get("scale", "diffuser"),
            float((config.get("spectro") or {}).get("detector_cone_deg", 6.0)),
        )

    @classmethod
    def from_config(cls, config: LabConfig) -> PointColour:
        """From a lab config's ``[colour]`` and ``[spectro] detector_cone_deg``."""
        c = config.colour
        return cls(
            ColourSettings(c.illuminant, c.observer, c.method),
            c.scale,
            config.spectro.detector_cone_deg,
        )

    def factors(
        self,
        values_pct: Sequence[float] | np.ndarray,
        theta_r_deg: float,
        mirror_pct: float | None = None,
    ) -> np.ndarray:
        """Reflectance factors of a reading's spectrum (``values_pct`` in % of the reference)."""
        r = np.asarray(values_pct, dtype=np.float64) / 100.0
        if mirror_pct:
            r = r * (100.0 / mirror_pct)
        return r * float(reflectance_factor_scale(theta_r_deg, self.detector_cone_deg, self.scale))

    def measured(
        self,
        wavelengths_nm: Sequence[float],
        values_pct: Sequence[float],
        theta_r_deg: float,
        mirror_pct: float | None = None,
    ) -> ColourValues:
        """The colour of one reading (blocking: the first call imports colour-science)."""
        from goniolab.colour.spectra import check_spectrum

        wl, v = check_spectrum(
            wavelengths_nm, values_pct, what="spectrum", noise_floor=NOISE_FLOOR_PCT
        )
        return spectrum_to_colour(
            wl, self.factors(v, theta_r_deg, mirror_pct), self.settings, what="spectrum"
        )

    def describe(self) -> dict[str, object]:
        s = self.settings
        return {
            "illuminant": s.illuminant,
            "observer": s.observer,
            "method": s.method,
            "scale": self.scale,
            "detector_cone_deg": self.detector_cone_deg,
        }


def _mean(values: Sequence[float]) -> float:
    return float(np.mean(values)) if values else float("nan")


def _spectrum_of(p: PointRow) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """A stored reading's grid and spectrum (the absolute one when referenced), or None."""
    wl = p.raw.get("wavelengths_nm")
    v = p.raw.get("absolute_values") or p.raw.get("values")
    if not wl or not v or len(wl) != len(v):
        return None
    return tuple(float(x) for x in wl), tuple(float(x) for x in v)


def _mean_spectrum_colour(
    pts: Sequence[PointRow], point_colour: PointColour, theta_r_deg: float
) -> tuple[tuple[float, float, float] | None, str]:
    """L*a*b* of the repeats' mean spectrum (the spectra averaged, then converted), or
    ``None`` and why not: a repeat has no stored spectrum, the grids differ, or the mean
    spectrum cannot be converted."""
    spectra = [_spectrum_of(p) for p in pts]
    missing = [p.repeat for p, s in zip(pts, spectra, strict=True) if s is None]
    if missing:
        which = ", ".join(str(r) for r in missing)
        return None, f"repeat {which} has no stored spectrum"
    grids = {s[0] for s in spectra if s is not None}
    if len(grids) != 1:
        return None, f"the repeats' spectra are on {len(grids)} different wavelength grids"
    mean = np.mean([s[1] for s in spectra if s is not None], axis=0)
    try:
        return point_colour.measured(next(iter(grids)), list(mean), theta_r_deg).lab, ""
    except ValueError as exc:
        return None, f"their mean spectrum cannot be converted ({exc})"


def colour_rows(
    points: Sequence[PointRow],
    predicted: Mapping[int, PredictedColour],
    theta_i_deg: float,
    point_colour: PointColour | None = None,
) -> list[dict[str, Any]]:
    """Per geometry: measured L*a*b*, C*, h, the predicted L*a*b* and dE*ab / dE94 / dE2000
    between them, the aspecular angle, and the repeatability.

    With ``point_colour`` (the run's colour settings) the repeats are averaged as spectra
    (the mean spectrum converted once: ``averaged = "spectra"``); otherwise, or when a
    repeat has no spectrum, as L*a*b* (``averaged = "lab"``; ``averaged_reason`` says why).
    Readings flagged saturated or under the noise floor are left out. With two or more repeats: ``sd_L``, ``sd_a``,
    ``sd_b`` (sample standard deviations between repeats) and ``dE00_repeat_mean`` /
    ``dE00_repeat_max`` (CIEDE2000 of each repeat from the row's colour), the
    repeatability a lab compares with its instrument's (0.05 dE for a good one).
    """
    from goniolab.colour.multiangle import aspecular_deg
    from goniolab.colour.spectra import delta_e

    by_index: dict[int, list[PointRow]] = {}
    for p in points:
        if p.index >= 0:
            by_index.setdefault(p.index, []).append(p)
    rows: list[dict[str, Any]] = []
    for idx in sorted(by_index):
        pts = by_index[idx]
        good = [
            p for p in pts if p.colour is not None and quality_of_raw(p.raw) not in EXCLUDED_QUALITY
        ]
        cols = [p.colour for p in good if p.colour is not None]
        row: dict[str, Any] = {
            "index": idx,
            "theta_r_deg": pts[0].theta_r_deg,
            "aspecular_deg": aspecular_deg(pts[0].theta_r_deg, theta_i_deg),
            "n": len(cols),
        }
        if cols:
            each = np.array([[c["L"], c["a"], c["b"]] for c in cols])
            from_spectra, why = (
                (None, "the run's stored config gives no colour settings to convert a spectrum")
                if point_colour is None
                else _mean_spectrum_colour(good, point_colour, pts[0].theta_r_deg)
            )
            lab = each.mean(axis=0) if from_spectra is None else np.asarray(from_spectra)
            row["averaged"] = "lab" if from_spectra is None else "spectra"
            if from_spectra is None:
                row["averaged_reason"] = why  # the fallback says why (no silent substitution)
            row.update(L=float(lab[0]), a=float(lab[1]), b=float(lab[2]))
            if len(cols) > 1:
                sd = each.std(axis=0, ddof=1)
                de = np.atleast_1d(delta_e(each, np.broadcast_to(lab, each.shape), "CIE 2000"))
                row.update(
                    sd_L=float(sd[0]),
                    sd_a=float(sd[1]),
                    sd_b=float(sd[2]),
                    dE00_repeat_mean=float(de.mean()),
                    dE00_repeat_max=float(de.max()),
                )
            row.update(
                C=float(np.hypot(lab[1], lab[2])),
                h_deg=float(np.degrees(np.arctan2(lab[2], lab[1])) % 360.0),
            )
        pc = predicted.get(idx)
        if pc is not None:
            row.update(predicted_L=pc.L, predicted_a=pc.a, predicted_b=pc.b)
            if cols:
                m = [row["L"], row["a"], row["b"]]
                p_ = [pc.L, pc.a, pc.b]
                row["dE76"] = float(delta_e(m, p_, "CIE 1976"))
                row["dE94"] = float(delta_e(m, p_, "CIE 1994"))
                row["dE2000"] = float(delta_e(m, p_, "CIE 2000"))
        rows.append(row)
    return rows


def compare_rows(
    rows_a: Sequence[Mapping[str, Any]], rows_b: Sequence[Mapping[str, Any]]
) -> list[dict[str, Any]]:
    """Two runs' measured colours matched by detector angle (within 0.01 deg), with dE."""
    from goniolab.colour.spectra import delta_e

    out: list[dict[str, Any]] = []
    for ra in rows_a:
        if "L" not in ra:
            continue
        match = next(
            (
                rb
                for rb in rows_b
                if "L" in rb and abs(float(rb["theta_r_deg"]) - float(ra["theta_r_deg"])) < 0.01
            ),
            None,
        )
        if match is None:
            continue
        a = [ra["L"], ra["a"], ra["b"]]
        b = [match["L"], match["a"], match["b"]]
        out.append(
            {
                "theta_r_deg": ra["theta_r_deg"],
                "aspecular_deg": ra["aspecular_deg"],
                "L": ra["L"],
                "a": ra["a"],
                "b": ra["b"],
                "other_L": match["L"],
                "other_a": match["a"],
                "other_b": match["b"],
                "dE76": float(delta_e(a, b, "CIE 1976")),
                "dE94": float(delta_e(a, b, "CIE 1994")),
                "dE2000": float(delta_e(a, b, "CIE 2000")),
            }
        )
    return out


def flop_of_rows(rows: Sequence[Mapping[str, Any]], key: str = "L") -> float | None:
    """Flop index from rows at the E2194 aspecular angles 15, 45, 110 (``None`` if absent)."""
    from goniolab.colour.multiangle import flop_index

    ls = {
        round(float(r["aspecular_deg"]), 6): float(r[key])
        for r in rows
        if key in r and math.isfinite(float(r[key]))
    }
    try:
        return flop_index(ls)
    except ValueError:
        return None
