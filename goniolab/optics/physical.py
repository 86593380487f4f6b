"""Physical-optics reflectance models on a height map: the shared instrument machinery.

:class:`~goniolab.optics.kirchhoff.KirchhoffModel` (scalar Kirchhoff, tangent plane) and
:class:`~goniolab.optics.rayleigh_rice.RayleighRiceModel` (first-order vector
perturbation) both predict, for one nominal incident direction ``wi = (sin ti, 0, cos ti)``
and one wavelength, the fraction ``P`` of the incident flux scattered into each cell of a
regular grid in direction-cosine space: the FFT grid of the map's tiles,

.. math:: (w_i + w_o)_{x,y} = \\lambda\\,(m_x / (N_x\\,dx),\\; m_y / (N_y\\,dy)),
          \\qquad |m_x| \\le N_x/2,\\; |m_y| \\le N_y/2,

of cell area ``lambda^2 / (N_x dx N_y dy)`` (the grating equation: a spatial frequency f
of the surface sends light to ``sin ts - sin t_spec = lambda f``). Their BRDF in a cell is
``P / cell area`` (a BRDF is the flux density per unit of direction-cosine area,
``dOmega cos ts = d alpha d beta``).

Everything an instrument reads is a sum of ``P`` over cells (:mod:`._cell_kernels`):
goniometer cones and ISO 2813 / E430 rectangles with the source aperture (its mirror image
around each cell's direction, as in :mod:`goniolab.optics.facet`), the gloss of
:func:`goniolab.optics.gloss_standards.gloss_report`, haze and DOI. With ``masking`` (the
default) the result is multiplied by the height-correlated Smith term
``G2 = 1/(1 + Lambda(wi) + Lambda(wo))`` of the map's slopes at the receptor centre (Heitz
2014), as the facet model does; it only matters at grazing angles on rough maps.

What a map cannot say (module :func:`PhysicalOpticsModel.coverage`):

- directions further from specular than ``|sin ts - sin t_spec| <= lambda / (2 step)``
  (the Nyquist frequency of the map) have no cell: an aperture whose reach (receptor plus
  source image) leaves that window is evaluated with the **facet model** of the same map;
- a field too small to resolve the aperture (fewer than :data:`MIN_CELLS_ACROSS` cells
  across the receptor's narrowest side) likewise falls back to the facet model.

The fallback is stated: ``coverage()`` returns the reason (``None`` when the map resolves
the geometry), and the CLI reports it in ``--json`` output under ``"fallback"``.

Wavelength and index per call (for the colour and spectral code): a model is built for
``(height map, n, wavelength_nm)``. ``model.with_optics(n=..., wavelength_nm=...)`` returns
a sibling model for another index (real or complex ``n + ik``) and wavelength that shares
the tiled map, its FFT caches and its fallback facet model, so a spectral loop costs no
re-levelling. ``gloss()`` weights over wavelength as ISO 2813 does (CIE illuminant C x
V(lambda), :func:`goniolab.optics.spectral.iso2813_weights`) unless
``gloss_weighting="single"``; the goniometer responses and BRDFs use ``wavelength_nm``.

References
----------
.. [1] NIST appearance project, "Ray method and Kirchhoff approximation" (seed text).
.. [2] J. C. Stover, "Optical Scattering", 3rd ed., SPIE 2012, ch. 2 (grating equation).
.. [3] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", eqs. 15-17.
.. [4] E. Heitz, "Understanding the masking-shadowing function in microfacet-based BRDFs",
   JCGT 3(2) 2014.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics import _cell_kernels as CK
from goniolab.optics.apertures import (
    GONIO_CONE,
    ISO2813_BLACK_GLASS_N,
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Aperture,
    Cone,
    Rect,
    solid_angle_sr,
)
from goniolab.optics.facet import (
    SPLIT_SOURCE_RINGS,
    FacetModel,
    _clipped_source_parts,
    _cone_table,
    _reaches_horizon,
)
from goniolab.optics.fresnel import fresnel, fresnel_dielectric
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.psd import DEFAULT_TAPER, DEFAULT_TILE, TiledMap
from goniolab.optics.surface import Surface

__all__ = [
    "MAX_THETA_I_DEG",
    "MIN_CELLS_ACROSS",
    "POINT_BRDF_BOX_DEG",
    "GlossWeighting",
    "MapStats",
    "PhysicalOpticsModel",
    "Progress",
]

FloatArray = NDArray[np.float64]
GlossWeighting = Literal["iso2813", "single"]
Backend = Literal["numba", "numpy"]
#: ``progress(done, total, what)``: called while long work runs.
Progress = Callable[[int, int, str], None]

#: Fewest FFT cells across the receptor's narrowest side for the map to resolve it.
MIN_CELLS_ACROSS: int = 4
#: Full width of the square receptor the point BRDF is averaged over (deg).
POINT_BRDF_BOX_DEG: float = 1.0
#: Largest incidence angle accepted (deg).
MAX_THETA_I_DEG: float = 89.0
#: Facets used for the Smith masking table (strided subsample of the map's slopes).
_MASKING_FACETS: int = 1 << 17
#: Rows of the levelled map per block when the roughness statistics are summed.
_STATS_ROWS: int = 256
#: Cached cell-power maps per shared map.
_CACHE_SIZE: int = 24


@dataclass(frozen=True)
class MapStats:
    """Roughness of the (levelled, windowed) map the physical models see.

    ``sq_um``: rms height; ``sdq``: rms gradient ``sqrt(<p^2 + q^2>)``;
    ``corr_length_um``: where the isotropic autocorrelation falls to 1/e;
    ``step_um``: the larger lateral step; ``field_um``: the smaller tile side.
    """

    sq_um: float
    sdq: float
    corr_length_um: float
    step_um: float
    field_um: float


class _Shared:
    """State shared by all models of one map: tiles, FFT-power cache, masking, fallback."""

    def __init__(self, hm: HeightMap, tile: int, taper: float) -> None:
        self.hm = hm
        self.tiled = TiledMap.from_heightmap(hm, tile=tile, taper=taper)
        self.cache: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
        self.lock = threading.Lock()
        self._facets: dict[tuple[complex, bool], FacetModel] = {}

    def cached(self, key: tuple[Any, ...], make: Callable[[], Any]) -> Any:
        with self.lock:
            if key in self.cache:
                self.cache.move_to_end(key)
                return self.cache[key]
        value = make()
        with self.lock:
            self.cache[key] = value
            while len(self.cache) > _CACHE_SIZE:
                self.cache.popitem(last=False)
        return value

    @cached_property
    def h_max_um(self) -> float:
        """Largest |height - tile mean| over all tiles (bounds the Taylor terms)."""
        out = 0.0
        for k in range(self.tiled.n_tiles):
            h, _ = self.tiled.tile(k)
            out = max(out, float(np.max(np.abs(h))))
        return out

    @cached_property
    def masking_model(self) -> FacetModel:
        """A facet model of a strided subsample of the map's forward slopes (for Smith G2)."""
        t = self.tiled
        ny, nx = t.shape
        stride = max(1, math.ceil(math.sqrt(ny * nx / _MASKING_FACETS)))
        mx, my = (nx - 1) // stride, (ny - 1) // stride
        rows = slice(None, None, stride)
        p = (
            t.levelled(rows, slice(1, None, stride))[:, :mx]
            - t.levelled(rows, slice(0, nx - 1, stride))[:, :mx]
        ) / t.dx_um
        cols = slice(None, None, stride)
        q = (
            t.levelled(slice(1, None, stride), cols)[:my]
            - t.levelled(slice(0, ny - 1, stride), cols)[:my]
        ) / t.dy_um
        m = min(p.shape[0], q.shape[0]), min(p.shape[1], q.shape[1])
        surf = Surface(
            p=p[: m[0], : m[1]].ravel().astype(np.float64),
            q=q[: m[0], : m[1]].ravel().astype(np.float64),
            dx_um=t.dx_um,
            dy_um=t.dy_um,
            source=t.source,
        )
        return FacetModel(surf, masking=True, backend="numpy")

    def facet(self, n: complex, masking: bool) -> FacetModel:
        """The facet model of the full map (fallback), built on first use."""
        key = (n, masking)
        with self.lock:
            if key not in self._facets:
                surf = self._facets_surface
                self._facets[key] = FacetModel(surf, n=n, masking=masking)
            return self._facets[key]

    @cached_property
    def _facets_surface(self) -> Surface:
        return Surface.from_heightmap(self.hm)

    @cached_property
    def stats(self) -> MapStats:
        t = self.tiled
        ny, nx = t.shape
        # sums over blocks of rows of the levelled map (float64): no copy of the whole map
        blocks = [(r0, min(r0 + _STATS_ROWS, ny)) for r0 in range(0, ny, _STATS_ROWS)]
        s1 = sp = sq2 = 0.0
        for r0, r1 in blocks:  # one more row for the y differences
            z = t.levelled(slice(r0, min(r1 + 1, ny)), slice(None)).astype(np.float64)
            s1 += float(np.sum(z[: r1 - r0]))
            sp += float(np.sum((np.diff(z[: r1 - r0], axis=1) / t.dx_um) ** 2))
            sq2 += float(np.sum((np.diff(z, axis=0) / t.dy_um) ** 2))
        mean = s1 / (ny * nx)
        s2 = 0.0
        for r0, r1 in blocks:
            z = t.levelled(slice(r0, r1), slice(None)).astype(np.float64)
            s2 += float(np.sum((z - mean) ** 2))
        sq = math.sqrt(s2 / (ny * nx))
        sdq = math.sqrt(sp / (ny * (nx - 1)) + sq2 / ((ny - 1) * nx))
        # isotropic ACF along x and y from the first tile's periodogram (1/e crossing)
        h, w = t.tile(0)
        spec = np.abs(np.fft.rfft2((h * w).astype(np.float64))) ** 2
        acf = np.fft.irfft2(spec, s=h.shape)
        acf /= acf[0, 0] if acf[0, 0] > 0 else 1.0
        lx = _first_below(acf[0, : h.shape[1] // 2], math.exp(-1.0)) * t.dx_um
        ly = _first_below(acf[: h.shape[0] // 2, 0], math.exp(-1.0)) * t.dy_um
        return MapStats(
            sq_um=sq,
            sdq=sdq,
            corr_length_um=0.5 * (lx + ly),
            step_um=max(t.dx_um, t.dy_um),
            field_um=min(t.nx_t * t.dx_um, t.ny_t * t.dy_um),
        )


def _first_below(a: FloatArray, level: float) -> float:
    """Fractional index where ``a`` first drops below ``level`` (linear interpolation)."""
    idx = np.nonzero(a < level)[0]
    if idx.size == 0:
        return float(a.size)
    i = int(idx[0])
    if i == 0:
        return 0.0
    a0, a1 = float(a[i - 1]), float(a[i])
    return (i - 1) + (a0 - level) / (a0 - a1) if a0 != a1 else float(i)


def _check_theta_i(theta_i_deg: float) -> float:
    v = float(theta_i_deg)
    if not (math.isfinite(v) and 0.0 <= v <= MAX_THETA_I_DEG):
        raise ValueError(
            f"theta_i_deg must be in [0, {MAX_THETA_I_DEG:g}] deg, got {theta_i_deg!r}"
        )
    return v


@dataclass(frozen=True)
class _Box:
    """Signed FFT index ranges (inclusive) of a block of cells."""

    ix0: int
    ix1: int
    iy0: int
    iy1: int

    def union(self, other: _Box) -> _Box:
        return _Box(
            min(self.ix0, other.ix0),
            max(self.ix1, other.ix1),
            min(self.iy0, other.iy0),
            max(self.iy1, other.iy1),
        )

    @property
    def ix(self) -> NDArray[np.int64]:
        return np.arange(self.ix0, self.ix1 + 1, dtype=np.int64)

    @property
    def iy(self) -> NDArray[np.int64]:
        return np.arange(self.iy0, self.iy1 + 1, dtype=np.int64)


class PhysicalOpticsModel:
    """Base of the wave-optics models (implements ``ReflectanceModel``; module docstring).

    Parameters
    ----------
    hm : HeightMap
        The measured (or simulated) map; levelled, gaps filled, cut into tiles.
    n : float or complex
        Refractive index at ``wavelength_nm``; complex ``n + ik`` for conductors.
    wavelength_nm : float
        Wavelength of the goniometer responses and BRDFs (and of gloss with
        ``gloss_weighting="single"``).
    gloss_weighting : {"iso2813", "single"}
        ``"iso2813"``: gloss weighted over 16 wavelengths 400-700 nm by CIE illuminant C x
        V(lambda) (the index ``n`` is taken constant); ``"single"``: at ``wavelength_nm``.
    masking : bool
        Multiply by the Smith G2 of the map's slopes (default on).
    backend : {"numba", "numpy"}
        Aperture-sum kernels.
    tile, taper : int, float
        Tile side (points) and window taper (:mod:`goniolab.optics.psd`).
    progress : callable, optional
        ``progress(done, total, what)`` during long transforms.
    """

    kind: ClassVar[str] = "physical"

    def __init__(
        self,
        hm: HeightMap | None = None,
        *,
        n: complex | float = 1.55,
        wavelength_nm: float = 550.0,
        gloss_weighting: GlossWeighting = "iso2813",
        masking: bool = True,
        backend: Backend = "numba",
        tile: int = DEFAULT_TILE,
        taper: float = DEFAULT_TAPER,
        progress: Progress | None = None,
        shared: _Shared | None = None,
    ) -> None:
        eta = complex(n)
        if (
            not (math.isfinite(eta.real) and math.isfinite(eta.imag))
            or eta.real <= 0
            or eta.imag < 0
        ):
            raise ValueError(f"refractive index must have n > 0 and k >= 0, got {n!r}")
        lam = float(wavelength_nm)
        if not (math.isfinite(lam) and 100.0 <= lam <= 20000.0):
            raise ValueError(f"wavelength_nm must be in [100, 20000] nm, got {wavelength_nm!r}")
        if gloss_weighting not in ("iso2813", "single"):
            raise ValueError(
                f"gloss_weighting must be 'iso2813' or 'single', got {gloss_weighting!r}"
            )
        if backend not in ("numba", "numpy"):
            raise ValueError(f"backend must be 'numba' or 'numpy', got {backend!r}")
        if shared is None:
            if hm is None:
                raise TypeError(f"{type(self).__name__} needs a HeightMap")
            if not isinstance(hm, HeightMap):
                raise TypeError(f"{type(self).__name__} needs a HeightMap, got {type(hm).__name__}")
            shared = _Shared(hm, int(tile), float(taper))
        self._shared = shared
        self.n = eta
        self.wavelength_nm = lam
        self.gloss_weighting: GlossWeighting = gloss_weighting
        self.masking = bool(masking)
        self.backend: Backend = backend
        self.progress = progress

    # ------------------------------------------------------------------ construction
    def with_optics(
        self, *, n: complex | float | None = None, wavelength_nm: float | None = None
    ) -> PhysicalOpticsModel:
        """A sibling model for another index and/or wavelength, sharing the map and caches."""
        return type(self)(
            n=self.n if n is None else n,
            wavelength_nm=self.wavelength_nm if wavelength_nm is None else wavelength_nm,
            gloss_weighting=self.gloss_weighting,
            masking=self.masking,
            backend=self.backend,
            progress=self.progress,
            shared=self._shared,
        )

    def __repr__(self) -> str:
        t = self._shared.tiled
        return (
            f"{type(self).__name__}({t.source!r}, n={self.n}, wavelength_nm={self.wavelength_nm:g}, "
            f"tiles={t.n_tiles} x {t.nx_t}x{t.ny_t}, masking={self.masking})"
        )

    @property
    def source(self) -> str:
        return self._shared.tiled.source

    @property
    def stats(self) -> MapStats:
        """Roughness of the map as the physical models see it."""
        return self._shared.stats

    @property
    def facet_model(self) -> FacetModel:
        """The facet model of the same map, index and masking (the stated fallback)."""
        return self._shared.facet(self.n, self.masking)

    # ------------------------------------------------------------------ cells (subclasses)
    def _cell_powers(
        self, theta_i_deg: float, lams_um: Sequence[float], boxes: Sequence[_Box]
    ) -> list[FloatArray]:
        """Flux fraction per cell (rows iy, columns ix of each box), one array per wavelength."""
        raise NotImplementedError

    def specular_reflectance(self, theta_i_deg: float) -> float:
        """Reflectance of the coherent specular beam at ``wavelength_nm``."""
        raise NotImplementedError

    # ------------------------------------------------------------------ geometry helpers
    def _cell_size(self, lam_um: float) -> tuple[float, float]:
        t = self._shared.tiled
        return lam_um / (t.nx_t * t.dx_um), lam_um / (t.ny_t * t.dy_um)

    def _nyquist(self) -> tuple[int, int, int, int]:
        t = self._shared.tiled
        return -(t.nx_t // 2), (t.nx_t - 1) // 2, -(t.ny_t // 2), (t.ny_t - 1) // 2

    def _wo_axes(
        self, theta_i_deg: float, lam_um: float, box: _Box
    ) -> tuple[FloatArray, FloatArray]:
        cx, cy = self._cell_size(lam_um)
        wox = box.ix.astype(np.float64) * cx - math.sin(math.radians(theta_i_deg))
        woy = box.iy.astype(np.float64) * cy
        return wox, woy

    def _geometry(
        self, theta_i_deg: float, lam_um: float, box: _Box
    ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
        """``wo`` components (2-D) of the cells of ``box`` and the mask of real directions."""
        wox, woy = self._wo_axes(theta_i_deg, lam_um, box)
        x = np.broadcast_to(wox[None, :], (woy.size, wox.size))
        y = np.broadcast_to(woy[:, None], (woy.size, wox.size))
        z2 = 1.0 - x * x - y * y
        ok = z2 > 1e-12
        return x, y, np.sqrt(np.where(ok, z2, 0.0)), ok

    def _fresnel_geom(
        self, theta_i_deg: float, x: FloatArray, y: FloatArray, z: FloatArray, ok: NDArray[np.bool_]
    ) -> FloatArray:
        """Fresnel at the local incidence ``wi.h`` of each cell (h the half vector)."""
        t = math.radians(theta_i_deg)
        sx, cz = math.sin(t), math.cos(t)
        hx, hy, hz = x + sx, y, z + cz
        hn = np.sqrt(hx * hx + hy * hy + hz * hz)
        cos_ih = np.where(ok, 0.5 * hn, 1.0)
        out: FloatArray = np.where(ok, fresnel(np.clip(cos_ih, 0.0, 1.0), self.n), 0.0)
        return out

    def _reach(self, source: Aperture, receptor: Aperture) -> tuple[float, float]:
        """Half reach in plane and out of plane (rad) of receptor plus the source image."""
        if isinstance(source, Cone) and isinstance(receptor, Cone):
            r = math.radians(source.half_angle_deg + receptor.half_angle_deg)
            return r, r
        if isinstance(source, Rect) and isinstance(receptor, Rect):
            return (
                math.radians(0.5 * (source.in_plane_deg + receptor.in_plane_deg)),
                math.radians(0.5 * (source.perp_deg + receptor.perp_deg)),
            )
        raise ValueError(
            "source and receptor apertures must both be Cone or both be Rect, got "
            f"{type(source).__name__} and {type(receptor).__name__}"
        )

    def _box_for(
        self, theta_i_deg: float, lam_um: float, alpha_lo: float, alpha_hi: float, half_b: float
    ) -> tuple[_Box, bool]:
        """Cells covering in-plane angles [alpha_lo, alpha_hi] x out-of-plane [-half_b, half_b]
        (rad); ``inside`` is False when part of that region is beyond the map's Nyquist window."""
        cb = math.cos(min(half_b, 1.5))
        s_hi = -math.sin(min(alpha_hi, 0.5 * math.pi))
        s_lo = -math.sin(max(alpha_lo, -0.5 * math.pi))
        x_lo, x_hi = min(s_hi, s_hi * cb), max(s_lo, s_lo * cb)
        y_hi = math.sin(min(half_b, 1.5))
        sx = math.sin(math.radians(theta_i_deg))
        cx, cy = self._cell_size(lam_um)
        ix0 = math.floor((x_lo + sx) / cx) - 1
        ix1 = math.ceil((x_hi + sx) / cx) + 1
        iy1 = math.ceil(y_hi / cy) + 1
        nx0, nx1, ny0, ny1 = self._nyquist()
        inside = ix0 >= nx0 and ix1 <= nx1 and -iy1 >= ny0 and iy1 <= ny1
        box = _Box(max(ix0, nx0), min(ix1, nx1), max(-iy1, ny0), min(iy1, ny1))
        return box, inside

    def _lams_for_gloss(self) -> tuple[FloatArray, FloatArray]:
        if self.gloss_weighting == "single":
            return np.array([self.wavelength_nm]), np.array([1.0])
        from goniolab.optics.spectral import iso2813_weights

        return iso2813_weights()

    def coverage(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        source: Aperture,
        receptor: Aperture,
        *,
        wavelengths_nm: Sequence[float] | None = None,
    ) -> str | None:
        """Why the map cannot resolve this geometry (the facet model is used), or None.

        Checks, at each wavelength (default ``wavelength_nm``): the receptor's reach lies
        inside the map's Nyquist window ``|sin ts - sin t_spec| <= lambda / (2 step)``, and
        the FFT cell ``lambda / field`` is at most 1/:data:`MIN_CELLS_ACROSS` of the
        receptor's narrowest side.
        """
        lams = [self.wavelength_nm] if wavelengths_nm is None else list(wavelengths_nm)
        ra, rb = self._reach(source, receptor)
        tr = math.radians(float(theta_r_deg))
        if isinstance(receptor, Cone):
            w_in = w_perp = math.radians(receptor.full_angle_deg)
        else:
            w_in, w_perp = math.radians(receptor.in_plane_deg), math.radians(receptor.perp_deg)
        for lam_nm in lams:
            lam = lam_nm * 1e-3
            _, inside = self._box_for(theta_i_deg, lam, tr - ra, tr + ra, rb)
            if not inside:
                t = self._shared.tiled
                step = max(t.dx_um, t.dy_um)
                return (
                    f"the map resolves directions within |sin ts - sin t_spec| <= "
                    f"lambda/(2 step) = {lam / (2 * step):.3g} of specular at {lam_nm:g} nm "
                    f"(step {step:g} um); this aperture reaches further"
                )
            cx, cy = self._cell_size(lam)
            across_in = w_in * math.cos(tr) / cx if cx > 0 else math.inf
            across_perp = w_perp / cy if cy > 0 else math.inf
            if min(across_in, across_perp) < MIN_CELLS_ACROSS:
                t = self._shared.tiled
                return (
                    f"field of {t.nx_t * t.dx_um:g} x {t.ny_t * t.dy_um:g} um resolves "
                    f"{min(across_in, across_perp):.2g} cells across the receptor at "
                    f"{lam_nm:g} nm (needs {MIN_CELLS_ACROSS})"
                )
        return None

    # ------------------------------------------------------------------ masking
    def _g2(self, theta_i_deg: float, wo: FloatArray) -> FloatArray:
        if not self.masking:
            return np.ones(wo.shape[:-1])
        t = math.radians(theta_i_deg)
        wi = np.array([math.sin(t), 0.0, math.cos(t)])
        return self._shared.masking_model.masking_g2(wi, wo)

    # ------------------------------------------------------------------ aperture sums
    def _sum_apertures(
        self,
        theta_i_deg: float,
        lam_um: float,
        box: _Box,
        p: FloatArray,
        theta_r_deg: FloatArray,
        source: Aperture,
        receptor: Aperture,
        g2: FloatArray | None = None,
    ) -> FloatArray:
        """Aperture sums of the cell powers ``p`` at each detector angle, times the Smith G2
        of the detector's direction (``g2`` when given: it does not depend on lambda)."""
        wox, woy = self._wo_axes(theta_i_deg, lam_um, box)
        tr = np.radians(theta_r_deg)
        if (
            isinstance(source, Cone)
            and isinstance(receptor, Cone)
            and self._split_source(theta_i_deg, source)
        ):
            return self._clipped_cone_sums(theta_i_deg, wox, woy, p, tr, source, receptor)
        if isinstance(source, Cone) and isinstance(receptor, Cone):
            table, g0, g1, o_in, _ = _cone_table(
                math.radians(source.half_angle_deg), math.radians(receptor.half_angle_deg)
            )
            dirs = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
            fn = CK.cone_cells_numba if self.backend == "numba" else CK.cone_cells_numpy
            out = fn(wox, woy, p, np.ascontiguousarray(dirs), table, g0, g1, o_in)
        else:
            assert isinstance(source, Rect) and isinstance(receptor, Rect)
            fn2 = CK.rect_cells_numba if self.backend == "numba" else CK.rect_cells_numpy
            out = fn2(
                wox,
                woy,
                p,
                np.ascontiguousarray(tr),
                math.radians(source.in_plane_deg),
                math.radians(receptor.in_plane_deg),
                math.radians(source.perp_deg),
                math.radians(receptor.perp_deg),
            )
        if g2 is None:
            d = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
            g2 = self._g2(theta_i_deg, d)
        result: FloatArray = np.asarray(out, dtype=np.float64) * g2
        return result

    def _split_source(self, theta_i_deg: float, source: Aperture) -> bool:
        """Whether a source cone is summed over sub-cones (:meth:`_clipped_cone_sums`): when it
        reaches the horizon, and with masking from where the facet model splits it too
        (:data:`goniolab.optics.facet.SPLIT_SOURCE_RINGS`), so that G2 is that of each source
        direction (at grazing incidence it varies several-fold across a 6 deg cone; taken at
        the nominal incidence it made the reading jump by 8 % where the clipping starts)."""
        if not isinstance(source, Cone) or source.half_angle_deg == 0.0:
            return False
        if _reaches_horizon(theta_i_deg, source):
            return True
        edge = min(e for e, _ in SPLIT_SOURCE_RINGS)
        return self.masking and theta_i_deg + source.half_angle_deg >= edge

    def _clipped_cone_sums(
        self,
        theta_i_deg: float,
        wox: FloatArray,
        woy: FloatArray,
        p: FloatArray,
        tr: FloatArray,
        source: Cone,
        receptor: Cone,
    ) -> FloatArray:
        """Cone sums over the source's sub-cones (:meth:`_split_source`), clipped at the
        horizon when the cone reaches it.

        The source is split as in the facet model (:func:`_clipped_source_parts`: sub-cones
        of the part above the horizon, shares over the whole cone). As everywhere in these
        models the scattered pattern is that of the nominal incidence, carried over the
        source (zeroth order in the source direction): a sub-cone centred at polar angle
        ``theta_i + delta`` and azimuth ``phi`` turns the pattern about z by phi and shifts
        it by delta in plane, so it reads the nominal pattern through the receptor turned
        back, ``R_y(-delta) R_z(-phi) d``, with the sub-cone's own cap-overlap table and the
        Smith G2 of its own direction.
        """
        a_d = math.radians(receptor.half_angle_deg)
        d = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
        fn = CK.cone_cells_numba if self.backend == "numba" else CK.cone_cells_numpy
        out = np.zeros(tr.size)
        ti = math.radians(theta_i_deg)
        for c, sub, share in _clipped_source_parts(theta_i_deg, source):
            delta = math.acos(min(1.0, float(c[2]))) - ti
            phi = math.atan2(float(c[1]), float(c[0]))
            cp, sp = math.cos(phi), math.sin(phi)
            # R_z(-phi) d, then R_y(-delta): alpha = atan2(-x, z) decreases by delta
            x1, y1 = cp * d[:, 0] + sp * d[:, 1], -sp * d[:, 0] + cp * d[:, 1]
            cd, sd = math.cos(delta), math.sin(delta)
            dirs = np.stack([cd * x1 + sd * d[:, 2], y1, -sd * x1 + cd * d[:, 2]], axis=-1)
            table, g0, g1, o_in, _ = _cone_table(math.radians(sub.half_angle_deg), a_d)
            part = fn(wox, woy, p, np.ascontiguousarray(dirs), table, g0, g1, o_in)
            g2 = (
                self._shared.masking_model.masking_g2(np.broadcast_to(c, d.shape), d)
                if self.masking
                else 1.0
            )
            out += share * np.asarray(part, dtype=np.float64) * g2
        return out

    def _fractions(
        self,
        theta_i_deg: float,
        theta_r_deg: FloatArray,
        source: Aperture,
        receptor: Aperture,
        lams_nm: Sequence[float],
    ) -> FloatArray:
        """Flux fractions ``(n_lambda, n_points)``; every point must be covered."""
        ra, rb = self._reach(source, receptor)
        if isinstance(source, Cone) and self._split_source(theta_i_deg, source):
            # the turned-back receptors of the source's sub-cones reach one source half
            # angle further
            ra = rb = ra + math.radians(source.half_angle_deg)
        tr = np.radians(theta_r_deg)
        boxes: list[_Box] = []
        for lam_nm in lams_nm:
            box, _ = self._box_for(
                theta_i_deg, lam_nm * 1e-3, float(tr.min()) - ra, float(tr.max()) + ra, rb
            )
            boxes.append(box)
        lams_um = [lam * 1e-3 for lam in lams_nm]
        powers = self._cell_powers(theta_i_deg, lams_um, boxes)
        out = np.empty((len(lams_nm), theta_r_deg.size))
        g2 = self._g2(theta_i_deg, np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1))
        for k, (lam, box, p) in enumerate(zip(lams_um, boxes, powers, strict=True)):
            out[k] = self._sum_apertures(
                theta_i_deg, lam, box, p, theta_r_deg, source, receptor, g2
            )
        return out

    def _check_apertures(self, theta_i_deg: float, source: Aperture, receptor: Aperture) -> None:
        self._reach(source, receptor)
        if isinstance(source, Rect) and _reaches_horizon(theta_i_deg, source):
            raise ValueError(
                f"source rectangle of half width {0.5 * source.in_plane_deg:g} deg at "
                f"theta_i_deg = {theta_i_deg:g} reaches the horizon (theta_i + half width "
                ">= 90 deg): only cones are clipped there"
            )
        if solid_angle_sr(receptor) == 0.0:
            raise ValueError(
                f"{self.kind}: a receptor without solid angle reads nothing; use brdf_point"
            )

    # ------------------------------------------------------------------ ReflectanceModel
    def reflected_fraction(
        self, theta_i_deg: float, theta_r_deg: float, source: Aperture, receptor: Aperture
    ) -> float:
        """Fraction of the flux from ``source`` (centred on theta_i) reaching ``receptor``.

        The facet model of the same map answers when :meth:`coverage` gives a reason.
        """
        ti = _check_theta_i(theta_i_deg)
        tr = float(theta_r_deg)
        if not (math.isfinite(tr) and -90.0 < tr < 90.0):
            raise ValueError(f"theta_r_deg must be in (-90, 90) deg, got {theta_r_deg!r}")
        self._check_apertures(ti, source, receptor)
        if self.coverage(ti, tr, source, receptor) is not None:
            return self.facet_model.reflected_fraction(ti, tr, source, receptor)
        return float(
            self._fractions(ti, np.array([tr]), source, receptor, [self.wavelength_nm])[0, 0]
        )

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = GONIO_CONE,
        detector: Aperture = GONIO_CONE,
    ) -> FloatArray:
        """Goniometer reading in % of a mirror at the signed detector angles.

        One cell-power map serves every angle the map resolves; the others come from the
        facet model (:meth:`coverage` says which and why).
        """
        ti = _check_theta_i(theta_i_deg)
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        if np.any(~np.isfinite(tr)) or np.any(np.abs(tr) >= 90.0):
            raise ValueError("theta_r_deg must be in (-90, 90) deg")
        self._check_apertures(ti, source, detector)
        flat = tr.ravel()
        out = np.empty(flat.size)
        if flat.size == 0:
            return out.reshape(tr.shape)
        covered = np.array([self.coverage(ti, float(t), source, detector) is None for t in flat])
        if np.any(covered):
            out[covered] = self._fractions(
                ti, flat[covered], source, detector, [self.wavelength_nm]
            )[0]
        if np.any(~covered):
            out[~covered] = (
                self.facet_model.luminance_pct(ti, flat[~covered], source=source, detector=detector)
                / 100.0
            )
        result: FloatArray = 100.0 * out.reshape(tr.shape)
        return result

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """In-plane BRDF (sr^-1), averaged over a :data:`POINT_BRDF_BOX_DEG` square receptor.

        A single map's wave-optics BRDF is speckle at the resolution ``lambda / field``; the
        average over the 1 deg x 1 deg receptor (a point source) is the BRDF an instrument
        with that aperture sees. The coherent specular beam is spread over the box when it
        falls inside it.
        """
        ti = _check_theta_i(theta_i_deg)
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        if np.any(~np.isfinite(tr)) or np.any(np.abs(tr) >= 90.0):
            raise ValueError("theta_r_deg must be in (-90, 90) deg")
        src, box = Rect(0.0, 0.0), Rect(POINT_BRDF_BOX_DEG, POINT_BRDF_BOX_DEG)
        flat = tr.ravel()
        frac = np.empty(flat.size)
        covered = np.array([self.coverage(ti, float(t), src, box) is None for t in flat])
        if np.any(covered):
            frac[covered] = self._fractions(ti, flat[covered], src, box, [self.wavelength_nm])[0]
        omega = solid_angle_sr(box)
        proj = omega * np.cos(np.radians(flat))
        out = np.where(proj > 0, frac / np.where(proj > 0, proj, 1.0), 0.0)
        if np.any(~covered):
            out[~covered] = self.facet_model.brdf_inplane(ti, flat[~covered])
        result: FloatArray = out.reshape(tr.shape)
        return result

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        """In-plane BRDF (sr^-1) via :meth:`brdf_inplane`; out-of-plane directions use the
        facet model (the box average is defined in the plane of incidence)."""
        phi = float(phi_r_deg) % 360.0
        tr = float(theta_r_deg)
        if phi in (0.0, 180.0):
            signed = tr if phi == 180.0 else -tr
            return float(self.brdf_inplane(theta_i_deg, np.array([signed]))[0])
        return self.facet_model.brdf_point(theta_i_deg, theta_r_deg, phi_r_deg)

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        """ISO 2813 gloss in GU, weighted over wavelength by C x V(lambda) (or one wavelength).

        ``G = 100 sum_l w_l Phi_l / sum_l w_l F(1.567, t)`` with ``Phi_l`` the flux fraction
        from the ISO source into the ISO receptor at wavelength l. Geometries the map cannot
        resolve at some wavelength are read from the facet model (:meth:`gloss_fallbacks`).
        """
        lams, w = self._lams_for_gloss()
        out: dict[int, float] = {}
        for t in angles_deg:
            key = int(t)
            if key not in ISO2813_RECEPTOR:
                raise ValueError(
                    f"no ISO 2813 geometry at {t} deg; known: {sorted(ISO2813_RECEPTOR)}"
                )
            rec = ISO2813_RECEPTOR[key]
            ref = float(fresnel_dielectric(math.cos(math.radians(key)), ISO2813_BLACK_GLASS_N))
            if (
                self.coverage(key, key, ISO2813_SOURCE, rec, wavelengths_nm=lams.tolist())
                is not None
            ):
                out[key] = self.facet_model.gloss((key,))[key]
                continue
            frac = self._fractions(key, np.array([float(key)]), ISO2813_SOURCE, rec, list(lams))
            out[key] = 100.0 * float(np.sum(w * frac[:, 0]) / np.sum(w)) / ref
        return out

    def gloss_fallbacks(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, str]:
        """Geometries whose gloss comes from the facet model, with the reason."""
        lams, _ = self._lams_for_gloss()
        out: dict[int, str] = {}
        for t in angles_deg:
            rec = ISO2813_RECEPTOR[int(t)]
            why = self.coverage(int(t), int(t), ISO2813_SOURCE, rec, wavelengths_nm=lams.tolist())
            if why is not None:
                out[int(t)] = why
        return out

    def albedo(self, theta_i_deg: float) -> float:
        """Directional albedo: the scattered fraction summed over every cell the map resolves
        (with G2 per cell when masking); an upper bound check, ``<= 1``."""
        ti = _check_theta_i(theta_i_deg)
        nx0, nx1, ny0, ny1 = self._nyquist()
        box = _Box(nx0, nx1, ny0, ny1)
        lam = self.wavelength_nm * 1e-3
        p = self._cell_powers(ti, [lam], [box])[0]
        if self.masking:
            x, y, z, ok = self._geometry(ti, lam, box)
            g2 = self._g2(ti, np.stack([x, y, np.where(ok, z, 1.0)], axis=-1))
            p = p * np.where(ok, g2, 0.0)
        return float(np.sum(p))
