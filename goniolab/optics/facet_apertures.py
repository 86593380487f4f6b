"""Cone-and-aperture integration of the facet model (:mod:`goniolab.optics.facet`).

A facet's mirror ``M = 2 m m^T - I`` maps the source cone onto a cone of the same size
around its mirror direction, so a facet's share of a detector cone is the overlap of two
spherical caps (:func:`cap_overlap_moments`, tabulated by :func:`cone_table`) plus the
first-order term of the facet weight across the source. Towards grazing incidence the
source is split into sub-cones (:func:`source_parts`), and a cone that reaches the horizon
is clipped there (:func:`clipped_source_parts`); the module docstring of
:mod:`goniolab.optics.facet` gives the accuracy of each step against brute force.
:func:`aperture_directions` samples an aperture uniformly in solid angle (the point
receptor's average); the angle checks are shared with the physical-optics models.

References
----------
.. [1] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eqs. 15-17.
.. [2] A. Tovchigrechko, I. A. Vakser, "How common is the funnel-like energy landscape in
   protein-protein interactions?", Protein Sci. 10 (2001) 1572 (area of intersection of
   two spherical caps).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics.apertures import Aperture, Cone, cap_overlap_fraction, sample_aperture

__all__ = [
    "HORIZON_RINGS",
    "SPLIT_SOURCE_RINGS",
    "aperture_directions",
    "cap_overlap_moments",
    "check_angle",
    "check_source_above_horizon",
    "clipped_source_parts",
    "cone_table",
    "node_gamma",
    "reaches_horizon",
    "source_parts",
    "unit_direction",
    "unit_wi",
    "zero_solid_angle",
]

FloatArray = NDArray[np.float64]

#: Nodes of the tabulated cap-overlap fraction O(gamma).
_CONE_TABLE_SIZE = 4097
#: Nodes of the tabulated first moment M1(gamma), each by 3 x 16 Gauss-Legendre nodes: within
#: 3.5e-4 of its peak of 4097 x 3 x 48 (cones 0.2-3 deg), in a term that is itself a 1-2 %
#: correction, at a tenth of the cost (80 ms per cone pair, more than the lean curve).
_M1_TABLE_SIZE = 1025

#: The positive half of the 16-point Gauss-Legendre rule on [-1, 1] (nodes, weights), the
#: doubles ``numpy.polynomial.legendre.leggauss(16)`` gives (its rule is symmetric to the
#: last bit; tests/optics/test_facet.py holds them to it): the cone table's rule without
#: importing numpy.polynomial, 2 ms of a ``predict brdf`` process.
_GL16_X = (0.09501250983763744, 0.2816035507792589, 0.45801677765722737, 0.6178762444026438,
           0.755404408355003, 0.8656312023878318, 0.9445750230732326, 0.9894009349916499)  # fmt: skip
_GL16_W = (0.18945061045506864, 0.18260341504492364, 0.16915651939500265, 0.1495959888165767,
           0.12462897125553407, 0.0951585116824926, 0.062253523938647456, 0.027152459411754176)  # fmt: skip


def gauss_legendre(n: int) -> tuple[FloatArray, FloatArray]:
    """``numpy.polynomial.legendre.leggauss(n)``: nodes and weights of the n-point rule on
    [-1, 1] (the 16-point rule from :data:`_GL16_X`, :data:`_GL16_W`, the same doubles)."""
    if n == len(_GL16_X) * 2:
        x = np.array(_GL16_X)
        w = np.array(_GL16_W)
        return np.concatenate((-x[::-1], x)), np.concatenate((w[::-1], w))
    from numpy.polynomial.legendre import leggauss

    nodes, weights = leggauss(n)
    return nodes, weights


def cap_overlap_moments(
    gamma_rad: ArrayLike, a_s_rad: float, a_d_rad: float, *, n_nodes: int = 48
) -> tuple[FloatArray, FloatArray]:
    """Zeroth and first moments of the part of a source cap inside a detector cap.

    Polar coordinates (r, phi) about the source cap's centre, phi from the direction to the
    detector's centre at angular distance gamma: a point is inside the detector when
    ``cos phi >= (cos a_d - cos r cos gamma)/(sin r sin gamma)``, i.e. for
    ``|phi| <= phi0(r)``. Then, over the source cap area ``2 pi (1 - cos a_s)``,

    - ``O = int_0^a_s 2 phi0(r) sin r dr / area`` (equals :func:`cap_overlap_fraction`);
    - ``M1 = int_0^a_s 2 sin phi0(r) sin^2 r dr / area``: the mean over the source cap of
      ``sin r cos phi`` (the tangent offset towards the detector) times the indicator,
      which turns a weight's gradient along that tangent into its first-order change of
      the collected flux.

    Gauss-Legendre with ``n_nodes`` per piece, the r range split where phi0 has its kinks
    (r = |gamma - a_d| and gamma + a_d). Returns ``(O, M1)`` shaped like ``gamma_rad``.
    """
    g = np.abs(np.asarray(gamma_rad, dtype=np.float64))
    a, b = float(a_s_rad), float(a_d_rad)
    if a <= 0.0 or b <= 0.0:
        raise ValueError("cap_overlap_moments needs cap half angles > 0")
    x_gl, w_gl = gauss_legendre(n_nodes)
    flat = g.ravel()[:, None]
    cuts = np.concatenate(
        [np.zeros_like(flat), np.clip(np.abs(flat - b), 0.0, a), np.clip(flat + b, 0.0, a)],
        axis=1,
    )
    cuts = np.sort(np.concatenate([cuts, np.full_like(flat, a)], axis=1), axis=1)
    lo, hi = cuts[:, :-1, None], cuts[:, 1:, None]  # (G, 3, 1)
    r = lo + (hi - lo) * 0.5 * (x_gl + 1.0)
    wr = (hi - lo) * 0.5 * w_gl
    hr, hg, hb = np.sin(0.5 * r) ** 2, np.sin(0.5 * flat[..., None]) ** 2, math.sin(0.5 * b) ** 2
    # cos b - cos r cos g = 2 (hr + hg - hb - 2 hr hg), h. = sin^2(./2): no cancellation
    num = 2.0 * (hr + hg - hb - 2.0 * hr * hg)
    den = np.sin(r) * np.sin(flat[..., None])
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_phi0 = np.where(den > 0.0, num / den, np.where(num <= 0.0, -1.0, 1.0))
    phi0 = np.arccos(np.clip(cos_phi0, -1.0, 1.0))
    area = 4.0 * math.pi * math.sin(0.5 * a) ** 2
    o = np.sum(2.0 * phi0 * np.sin(r) * wr, axis=(1, 2)) / area
    m1 = np.sum(2.0 * np.sin(phi0) * np.sin(r) ** 2 * wr, axis=(1, 2)) / area
    return o.reshape(g.shape), m1.reshape(g.shape)


@functools.lru_cache(maxsize=32)
def cone_table(a_s: float, a_d: float) -> tuple[FloatArray, float, float, float, FloatArray]:
    """Tabulated O(gamma) on [|a_s - a_d|, a_s + a_d], its value inside g0, and M1 on [0, g1].

    M1 is the first moment of :func:`cap_overlap_moments`; it is zero for a point source
    or a point detector (no first-order correction there).
    """
    g0, g1 = abs(a_s - a_d), a_s + a_d
    if a_d == 0.0:
        return np.zeros(2), g0, g1, 0.0, np.zeros(2)
    if a_s == 0.0:
        return np.zeros(2), a_d, a_d, 1.0, np.zeros(2)
    o_in = float(cap_overlap_fraction(np.array([0.0]), a_s, a_d)[0])
    table = cap_overlap_fraction(np.linspace(g0, g1, _CONE_TABLE_SIZE), a_s, a_d)
    _, m1 = cap_overlap_moments(np.linspace(0.0, g1, _M1_TABLE_SIZE), a_s, a_d, n_nodes=16)
    for arr in (table, m1):
        arr.setflags(write=False)
    return table, g0, g1, o_in, m1


def node_gamma(d_alpha: FloatArray, beta: FloatArray) -> FloatArray:
    """Angle between a node (in-plane offset d_alpha, out-of-plane beta) and the detector axis."""
    s2 = np.sin(0.5 * beta) ** 2 + np.cos(beta) * np.sin(0.5 * d_alpha) ** 2
    out: FloatArray = 2.0 * np.arcsin(np.sqrt(np.clip(s2, 0.0, 1.0)))
    return out


def zero_solid_angle(ap: Aperture) -> bool:
    if isinstance(ap, Cone):
        return ap.full_angle_deg == 0.0
    return ap.in_plane_deg == 0.0 or ap.perp_deg == 0.0


def unit_direction(alpha: FloatArray, beta: FloatArray) -> FloatArray:
    """Unit vector of in-plane angle alpha = atan2(-x, z) and out-of-plane beta = asin(y)."""
    out: FloatArray = np.stack(
        [-np.sin(alpha) * np.cos(beta), np.sin(beta), np.cos(alpha) * np.cos(beta)], axis=-1
    )
    return out


def aperture_directions(ap: Aperture, alpha_c: float) -> tuple[FloatArray, FloatArray]:
    """Directions (k, 3) and weights (sum 1) uniform in solid angle over an aperture.

    The aperture is centred on the in-plane direction of angle ``alpha_c`` (radians). Cones:
    512 Fibonacci-spiral points over the cap; rectangles: a 32 x 32 midpoint grid in
    (alpha, beta) weighted by cos(beta); zero extents collapse to the centre line/point.
    """
    if isinstance(ap, Cone):
        a = math.radians(ap.half_angle_deg)
        if a == 0.0:
            return unit_direction(np.array([alpha_c]), np.array([0.0])), np.ones(1)
        k = 512
        i = np.arange(k) + 0.5
        ct = 1.0 - i / k * (1.0 - math.cos(a))
        st = np.sqrt(1.0 - ct * ct)
        ph = i * math.pi * (3.0 - math.sqrt(5.0))
        local = np.stack([st * np.cos(ph), st * np.sin(ph), ct], axis=-1)
        # rotate the local frame (axis +z) about y onto the aperture centre
        ca, sa = math.cos(alpha_c), math.sin(alpha_c)
        rot = np.array([[ca, 0.0, -sa], [0.0, 1.0, 0.0], [sa, 0.0, ca]])
        return local @ rot.T, np.full(k, 1.0 / k)
    na = 32 if ap.in_plane_deg > 0 else 1
    nb = 32 if ap.perp_deg > 0 else 1
    da = math.radians(ap.in_plane_deg) * ((np.arange(na) + 0.5) / na - 0.5)
    db = math.radians(ap.perp_deg) * ((np.arange(nb) + 0.5) / nb - 0.5)
    aa, bb = np.meshgrid(alpha_c + da, db, indexing="ij")
    w = np.cos(bb).ravel()
    return unit_direction(aa.ravel(), bb.ravel()), w / w.sum()


def check_angle(name: str, value: float, lo: float, hi: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and lo <= v < hi):
        raise ValueError(f"{name} must be in [{lo}, {hi}) deg, got {value!r}")
    return v


def reaches_horizon(theta_i_deg: float, source: Aperture) -> bool:
    """Whether the source's in-plane half width takes it to the horizon (theta_i + it >= 90)."""
    half = source.half_angle_deg if isinstance(source, Cone) else 0.5 * source.in_plane_deg
    return theta_i_deg + half >= 90.0


def check_source_above_horizon(theta_i_deg: float, source: Aperture, masking: bool) -> None:
    """Reject a source that reaches the horizon (theta_i + in-plane half width >= 90) unless
    the model can take it: a cone with masking, whose part below the horizon is clipped
    (:func:`clipped_source_parts`).

    Without masking the facet weight ``c/(m_z cos theta)`` of a source direction diverges
    at the horizon, and so does the reading (brute-force source sampling gives 450-550 % of
    a mirror at 89 deg): Smith's shadowing ``G1(wi) ~ cos(theta)`` is what bounds it.
    """
    if not reaches_horizon(theta_i_deg, source):
        return
    half = source.half_angle_deg if isinstance(source, Cone) else 0.5 * source.in_plane_deg
    kind = "cone" if isinstance(source, Cone) else "rectangle"
    if kind == "rectangle" or not masking:
        why = "needs masking-shadowing" if kind == "cone" else "only cones are clipped there"
        raise ValueError(
            f"source {kind} of half width {half:g} deg at theta_i_deg = {theta_i_deg:g} "
            f"reaches the horizon (theta_i + half width >= 90 deg): the facet model {why}"
            + (" (masking=True; the CLI's default, --masking)" if kind == "cone" else "")
        )


def unit_wi(theta_i_deg: float) -> FloatArray:
    t = math.radians(theta_i_deg)
    return np.array([math.sin(t), 0.0, math.cos(t)])


#: Lamp angle (deg, centre + half width) from which a source cone is split into sub-cones:
#: (angle, rings of the ring quadrature); r rings give 1 + 3 r (r - 1) sub-cones (4: 37).
SPLIT_SOURCE_RINGS: tuple[tuple[float, int], ...] = ((78.0, 4),)


def source_parts(theta_i_deg: float, source: Cone) -> list[tuple[FloatArray, Cone, float]]:
    """The source cone as sub-cones ``(centre direction, cone, share of the flux)``.

    The cap-overlap (isometry) response carries the facet weight's variation across the
    source to first order only; the weight's ``1/cos(theta_s)`` grows fourfold across a
    6 deg cone at 85 deg, and the neglected second order left readings 8-10 % low there
    (18-23 % at 86.5; the module docstring). Towards grazing incidence the source is split
    into the patches of the ring quadrature of :func:`goniolab.optics.apertures.sample_aperture`
    (a central cap and rings of 6k patches, exact solid angles), each replaced by the cap of
    the same solid angle around its centre, whose response is again first-order exact: the
    remaining error falls with the square of the patch size. Measured against brute-force
    source sampling (64 x 64 Gaussian maps, rms slopes 0.05 and 0.2, specular -10..+2 deg,
    6 deg cones, 37 sub-cones): 0.25 % at 75 and 80 deg, 0.6 % at 85, 2.8 % at 86.5,
    against 1.4 / 2.4 / 9 / 23 % unsplit. The price is at the edge of the cones: a sub-cap
    of the outer ring reaches beyond the source's rim, so a flat mirror with equal cones
    reads 1.6 % low at its peak (against 1 % unsplit; error ~ 1/rings), which is why the
    split starts only where the second-order error of the unsplit cone exceeds it.
    Closer to the horizon the per-direction normalisation of eq. 15 itself diverges without
    masking (each source direction's reading is relative to its own irradiance, which
    vanishes: brute force gives 450-550 % of a mirror at 89 deg); with masking, Smith's
    shadowing bounds it, and a cone that reaches the horizon is clipped there
    (:func:`clipped_source_parts`); without, it is refused
    (:func:`check_source_above_horizon`).
    The share of a patch is its solid angle over the cone's, as in Mihalik eq. 15 (the
    source radiance uniform per solid angle).
    """
    a_deg = source.half_angle_deg
    rings = [r for edge, r in SPLIT_SOURCE_RINGS if theta_i_deg + a_deg >= edge]
    if a_deg == 0.0 or not rings:
        return [(unit_wi(theta_i_deg), source, 1.0)]
    dirs, omega = sample_aperture(source, theta_i_deg, 0.0, n=rings[-1])
    total = float(omega.sum())
    parts: list[tuple[FloatArray, Cone, float]] = []
    for d, w in zip(dirs, omega, strict=True):
        half = math.degrees(math.acos(1.0 - float(w) / (2.0 * math.pi)))
        parts.append((np.asarray(d, dtype=np.float64), Cone(2.0 * half), float(w) / total))
    return parts


#: Rings of the split of a source cone that reaches the horizon: 1 + 3 r (r - 1) = 169
#: patches of about 0.4 deg for the 6 deg goniometer cone.
HORIZON_RINGS = 8


def clipped_source_parts(theta_i_deg: float, source: Cone) -> list[tuple[FloatArray, Cone, float]]:
    """The part of a source cone above the horizon, as sub-cones ``(centre, cone, share)``.

    Source directions below the horizon do not light the surface: their flux misses the
    sample, and the share of every patch stays its solid angle over the whole cone's (the
    lamp's flux, Mihalik eq. 15), so a mirror at 89 deg reads the fraction of the beam that
    reaches it. The cone is split into the :data:`HORIZON_RINGS` ring quadrature of
    :func:`sample_aperture`; a patch straddling the horizon keeps the part above it (its
    solid angle and centroid, from 271 directions over its cap). Each sub-cone's response is
    taken at its centre (zeroth order, second-order error in the 0.4 deg patch): near the
    horizon the weight ``1/cos(theta_s)`` and Smith's ``G2 ~ cos(theta_s)`` vary inversely,
    and a first-order term of the weight alone would add, not cancel, their variation.
    """
    dirs, omega = sample_aperture(source, theta_i_deg, 0.0, n=HORIZON_RINGS)
    total = float(omega.sum())
    parts: list[tuple[FloatArray, Cone, float]] = []
    for d, w in zip(dirs, omega, strict=True):
        half = math.acos(1.0 - float(w) / (2.0 * math.pi))
        elevation = math.asin(max(-1.0, min(1.0, float(d[2]))))
        if elevation <= -half:
            continue
        centre, solid = np.asarray(d, dtype=np.float64), float(w)
        if elevation < half:  # straddles the horizon: keep what is above it
            theta_d = math.degrees(math.acos(float(d[2])))
            phi_d = math.degrees(math.atan2(float(d[1]), float(d[0])))
            cap, cw = sample_aperture(Cone(2.0 * math.degrees(half)), theta_d, phi_d, n=10)
            up = cap[:, 2] > 0.0
            if not up.any():
                continue
            solid = float(w) * float(cw[up].sum() / cw.sum())
            centre = cw[up] @ cap[up]
            centre = centre / float(np.linalg.norm(centre))
        sub_half = math.degrees(math.acos(1.0 - solid / (2.0 * math.pi)))
        parts.append((centre, Cone(2.0 * sub_half), solid / total))
    return parts
