"""The twin's spectra: the wavelength grid, the named body reflectances and the luminance weights.

Every simulated spectrum is sampled on :data:`SPECTRUM_WAVELENGTHS_NM`; a sample's body (the
paint under its clear coat) is one of :data:`BODY_SPECTRA` (:func:`body_reflectance`); a
spectrum becomes a luminance reading through :func:`luminance_weights` (CIE 15:2004 eq. 7.1).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["BODY_SPECTRA", "SPECTRUM_WAVELENGTHS_NM", "body_reflectance", "luminance_weights"]

FloatArray = NDArray[np.float64]

#: Wavelength grid of the simulated spectra: 380..780 nm in 10 nm steps.
SPECTRUM_WAVELENGTHS_NM: tuple[float, ...] = tuple(float(w) for w in range(380, 781, 10))

#: Named body reflectances (fractions), smooth analytic curves over 380..780 nm: the
#: black-inked PVC under the seed's coatings, a TiO2 white, a neutral grey and two colours.
BODY_SPECTRA: tuple[str, ...] = ("black", "white", "grey", "red", "blue")


def _sigmoid(x: FloatArray) -> FloatArray:
    return np.asarray(1.0 / (1.0 + np.exp(-x)))


def body_reflectance(
    name: str, wavelengths_nm: Sequence[float] = SPECTRUM_WAVELENGTHS_NM
) -> FloatArray:
    """Diffuse reflectance (fraction) of a named body at ``wavelengths_nm``.

    A painted truth's name (:data:`sim.twin_flakes.TWIN_PAINTS`) gives its diffuse body,
    the binder between and above the flakes (the flakes' lobe is added by
    :class:`sim.truth.TruthOptics`).

    Raises
    ------
    ValueError
        Unknown name (the message lists :data:`BODY_SPECTRA` and the painted truths).
    """
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    if name == "black":  # carbon-black ink: ~3 %, slightly rising to the red
        r = 0.028 + 0.006 * (wl - 380.0) / 400.0
    elif name == "white":  # TiO2 white: absorbs below ~410 nm
        r = 0.88 * _sigmoid((wl - 410.0) / 8.0) + 0.05
    elif name == "grey":
        r = np.full_like(wl, 0.30)
    elif name == "red":
        r = 0.05 + 0.65 * _sigmoid((wl - 600.0) / 15.0)
    elif name == "blue":
        r = 0.05 + 0.45 * np.exp(-(((wl - 460.0) / 45.0) ** 2))
    else:
        from sim.twin_flakes import TWIN_PAINTS  # a painted truth: its diffuse body

        paint = TWIN_PAINTS.get(name)
        if paint is None:
            known = ", ".join((*BODY_SPECTRA, *TWIN_PAINTS))
            raise ValueError(f"unknown body {name!r}; known: {known}")
        r = np.interp(wl, SPECTRUM_WAVELENGTHS_NM, paint.diffuse_reflectance())
    return np.asarray(r, dtype=np.float64)


@functools.lru_cache(maxsize=4)
def luminance_weights(
    observer: str = "CIE 1964 10 Degree Standard Observer", illuminant: str = "D65"
) -> FloatArray:
    """Normalised weights ``ybar(l) S(l)`` on :data:`SPECTRUM_WAVELENGTHS_NM`.

    ``Y = sum(w R)`` for a reflectance R (CIE 15:2004 eq. 7.1). The spectro uses the 10 deg
    observer and D65 (PHYSICS.md), the glossmeter the 2 deg V(lambda) and illuminant C
    (ISO 2813). colour-science is imported here, lazily (it is slow to import).
    """
    from goniolab.lazy_imports import import_colour

    colour = import_colour()

    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    cmfs = colour.MSDS_CMFS[observer]
    ybar = np.interp(wl, cmfs.wavelengths, cmfs.values[:, 1])
    sd = colour.SDS_ILLUMINANTS[illuminant]
    s = np.interp(wl, sd.wavelengths, sd.values)
    w = ybar * s
    return np.asarray(w / w.sum(), dtype=np.float64)
