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

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "BRDF",
    "DEFAULT_N_RECEPTOR",
    "DEFAULT_N_SOURCE",
    "GONIO_CONE",
    "ISO2813_BLACK_GLASS_N",
    "ISO2813_RECEPTOR",
    "ISO2813_SOURCE",
    "MAX_CONE_RINGS",
    "MAX_SUBDIVISIONS",
    "Aperture",
    "Cone",
    "Rect",
    "Subdivisions",
    "aperture_contains",
    "cap_overlap_fraction",
    "direction",
    "inplane_centre",
    "integrate_brdf",
    "lobe_subdivisions",
    "projected_solid_angle_sr",
    "sample_aperture",
    "solid_angle_sr",
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

#: The Wittmann goniometer's lamp divergence and detector opening (6 deg full angle, sec. 2.3).
GONIO_CONE: Cone = Cone(6.0)

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


# --------------------------------------------------------------------------------------
# Direction sampling and the aperture double integral (Mihalik & Durikovic eqs. 15-17)
# --------------------------------------------------------------------------------------

#: Default number of subdivisions of the source aperture (per axis for a Rect, rings for a Cone).
DEFAULT_N_SOURCE: int = 8
#: Default number of subdivisions of the receptor aperture (per axis / rings).
DEFAULT_N_RECEPTOR: int = 16

FloatArray = NDArray[np.float64]
BRDF = Callable[[FloatArray, FloatArray], ArrayLike]
#: Aperture subdivisions: one count for both axes, or ``(n_in_plane, n_perpendicular)``.
Subdivisions = int | tuple[int, int]
#: Upper bound on subdivisions per axis chosen by :func:`lobe_subdivisions`.
MAX_SUBDIVISIONS: int = 400
#: Most (source, receptor) direction pairs passed to one brdf call by integrate_brdf.
_MAX_PAIRS: int = 262_144
#: Upper bound on the rings of a Cone chosen by :func:`lobe_subdivisions` (~3 k^2 patches).
MAX_CONE_RINGS: int = 64


def direction(theta_deg: ArrayLike, phi_deg: ArrayLike) -> FloatArray:
    """Unit vector(s) at polar angle ``theta_deg`` from +z and azimuth ``phi_deg`` from +x.

    Returns an array of shape ``(..., 3)``: ``(sin t cos p, sin t sin p, cos t)`` (docs/PHYSICS.md,
    "Frame and angles").
    """
    t = np.radians(np.asarray(theta_deg, dtype=np.float64))
    p = np.radians(np.asarray(phi_deg, dtype=np.float64))
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def inplane_centre(theta_r_deg: float) -> tuple[float, float]:
    """Polar and azimuth angle (deg) of a signed in-plane receptor angle.

    ``theta_r_deg > 0`` is the specular side (azimuth 180 deg, opposite the lamp at azimuth 0),
    ``theta_r_deg < 0`` the lamp side (azimuth 0).
    """
    t = float(theta_r_deg)
    return (t, 180.0) if t >= 0.0 else (-t, 0.0)


def _frame(theta_deg: float, phi_deg: float) -> FloatArray:
    """Rotation R = Rz(phi) Ry(theta): local +z -> centre, local +x -> e_theta, +y -> e_phi."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    ct, st, cp, sp = np.cos(t), np.sin(t), np.cos(p), np.sin(p)
    ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
    rz = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry


def _local_cone(cone: Cone, n: int) -> tuple[FloatArray, FloatArray]:
    """Central cap of polar radius du/2 plus rings [(k - 1/2) du, (k + 1/2) du] of 6k patches."""
    h = np.radians(cone.half_angle_deg)
    if h == 0.0:
        return np.array([[0.0, 0.0, 1.0]]), np.array([0.0])
    du = h / (n - 0.5) if n > 1 else 2.0 * h
    dirs: list[FloatArray] = [np.array([[0.0, 0.0, 1.0]])]
    weights: list[FloatArray] = [np.array([2.0 * np.pi * (1.0 - np.cos(min(0.5 * du, h)))])]
    for k in range(1, n):
        m = 6 * k
        u0, u1 = (k - 0.5) * du, (k + 0.5) * du
        u = k * du
        v = (np.arange(m) + 0.5) * (2.0 * np.pi / m)
        su = np.sin(u)
        dirs.append(np.stack([su * np.cos(v), su * np.sin(v), np.full(m, np.cos(u))], axis=-1))
        weights.append(np.full(m, 2.0 * np.pi * (np.cos(u0) - np.cos(u1)) / m))
    return np.concatenate(dirs), np.concatenate(weights)


def _local_rect(rect: Rect, n_in: int, n_perp: int) -> tuple[FloatArray, FloatArray]:
    """Midpoint grid in (alpha, beta) with exact patch solid angles da (sin b1 - sin b0)."""
    a_half, b_half = np.radians(0.5 * rect.in_plane_deg), np.radians(0.5 * rect.perp_deg)
    na = 1 if a_half == 0.0 else n_in
    nb = 1 if b_half == 0.0 else n_perp
    a_edges = np.linspace(-a_half, a_half, na + 1)
    b_edges = np.linspace(-b_half, b_half, nb + 1)
    a = 0.5 * (a_edges[:-1] + a_edges[1:])
    b = 0.5 * (b_edges[:-1] + b_edges[1:])
    da = np.diff(a_edges)
    dsinb = np.diff(np.sin(b_edges))
    aa, bb = np.meshgrid(a, b, indexing="ij")
    w = np.outer(da, dsinb).ravel()
    cb = np.cos(bb).ravel()
    d = np.stack([np.sin(aa).ravel() * cb, np.sin(bb).ravel(), np.cos(aa).ravel() * cb], axis=-1)
    return d, w


def sample_aperture(
    aperture: Aperture, theta_deg: float, phi_deg: float, *, n: Subdivisions = DEFAULT_N_RECEPTOR
) -> tuple[FloatArray, FloatArray]:
    """Deterministic quadrature of an aperture centred on the direction (theta_deg, phi_deg).

    The aperture is sampled in a local frame whose +z axis is the centre direction, +x the
    direction of increasing theta in the plane through the surface normal and the centre
    (the plane of incidence for an in-plane instrument) and +y = z cross x, perpendicular to it.
    World directions are ``R @ d_local`` with ``R = Rz(phi) Ry(theta)``.

    - :class:`Cone` of half angle h: a central cap of polar radius du/2 (one patch, the
      centre) and rings k = 1..n-1 covering polar angles [(k - 1/2) du, (k + 1/2) du] with
      du = h / (n - 1/2), each of 6k patches at polar angle k du. Weights are the exact ring
      solid angles 2 pi (cos u0 - cos u1) split evenly.
    - :class:`Rect`: in-plane angle alpha in [-A/2, A/2] and out-of-plane angle beta in
      [-B/2, B/2] (A = ``in_plane_deg``, B = ``perp_deg``), local direction
      ``(sin a cos b, sin b, cos a cos b)``, an n_in x n_perp midpoint grid; the patch solid
      angle is exact, ``dOmega = cos b da db`` integrated: ``da (sin b1 - sin b0)``.

    A zero-size aperture (``Cone(0)``, ``Rect(0, 0)``) is one direction of weight 0 (a point);
    a Rect with one zero side is a line of n directions of weight 0.

    Parameters
    ----------
    aperture
        The :class:`Cone` or :class:`Rect`.
    theta_deg, phi_deg
        Centre direction: polar angle from the normal and azimuth from +x, in degrees.
    n
        Subdivisions (>= 1): rings of a cone; cells per axis of a rectangle, or a pair
        ``(n_in, n_perp)`` (a cone uses the larger of the pair).

    Returns
    -------
    dirs, weights
        Unit directions ``(N, 3)`` in the sample frame and their solid angles ``(N,)`` in sr.
        Patches may lie below the horizon (``dirs[:, 2] <= 0``) for grazing centres; callers
        decide what to do with them (:func:`integrate_brdf` gives them no flux).

    References
    ----------
    .. [1] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", sec. 2.6 and eq. 15.
    """
    n_in, n_perp = (n, n) if isinstance(n, int) else (int(n[0]), int(n[1]))
    if min(n_in, n_perp) < 1:
        raise ValueError(f"aperture subdivisions must be >= 1, got {n}")
    if isinstance(aperture, Cone):
        local, w = _local_cone(aperture, max(n_in, n_perp))
    elif isinstance(aperture, Rect):
        local, w = _local_rect(aperture, n_in, n_perp)
    else:
        raise TypeError(f"unknown aperture type {type(aperture).__name__}")
    dirs = local @ _frame(theta_deg, phi_deg).T
    return dirs, w


def lobe_subdivisions(
    aperture: Aperture,
    theta_deg: float,
    lobe_in_rad: float,
    lobe_perp_rad: float,
    *,
    minimum: int = DEFAULT_N_RECEPTOR,
    maximum: int = MAX_SUBDIVISIONS,
) -> tuple[int, int]:
    """Receptor subdivisions whose step is at most the lobe's angular width in each axis.

    A midpoint rule over a Gaussian-like lobe of standard deviation sigma is accurate to
    ~exp(-2 pi^2 sigma^2 / h^2) when the step h <= sigma. A specular lobe of a surface with
    per-axis rms slope s has ``sigma_in ~ 2 s`` in the plane of incidence and
    ``sigma_perp ~ 2 s cos(theta)`` perpendicular to it (the mirror direction turns by twice
    the facet tilt, foreshortened by cos(theta) out of the plane); callers pass those widths.

    Returns ``(n_in, n_perp)`` clipped to ``[minimum, maximum]``; for a Cone both are the ring
    count needed for the narrower width, at most :data:`MAX_CONE_RINGS`.
    """
    lin = max(float(lobe_in_rad), 1e-9)
    lperp = max(float(lobe_perp_rad), 1e-9)
    if isinstance(aperture, Cone):
        rings = int(np.ceil(np.radians(aperture.half_angle_deg) / min(lin, lperp) + 0.5))
        k = int(np.clip(rings, minimum, min(maximum, MAX_CONE_RINGS)))
        return k, k
    n_in = int(np.ceil(np.radians(aperture.in_plane_deg) / lin))
    n_perp = int(np.ceil(np.radians(aperture.perp_deg) / lperp))
    return int(np.clip(n_in, minimum, maximum)), int(np.clip(n_perp, minimum, maximum))


def solid_angle_sr(aperture: Aperture) -> float:
    """Exact solid angle of an aperture in sr: 2 pi (1 - cos h) or 4 sin(A/2) sin(B/2)."""
    if isinstance(aperture, Cone):
        return float(2.0 * np.pi * (1.0 - np.cos(np.radians(aperture.half_angle_deg))))
    a, b = np.radians(0.5 * aperture.in_plane_deg), np.radians(0.5 * aperture.perp_deg)
    return float(2.0 * a * 2.0 * np.sin(b))


def projected_solid_angle_sr(detector: Cone, theta_r_deg: float) -> float:
    """``int cos(theta) dOmega`` over a detector cone centred on the signed in-plane angle
    ``theta_r_deg``, counting only its part above the horizon, in sr.

    A cap of half angle a wholly above the horizon has ``int w dOmega = pi sin^2(a) c`` (c its
    axis: the vector area of a spherical cap), so ``pi sin^2(a) cos(theta_r)``; a cap that
    crosses the horizon is integrated over its part above it (32 rings of
    :func:`sample_aperture`).
    """
    a_deg = detector.half_angle_deg
    if abs(theta_r_deg) + a_deg < 90.0:
        return math.pi * math.sin(math.radians(a_deg)) ** 2 * math.cos(math.radians(theta_r_deg))
    dirs, w = sample_aperture(detector, *inplane_centre(theta_r_deg), n=32)
    return float(np.sum(np.clip(dirs[:, 2], 0.0, None) * w))


def aperture_contains(
    aperture: Aperture, theta_deg: float, phi_deg: float, dirs: ArrayLike
) -> NDArray[np.bool_]:
    """Whether unit directions ``(N, 3)`` fall inside an aperture centred on (theta, phi).

    Uses the local frame of :func:`sample_aperture`: a Cone contains directions within its half
    angle of the centre; a Rect those with ``|alpha| <= A/2`` and ``|beta| <= B/2`` where
    ``beta = asin(y_local)`` and ``alpha = atan2(x_local, z_local)``.
    """
    d = np.asarray(dirs, dtype=np.float64) @ _frame(theta_deg, phi_deg)
    if isinstance(aperture, Cone):
        cos_h = np.cos(np.radians(aperture.half_angle_deg))
        return np.asarray(d[..., 2] >= cos_h - 1e-15)
    beta = np.arcsin(np.clip(d[..., 1], -1.0, 1.0))
    alpha = np.arctan2(d[..., 0], d[..., 2])
    eps = 1e-12
    return np.asarray(
        (np.abs(alpha) <= np.radians(0.5 * aperture.in_plane_deg) + eps)
        & (np.abs(beta) <= np.radians(0.5 * aperture.perp_deg) + eps)
    )


def integrate_brdf(
    brdf: BRDF,
    theta_i_deg: float,
    theta_r_deg: float,
    source: Aperture,
    receptor: Aperture,
    *,
    n_source: Subdivisions = DEFAULT_N_SOURCE,
    n_receptor: Subdivisions = DEFAULT_N_RECEPTOR,
    phi_i_deg: float = 0.0,
) -> float:
    """Fraction of the incident flux reaching the receptor (Mihalik eq. 15, source normalised).

    With source patches ``s`` (directions ``wi_s``, solid angles ``dOmega_s``, uniform radiance
    over the source aperture) and receptor patches ``d``::

        Phi = sum_s dOmega_s sum_d f(wi_s, wo_d) cos(theta_d) dOmega_d / sum_s dOmega_s

    i.e. Mihalik's double sum (eq. 15) divided by the source's solid angle, so a mirror of
    reflectance R whose mirror image of the source falls inside the receptor gives ``R``.
    A glossmeter reading is then ``100 Phi / F(1.567, theta)`` (eqs. 16-17; the black-glass
    flux is its Fresnel reflectance, its mirror image lying inside the receptor).

    Parameters
    ----------
    brdf
        Vectorised ``f(wi, wo) -> sr^-1`` taking two ``(N, 3)`` arrays of unit vectors
        (``wi`` points to the lamp, ``wo`` to the receptor).
    theta_i_deg
        Polar angle of the source centre (azimuth ``phi_i_deg``, default 0).
    theta_r_deg
        Signed in-plane receptor angle: > 0 specular side (azimuth ``phi_i_deg + 180``),
        < 0 lamp side.
    source, receptor
        Apertures. A point source (``Cone(0)``) is a collimated beam. A point receptor has no
        solid angle; the result is then the flux per steradian ``mean_s f cos(theta_o)``
        (sr^-1) in the receptor's direction (averaged over the directions of a line aperture).
    n_source, n_receptor
        Subdivisions passed to :func:`sample_aperture`. The receptor grid must resolve the
        BRDF lobe: the midpoint rule is accurate when the step is below the lobe's angular
        width in each axis (see :func:`lobe_subdivisions`).

    Returns
    -------
    float
        Fraction of the incident flux (dimensionless; sr^-1 for a point receptor).
        Receptor patches at or below the horizon receive nothing.

    References
    ----------
    .. [1] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eqs. 15-17.
    .. [2] B. Wittmann et al., Prog. Org. Coat. 156 (2021) 106247, sec. 2.3.
    """
    t_r, p_r = inplane_centre(theta_r_deg)
    wi, w_s = sample_aperture(source, float(theta_i_deg), float(phi_i_deg), n=n_source)
    wo, w_d = sample_aperture(receptor, t_r, p_r + float(phi_i_deg), n=n_receptor)
    src_ok = wi[:, 2] > 0.0
    rec_ok = wo[:, 2] > 0.0
    if solid_angle_sr(source) == 0.0:
        w_s = np.full_like(w_s, 1.0 / w_s.size)
    if solid_angle_sr(receptor) == 0.0:
        w_d = np.full_like(w_d, 1.0 / w_d.size)
    wi, w_s = wi[src_ok], w_s[src_ok]
    wo, w_d = wo[rec_ok], w_d[rec_ok]
    total_source = float(np.sum(w_s))
    if total_source == 0.0 or wo.shape[0] == 0:
        return 0.0
    ns, nd = wi.shape[0], wo.shape[0]
    proj = wo[:, 2] * w_d
    per_source = np.empty(ns)
    step = max(1, _MAX_PAIRS // nd)  # bound the memory of one brdf call
    for k in range(0, ns, step):
        chunk = wi[k : k + step]
        m = chunk.shape[0]
        f = np.asarray(
            brdf(np.repeat(chunk, nd, axis=0), np.tile(wo, (m, 1))), dtype=np.float64
        ).reshape(m, nd)
        per_source[k : k + m] = f @ proj
    return float(per_source @ w_s / total_source)


def cap_overlap_fraction(gamma_rad: ArrayLike, a_s_rad: float, a_d_rad: float) -> FloatArray:
    """Fraction of a spherical cap of half angle ``a_s`` inside a cap of half angle ``a_d``.

    Parameters
    ----------
    gamma_rad : array_like
        Angular separation of the cap centres (radians).
    a_s_rad, a_d_rad : float
        Half angles of the source and detector caps (radians, < pi/2).

    Returns
    -------
    ndarray
        ``area(cap_s ∩ cap_d) / area(cap_s)``, cap area ``2 pi (1 - cos a)``. The lens area
        is Tovchigrechko & Vakser's spherical formula; for caps below 1e-3 rad it is the
        planar circle-circle lens (relative error < 1e-6, and free of the cancellation the
        spherical form suffers there). A point source (a_s = 0) gives the indicator of
        ``gamma < a_d``; a point detector (a_d = 0) collects nothing (0).
    """
    g = np.abs(np.asarray(gamma_rad, dtype=np.float64))
    a, b = float(a_s_rad), float(a_d_rad)
    if a < 0 or b < 0:
        raise ValueError("cap half angles must be >= 0")
    if b == 0.0:
        return np.zeros_like(g)
    if a == 0.0:
        return np.where(g < b, 1.0, np.where(g == b, 0.5, 0.0))
    area_s = 4.0 * math.pi * math.sin(0.5 * a) ** 2
    area_d = 4.0 * math.pi * math.sin(0.5 * b) ** 2
    full = min(area_s, area_d) / area_s
    out = np.where(g <= abs(a - b), full, 0.0)
    lens = (g > abs(a - b)) & (g < a + b)
    if np.any(lens):
        gl = g[lens]
        if max(a, b) < 1e-3:
            c1 = np.clip((gl * gl + a * a - b * b) / (2.0 * gl * a), -1.0, 1.0)
            c2 = np.clip((gl * gl + b * b - a * a) / (2.0 * gl * b), -1.0, 1.0)
            tri = (-gl + a + b) * (gl + a - b) * (gl - a + b) * (gl + a + b)
            area = (
                (
                    a * a * np.arccos(c1)
                    + b * b * np.arccos(c2)
                    - 0.5 * np.sqrt(np.maximum(tri, 0.0))
                )
                / (math.pi * a * a)
                * area_s
            )
        else:
            # Numerators as 1 - cos = 2 sin^2(./2) sums, free of cancellation for small caps:
            # cos u - cos v cos w = 2 (hv + hw - hu - 2 hv hw), h. = sin^2(./2).
            ha, hb = math.sin(0.5 * a) ** 2, math.sin(0.5 * b) ** 2
            hg = np.sin(0.5 * gl) ** 2
            sa, sb, sg = math.sin(a), math.sin(b), np.sin(gl)
            x = np.clip(2.0 * (ha + hb - hg - 2.0 * ha * hb) / (sa * sb), -1.0, 1.0)
            y = np.clip(2.0 * (hg + ha - hb - 2.0 * hg * ha) / (sg * sa), -1.0, 1.0)
            z = np.clip(2.0 * (hg + hb - ha - 2.0 * hg * hb) / (sg * sb), -1.0, 1.0)
            acy, acz = np.arccos(y), np.arccos(z)
            # 2 [pi - acos x - cos a acos y - cos b acos z], the spherical excess split off
            area = 2.0 * ((math.pi - np.arccos(x) - acy - acz) + 2.0 * ha * acy + 2.0 * hb * acz)
        out[lens] = np.clip(area / area_s, 0.0, full)
    result: FloatArray = out
    return result
