"""Instrument apertures: the goniometer's circular cones and ISO 2813 rectangles.

An aperture is described by its angular size around a central direction. Circular cones
(:class:`Cone`) model the goniospectrophotometer of Wittmann et al. (2021, sec. 2.3): a lamp
of 6 deg divergence and a STIL Ruby detector of 6 deg opening. Rectangles (:class:`Rect`)
model the glossmeter apertures of ISO 2813 / ASTM D523 (Mihalik & Durikovic, table 1):
``in_plane_deg`` is the full angle in the plane of incidence, ``perp_deg`` the full angle
perpendicular to it.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 2.3-2.4, eqs. 12-13.
.. [2] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", table 1, eqs. 15-17.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "ISO2813_BLACK_GLASS_N",
    "ISO2813_RECEPTOR",
    "ISO2813_SOURCE",
    "Aperture",
    "Cone",
    "Rect",
]


@dataclass(frozen=True, slots=True)
class Cone:
    """A circular aperture of full opening angle ``full_angle_deg``."""

    full_angle_deg: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.full_angle_deg < 90.0:
            raise ValueError(f"cone full angle must be in [0, 90) deg, got {self.full_angle_deg}")

    @property
    def half_angle_deg(self) -> float:
        return 0.5 * self.full_angle_deg


@dataclass(frozen=True, slots=True)
class Rect:
    """A rectangular aperture: full angles in the plane of incidence and perpendicular to it."""

    in_plane_deg: float
    perp_deg: float

    def __post_init__(self) -> None:
        for name, v in (("in_plane_deg", self.in_plane_deg), ("perp_deg", self.perp_deg)):
            if not 0.0 <= v < 90.0:
                raise ValueError(f"rect {name} must be in [0, 90) deg, got {v}")


Aperture = Cone | Rect

#: Refractive index of the ISO 2813 primary standard (polished black glass) at 587.6 nm.
ISO2813_BLACK_GLASS_N: float = 1.567

#: Source image aperture, the same for all three geometries (Mihalik table 1).
ISO2813_SOURCE: Rect = Rect(0.75, 2.5)

#: Receptor apertures per geometry (Mihalik table 1; Wittmann sec. 2.4 for 60 and 85 deg).
ISO2813_RECEPTOR: dict[int, Rect] = {
    20: Rect(1.8, 3.6),
    60: Rect(4.4, 11.7),
    85: Rect(4.0, 6.0),
}
