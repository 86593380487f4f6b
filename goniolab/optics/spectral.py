"""ISO 2813 spectral weighting: CIE illuminant C x photopic V(lambda).

ISO 2813 / ASTM D523 specify a glossmeter whose source and receptor together respond like
CIE illuminant C seen by the CIE 1924 photopic observer V(lambda) (PHYSICS.md, "Where the facet model stops: physical optics"). A wavelength-dependent model (Kirchhoff, Rayleigh-Rice) reads
``G = 100 sum_l w_l Phi_l / sum_l w_l Phi_std`` with ``w_l = S_C(l) V(l)``; the black
glass standard's reflectance is taken at its defining index 1.567 at every wavelength.

:func:`iso2813_weights` samples 16 wavelengths, 400 to 700 nm every 20 nm (V is below 0.4 %
of its peak outside), from colour-science's tables (imported here, lazily).

References
----------
.. [1] ISO 2813:2014, ASTM D523: specular gloss, spectral conditions (CIE C, V(lambda)).
.. [2] CIE 015:2018 Colorimetry (illuminant C; CIE 1924 photopic luminous efficiency).
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
from numpy.typing import NDArray

__all__ = ["ISO2813_WAVELENGTHS_NM", "iso2813_weights"]

#: The 16 wavelengths of the spectral gloss sum (nm).
ISO2813_WAVELENGTHS_NM: tuple[float, ...] = tuple(float(v) for v in range(400, 701, 20))


@functools.lru_cache(maxsize=8)
def _weights(lams: tuple[float, ...]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
        from colour.colorimetry import SDS_LEFS_PHOTOPIC

    c = colour.SDS_ILLUMINANTS["C"]
    v = SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]
    lam = np.asarray(lams, dtype=np.float64)
    w = np.asarray(c[lam], dtype=np.float64) * np.asarray(v[lam], dtype=np.float64)
    w = w / w.sum()
    lam.setflags(write=False)
    w.setflags(write=False)
    return lam, w


def iso2813_weights(
    wavelengths_nm: tuple[float, ...] = ISO2813_WAVELENGTHS_NM,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Wavelengths (nm) and normalised weights ``S_C V / sum(S_C V)`` (read-only arrays)."""
    return _weights(tuple(float(v) for v in wavelengths_nm))
