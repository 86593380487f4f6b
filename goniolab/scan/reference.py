"""A reference reading divided out spectrally and replaced by the standard's certified value.

The mirror reference of a BRDF plan (``--mirror-reference``) is read at the specular
geometry ``(theta_i, theta_i)`` before the sample. Every later reading ``v(lambda)`` (in the
instrument's own units) becomes absolute (docs/CALIBRATION.md, step 3)::

    R(lambda) = v(lambda) / m(lambda) x R_cert(lambda, theta_i)          (% of a perfect mirror)
    Y         = sum_l W_Y(l) R(l)                                         (CIE 15:2004 eq. 7.1)

``m`` the mean reference spectrum over its repeats (averaged as spectra), ``R_cert`` the
certified reflectance of the standard (:mod:`goniolab.scan.standards`) and ``W_Y`` the
luminance row of the ASTM E308 weights of the lab's ``[colour]`` illuminant and observer
(:func:`goniolab.colour.spectra.xyz_weights`, Y = 100 for R = 1). The instrument's own
luminance is never used: it would count the mirror as 100 % (a real aluminium mirror is
88-92 %, not flat in wavelength).

When a reading has no usable spectrum, the fallback is the scalar
``Y = y / y_m x Y(R_cert)`` (``y``, ``y_m`` the instrument's luminances) and the reading's
``reference.method`` says so, with the reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from goniolab.colour.spectra import ColourSettings
from goniolab.scan.standards import Standard

__all__ = ["SpectralReference"]

#: A reference channel below this (in the instrument's %) is too dark to divide by.
MIN_REFERENCE_PCT = 0.5


@dataclass(frozen=True)
class SpectralReference:
    """The mean reference spectrum of a run and the standard it was read on."""

    standard: Standard
    theta_i_deg: float
    wavelengths_nm: tuple[float, ...]
    values_pct: NDArray[np.float64]
    luminance_pct: float
    settings: ColourSettings
    repeats: int

    @classmethod
    def from_readings(
        cls,
        standard: Standard,
        theta_i_deg: float,
        readings: Sequence[tuple[Sequence[float], Sequence[float], float]],
        settings: ColourSettings,
    ) -> SpectralReference:
        """From the reference's ``(wavelengths_nm, values_pct, luminance_pct)`` repeats,
        averaged as spectra (a grid that differs between repeats keeps the first grid's
        repeats only)."""
        if not readings:
            raise ValueError("no reference reading")
        wl0 = tuple(float(w) for w in readings[0][0])
        same = [
            r for r in readings if tuple(float(w) for w in r[0]) == wl0 and len(r[1]) == len(wl0)
        ]
        values = (
            np.mean(np.asarray([list(r[1]) for r in same], dtype=np.float64), axis=0)
            if same and wl0
            else np.zeros(0)
        )
        lum = float(np.mean([r[2] for r in readings]))
        return cls(standard, theta_i_deg, wl0, values, lum, settings, len(readings))

    def _y_row(self) -> NDArray[np.float64]:
        from goniolab.colour.spectra import xyz_weights

        return np.asarray(xyz_weights(self.wavelengths_nm, self.settings)[1], dtype=np.float64)

    def certified(self) -> NDArray[np.float64]:
        """The standard's certified reflectance (fraction) on the reference's grid."""
        return self.standard.reflectance(self.wavelengths_nm, self.theta_i_deg)

    def certified_luminance_pct(self) -> float:
        """Y of the certified reflectance (the reference reading's true luminance, %)."""
        from goniolab.colour.spectra import xyz_weights

        wl = np.arange(380.0, 781.0, 10.0)
        return self.standard.luminance_pct(self.theta_i_deg, xyz_weights(wl, self.settings)[1])

    def spectral_problem(self, wavelengths_nm: Sequence[float], values: Sequence[float]) -> str:
        """Why this reading cannot be referenced spectrally ("" if it can)."""
        if self.values_pct.size == 0:
            return "the reference readings carry no spectrum"
        if (
            len(values) != len(self.wavelengths_nm)
            or tuple(float(w) for w in wavelengths_nm) != self.wavelengths_nm
        ):
            return "the reading's wavelength grid differs from the reference's"
        low = float(self.values_pct.min())
        if low < MIN_REFERENCE_PCT:
            at = self.wavelengths_nm[int(np.argmin(self.values_pct))]
            return f"the reference reads {low:.3g} % at {at:g} nm, too dark to divide by"
        if not np.all(np.isfinite(np.asarray(values, dtype=np.float64))):
            return "the reading's spectrum is not finite"
        return ""

    def apply(
        self, wavelengths_nm: Sequence[float], values: Sequence[float], luminance_pct: float
    ) -> tuple[tuple[float, ...] | None, float, dict[str, Any]]:
        """``(absolute spectrum in % or None, absolute luminance in %, provenance)``; the
        scalar fallback scales the spectrum (if any) by ``Y(R_cert) / y_m``."""
        info: dict[str, Any] = {
            **self.standard.cite(),
            "theta_i_deg": self.theta_i_deg,
            "reference_luminance_pct": self.luminance_pct,
            "certified_luminance_pct": self.certified_luminance_pct(),
            "repeats": self.repeats,
        }
        problem = self.spectral_problem(wavelengths_nm, values)
        if not problem:
            try:
                y_row = self._y_row()
            except Exception as exc:  # colour-science refused the grid
                problem = f"no luminance weights for the grid: {exc}"
            else:
                v = np.asarray(values, dtype=np.float64)
                absolute = v / self.values_pct * self.certified() * 100.0
                info["method"] = "spectral"
                return (
                    tuple(float(x) for x in absolute),
                    float(y_row @ (absolute / 100.0)),
                    info,
                )
        if self.luminance_pct <= 0:
            raise ValueError(f"the reference reads {self.luminance_pct:g} %: not a reference")
        info["method"] = f"scalar ({problem})"
        factor = info["certified_luminance_pct"] / self.luminance_pct
        scaled = tuple(float(v) * factor for v in values) if len(values) else None
        return scaled, luminance_pct * factor, info
