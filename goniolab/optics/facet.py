"""The facet model: BRDF, goniometer luminance and ISO 2813 gloss from a measured surface.

Every pixel of a levelled height map is a small mirror (facet) of normal
``m = (-p, -q, 1)/sqrt(1 + p^2 + q^2)``. For the incident direction
``wi = (sin ti, 0, cos ti)`` a facet reflects towards ``wo = 2 (wi.m) m - wi`` (Wittmann
et al. 2021, eqs. 5-8) the fraction ``w / N`` of the incident flux, with the radiometric
weight (docs/PHYSICS.md, "The facet weight and the facet BRDF")

.. math:: w = \\frac{\\max(0, w_i\\cdot m)}{m_z \\cos\\theta_i} F(\\iota),
          \\qquad \\cos\\iota = w_i\\cdot m,

(the facet's area projected on x-y is one pixel). The local incidence angle iota is the
angle between wi and the facet normal: the seed's eq. 10 writes theta_r, phi_r where it means
theta_N, phi_N; ``cos iota = wi.m`` is the corrected form. With ``weighting="seed"``, ``w = F``
as in the seed, which weighs the slope histogram by Fresnel alone. Facets facing away from
the lamp get no light; facets whose mirror direction points into the surface
(``wo_z <= 0``) are dropped: their flux would need multiple scattering, which the model
does not follow, so it is lost rather than redistributed.

Binning ``w`` on the hemisphere estimates the BRDF, ``f = sum(w in bin)/(N dW cos to)``.
Its continuous counterpart is the analytic facet BRDF (Barrick's specular-point theory,
NIST SCATMECH ``Facet_BRDF_Model``)

.. math:: f = \\frac{F(w_i\\cdot h)\\, P_{22}(p_h, q_h)}{4\\cos\\theta_i\\cos\\theta_o
          \\cos^4\\theta_h},\\qquad p_h = -h_x/h_z,\\; q_h = -h_y/h_z,

used by :meth:`FacetModel.brdf_point` with P22 read from the slope histogram.

Instrument responses use that ``M = 2 m m^T - I`` is an isometry of the sphere: it maps the
source cone (half angle ``a_s`` around wi) onto a cone of the same size around ``wo_k``,
so a facet's contribution to a detector cone of half angle ``a_d`` at angular distance
``gamma_k`` is ``w_k O(gamma_k)``, with ``O`` the area of the intersection of the two
spherical caps over the area of the source cap (the source radiance is uniform per unit
solid angle, as in :func:`goniolab.optics.apertures.integrate_brdf`).

The weight of a facet varies across the source: in the image space ``o = M s``,
``w = c F(c)/(m_z s_z)`` with ``c = o.m`` and ``s_z = (M o)_z``, and ``1/s_z`` grows like
``tan(ti)`` across the cone. Taken at the cone's centre only, this is a first-order error
for images straddling the detector edge (2 % at ti = 45, 4 % at 60 in the flanks of the
curve against brute-force source sampling). The cone responses therefore carry the
first-order term: ``w_k O(gamma_k) + (grad w_k . e_k) M1(gamma_k)``, with ``e_k`` the unit
tangent at wo_k towards the detector and ``M1`` the first moment of the cap-cap lens
(:func:`cap_overlap_moments`). Stated approximation: the second-order term (the mean of
the weight's curvature over the cone) is neglected. Measured against brute-force source
sampling (tests; rms slopes 0.05 and 0.2, within 15 deg of specular): 0.1 % at normal
incidence, 0.5 % at ti = 45, 0.7 % at 60, 1.5 % at 75, 3 % at 80, 10 % low at 85 and
15-40 % at 86-87 with 6 deg cones, where 1/cos varies fourfold across the cone. From
theta_i + half width = 78 deg the source cone is therefore split into 37 sub-cones, each
with its own first-order response (:func:`_source_parts`): within 0.6 % up to 85 deg
(a flat mirror with equal cones then reads 1.6 % low at its peak). A flat mirror at 70 deg is within 0.9 % of the peak of its
exact curve. A source cone reaching the horizon (theta_i + half width >= 90 deg) is clipped
there, with masking (:func:`_clipped_source_parts`: 169 sub-cones, those below the horizon
dropped; within 0.3 % of brute force with per-facet masking from 87 to 89 deg); without
masking the weight of a source direction diverges at the horizon and the model refuses it
with a ValueError. With masking the cone readings take G2 at the grid nodes, where the
light leaves (:meth:`FacetModel._cone_grid`). The ISO 2813 rectangles keep the zeroth-order form (the 0.75 deg
in-plane source makes the variation small): within 0.2 % of brute force at 60 and 85 deg.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, eqs. 3-13.
.. [2] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eqs. 15-17 (source and
   receptor apertures), table 1.
.. [3] T. A. Germer, NIST SCATMECH ``Facet_BRDF_Model``; G. S. Brown / D. E. Barrick,
   specular-point theory of rough-surface scattering.
.. [4] E. Heitz, "Understanding the masking-shadowing function in microfacet-based BRDFs",
   JCGT 3(2) 2014 (Smith Lambda from a slope distribution, height-correlated G2).
.. [5] A. Tovchigrechko, I. A. Vakser, "How common is the funnel-like energy landscape in
   protein-protein interactions?", Protein Sci. 10 (2001) 1572 (area of intersection of
   two spherical caps).
"""

from __future__ import annotations

import functools
import itertools
import math
import os
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics import _kernels_numpy as KN
from goniolab.optics.apertures import (
    GONIO_CONE,
    ISO2813_BLACK_GLASS_N,
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Aperture,
    Cone,
    Rect,
    cap_overlap_fraction,
    sample_aperture,
)
from goniolab.optics.fresnel import fresnel, fresnel_dielectric
from goniolab.optics.surface import Surface

__all__ = [
    "FacetModel",
    "HemisphereBRDF",
    "cap_overlap_fraction",
    "cap_overlap_moments",
    "limit_threads",
]

FloatArray = NDArray[np.float64]
Weighting = Literal["radiometric", "seed"]
Backend = Literal["numba", "numpy", "lean"]

#: Facets per thread below which the numba kernels run on one thread.
_MIN_CHUNK = 1 << 16

#: Most facets used to tabulate the Smith Lambda function (deterministic subsample).
_LAMBDA_MAX_FACETS = 1 << 17
_LAMBDA_THETA_STEP_DEG = 0.5
_LAMBDA_PHI_STEP_DEG = 5.0
#: luminance_pct evaluates up to this many detector angles exactly, facet by facet.
_EXACT_MAX_POINTS = 2
#: Nodes of the tabulated cap-overlap fraction O(gamma).
_CONE_TABLE_SIZE = 4097
#: Rectangles narrower than this (deg, in plane) are read facet by facet in the ``"lean"``
#: backend: the slope cells' 0.06 deg steps of mirror direction are too coarse for the
#: ASTM E430 slits (0.05-0.4 deg; 1-50 % off), while the ISO 2813 readings stay within
#: 0.2 % of the facets' (Gaussian maps of rms slope 0.001-0.3).
LEAN_EXACT_BELOW_DEG = 0.5
#: Nodes of the tabulated first moment M1(gamma), each by 3 x 16 Gauss-Legendre nodes: within
#: 3.5e-4 of its peak of 4097 x 3 x 48 (cones 0.2-3 deg), in a term that is itself a 1-2 %
#: correction, at a tenth of the cost (80 ms per cone pair, more than the lean curve).
_M1_TABLE_SIZE = 1025
#: Slope bin of the histogram whose occupied cells stand for the facets in the ``"lean"``
#: backend's deposits and cone responses (a facet moves by up to half a bin in each slope,
#: its mirror direction by about 0.06 deg, against cones of degrees).
LEAN_SLOPE_BIN = 1e-3
#: Facets per block when the slope cells are counted.
_CELL_BLOCK = 1 << 18
#: The lean histogram keeps its counts dense while the slope range has at most this many
#: cells per facet (8 bytes each): beyond, only the occupied cells are counted.
_DENSE_CELLS_PER_FACET = 4
#: ... and always up to this many cells (8 MiB).
_DENSE_MIN_CELLS = 1 << 20
#: Largest |slope| / bin the lean histogram indexes: (2 * 2**30)**2 cells fit an int64 key.
_MAX_SLOPE_CELLS = 1 << 30


def _check_slope_range(p: FloatArray, q: FloatArray, bin_: float, source: str) -> None:
    """Refuse slopes the lean histogram cannot index, naming the map and the range.

    A slope of ``2**30 * 1e-3`` (about 1e6, a facet 6e-5 deg from vertical) means a map
    in the wrong units or with the wrong step, not a surface.
    """
    worst = max(float(np.max(np.abs(p))), float(np.max(np.abs(q))))
    if not (math.isfinite(worst) and worst / bin_ < _MAX_SLOPE_CELLS):
        raise ValueError(
            f"{source}: slopes up to {worst:.3g} (a facet {math.degrees(math.atan(worst)):.6g} "
            f"deg from horizontal): beyond the {_MAX_SLOPE_CELLS * bin_:.3g} the slope "
            "histogram indexes; check the map's height unit and lateral step"
        )


_executor: ThreadPoolExecutor | None = None
#: Empty third facet array: the kernels read ``(p, q)`` slopes instead of unit normals.
_SLOPES: FloatArray = np.empty(0)


_limits = threading.local()


def _numba_kernels() -> Any:
    """The compiled kernels (:mod:`goniolab.optics._kernels`), imported on first use: numba
    costs a process about 1 s to import and set up, which the ``"lean"`` backend avoids."""
    from goniolab.optics import _kernels

    return _kernels


@contextmanager
def limit_threads(n: int) -> Iterator[None]:
    """Within the block, this thread runs the facet kernels on at most ``n`` threads.

    A batch that spreads maps over worker processes (:mod:`goniolab.batch`) runs each map on
    one thread: the cores are busy with other maps, and a map's sums then do not depend on
    how the facets were split.
    """
    if n < 1:
        raise ValueError(f"limit_threads needs n >= 1, got {n}")
    old = getattr(_limits, "n", None)
    _limits.n = n
    try:
        yield
    finally:
        _limits.n = old


def _pool() -> ThreadPoolExecutor:
    global _executor
    if _executor is None:
        _executor = ThreadPoolExecutor(
            max_workers=max(1, os.cpu_count() or 1), thread_name_prefix="facet"
        )
    return _executor


@dataclass(frozen=True, eq=False)
class HemisphereBRDF:
    """BRDF estimated on a (theta_o, phi_o) grid of the reflection hemisphere.

    Attributes
    ----------
    theta_i_deg : float
        Incidence angle (phi_i = 0).
    theta_edges_deg, phi_edges_deg : ndarray
        Bin edges, theta 0..90 and phi 0..360 (phi_o = 180 is the specular half-plane).
    f_sr : ndarray
        ``f_sr[a, b]`` is the BRDF (sr^-1) averaged over bin (theta a, phi b):
        ``sum(w in bin) / (N * projected solid angle)``, projected solid angle
        ``(sin^2 th2 - sin^2 th1)/2 * dphi``.
    albedo : float
        Directional albedo ``sum(w)/N``: the fraction of the incident flux reflected.
    """

    theta_i_deg: float
    theta_edges_deg: FloatArray
    phi_edges_deg: FloatArray
    f_sr: FloatArray
    albedo: float


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
    x_gl, w_gl = np.polynomial.legendre.leggauss(n_nodes)
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
def _cone_table(a_s: float, a_d: float) -> tuple[FloatArray, float, float, float, FloatArray]:
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


def _node_gamma(d_alpha: FloatArray, beta: FloatArray) -> FloatArray:
    """Angle between a node (in-plane offset d_alpha, out-of-plane beta) and the detector axis."""
    s2 = np.sin(0.5 * beta) ** 2 + np.cos(beta) * np.sin(0.5 * d_alpha) ** 2
    out: FloatArray = 2.0 * np.arcsin(np.sqrt(np.clip(s2, 0.0, 1.0)))
    return out


def _zero_solid_angle(ap: Aperture) -> bool:
    if isinstance(ap, Cone):
        return ap.full_angle_deg == 0.0
    return ap.in_plane_deg == 0.0 or ap.perp_deg == 0.0


def _dir(alpha: FloatArray, beta: FloatArray) -> FloatArray:
    """Unit vector of in-plane angle alpha = atan2(-x, z) and out-of-plane beta = asin(y)."""
    out: FloatArray = np.stack(
        [-np.sin(alpha) * np.cos(beta), np.sin(beta), np.cos(alpha) * np.cos(beta)], axis=-1
    )
    return out


def _sample_aperture(ap: Aperture, alpha_c: float) -> tuple[FloatArray, FloatArray]:
    """Directions (k, 3) and weights (sum 1) uniform in solid angle over an aperture.

    The aperture is centred on the in-plane direction of angle ``alpha_c`` (radians). Cones:
    512 Fibonacci-spiral points over the cap; rectangles: a 32 x 32 midpoint grid in
    (alpha, beta) weighted by cos(beta); zero extents collapse to the centre line/point.
    """
    if isinstance(ap, Cone):
        a = math.radians(ap.half_angle_deg)
        if a == 0.0:
            return _dir(np.array([alpha_c]), np.array([0.0])), np.ones(1)
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
    return _dir(aa.ravel(), bb.ravel()), w / w.sum()


def _check_angle(name: str, value: float, lo: float, hi: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and lo <= v < hi):
        raise ValueError(f"{name} must be in [{lo}, {hi}) deg, got {value!r}")
    return v


def _reaches_horizon(theta_i_deg: float, source: Aperture) -> bool:
    """Whether the source's in-plane half width takes it to the horizon (theta_i + it >= 90)."""
    half = source.half_angle_deg if isinstance(source, Cone) else 0.5 * source.in_plane_deg
    return theta_i_deg + half >= 90.0


def _check_source_above_horizon(theta_i_deg: float, source: Aperture, masking: bool) -> None:
    """Reject a source that reaches the horizon (theta_i + in-plane half width >= 90) unless
    the model can take it: a cone with masking, whose part below the horizon is clipped
    (:func:`_clipped_source_parts`).

    Without masking the facet weight ``c/(m_z cos theta)`` of a source direction diverges
    at the horizon, and so does the reading (brute-force source sampling gives 450-550 % of
    a mirror at 89 deg): Smith's shadowing ``G1(wi) ~ cos(theta)`` is what bounds it.
    """
    if not _reaches_horizon(theta_i_deg, source):
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


def _unit_wi(theta_i_deg: float) -> FloatArray:
    t = math.radians(theta_i_deg)
    return np.array([math.sin(t), 0.0, math.cos(t)])


#: Lamp angle (deg, centre + half width) from which a source cone is split into sub-cones:
#: (angle, rings of the ring quadrature); r rings give 1 + 3 r (r - 1) sub-cones (4: 37).
SPLIT_SOURCE_RINGS: tuple[tuple[float, int], ...] = ((78.0, 4),)


def _source_parts(theta_i_deg: float, source: Cone) -> list[tuple[FloatArray, Cone, float]]:
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
    (:func:`_clipped_source_parts`); without, it is refused
    (:func:`_check_source_above_horizon`).
    The share of a patch is its solid angle over the cone's, as in Mihalik eq. 15 (the
    source radiance uniform per solid angle).
    """
    a_deg = source.half_angle_deg
    rings = [r for edge, r in SPLIT_SOURCE_RINGS if theta_i_deg + a_deg >= edge]
    if a_deg == 0.0 or not rings:
        return [(_unit_wi(theta_i_deg), source, 1.0)]
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


def _clipped_source_parts(theta_i_deg: float, source: Cone) -> list[tuple[FloatArray, Cone, float]]:
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


#: Histogram bin of P22 for maps without slope spread (Wittmann et al. 2021, sec. 3.1).
_HIST_BIN = 1e-3
#: Most grid nodes per axis of the slope kernel density.
_KDE_MAX_NODES = 2048


def _bilinear(
    kde: tuple[FloatArray, float, float, float, float], p: FloatArray, q: FloatArray
) -> FloatArray:
    """Bilinear interpolation of a gridded density at (p, q); 0 outside or for NaN."""
    dens, p0, q0, gp, gq = kde
    n_p, n_q = dens.shape
    x = np.nan_to_num((p - p0) / gp, nan=-1.0, posinf=-1.0, neginf=-1.0)
    y = np.nan_to_num((q - q0) / gq, nan=-1.0, posinf=-1.0, neginf=-1.0)
    inside = (x >= 0) & (x <= n_p - 1) & (y >= 0) & (y <= n_q - 1)
    x, y = np.where(inside, x, 0.0), np.where(inside, y, 0.0)
    i = np.minimum(np.floor(x).astype(np.int64), n_p - 2)
    j = np.minimum(np.floor(y).astype(np.int64), n_q - 2)
    fx, fy = x - i, y - j
    v = (
        dens[i, j] * (1 - fx) * (1 - fy)
        + dens[i + 1, j] * fx * (1 - fy)
        + dens[i, j + 1] * (1 - fx) * fy
        + dens[i + 1, j + 1] * fx * fy
    )
    out: FloatArray = np.where(inside, v, 0.0)
    return out


class FacetModel:
    """Facet model of a measured surface (implements ``ReflectanceModel``).

    Parameters
    ----------
    surface : Surface
        The facet set (see :meth:`Surface.from_heightmap`).
    n : float or complex
        Refractive index; complex ``n + ik`` selects the conductor Fresnel term.
    weighting : {"radiometric", "seed"}
        Facet weight: ``c/(m_z cos ti) F`` (radiometric, docs/PHYSICS.md) or ``F`` (Wittmann).
    masking : bool
        Without masking the model is the seed's: unshadowed facets. It is reciprocal, but at
        grazing incidence on rough surfaces (slopes above cot ti) the lit facets intercept
        more than the flux falling on the surface and the albedo can exceed 1. With masking,
        multiply by the height-correlated Smith term ``G2 = 1/(1 + Lambda(wi) + Lambda(wo))``
        with Lambda computed from the measured slopes (Heitz 2014, the height-correlated
        Smith form, with the empirical slope distribution). For the aperture responses G2 is applied per
        direction (hemisphere bin, luminance grid node, or the receptor centre for
        :meth:`reflected_fraction`), not per facet.
    backend : {"numba", "numpy", "lean"}
        Fused numba kernels (threads over the facets), their numpy twins, or ``"lean"``:
        the numpy twins without numba (whose import and set-up cost a process about 1 s,
        more than a command's work on a 2048^2 map) over fewer facets: deposits and cone
        responses over the occupied cells of the slope histogram of bin
        :data:`LEAN_SLOPE_BIN` weighted by their counts (:attr:`_slope_cells`), and so
        are rectangle responses, except those of slits narrower than
        :data:`LEAN_EXACT_BELOW_DEG`, read exactly over the facets that can reach the
        receptor (:meth:`_facets_near`).
    slope_bin : float or None
        How :meth:`brdf_point` / :meth:`brdf` estimate the slope density P22.
        ``None`` (default): a Gaussian kernel density of the facet slopes with Scott's rule
        bandwidth per axis, ``h_p = sigma_p N**(-1/6)``, ``h_q = sigma_q N**(-1/6)`` (in two
        dimensions Scott's and Silverman's rules coincide), see :meth:`slope_density`. On a
        1024^2 Gaussian map of rms slope 0.14 it is within 5 % of the analytic Beckmann facet
        BRDF above 10 % of the peak and within 15 % above 1 % (the 1e-3 histogram: up to
        49 %). A float: the slope histogram of that bin (Wittmann: 1e-3), whose relative
        noise is about ``1/sqrt(N P22 slope_bin^2)`` per bin, more when neighbouring slopes
        are correlated: for N = 1e6 facets of rms slope 0.05, 1e-2 gives a few % near the
        peak, 1e-3 gives 15-30 %. A map without slope spread (flat) uses the 1e-3 histogram.
    grid_step_deg : float
        Node spacing of the angular grid used by :meth:`luminance_pct`.
    """

    def __init__(
        self,
        surface: Surface,
        *,
        n: complex | float = 1.55,
        weighting: Weighting = "radiometric",
        masking: bool = False,
        backend: Backend = "numba",
        slope_bin: float | None = None,
        grid_step_deg: float = 0.05,
    ) -> None:
        if not isinstance(surface, Surface):
            raise TypeError(f"FacetModel needs a Surface, got {type(surface).__name__}")
        eta = complex(n)
        if (
            not (math.isfinite(eta.real) and math.isfinite(eta.imag))
            or eta.real <= 0
            or eta.imag < 0
        ):
            raise ValueError(f"refractive index must have n > 0 and k >= 0, got {n!r}")
        if weighting not in ("radiometric", "seed"):
            raise ValueError(f"weighting must be 'radiometric' or 'seed', got {weighting!r}")
        if backend not in ("numba", "numpy", "lean"):
            raise ValueError(f"backend must be 'numba', 'numpy' or 'lean', got {backend!r}")
        if slope_bin is not None and not (math.isfinite(slope_bin) and slope_bin > 0):
            raise ValueError(f"slope_bin must be positive, got {slope_bin}")
        if not (math.isfinite(grid_step_deg) and 0 < grid_step_deg <= 0.5):
            raise ValueError(f"grid_step_deg must be in (0, 0.5], got {grid_step_deg}")
        self.surface = surface
        self.n = eta
        self.weighting: Weighting = weighting
        self.masking = bool(masking)
        self.backend: Backend = backend
        self.slope_bin = _HIST_BIN if slope_bin is None else float(slope_bin)
        self._use_kde = slope_bin is None
        self.grid_step_deg = float(grid_step_deg)
        self._seed = weighting == "seed"
        # The kernels take the slopes and form each normal on the fly (an empty third array
        # says so, see goniolab.optics._kernels): no normal arrays beside the slopes.
        self._mx, self._my, self._mz = surface.p, surface.q, _SLOPES
        self._node_lambda: dict[tuple[float, float, int, float, float, int], FloatArray] = {}

    def __repr__(self) -> str:
        return (
            f"FacetModel({self.surface.source!r}, n={self.n}, weighting={self.weighting!r}, "
            f"masking={self.masking}, backend={self.backend!r}, facets={self.surface.n_facets})"
        )

    # ------------------------------------------------------------------ kernel dispatch
    def _chunks(self) -> list[tuple[FloatArray, FloatArray, FloatArray]]:
        n = self._mx.size
        cpus = getattr(_limits, "n", None) or os.cpu_count() or 1
        n_threads = max(1, min(cpus, n // _MIN_CHUNK))
        if self.backend != "numba" or n_threads == 1:
            return [(self._mx, self._my, self._mz)]
        bounds = np.linspace(0, n, n_threads + 1).astype(np.int64)
        return [
            (self._mx[a:b], self._my[a:b], self._mz[a:b]) for a, b in itertools.pairwise(bounds)
        ]

    def _run(
        self,
        kernel: str,
        wi: FloatArray,
        *args: Any,
        near: tuple[float, float, float] | None = None,
    ) -> list[Any]:
        """Run a kernel (``"deposit"``, ``"cone_response"``, ...) over the facets, one
        result per chunk: its numba version in threaded chunks, or its numpy twin.

        The ``"lean"`` backend runs the numpy twin over the occupied cells of the slope
        histogram, each weighted by its count (:attr:`_slope_cells`), or, when ``near``
        ``= (alpha_rad, reach_a, reach_b)`` is given, exactly over the facets that can
        send light that close to the in-plane angle alpha (:meth:`_facets_near`).
        """
        common = (wi, self.n.real, self.n.imag, self._seed, *args)
        numpy_fn = getattr(KN, kernel + "_numpy")
        if self.backend == "lean":
            if near is not None:
                p, q = self._facets_near(wi, *near)
                return [numpy_fn(p, q, _SLOPES, *common)]
            cp, cq, counts = self._slope_cells
            return [numpy_fn(cp, cq, _SLOPES, *common, counts=counts)]
        chunks = self._chunks()
        if self.backend == "numpy":
            return [numpy_fn(*c, *common) for c in chunks]
        numba_fn = getattr(_numba_kernels(), kernel + "_numba")
        if len(chunks) == 1:
            return [numba_fn(*chunks[0], *common)]
        futures = [_pool().submit(numba_fn, *c, *common) for c in chunks]
        return [f.result() for f in futures]

    @cached_property
    def _slope_cells(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The occupied cells of the slope histogram of bin :data:`LEAN_SLOPE_BIN`:
        ``(p, q, count)`` of each cell's centre, for the ``"lean"`` backend.

        Every facet is moved to its cell's centre, at most half a bin in each slope: its
        mirror direction by up to about 0.06 deg, and the readings, which average
        over many facets spread over apertures of degrees, by a fraction of that (the
        tests hold the lean readings to the per-facet kernels).

        Memory is bounded by the map, never by its slope range (issue 23.5: one 20 um spike
        on a 512^2 map asked a dense 1e-3 histogram for 48 GiB): the counts are kept dense
        only while the slope range's cells number at most :data:`_DENSE_CELLS_PER_FACET`
        per facet (or :data:`_DENSE_MIN_CELLS`), otherwise only the occupied cells are counted (a sort of each
        block's cell keys, merged), at most one per facet. A slope range whose cell index
        does not fit 64-bit integers is refused (:func:`_check_slope_range`).
        """
        b = LEAN_SLOPE_BIN
        p, q = self.surface.p, self.surface.q
        _check_slope_range(p, q, b, self.surface.source)
        p0 = math.floor(float(p.min()) / b + 0.5)
        q0 = math.floor(float(q.min()) / b + 0.5)
        n_q = math.floor(float(q.max()) / b + 0.5) - q0 + 1
        n_p = math.floor(float(p.max()) / b + 0.5) - p0 + 1
        size = p.size
        dense = n_p * n_q <= max(_DENSE_CELLS_PER_FACET * size, _DENSE_MIN_CELLS)
        counts = np.zeros(n_p * n_q if dense else 0, dtype=np.int64)
        keys: list[NDArray[np.int64]] = []
        tallies: list[NDArray[np.int64]] = []
        # the cell index (ip - p0) n_q + (iq - q0), ip = floor(p/b + 1/2), block by block:
        # the temporaries stay a block's, not the map's
        for lo in range(0, size, _CELL_BLOCK):
            hi = min(lo + _CELL_BLOCK, size)
            kp = np.multiply(p[lo:hi], 1.0 / b)
            kp += 0.5
            np.floor(kp, out=kp)
            kq = np.multiply(q[lo:hi], 1.0 / b)
            kq += 0.5
            np.floor(kq, out=kq)
            key = kp.astype(np.int64)
            del kp
            key -= p0
            np.clip(key, 0, n_p - 1, out=key)  # rounding at the last cell's edge
            key *= n_q
            iq = kq.astype(np.int64)
            del kq
            iq -= q0
            np.clip(iq, 0, n_q - 1, out=iq)
            key += iq
            del iq
            if dense:
                counts += np.bincount(key, minlength=n_p * n_q)
            else:
                k, c = np.unique(key, return_counts=True)
                keys.append(k)
                tallies.append(c)
        if dense:
            cells = np.flatnonzero(counts)
            weights = counts[cells]
        elif len(keys) == 1:
            cells, weights = keys[0], tallies[0]
        else:
            cells, inverse = np.unique(np.concatenate(keys), return_inverse=True)
            weights = np.bincount(inverse, weights=np.concatenate(tallies)).astype(np.int64)
        cp = ((cells // n_q + p0) * b).astype(np.float64)
        cq = ((cells % n_q + q0) * b).astype(np.float64)
        return cp, cq, weights.astype(np.float64)

    def _facets_near(
        self, wi: FloatArray, alpha_rad: float, reach_a: float, reach_b: float
    ) -> tuple[FloatArray, FloatArray]:
        """Slopes ``(p, q)`` of a superset of the facets whose mirror direction of ``wi``
        lies within ``reach_a`` in plane of the in-plane angle ``alpha_rad`` and within
        ``reach_b`` out of plane (the directions a rectangle response can reach).

        A facet reflects wi into o when its normal is along ``wi + o``, i.e. its slopes
        are ``p = -(wi + o)_x/(wi + o)_z``, ``q = -(wi + o)_y/(wi + o)_z``. This map of the
        directions onto the slopes is continuous and one-to-one, so the slopes of the
        facets that can reach the rectangle of directions lie within the bounding box of
        the image of its edge (sampled on 64 points a side, the box widened by 1 % of its
        size). All facets when a corner of the rectangle leaves the hemisphere.
        """
        p, q = self.surface.p, self.surface.q
        t = np.linspace(-1.0, 1.0, 65)
        one = np.ones_like(t)
        al = alpha_rad + reach_a * np.concatenate([t, one, -t, -one])
        be = reach_b * np.concatenate([-one, t, one, -t])
        if np.any(np.abs(al) >= 0.5 * math.pi) or reach_b >= 0.5 * math.pi:
            return p, q
        hx = wi[0] - np.sin(al) * np.cos(be)
        hy = wi[1] + np.sin(be)
        hz = wi[2] + np.cos(al) * np.cos(be)
        if np.any(hz <= 1e-9):
            return p, q
        rp, rq = -hx / hz, -hy / hz
        wp = 0.01 * float(rp.max() - rp.min()) + 1e-12
        wq = 0.01 * float(rq.max() - rq.min()) + 1e-12
        inside = p >= float(rp.min()) - wp
        inside &= p <= float(rp.max()) + wp
        inside &= q >= float(rq.min()) - wq
        inside &= q <= float(rq.max()) + wq
        idx = np.flatnonzero(inside)
        return p[idx], q[idx]

    # ------------------------------------------------------------------ slope density P22
    @cached_property
    def _p22_index(self) -> tuple[NDArray[np.int64], NDArray[np.int64], int, int, int, int]:
        b = self.slope_bin
        _check_slope_range(self.surface.p, self.surface.q, b, self.surface.source)
        ip = np.floor(self.surface.p / b + 0.5).astype(np.int64)
        iq = np.floor(self.surface.q / b + 0.5).astype(np.int64)
        p0, q0 = int(ip.min()), int(iq.min())
        n_q = int(iq.max()) - q0 + 1
        n_p = int(ip.max()) - p0 + 1
        keys, counts = np.unique((ip - p0) * n_q + (iq - q0), return_counts=True)
        return keys, counts, p0, q0, n_p, n_q

    def _bin_counts(self, ip: NDArray[np.int64], iq: NDArray[np.int64]) -> FloatArray:
        """Facet counts of the histogram bins centred on (ip, iq) x slope_bin (0 outside)."""
        keys, counts, p0, q0, n_p, n_q = self._p22_index
        a, b = ip - p0, iq - q0
        ok = (a >= 0) & (a < n_p) & (b >= 0) & (b < n_q)
        key = np.where(ok, a * n_q + b, 0)
        pos = np.clip(np.searchsorted(keys, key), 0, keys.size - 1)
        hit = ok & (keys[pos] == key)
        out: FloatArray = np.where(hit, counts[pos], 0).astype(np.float64)
        return out

    @cached_property
    def _kde_grid(self) -> tuple[FloatArray, float, float, float, float] | None:
        """Gaussian kernel density of the slopes on a grid: (density, p0, q0, gp, gq).

        Scott's rule bandwidth per axis, ``h = sigma N**(-1/6)`` (Scott 1992, d = 2). The
        slopes are linearly binned (bilinear weights) on a grid of step ``h/4`` (coarser
        only if the slope range needs more than 2048 nodes per axis) and convolved with the
        Gaussian kernel (``scipy.ndimage.gaussian_filter``, truncated at 5 h): the binned
        estimate differs from the exact kernel sum by ``O((step/h)^2)``, well under 1 %.
        ``None`` when the slopes have no spread (a flat map): the histogram is used.
        """
        from scipy.ndimage import gaussian_filter

        p, q = self.surface.p, self.surface.q
        ok = np.isfinite(p) & np.isfinite(q)
        p, q = p[ok], q[ok]
        n = p.size
        if n < 2:
            return None
        sp, sq = float(np.std(p)), float(np.std(q))
        if not (sp > 0 and sq > 0):
            return None
        shrink = n ** (-1.0 / 6.0)
        hp, hq = sp * shrink, sq * shrink
        axes = []
        for v, h in ((p, hp), (q, hq)):
            lo, hi = float(v.min()) - 5.0 * h, float(v.max()) + 5.0 * h
            step = max(h / 4.0, (hi - lo) / (_KDE_MAX_NODES - 1))
            axes.append((lo, step, math.ceil((hi - lo) / step) + 2))
        (p0, gp, n_p), (q0, gq, n_q) = axes
        x, y = (p - p0) / gp, (q - q0) / gq
        i, j = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
        fx, fy = x - i, y - j
        grid = np.zeros(n_p * n_q)
        for di, dj, w in (
            (0, 0, (1 - fx) * (1 - fy)),
            (1, 0, fx * (1 - fy)),
            (0, 1, (1 - fx) * fy),
            (1, 1, fx * fy),
        ):
            grid += np.bincount((i + di) * n_q + (j + dj), weights=w, minlength=n_p * n_q)
        dens = gaussian_filter(
            grid.reshape(n_p, n_q), sigma=(hp / gp, hq / gq), mode="constant", truncate=5.0
        )
        out: FloatArray = dens / (self.surface.n_facets * gp * gq)
        return out, p0, q0, gp, gq

    def slope_density(self, p: ArrayLike, q: ArrayLike) -> FloatArray:
        """Slope density P22 (per unit p per unit q): the Gaussian kernel density of the
        slopes (default, see :attr:`_kde_grid`, interpolated bilinearly on its grid) or,
        with an explicit ``slope_bin``, the histogram of that bin.

        The histogram (bins centred on multiples of ``slope_bin``, Wittmann sec. 3.1) is
        interpolated bilinearly between bin centres, so P22 is continuous: its error is then
        second order in the bin (curvature x bin^2 / 8) instead of the first-order step of
        a piecewise-constant histogram. Non-finite slopes give 0.
        """
        b = self.slope_bin
        pa, qa = np.broadcast_arrays(
            np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
        )
        finite = np.isfinite(pa) & np.isfinite(qa)
        kde = self._kde_grid if self._use_kde else None
        if kde is not None:
            return _bilinear(kde, np.where(finite, pa, np.nan), np.where(finite, qa, np.nan))
        # clipped far outside any histogram, so the integer bin indices cannot overflow
        x = np.clip(np.where(finite, pa, 0.0) / b, -1e15, 1e15)
        y = np.clip(np.where(finite, qa, 0.0) / b, -1e15, 1e15)
        i0, j0 = np.floor(x), np.floor(y)
        fx, fy = x - i0, y - j0
        i0i, j0i = i0.astype(np.int64), j0.astype(np.int64)
        acc = (
            self._bin_counts(i0i, j0i) * (1 - fx) * (1 - fy)
            + self._bin_counts(i0i + 1, j0i) * fx * (1 - fy)
            + self._bin_counts(i0i, j0i + 1) * (1 - fx) * fy
            + self._bin_counts(i0i + 1, j0i + 1) * fx * fy
        )
        out: FloatArray = np.where(finite, acc, 0.0) / (self.surface.n_facets * b * b)
        return out

    # ------------------------------------------------------------------ Smith masking
    @cached_property
    def _lambda_table(self) -> FloatArray:
        """``T(theta, phi) = mean(max(0, cos t - sin t (p cos ph + q sin ph)))`` on a grid."""
        n = self.surface.n_facets
        if n > _LAMBDA_MAX_FACETS:
            idx = np.linspace(0, n - 1, _LAMBDA_MAX_FACETS).astype(np.int64)
            p, q = self.surface.p[idx], self.surface.q[idx]
        else:
            p, q = self.surface.p, self.surface.q
        th = np.radians(np.arange(0.0, 90.0 + 1e-9, _LAMBDA_THETA_STEP_DEG))
        ph = np.radians(np.arange(0.0, 360.0 + 1e-9, _LAMBDA_PHI_STEP_DEG))
        ct, st = np.cos(th), np.sin(th)
        with np.errstate(divide="ignore"):
            cot = np.where(st > 0, ct / st, np.inf)
        table = np.empty((th.size, ph.size))
        m = p.size
        for j, phi in enumerate(ph):
            s = np.sort(p * math.cos(phi) + q * math.sin(phi))
            cs = np.concatenate(([0.0], np.cumsum(s)))
            k = np.searchsorted(s, cot, side="left")
            table[:, j] = (k * ct - st * cs[k]) / m
        return table

    def smith_lambda(self, w: ArrayLike) -> FloatArray:
        """Smith ``Lambda(w)`` of the measured slopes for unit directions ``w`` (..., 3).

        ``Lambda(w) = mean(max(0, cos t - sin t (p cos ph + q sin ph))) / cos t - 1``
        (docs/PHYSICS.md, "Masking and shadowing"; Heitz 2014, Smith Lambda of the empirical slope distribution), tabulated on a
        0.5 deg x 5 deg (theta, phi) grid from at most 2**17 facets and interpolated
        bilinearly. Infinite at grazing directions.
        """
        wa = np.asarray(w, dtype=np.float64)
        cz = np.clip(wa[..., 2], -1.0, 1.0)
        th_deg = np.degrees(np.arccos(cz))
        ph_deg = np.degrees(np.arctan2(wa[..., 1], wa[..., 0])) % 360.0
        table = self._lambda_table
        x = np.clip(th_deg / _LAMBDA_THETA_STEP_DEG, 0.0, table.shape[0] - 1.0)
        y = np.clip(ph_deg / _LAMBDA_PHI_STEP_DEG, 0.0, table.shape[1] - 1.0)
        i = np.minimum(np.floor(x).astype(np.int64), table.shape[0] - 2)
        j = np.minimum(np.floor(y).astype(np.int64), table.shape[1] - 2)
        fx, fy = x - i, y - j
        t = (
            table[i, j] * (1 - fx) * (1 - fy)
            + table[i + 1, j] * fx * (1 - fy)
            + table[i, j + 1] * (1 - fx) * fy
            + table[i + 1, j + 1] * fx * fy
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(cz > 0, t / np.where(cz > 0, cz, 1.0) - 1.0, np.inf)
        out: FloatArray = np.maximum(lam, 0.0)
        return out

    def masking_g2(self, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
        """Height-correlated Smith masking-shadowing ``1/(1 + Lambda(wi) + Lambda(wo))``."""
        out: FloatArray = 1.0 / (1.0 + self.smith_lambda(wi) + self.smith_lambda(wo))
        return out

    # ------------------------------------------------------------------ point BRDF
    def brdf(self, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
        """Analytic facet BRDF (sr^-1) for unit direction arrays ``wi``, ``wo`` of shape (..., 3).

        ``f = F(wi.h) P22(p_h, q_h) / (4 cos ti cos to cos^4 theta_h)`` (radiometric
        weighting; NIST SCATMECH Facet_BRDF_Model), times ``cos ti h_z / (wi.h)`` for the
        "seed" weighting (Fresnel-only facet weight, not reciprocal), times G2 when masking.
        Zero when either direction is below the horizon.
        """
        a = np.asarray(wi, dtype=np.float64)
        b = np.asarray(wo, dtype=np.float64)
        a, b = np.broadcast_arrays(a, b)
        h = a + b
        hn = np.linalg.norm(h, axis=-1)
        ok = (a[..., 2] > 0) & (b[..., 2] > 0) & (hn > 0)
        hn = np.where(ok, hn, 1.0)
        hx, hy, hz = h[..., 0] / hn, h[..., 1] / hn, h[..., 2] / hn
        hz_safe = np.where(ok, hz, 1.0)
        cos_ih = np.clip(np.sum(a * h, axis=-1) / hn, 0.0, 1.0)
        p22 = self.slope_density(-hx / hz_safe, -hy / hz_safe)
        cti = np.where(ok, a[..., 2], 1.0)
        cto = np.where(ok, b[..., 2], 1.0)
        f = fresnel(cos_ih, self.n) * p22 / (4.0 * cti * cto * hz_safe**4)
        if self._seed:
            f = f * cti * hz_safe / np.where(cos_ih > 0, cos_ih, 1.0)
        if self.masking:
            f = f * self.masking_g2(a, b)
        out: FloatArray = np.where(ok, f, 0.0)
        return out

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        """BRDF (sr^-1) for wi at (theta_i, phi_i = 0) and wo at (theta_r, phi_r)."""
        ti = _check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        tr = math.radians(_check_angle("theta_r_deg", theta_r_deg, -90.0, 90.0))
        pr = math.radians(float(phi_r_deg))
        wo = np.array([math.sin(tr) * math.cos(pr), math.sin(tr) * math.sin(pr), math.cos(tr)])
        return float(self.brdf(_unit_wi(ti), wo))

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """In-plane BRDF (sr^-1) at signed theta_r (> 0 specular side): wo = (-sin tr, 0, cos tr)."""
        ti = _check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        tr = np.radians(np.asarray(theta_r_deg, dtype=np.float64))
        if np.any(~np.isfinite(tr)) or np.any(np.abs(tr) >= math.pi / 2):
            raise ValueError("theta_r_deg must be in (-90, 90) deg")
        wo = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
        return self.brdf(_unit_wi(ti), wo)

    # ------------------------------------------------------------------ hemisphere
    def brdf_hemisphere(self, theta_i_deg: float, *, bin_deg: float = 0.5) -> HemisphereBRDF:
        """Histogram BRDF over the whole reflection hemisphere (Wittmann sec. 3.4, fig. 5).

        Parameters
        ----------
        theta_i_deg : float
            Incidence angle, phi_i = 0.
        bin_deg : float
            Bin size in theta_o and phi_o; must divide 90.

        Returns
        -------
        HemisphereBRDF
            ``f = sum(w in bin)/(N * projected solid angle)`` and the albedo ``sum(w)/N``.
        """
        ti = _check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        n_theta = round(90.0 / bin_deg) if bin_deg > 0 else 0
        if n_theta < 1 or abs(n_theta * bin_deg - 90.0) > 1e-9:
            raise ValueError(f"bin_deg must divide 90, got {bin_deg}")
        n_phi = 4 * n_theta
        wi = _unit_wi(ti)
        tables = KN.hemisphere_bin_tables(math.radians(bin_deg), n_theta, n_phi)
        parts = self._run("hemisphere", wi, *tables)
        hist = np.sum([h for h, _ in parts], axis=0)
        total = float(sum(t for _, t in parts))
        th_e = np.linspace(0.0, 90.0, n_theta + 1)
        ph_e = np.linspace(0.0, 360.0, n_phi + 1)
        s2 = np.sin(np.radians(th_e)) ** 2
        proj = 0.5 * np.diff(s2)[:, None] * math.radians(bin_deg)
        n = self.surface.n_facets
        if self.masking:
            thc = np.radians(0.5 * (th_e[1:] + th_e[:-1]))[:, None]
            phc = np.radians(0.5 * (ph_e[1:] + ph_e[:-1]))[None, :]
            wo = np.stack(
                np.broadcast_arrays(
                    np.sin(thc) * np.cos(phc), np.sin(thc) * np.sin(phc), np.cos(thc)
                ),
                axis=-1,
            )
            hist = hist * self.masking_g2(wi, wo)
            total = float(hist.sum())
        return HemisphereBRDF(
            theta_i_deg=ti,
            theta_edges_deg=th_e,
            phi_edges_deg=ph_e,
            f_sr=hist / (n * proj),
            albedo=total / n,
        )

    # ------------------------------------------------------------------ apertures
    @staticmethod
    def _aperture_pair(source: Aperture, receptor: Aperture) -> str:
        if isinstance(source, Cone) and isinstance(receptor, Cone):
            return "cone"
        if isinstance(source, Rect) and isinstance(receptor, Rect):
            return "rect"
        raise ValueError(
            "source and receptor apertures must both be Cone or both be Rect, got "
            f"{type(source).__name__} and {type(receptor).__name__}"
        )

    def _g2_nodes(self, wi: FloatArray, alpha_deg: FloatArray, beta_rad: FloatArray) -> FloatArray:
        """Smith G2 at grid nodes (in-plane angle alpha in degrees x out-of-plane beta).

        ``Lambda`` of the nodes does not depend on wi: it is kept for the last few grids, which
        the sub-cones of a split source share (169 of them at grazing incidence).
        """
        key = (
            float(alpha_deg[0]),
            float(alpha_deg[-1]),
            alpha_deg.size,
            float(beta_rad[0]),
            float(beta_rad[-1]),
            beta_rad.size,
        )
        lam = self._node_lambda.get(key)
        if lam is None:
            al = np.radians(alpha_deg)[:, None]
            be = beta_rad[None, :]
            wo = np.stack(
                np.broadcast_arrays(-np.sin(al) * np.cos(be), np.sin(be), np.cos(al) * np.cos(be)),
                axis=-1,
            )
            lam = self.smith_lambda(wo)
            if len(self._node_lambda) >= 8:
                self._node_lambda.pop(next(iter(self._node_lambda)))
            self._node_lambda[key] = lam
        out: FloatArray = 1.0 / (1.0 + self.smith_lambda(wi) + lam)
        return out

    def _g2_at(self, wi: FloatArray, wo: FloatArray) -> FloatArray:
        return self.masking_g2(wi, wo) if self.masking else np.ones(wo.shape[:-1])

    def _point_receptor(
        self, theta_i_deg: float, theta_r_deg: FloatArray, source: Aperture, receptor: Aperture
    ) -> FloatArray:
        """Flux per steradian (sr^-1) towards a zero-solid-angle receptor, per theta_r.

        ``mean_s mean_d f(wi_s, wo_d) cos(theta_d)`` over the source directions and the
        receptor's centre (or line), with :meth:`brdf`: the limit that :func:`integrate_brdf`
        also returns for a point receptor.
        """
        wi, ws = _sample_aperture(source, -math.radians(theta_i_deg))
        out = np.empty(theta_r_deg.size)
        for k, t in enumerate(theta_r_deg.ravel()):
            wo, wd = _sample_aperture(receptor, math.radians(float(t)))
            f = self.brdf(wi[:, None, :], wo[None, :, :]) * np.maximum(wo[None, :, 2], 0.0)
            out[k] = float(ws @ f @ wd)
        result: FloatArray = out.reshape(theta_r_deg.shape)
        return result

    def reflected_fraction(
        self, theta_i_deg: float, theta_r_deg: float, source: Aperture, receptor: Aperture
    ) -> float:
        """Fraction of the flux from ``source`` (centred on theta_i) reaching ``receptor``.

        Per-facet evaluation (no grid): ``(1/N) sum_k w_k O_k`` with ``O_k`` the
        fraction of the mirror image of the source aperture (centred on wo_k) inside the
        receptor centred on the signed in-plane angle theta_r. Cones: spherical-cap
        overlap (see :func:`cap_overlap_fraction`) plus the first-order term of the weight's
        variation across the source (module docstring). Rectangles: product of the 1-D overlaps
        in the in-plane angle ``alpha = atan2(-wo_x, wo_z)`` and the out-of-plane angle
        ``beta = asin(wo_y)``, the mirror image taken as the source rectangle translated to
        wo_k (Mihalik eqs. 15-17 evaluated facet by facet). With masking, G2 is taken at the
        receptor centre. A receptor of zero solid angle gives the flux per steradian
        (sr^-1), as in :meth:`luminance_pct`.
        """
        ti = _check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        tr_deg = _check_angle("theta_r_deg", theta_r_deg, -90.0, 90.0)
        kind = self._aperture_pair(source, receptor)
        _check_source_above_horizon(ti, source, self.masking)
        if _zero_solid_angle(receptor):
            return float(self._point_receptor(ti, np.array([tr_deg]), source, receptor)[0])
        if self.masking and isinstance(source, Cone):
            return float(self._cone_grid(ti, np.array([tr_deg]), source, receptor)[0])
        wi = _unit_wi(ti)
        tr = math.radians(tr_deg)
        d = np.array([-math.sin(tr), 0.0, math.cos(tr)])
        if kind == "cone":
            assert isinstance(source, Cone) and isinstance(receptor, Cone)
            total = 0.0
            for wi_s, sub, share in _source_parts(ti, source):
                table, g0, g1, o_in, m1 = _cone_table(
                    math.radians(sub.half_angle_deg), math.radians(receptor.half_angle_deg)
                )
                parts = self._run("cone_response", wi_s, d, table, g0, g1, o_in, m1)
                g2 = float(self._g2_at(wi_s, d[None, :])[0])
                total += share * float(sum(parts)) * g2
            return total / self.surface.n_facets
        else:
            assert isinstance(source, Rect) and isinstance(receptor, Rect)
            near = None
            if min(source.in_plane_deg, receptor.in_plane_deg) < LEAN_EXACT_BELOW_DEG:
                near = (
                    tr,
                    math.radians(0.5 * (source.in_plane_deg + receptor.in_plane_deg)),
                    math.radians(0.5 * (source.perp_deg + receptor.perp_deg)),
                )
            parts = self._run(
                "rect_response",
                wi,
                tr,
                math.radians(source.in_plane_deg),
                math.radians(receptor.in_plane_deg),
                math.radians(source.perp_deg),
                math.radians(receptor.perp_deg),
                near=near,
            )
        frac = float(sum(parts)) / self.surface.n_facets
        return frac * float(self._g2_at(wi, d[None, :])[0])

    def _kernel_values(
        self, source: Aperture, detector: Aperture, d_alpha: FloatArray, beta: FloatArray
    ) -> FloatArray:
        """Overlap weight ``O`` of grid nodes at (d_alpha, beta) from the detector axis (rad)."""
        if isinstance(source, Cone) and isinstance(detector, Cone):
            a_s = math.radians(source.half_angle_deg)
            a_d = math.radians(detector.half_angle_deg)
            table, g0, g1, o_in, _ = _cone_table(a_s, a_d)
            return KN.table_numpy(_node_gamma(d_alpha, beta), table, g0, g1, o_in)
        assert isinstance(source, Rect) and isinstance(detector, Rect)
        return KN.interval_overlap_numpy(
            d_alpha, math.radians(source.in_plane_deg), math.radians(detector.in_plane_deg)
        ) * KN.interval_overlap_numpy(
            beta, math.radians(source.perp_deg), math.radians(detector.perp_deg)
        )

    @staticmethod
    def _gradient_kernel(
        source: Cone, detector: Cone, d_alpha: FloatArray, beta: FloatArray
    ) -> FloatArray:
        """First-moment weights ``M1(gamma) (e . t_alpha), M1(gamma) (e . t_beta)`` (last axis).

        e is the unit tangent at the node towards the detector; in the frame turned so that
        the detector is at alpha = 0, ``e . t_alpha = -sin(d_alpha)/sin(gamma)`` and
        ``e . t_beta = -cos(d_alpha) sin(beta)/sin(gamma)``.
        """
        a_s = math.radians(source.half_angle_deg)
        a_d = math.radians(detector.half_angle_deg)
        _, _, g1, _, m1 = _cone_table(a_s, a_d)
        g = _node_gamma(d_alpha, beta)
        m1_val = KN.table_numpy(g, m1, 0.0, g1, 0.0)
        sin_g = np.sin(g)
        ok = sin_g > 1e-12
        scale = np.where(ok, m1_val / np.where(ok, sin_g, 1.0), 0.0)
        ka, kb = np.broadcast_arrays(
            -np.sin(d_alpha) * scale, -np.cos(d_alpha) * np.sin(beta) * scale
        )
        out: FloatArray = np.stack([ka, kb], axis=-1)
        return out

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = GONIO_CONE,
        detector: Aperture = GONIO_CONE,
    ) -> FloatArray:
        """Goniometer reading: 100 x the fraction of the incident flux reaching the detector.

        Source directions are uniform in solid angle over the source aperture around wi;
        the detector is centred on the signed in-plane angle theta_r. One or two angles are
        evaluated exactly with :meth:`reflected_fraction`. For more, the weights are
        deposited once (cloud-in-cell) on a grid of in-plane angle x out-of-plane angle
        nodes ``grid_step_deg`` apart around the in-plane arc, with (cones) the weights'
        gradients over the source image on a 4x coarser grid; each reading is the grid
        weighted by the aperture overlap ``O`` (and the first moments) at every node (see
        :meth:`reflected_fraction` for the exact per-facet form this approximates to
        second order in the grid step). A point source (``Cone(0)``) reads the flux whose
        mirror direction falls inside the detector. A point detector (``Cone(0)``) has no
        solid angle: it then reads ``100 x`` the flux per steradian, ``f cos(theta_r)``
        averaged over the source (sr^-1, from :meth:`brdf`), as :func:`integrate_brdf` does.

        Parameters
        ----------
        theta_i_deg : float
            Lamp angle.
        theta_r_deg : array_like
            Signed detector angles (> 0 specular side), each in (-90, 90).
        source, detector : Cone or Rect
            Apertures (both of the same kind). Defaults: the Wittmann goniometer, 6 deg.

        Returns
        -------
        ndarray
            Luminance in % of a perfect mirror, same shape as ``theta_r_deg``.
        """
        ti = _check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        tr_deg = np.asarray(theta_r_deg, dtype=np.float64)
        if np.any(~np.isfinite(tr_deg)) or np.any(np.abs(tr_deg) >= 90.0):
            raise ValueError("theta_r_deg must be in (-90, 90) deg")
        kind = self._aperture_pair(source, detector)
        _check_source_above_horizon(ti, source, self.masking)
        if tr_deg.size == 0:
            return np.zeros(tr_deg.shape)
        if _zero_solid_angle(detector):
            return 100.0 * self._point_receptor(ti, tr_deg, source, detector)
        if tr_deg.size <= _EXACT_MAX_POINTS and not (self.masking and kind == "cone"):
            # one pass per point beats the grid's deposit + tables; and it is exact
            exact = [self.reflected_fraction(ti, float(t), source, detector) for t in tr_deg.flat]
            return 100.0 * np.asarray(exact, dtype=np.float64).reshape(tr_deg.shape)
        flat = tr_deg.ravel()
        if kind == "cone":
            assert isinstance(source, Cone)
            out = self._cone_grid(ti, flat, source, detector)
        else:
            out = self._grid_fraction(_unit_wi(ti), source, detector, flat)
        result: FloatArray = 100.0 * out.reshape(tr_deg.shape)
        return result

    def _cone_grid(
        self, theta_i_deg: float, flat: FloatArray, source: Cone, detector: Aperture
    ) -> FloatArray:
        """Flux fractions of a source cone at each detector angle of ``flat`` (deg), by the
        deposited grid, summed over the source's sub-cones: :func:`_source_parts`, or
        :func:`_clipped_source_parts` (zeroth order) when the cone reaches the horizon.

        With masking every cone reading goes through the grid, where G2 is taken at each
        node (the direction the light leaves in), not at the receptor's centre: at grazing
        receptors G2 varies several-fold across a 6 deg cone (at 85 deg the centre value
        read 2.6 % high against brute force with per-facet G2, the nodes 0.3 %).
        """
        out = np.zeros(flat.size)
        if _reaches_horizon(theta_i_deg, source):
            for wi_s, sub, share in _clipped_source_parts(theta_i_deg, source):
                out += share * self._grid_fraction(wi_s, sub, detector, flat, grad=False)
            return out
        for wi_s, sub, share in _source_parts(theta_i_deg, source):
            out += share * self._grid_fraction(wi_s, sub, detector, flat)
        return out

    def _grid_fraction(
        self,
        wi: FloatArray,
        source: Aperture,
        detector: Aperture,
        flat: FloatArray,
        *,
        grad: bool = True,
    ) -> FloatArray:
        """Fraction of the flux of a source centred on ``wi`` reaching the detector at each
        in-plane angle of ``flat`` (deg), by the deposited grid (see :meth:`luminance_pct`);
        ``grad=False`` leaves out the first-order term of the weight across the source."""
        kind = self._aperture_pair(source, detector)
        if kind == "cone":
            assert isinstance(source, Cone) and isinstance(detector, Cone)
            reach_a = reach_b = source.half_angle_deg + detector.half_angle_deg
        else:
            assert isinstance(source, Rect) and isinstance(detector, Rect)
            reach_a = 0.5 * (source.in_plane_deg + detector.in_plane_deg)
            reach_b = 0.5 * (source.perp_deg + detector.perp_deg)
        h = self.grid_step_deg
        hv = math.radians(h)  # node step in sin(beta), the grid's out-of-plane coordinate
        u = math.ceil(reach_a / h) + 1  # window half-width in nodes
        v = math.ceil(math.sin(math.radians(min(reach_b, 90.0))) / hv) + 1
        i_lo = math.floor(flat.min() / h) - u - 1
        i_hi = math.ceil(flat.max() / h) + u + 1
        na, nb = i_hi - i_lo + 1, 2 * v + 1
        a0 = i_lo * h
        parts = self._run(
            "deposit",
            wi,
            math.radians(a0),
            math.radians(h),
            na,
            -v * hv,
            hv,
            nb,
            kind == "cone" and grad,
        )
        grid = np.sum([p[0] for p in parts], axis=0)
        ggrid = np.sum([p[1] for p in parts], axis=0)
        beta_nodes = np.arcsin(np.clip(hv * np.arange(-v, v + 1), -1.0, 1.0))
        cf = KN.GRAD_COARSEN
        beta_coarse = np.arcsin(np.clip(hv * (cf * np.arange(ggrid.shape[1]) - v), -1.0, 1.0))
        if self.masking:
            grid = grid * self._g2_nodes(wi, a0 + h * np.arange(na), beta_nodes)
            if kind == "cone" and grad:
                g2c = self._g2_nodes(wi, a0 + cf * h * np.arange(ggrid.shape[0]), beta_coarse)
                ggrid = ggrid * g2c[:, :, None]
        out = np.empty(flat.size)
        kernels: dict[float, FloatArray] = {}
        offsets = np.arange(-u, u + 1, dtype=np.float64)
        uc = u // cf + 2
        offsets_c = np.arange(-uc, uc + 1, dtype=np.float64)
        kernels_c: dict[float, FloatArray] = {}
        use_grad = kind == "cone" and grad
        for k, t in enumerate(flat):
            x = t / h - i_lo
            ix = math.floor(x + 1e-7)
            frac = round(max(0.0, x - ix), 6)
            if frac not in kernels:
                d_alpha = np.radians((offsets - frac) * h)[:, None]
                kernels[frac] = self._kernel_values(source, detector, d_alpha, beta_nodes[None, :])
            # einsum: no temporary, and no BLAS call (its spinning threads would compete
            # with the numba workers of the next deposit)
            out[k] = float(np.einsum("ij,ij->", grid[ix - u : ix + u + 1], kernels[frac]))
            if use_grad:
                assert isinstance(source, Cone) and isinstance(detector, Cone)
                xc = x / cf
                ixc = math.floor(xc + 1e-7)
                frac_c = round(max(0.0, xc - ixc), 6)
                if frac_c not in kernels_c:
                    d_alpha_c = np.radians((offsets_c - frac_c) * cf * h)[:, None]
                    kernels_c[frac_c] = self._gradient_kernel(
                        source, detector, d_alpha_c, beta_coarse[None, :]
                    )
                lo, hi = max(ixc - uc, 0), min(ixc + uc + 1, ggrid.shape[0])
                kg = kernels_c[frac_c][lo - (ixc - uc) : hi - (ixc - uc)]
                out[k] += float(np.einsum("ijk,ijk->", ggrid[lo:hi], kg))
        fraction: FloatArray = out / self.surface.n_facets
        return fraction

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        """ISO 2813 / ASTM D523 specular gloss in GU.

        ``G = 100 * reflected_fraction(t, t, ISO2813_SOURCE, ISO2813_RECEPTOR[t]) /
        F(1.567, t)``: the flux of the sample over that of the polished black glass
        standard, whose mirror image of the source lies entirely inside the receptor
        (Mihalik eqs. 15-17; Wittmann eqs. 11-13, with the source aperture integrated too).
        """
        out: dict[int, float] = {}
        for t in angles_deg:
            key = int(t)
            if key not in ISO2813_RECEPTOR:
                raise ValueError(
                    f"no ISO 2813 geometry at {t} deg; known: {sorted(ISO2813_RECEPTOR)}"
                )
            frac = self.reflected_fraction(key, key, ISO2813_SOURCE, ISO2813_RECEPTOR[key])
            ref = float(fresnel_dielectric(math.cos(math.radians(key)), ISO2813_BLACK_GLASS_N))
            out[key] = 100.0 * frac / ref
        return out
