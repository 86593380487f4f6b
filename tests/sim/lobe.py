"""A reflectance model with closed-form readings, shared by the simulator tests."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics.apertures import Aperture, Cone

CONE6 = Cone(6.0)


class LobeModel:
    """A Gaussian specular lobe, L = 100 exp(-((tr - ti)/w)^2) %, and fixed gloss values.

    Records every luminance evaluation (``calls``) and counts gloss evaluations
    (``gloss_calls``), so tests can check what the simulator asked the model.
    """

    def __init__(self, width_deg: float = 4.0, gloss_gu: dict[int, float] | None = None) -> None:
        self.width_deg = width_deg
        self.gloss_gu = gloss_gu or {20: 81.26, 60: 93.04, 85: 2500.0}
        self.calls: list[tuple[float, float, Aperture, Aperture]] = []
        self.gloss_calls = 0

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        return float(self._lobe(theta_i_deg, np.asarray([theta_r_deg]))[0])

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> NDArray[np.float64]:
        return self._lobe(theta_i_deg, np.asarray(theta_r_deg, dtype=np.float64))

    def _lobe(self, theta_i_deg: float, tr: NDArray[np.float64]) -> NDArray[np.float64]:
        return 100.0 * np.exp(-(((tr - theta_i_deg) / self.width_deg) ** 2))

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = CONE6,
        detector: Aperture = CONE6,
    ) -> NDArray[np.float64]:
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        self.calls.append((theta_i_deg, float(tr.reshape(-1)[0]), source, detector))
        return self._lobe(theta_i_deg, tr)

    def reflected_fraction(
        self, theta_i_deg: float, theta_r_deg: float, source: Aperture, receptor: Aperture
    ) -> float:
        return self.brdf_point(theta_i_deg, theta_r_deg) / 100.0

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        self.gloss_calls += 1
        return {a: self.gloss_gu[a] for a in angles_deg}
