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
from collections.abc import Sequence
from dataclasses import dataclass
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
)
from goniolab.optics.facet_apertures import (
    aperture_directions,
    cap_overlap_moments,
    check_angle,
    check_source_above_horizon,
    clipped_source_parts,
    cone_table,
    node_gamma,
    reaches_horizon,
    source_parts,
    unit_wi,
    zero_solid_angle,
)
from goniolab.optics.facet_backends import (
    LEAN_EXACT_BELOW_DEG,
    MIN_CHUNK,
    SLOPES,
    facets_near,
    kernel_pool,
    limit_threads,
    numba_kernels,
    run_blocks,
    slope_cells_indexed,
    thread_limit,
)
from goniolab.optics.fresnel import fresnel, fresnel_dielectric
from goniolab.optics.slope_statistics import SlopeStatistics
from goniolab.optics.surface import STREAM_MIN_FACETS, Surface

#: the facet model's public names; the cap overlaps and the thread limit are defined with
#: the aperture integration and the kernel backends and keep this import path
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

#: luminance_pct evaluates up to this many detector angles exactly, facet by facet.
_EXACT_MAX_POINTS = 2
#: The lean backend keeps its facets' cell indices (for the near slits) for maps of at
#: most this many facets (2048^2): a cached model of a larger map would hold tens of MB.
_KEEP_INDEX_MAX_FACETS = 1 << 22
#: The lean backend's numpy kernels take at most this many slope cells per call (their
#: temporaries, about ten arrays of the cells, stay a few tens of MB on any map).
_CELLS_PER_CALL = 1 << 20


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
        :data:`~goniolab.optics.facet_backends.LEAN_SLOPE_BIN` weighted by their counts (:attr:`_slope_cells`), and so
        are rectangle responses, except those of slits narrower than
        :data:`~goniolab.optics.facet_backends.LEAN_EXACT_BELOW_DEG`, read exactly over the facets that can reach the
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
        #: P22 and Smith Lambda of the facets
        self.slopes = SlopeStatistics(surface, slope_bin)
        self.slope_bin = self.slopes.slope_bin
        self.grid_step_deg = float(grid_step_deg)
        self._seed = weighting == "seed"
        # The kernels take the slopes and form each normal on the fly (an empty third array
        # says so, see goniolab.optics._kernels): no normal arrays beside the slopes. A
        # map's surface forms them when first asked (goniolab.optics.surface.MapSurface).
        self._mz = SLOPES

    @property
    def _mx(self) -> FloatArray:
        return self.surface.p

    @property
    def _my(self) -> FloatArray:
        return self.surface.q

    def __repr__(self) -> str:
        return (
            f"FacetModel({self.surface.source!r}, n={self.n}, weighting={self.weighting!r}, "
            f"masking={self.masking}, backend={self.backend!r}, facets={self.surface.n_facets})"
        )

    # ------------------------------------------------------------------ kernel dispatch
    def _chunks(self) -> list[tuple[FloatArray, FloatArray, FloatArray]]:
        n = self.surface.n_facets
        cpus = thread_limit() or os.cpu_count() or 1
        n_threads = max(1, min(cpus, n // MIN_CHUNK))
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
        keep_index: bool = True,
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
                return [numpy_fn(p, q, SLOPES, *common)]
            cp, cq, counts = self._cells(keep_index)  # in blocks: a block's temporaries only
            return [
                numpy_fn(cp[a:b], cq[a:b], SLOPES, *common, counts=counts[a:b])
                for a, b in itertools.pairwise([*range(0, cp.size, _CELLS_PER_CALL), cp.size])
            ]
        if self.surface.streamed and self.surface.n_facets > STREAM_MIN_FACETS:
            return run_blocks(self.surface, numpy_fn if self.backend == "numpy" else kernel, common)
        chunks = self._chunks()
        if self.backend == "numpy":
            return [numpy_fn(*c, *common) for c in chunks]
        numba_fn = getattr(numba_kernels(), kernel + "_numba")
        if len(chunks) == 1:
            return [numba_fn(*chunks[0], *common)]
        futures = [kernel_pool().submit(numba_fn, *c, *common) for c in chunks]
        return [f.result() for f in futures]

    @property
    def _slope_cells(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The lean backend's slope cells ``(p, q, count)``
        (:func:`goniolab.optics.facet_backends.slope_cells`), counted once, with the facets'
        cell indices kept beside them (``_cell_index``) for the narrow slits."""
        return self._cells(keep_index=True)

    def _cells(self, keep_index: bool) -> tuple[FloatArray, FloatArray, FloatArray]:
        """:attr:`_slope_cells`; ``keep_index=False`` (a cone grid's deposit) lets the int16
        indices go once counted: their 16 MB (2048^2 facets) are reused by the deposit's
        temporaries instead of fresh pages (a later slit counts again, :meth:`_facets_near`).

        Counted once when two threads ask at once (wave gloss geometries handed to the
        facet model run as tasks): the second waits. Re-entrant: a holder that, waiting
        for its walk's tasks, runs a task asking for the cells counts again, not waits."""
        got: tuple[FloatArray, FloatArray, FloatArray] | None = self.__dict__.get("_cells_")
        if got is not None:
            return got
        with self.__dict__.setdefault("_cells_lock", threading.RLock()):  # setdefault: atomic
            got = self.__dict__.get("_cells_")
            if got is None:
                got, index = slope_cells_indexed(self.surface)
                if keep_index:  # 4 bytes a facet, held
                    keep = self.surface.n_facets <= _KEEP_INDEX_MAX_FACETS
                    self.__dict__["_cell_index"] = index if keep else None
                self.__dict__["_cells_"] = got
        return got

    def _facets_near(
        self, wi: FloatArray, alpha_rad: float, reach_a: float, reach_b: float
    ) -> tuple[FloatArray, FloatArray]:
        """The facets a narrow slit can reach (:func:`goniolab.optics.facet_backends.facets_near`);
        from the second slit on, picked by the facets' cell indices (:attr:`_slope_cells`)."""
        walks = self.__dict__["_near_walks"] = self.__dict__.get("_near_walks", 0) + 1
        if walks > 1 and self.backend == "lean" and "_cell_index" not in self.__dict__:
            self.__dict__.pop("_cells_", None)  # one walk for all slits, keeping the index
            self._slope_cells  # noqa: B018
        index = self.__dict__.get("_cell_index")
        return facets_near(self.surface, None, wi, alpha_rad, reach_a, reach_b, index)

    # ------------------------------------------------------------------ slope statistics
    def slope_density(self, p: ArrayLike, q: ArrayLike) -> FloatArray:
        """Slope density P22 (per unit p per unit q) of the facets
        (:meth:`goniolab.optics.slope_statistics.SlopeStatistics.density`: the kernel
        density by default, the histogram of ``slope_bin`` when one is given)."""
        return self.slopes.density(p, q)

    def smith_lambda(self, w: ArrayLike) -> FloatArray:
        """Smith ``Lambda(w)`` of the measured slopes for unit directions ``w`` (..., 3)
        (:meth:`goniolab.optics.slope_statistics.SlopeStatistics.smith_lambda`)."""
        return self.slopes.smith_lambda(w)

    def masking_g2(self, wi: ArrayLike, wo: ArrayLike) -> FloatArray:
        """Height-correlated Smith masking-shadowing ``1/(1 + Lambda(wi) + Lambda(wo))``."""
        return self.slopes.masking_g2(wi, wo)

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
        ti = check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        tr = math.radians(check_angle("theta_r_deg", theta_r_deg, -90.0, 90.0))
        pr = math.radians(float(phi_r_deg))
        wo = np.array([math.sin(tr) * math.cos(pr), math.sin(tr) * math.sin(pr), math.cos(tr)])
        return float(self.brdf(unit_wi(ti), wo))

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """In-plane BRDF (sr^-1) at signed theta_r (> 0 specular side): wo = (-sin tr, 0, cos tr)."""
        ti = check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        tr = np.radians(np.asarray(theta_r_deg, dtype=np.float64))
        if np.any(~np.isfinite(tr)) or np.any(np.abs(tr) >= math.pi / 2):
            raise ValueError("theta_r_deg must be in (-90, 90) deg")
        wo = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
        return self.brdf(unit_wi(ti), wo)

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
        ti = check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        n_theta = round(90.0 / bin_deg) if bin_deg > 0 else 0
        if n_theta < 1 or abs(n_theta * bin_deg - 90.0) > 1e-9:
            raise ValueError(f"bin_deg must divide 90, got {bin_deg}")
        n_phi = 4 * n_theta
        wi = unit_wi(ti)
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
        wi, ws = aperture_directions(source, -math.radians(theta_i_deg))
        out = np.empty(theta_r_deg.size)
        for k, t in enumerate(theta_r_deg.ravel()):
            wo, wd = aperture_directions(receptor, math.radians(float(t)))
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
        ti = check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        tr_deg = check_angle("theta_r_deg", theta_r_deg, -90.0, 90.0)
        kind = self._aperture_pair(source, receptor)
        check_source_above_horizon(ti, source, self.masking)
        if zero_solid_angle(receptor):
            return float(self._point_receptor(ti, np.array([tr_deg]), source, receptor)[0])
        if self.masking and isinstance(source, Cone):
            return float(self._cone_grid(ti, np.array([tr_deg]), source, receptor)[0])
        wi = unit_wi(ti)
        tr = math.radians(tr_deg)
        d = np.array([-math.sin(tr), 0.0, math.cos(tr)])
        if kind == "cone":
            assert isinstance(source, Cone) and isinstance(receptor, Cone)
            total = 0.0
            for wi_s, sub, share in source_parts(ti, source):
                table, g0, g1, o_in, m1 = cone_table(
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
            table, g0, g1, o_in, _ = cone_table(a_s, a_d)
            return KN.table_numpy(node_gamma(d_alpha, beta), table, g0, g1, o_in)
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
        _, _, g1, _, m1 = cone_table(a_s, a_d)
        g = node_gamma(d_alpha, beta)
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
        ti = check_angle("theta_i_deg", theta_i_deg, 0.0, 90.0)
        tr_deg = np.asarray(theta_r_deg, dtype=np.float64)
        if np.any(~np.isfinite(tr_deg)) or np.any(np.abs(tr_deg) >= 90.0):
            raise ValueError("theta_r_deg must be in (-90, 90) deg")
        kind = self._aperture_pair(source, detector)
        check_source_above_horizon(ti, source, self.masking)
        if tr_deg.size == 0:
            return np.zeros(tr_deg.shape)
        if zero_solid_angle(detector):
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
            out = self._grid_fraction(unit_wi(ti), source, detector, flat)
        result: FloatArray = 100.0 * out.reshape(tr_deg.shape)
        return result

    def _cone_grid(
        self, theta_i_deg: float, flat: FloatArray, source: Cone, detector: Aperture
    ) -> FloatArray:
        """Flux fractions of a source cone at each detector angle of ``flat`` (deg), by the
        deposited grid, summed over the source's sub-cones: :func:`source_parts`, or
        :func:`clipped_source_parts` (zeroth order) when the cone reaches the horizon.

        With masking every cone reading goes through the grid, where G2 is taken at each
        node (the direction the light leaves in), not at the receptor's centre: at grazing
        receptors G2 varies several-fold across a 6 deg cone (at 85 deg the centre value
        read 2.6 % high against brute force with per-facet G2, the nodes 0.3 %).
        """
        out = np.zeros(flat.size)
        if reaches_horizon(theta_i_deg, source):
            for wi_s, sub, share in clipped_source_parts(theta_i_deg, source):
                out += share * self._grid_fraction(wi_s, sub, detector, flat, grad=False)
            return out
        for wi_s, sub, share in source_parts(theta_i_deg, source):
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
        caps = None  # the cone half angles, rad
        if kind == "cone":
            assert isinstance(source, Cone) and isinstance(detector, Cone)
            reach_a = reach_b = source.half_angle_deg + detector.half_angle_deg
            caps = (math.radians(source.half_angle_deg), math.radians(detector.half_angle_deg))
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
        grad_on = kind == "cone" and grad
        args = (math.radians(a0), math.radians(h), na, -v * hv, hv, nb, grad_on)
        deposit = functools.partial(self._run, "deposit", wi, *args, keep_index=False)
        cf = KN.GRAD_COARSEN
        beta_nodes = np.arcsin(np.clip(hv * np.arange(-v, v + 1), -1.0, 1.0))
        beta_coarse = np.arcsin(np.clip(hv * (cf * np.arange(KN.coarse_size(nb)) - v), -1.0, 1.0))
        alpha_nodes = a0 + h * np.arange(na)
        alpha_coarse = a0 + cf * h * np.arange(KN.coarse_size(na))
        if self.masking:  # the nodes' Lambda (and its table) beside the deposit
            grids = [(alpha_nodes, beta_nodes)] + ([(alpha_coarse, beta_coarse)] if grad_on else [])
            # and the cone kernels' overlap table (cached), which the readings need next
            table = None if caps is None else functools.partial(cone_table, *caps)
            parts: list[Any] = self.slopes.beside(deposit, grids, table)
        else:
            parts = deposit()
        grid = np.sum([p[0] for p in parts], axis=0)
        ggrid = np.sum([p[1] for p in parts], axis=0)
        if self.masking:
            grid = grid * self.slopes.g2_nodes(wi, alpha_nodes, beta_nodes)
            if kind == "cone" and grad:
                g2c = self.slopes.g2_nodes(wi, alpha_coarse, beta_coarse)
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
