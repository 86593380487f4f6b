"""The interface every reflectance model offers the instruments, the simulator and the runner.

:class:`goniolab.optics.facet.FacetModel` (from a measured height map) and
:class:`goniolab.optics.analytic.AnalyticModel` (Beckmann, GGX, Cook-Torrance, Ward) both
implement it, so a prediction, a simulated reading or a fit never depends on which it is.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics.apertures import Aperture

__all__ = ["ReflectanceModel"]


@runtime_checkable
class ReflectanceModel(Protocol):
    """A BRDF with the instrument responses derived from it (angles in degrees)."""

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        """BRDF in sr^-1 for the exact directions (no aperture)."""
        ...

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> NDArray[np.float64]:
        """In-plane BRDF in sr^-1 at signed theta_r (> 0 specular side)."""
        ...

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = ...,
        detector: Aperture = ...,
    ) -> NDArray[np.float64]:
        """Goniometer reading: 100 x fraction of incident flux reaching the detector aperture."""
        ...

    def reflected_fraction(
        self, theta_i_deg: float, theta_r_deg: float, source: Aperture, receptor: Aperture
    ) -> float:
        """Fraction of the flux from ``source`` (centred on theta_i) reaching ``receptor``."""
        ...

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        """ISO 2813 specular gloss in GU per geometry."""
        ...
