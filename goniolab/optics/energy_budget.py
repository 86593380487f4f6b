"""Energy conservation of the wave models' diffuse light towards grazing incidence.

Beckmann's obliquity factor grows without bound towards grazing incidence, and the
first-order Rayleigh-Rice Q factor may exceed the Fresnel reflectance there: from
:data:`ENERGY_CHECK_FROM_DEG` on, the diffuse cells of a physical-optics model are scaled
so that the hemisphere's total stays within what the coherent beam leaves
(:meth:`EnergyBudget._energy_scales`, each model's bound in ``_energy_scales_at``), and the
reading's provenance says so (:meth:`EnergyBudget._energy_note`; docs/PHYSICS.md, "Energy").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from goniolab.optics.shared_map import SharedMap


class NonFiniteEnergySums(FloatingPointError):
    """An energy check's sums came out non-finite (NaN or inf): raised rather than scale
    the diffuse light by a factor made of them (never a silent factor of 1); the
    application turns it into its overflow error naming the surface."""


__all__ = ["ENERGY_CHECK_FROM_DEG", "EnergyBudget"]

#: From this incidence on, the diffuse part of the wave models is held to energy
#: conservation over the whole hemisphere (:meth:`EnergyBudget._energy_scales`):
#: Beckmann's obliquity factor grows without bound towards grazing incidence, and the
#: first-order Rayleigh-Rice Q factor may exceed the Fresnel reflectance there.
ENERGY_CHECK_FROM_DEG: float = 70.0
#: The interpolation nodes of the energy scale over ISO 2813's band (um).
ISO_BAND_UM: tuple[float, float, float] = (0.4, 0.55, 0.7)


class EnergyBudget:
    """The energy scales of a physical-optics model (a base of
    :class:`goniolab.optics.physical.PhysicalOpticsModel`; 1 unless a model bounds them)."""

    #: the model's name in notes
    kind: ClassVar[str]
    #: the map, its tiles and caches
    _shared: SharedMap

    def _energy_scales(self, theta_i_deg: float, lams_um: Sequence[float]) -> list[float]:
        """Factors (<= 1) applied to the diffuse cells so that the hemisphere's total stays
        within energy conservation, per wavelength (1 below :data:`ENERGY_CHECK_FROM_DEG`;
        the subclasses' :meth:`_energy_scales_at` state their bound). For more than three
        wavelengths the factor is computed at the shortest, median and longest and
        interpolated linearly in ``1/lambda^2`` (it is smooth in lambda: g ~ 1/lambda^2);
        a set within ISO 2813's 400-700 nm uses that band's ends and middle (400, 550,
        700 nm: those of the gloss's 16 wavelengths), so the gloss and the validity checks'
        subset (:meth:`_lams_for_checks`) share one computation."""
        if theta_i_deg < ENERGY_CHECK_FROM_DEG:
            return [1.0 for _ in lams_um]
        if len(lams_um) > 3:
            if ISO_BAND_UM[0] - 1e-9 <= min(lams_um) and max(lams_um) <= ISO_BAND_UM[-1] + 1e-9:
                nodes = list(ISO_BAND_UM)
            else:
                nodes = sorted({min(lams_um), float(np.median(lams_um)), max(lams_um)})
            at = self._energy_scales(theta_i_deg, nodes)
            x = [1.0 / v**2 for v in nodes][::-1]
            return [float(np.interp(1.0 / v**2, x, at[::-1])) for v in lams_um]
        key = (self.kind, "energy", round(theta_i_deg, 9), tuple(round(v, 12) for v in lams_um))
        scales: list[float] = self._shared.cached(
            key, lambda: self._energy_scales_at(theta_i_deg, lams_um)
        )
        return scales

    def _energy_scales_at(self, theta_i_deg: float, lams_um: Sequence[float]) -> list[float]:
        return [1.0 for _ in lams_um]

    def _energy_note(self, theta_i_deg: float, lams_nm: Sequence[float]) -> str | None:
        if theta_i_deg < ENERGY_CHECK_FROM_DEG:
            return None
        scales = self._energy_scales(theta_i_deg, [lam * 1e-3 for lam in lams_nm])
        low = min(scales)
        if low >= 0.99:
            return None
        return (
            f"{self.kind}: diffuse light scaled by {low:.3g} to conserve energy over the "
            f"hemisphere at theta_i = {theta_i_deg:g} deg (docs/PHYSICS.md, energy)"
        )
