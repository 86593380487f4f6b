"""ISO 2813 spectral weighting: CIE illuminant C x photopic V(lambda).

ISO 2813 / ASTM D523 specify a glossmeter whose source and receptor together respond like
CIE illuminant C seen by the CIE 1924 photopic observer V(lambda) (PHYSICS.md, "Where the facet model stops: physical optics"). A wavelength-dependent model (Kirchhoff, Rayleigh-Rice) reads
``G = 100 sum_l w_l Phi_l / sum_l w_l Phi_std`` with ``w_l = S_C(l) V(l)``; the black
glass standard's reflectance is taken at its defining index 1.567 at every wavelength.

:func:`iso2813_weights` samples 16 wavelengths, 400 to 700 nm every 20 nm (V is below 0.4 %
of its peak outside). The 16 pairs of CIE values are written out below, not read from
colour-science at run time: ``import colour`` imports its plotting package and with it
matplotlib (1-7 s), which a gloss prediction does not need; tests/optics/test_spectral.py
checks the table against colour-science's CIE data.

References
----------
.. [1] ISO 2813:2014, ASTM D523: specular gloss, spectral conditions (CIE C, V(lambda)).
.. [2] CIE 015:2018 Colorimetry (illuminant C; CIE 1924 photopic luminous efficiency).
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "CIE_C_AT_WAVELENGTHS",
    "CIE_V_AT_WAVELENGTHS",
    "ISO2813_WAVELENGTHS_NM",
    "iso2813_weights",
]

#: The 16 wavelengths of the spectral gloss sum (nm).
ISO2813_WAVELENGTHS_NM: tuple[float, ...] = tuple(float(v) for v in range(400, 701, 20))


#: CIE illuminant C (relative spectral power, CIE 015:2018 table) at the 16 wavelengths.
CIE_C_AT_WAVELENGTHS: tuple[float, ...] = (
    63.3, 98.1, 121.5, 123.1, 123.9, 112.1, 96.9, 102.1,
    105.3, 97.8, 89.7, 88.1, 87.8, 87.9, 84.0, 76.3,
)  # fmt: skip
#: CIE 1924 photopic luminous efficiency V(lambda) at the 16 wavelengths.
CIE_V_AT_WAVELENGTHS: tuple[float, ...] = (
    0.000396, 0.004, 0.023, 0.06, 0.13902, 0.323, 0.71, 0.954,
    0.995, 0.87, 0.631, 0.381, 0.175, 0.061, 0.017, 0.004102,
)  # fmt: skip


@functools.lru_cache(maxsize=8)
def _weights(lams: tuple[float, ...]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    lam = np.asarray(lams, dtype=np.float64)
    if lams == ISO2813_WAVELENGTHS_NM:
        c = np.asarray(CIE_C_AT_WAVELENGTHS)
        v = np.asarray(CIE_V_AT_WAVELENGTHS)
    else:  # another grid: colour-science's tables (a slow first import)
        from goniolab.lazy_imports import import_colour

        colour = import_colour()
        from colour.colorimetry import SDS_LEFS_PHOTOPIC

        c = np.asarray(colour.SDS_ILLUMINANTS["C"][lam], dtype=np.float64)
        v = np.asarray(SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"][lam])
    w = c * v
    w = w / w.sum()
    lam.setflags(write=False)
    w.setflags(write=False)
    return lam, w


def iso2813_weights(
    wavelengths_nm: tuple[float, ...] = ISO2813_WAVELENGTHS_NM,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Wavelengths (nm) and normalised weights ``S_C V / sum(S_C V)`` (read-only arrays)."""
    return _weights(tuple(float(v) for v in wavelengths_nm))
