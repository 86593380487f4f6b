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

Everything an instrument reads is the coherent specular beam plus a sum of the diffuse
``P`` over cells (:mod:`._cell_kernels`): goniometer cones and ISO 2813 / E430 rectangles
with the source aperture (its mirror image around each cell's direction, as in
:mod:`goniolab.optics.facet`), the gloss of
:func:`goniolab.optics.gloss_standards.gloss_report`, haze and DOI.

No silent fallback (issue 20):

- **the coherent beam is analytic** (:meth:`PhysicalOpticsModel._coherent_sums`): every
  source direction sends ``R(theta_s) C(theta_s)`` (its own Fresnel reflectance and
  coherent factor) to its mirror direction, and the receptor collects the part of the
  source's mirror image inside it, whatever the FFT cell size;
- **the diffuse part at a resolution that fits the aperture**: the tile's transform is
  zero-padded (the windowed patch's far field sampled on a finer grid of directions)
  until the receptor spans :data:`CELLS_ACROSS` cells (:meth:`_oversampling`), so a 50 um
  AFM map reads the ISO 85 deg receptor as well as a 2 mm profilometer map;
- **validity, stated**: Rayleigh-Rice outside ``g <= RR_VALID_G``, ``Sdq <= RR_VALID_SDQ``
  hands the geometry to the Kirchhoff model of the same map; Kirchhoff on a map that does
  not sample its phase screen to Rayleigh-Rice (g small) or the facet model; an aperture
  reaching beyond the map's Nyquist window ``|sin ts - sin t_spec| <= lambda / (2 step)``
  is read by the facet model only from ``g >= FACET_MIN_HANDOVER_G`` (below, the wave
  model answers with the light the map resolves). Every reading has a
  :class:`~goniolab.optics.provenance.Provenance` (:meth:`provenance`,
  :meth:`gloss_provenance`): the model that computed it and the notes;
- **shadowing only where geometric optics holds**: none on the coherent beam nor in
  Rayleigh-Rice; the Kirchhoff diffuse part takes the Smith G2 of the map's slopes
  (Heitz 2014) to the power ``1 - exp(-g_d)`` (:meth:`KirchhoffModel._diffuse_g2`);
- **energy**: Rayleigh-Rice's diffuse part carries ``exp(-g)``, and from
  :data:`ENERGY_CHECK_FROM_DEG` both models hold the hemisphere's diffuse flux to what the
  coherent beam leaves (:meth:`_energy_scales`; docs/PHYSICS.md, "Energy").

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

import itertools
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
from goniolab.optics.facet import FacetModel
from goniolab.optics.facet_apertures import (
    SPLIT_SOURCE_RINGS,
    clipped_source_parts,
    cone_table,
    reaches_horizon,
)
from goniolab.optics.fresnel import fresnel
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.provenance import Provenance
from goniolab.optics.psd import DEFAULT_TAPER, DEFAULT_TILE, TiledMap
from goniolab.optics.surface import Surface

__all__ = [
    "CELLS_ACROSS",
    "ENERGY_CHECK_FROM_DEG",
    "FACET_MIN_HANDOVER_G",
    "MAX_PADDED_POINTS",
    "MAX_PHASE_STEP_RAD",
    "MAX_THETA_I_DEG",
    "POINT_BRDF_BOX_DEG",
    "RR_VALID_G",
    "RR_VALID_SDQ",
    "GlossWeighting",
    "MapStats",
    "PhysicalOpticsModel",
    "Progress",
    "Provenance",
    "box_projected_solid_angle_sr",
]

FloatArray = NDArray[np.float64]
GlossWeighting = Literal["iso2813", "single"]
Backend = Literal["numba", "numpy"]
#: ``progress(done, total, what)``: called while long work runs.
Progress = Callable[[int, int, str], None]

#: Cells across the receptor's narrowest side the diffuse sums aim for: the tile's transform
#: is zero-padded (sampled on a finer grid of directions) until the receptor spans them.
CELLS_ACROSS: int = 6
#: Most points of a zero-padded transform axis (bounds the padding of tiny receptors).
MAX_PADDED_POINTS: int = 1 << 15
#: Below this Rayleigh factor g no geometry is handed to the facet model: its coherent beam
#: ``exp(-g)`` is more than a third of the reflected light, which the facet model lacks.
FACET_MIN_HANDOVER_G: float = 1.0
#: Rayleigh-Rice answers up to this g (first-order perturbation with the Debye-Waller
#: factor: its second-order terms are ~ g/2 of the diffuse part) ...
RR_VALID_G: float = 0.3
#: ... and this rms gradient (small slopes); beyond, the Kirchhoff model of the map answers.
RR_VALID_SDQ: float = 0.3
#: Largest rms phase step between neighbouring map points for the Kirchhoff screen (rad).
MAX_PHASE_STEP_RAD: float = 1.2
#: From this incidence on, the diffuse part of the wave models is held to energy
#: conservation over the whole hemisphere (:meth:`PhysicalOpticsModel._energy_scales`):
#: Beckmann's obliquity factor grows without bound towards grazing incidence, and the
#: first-order Rayleigh-Rice Q factor may exceed the Fresnel reflectance there.
ENERGY_CHECK_FROM_DEG: float = 70.0
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
        #: the other wave models of the same map, by (kind, n, wavelength, weighting, masking)
        self.siblings: dict[tuple[Any, ...], Any] = {}

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
        self,
        theta_i_deg: float,
        lams_um: Sequence[float],
        boxes: Sequence[_Box],
        os: tuple[int, int] = (1, 1),
    ) -> tuple[list[FloatArray], list[float]]:
        """Diffuse flux fraction per cell (rows iy, columns ix of each box, on the grid
        refined ``os`` times by zero padding), one array per wavelength, and the coherent
        factor ``C`` of the specular beam (``R(ti) C`` is its reflectance) per wavelength."""
        raise NotImplementedError

    def specular_reflectance(self, theta_i_deg: float) -> float:
        """Reflectance of the coherent specular beam at ``wavelength_nm``."""
        raise NotImplementedError

    def _diffuse_g2(self, wi: FloatArray, wo: FloatArray, lam_um: float) -> FloatArray | float:
        """Shadowing applied to the diffuse cells seen from ``wo`` (rows of unit vectors)
        lit from ``wi``: none here (the coherent beam and Rayleigh-Rice take none);
        :class:`~goniolab.optics.kirchhoff.KirchhoffModel` weighs in Smith's G2 as the
        geometric limit needs it."""
        return 1.0

    @property
    def _g2_per_source(self) -> bool:
        """Whether the diffuse sums carry a shadowing term that varies across the source."""
        return False

    def _energy_scales(self, theta_i_deg: float, lams_um: Sequence[float]) -> list[float]:
        """Factors (<= 1) applied to the diffuse cells so that the hemisphere's total stays
        within energy conservation, per wavelength (1 below :data:`ENERGY_CHECK_FROM_DEG`;
        the subclasses' :meth:`_energy_scales_at` state their bound). For more than three
        wavelengths the factor is computed at the shortest, median and longest and
        interpolated linearly in ``1/lambda^2`` (it is smooth in lambda: g ~ 1/lambda^2)."""
        if theta_i_deg < ENERGY_CHECK_FROM_DEG:
            return [1.0 for _ in lams_um]
        if len(lams_um) > 3:
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

    # ------------------------------------------------------------------ geometry helpers
    def _cell_size(self, lam_um: float, os: tuple[int, int] = (1, 1)) -> tuple[float, float]:
        t = self._shared.tiled
        return lam_um / (os[0] * t.nx_t * t.dx_um), lam_um / (os[1] * t.ny_t * t.dy_um)

    def _nyquist(self, os: tuple[int, int] = (1, 1)) -> tuple[int, int, int, int]:
        t = self._shared.tiled
        nx, ny = os[0] * t.nx_t, os[1] * t.ny_t
        # the map's own band: |f| <= 1/(2 step), whatever the padding
        hx, hy = (os[0] * t.nx_t) // 2, (os[1] * t.ny_t) // 2
        return -hx, min(hx, nx - hx - 1), -hy, min(hy, ny - hy - 1)

    def _wo_axes(
        self, theta_i_deg: float, lam_um: float, box: _Box, os: tuple[int, int] = (1, 1)
    ) -> tuple[FloatArray, FloatArray]:
        cx, cy = self._cell_size(lam_um, os)
        wox = box.ix.astype(np.float64) * cx - math.sin(math.radians(theta_i_deg))
        woy = box.iy.astype(np.float64) * cy
        return wox, woy

    def _geometry(
        self, theta_i_deg: float, lam_um: float, box: _Box, os: tuple[int, int] = (1, 1)
    ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
        """``wo`` components (2-D) of the cells of ``box`` and the mask of real directions."""
        wox, woy = self._wo_axes(theta_i_deg, lam_um, box, os)
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
        self,
        theta_i_deg: float,
        lam_um: float,
        alpha_lo: float,
        alpha_hi: float,
        half_b: float,
        os: tuple[int, int] = (1, 1),
    ) -> tuple[_Box, bool]:
        """Cells covering in-plane angles [alpha_lo, alpha_hi] x out-of-plane [-half_b, half_b]
        (rad); ``inside`` is False when part of that region is beyond the map's Nyquist window."""
        cb = math.cos(min(half_b, 1.5))
        s_hi = -math.sin(min(alpha_hi, 0.5 * math.pi))
        s_lo = -math.sin(max(alpha_lo, -0.5 * math.pi))
        x_lo, x_hi = min(s_hi, s_hi * cb), max(s_lo, s_lo * cb)
        y_hi = math.sin(min(half_b, 1.5))
        sx = math.sin(math.radians(theta_i_deg))
        cx, cy = self._cell_size(lam_um, os)
        ix0 = math.floor((x_lo + sx) / cx) - 1
        ix1 = math.ceil((x_hi + sx) / cx) + 1
        iy1 = math.ceil(y_hi / cy) + 1
        nx0, nx1, ny0, ny1 = self._nyquist(os)
        # one cell of slack at the edges (the box has one more cell than its reach needs)
        inside = ix0 + 1 >= nx0 and ix1 - 1 <= nx1 and -iy1 + 1 >= ny0 and iy1 - 1 <= ny1
        # clipped to the window; a region wholly beyond it keeps the window's edge cell
        # (which no aperture of the region reaches: its sums are 0, as they must be)
        bx0, bx1 = min(max(ix0, nx0), nx1), max(min(ix1, nx1), nx0)
        if bx0 > bx1:
            bx0 = bx1 = nx1 if ix0 > nx1 else nx0
        box = _Box(bx0, bx1, max(-iy1, ny0), min(iy1, ny1))
        return box, inside

    def _lams_for_gloss(self) -> tuple[FloatArray, FloatArray]:
        if self.gloss_weighting == "single":
            return np.array([self.wavelength_nm]), np.array([1.0])
        from goniolab.optics.spectral import iso2813_weights

        return iso2813_weights()

    def _lams_for_checks(self) -> list[float]:
        """The gloss wavelengths the validity checks look at: those carrying at least 1 % of
        the peak ISO 2813 weight (440-680 nm; 400 and 420 nm weigh 0.02 and 0.4 %)."""
        lams, w = self._lams_for_gloss()
        return [float(v) for v, wi in zip(lams, w, strict=True) if wi >= 0.01 * float(w.max())]

    def _oversampling(
        self, lam_um: float, receptor: Aperture, theta_r_deg: FloatArray
    ) -> tuple[tuple[int, int], str | None]:
        """Zero-padding factors ``(os_x, os_y)`` giving at least :data:`CELLS_ACROSS` cells
        ``lambda / (os field)`` across the receptor's narrowest side at every angle, and a
        note when :data:`MAX_PADDED_POINTS` caps them (fewer cells: a coarser sum)."""
        t = self._shared.tiled
        if isinstance(receptor, Cone):
            w_in = w_perp = math.radians(receptor.full_angle_deg)
        else:
            w_in, w_perp = math.radians(receptor.in_plane_deg), math.radians(receptor.perp_deg)
        tmax = float(np.max(np.abs(theta_r_deg))) if np.size(theta_r_deg) else 0.0
        # the in-plane width in direction cosines shrinks as cos(theta_r) (rim: half a width)
        edge = min(math.radians(tmax) + 0.5 * w_in, 0.5 * math.pi)
        w_x = max(w_in * math.cos(edge), 1e-12)
        cx, cy = self._cell_size(lam_um)
        want_x = max(1, math.ceil(CELLS_ACROSS * cx / w_x)) if w_in > 0 else 1
        want_y = max(1, math.ceil(CELLS_ACROSS * cy / w_perp)) if w_perp > 0 else 1
        cap_x = max(1, MAX_PADDED_POINTS // t.nx_t)
        cap_y = max(1, MAX_PADDED_POINTS // t.ny_t)
        os = (min(want_x, cap_x), min(want_y, cap_y))
        note = None
        if os != (want_x, want_y):
            across = min(
                w_x / (cx / os[0]) if w_in > 0 else math.inf,
                w_perp / (cy / os[1]) if w_perp > 0 else math.inf,
            )
            note = (
                f"field of {t.nx_t * t.dx_um:g} x {t.ny_t * t.dy_um:g} um: the diffuse sum "
                f"resolves {across:.2g} cells across the receptor at {lam_um * 1e3:g} nm "
                f"(zero padding capped at {MAX_PADDED_POINTS} points; {CELLS_ACROSS} wanted)"
            )
        return os, note

    def rayleigh_factor(self, theta_i_deg: float, lam_nm: float | None = None) -> float:
        """``g = (4 pi Sq cos ti / lambda)^2`` of the map at ``lam_nm`` (default
        ``wavelength_nm``)."""
        lam = (self.wavelength_nm if lam_nm is None else float(lam_nm)) * 1e-3
        c = math.cos(math.radians(theta_i_deg))
        return (4.0 * math.pi * self._shared.stats.sq_um * c / lam) ** 2

    def _validity(self, theta_i_deg: float, lam_nm: float) -> str | None:
        """Why this model is outside its validity at the geometry (None when inside)."""
        return None

    def _route(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        source: Aperture,
        receptor: Aperture,
        lams_nm: Sequence[float],
    ) -> tuple[str, list[str]]:
        """Which model answers one geometry and the notes the user must see.

        ``"self"``; ``"kirchhoff"`` (Rayleigh-Rice outside its validity, or
        :meth:`_validity`); ``"rayleigh-rice"`` (Kirchhoff whose phase screen the map does
        not sample, while g is small); ``"facet"`` only where no wave model of this map can
        answer and ``g >= FACET_MIN_HANDOVER_G`` (the coherent beam is then below
        ``exp(-1)``): an aperture reaching beyond the map's Nyquist window, or a phase screen
        the map does not sample. Below that g the wave model answers what the map resolves
        and the note says what is missing.
        """
        notes: list[str] = []
        lam_lo = min(lams_nm)
        g = self.rayleigh_factor(theta_i_deg, lam_lo)
        why = self._validity(theta_i_deg, lam_lo)
        if why is not None:
            alt = self._alternative(theta_i_deg, lam_lo, g)
            if alt != "self":
                notes.append(f"{self.kind} {why}: {alt} used")
                return alt, notes
            notes.append(f"{self.kind} {why}: {self._why_self}")
        ra, rb = self._reach(source, receptor)
        tr = math.radians(float(theta_r_deg))
        t = self._shared.tiled
        step = max(t.dx_um, t.dy_um)
        for lam_nm in lams_nm:
            lam = lam_nm * 1e-3
            _, inside = self._box_for(theta_i_deg, lam, tr - ra, tr + ra, rb)
            if inside:
                continue
            what = (
                f"the map resolves directions within |sin ts - sin t_spec| <= lambda/(2 step) "
                f"= {lam / (2 * step):.3g} of specular at {lam_nm:g} nm (step {step:g} um); "
                "this aperture reaches further"
            )
            if g >= FACET_MIN_HANDOVER_G:
                notes.append(f"{what}: facet model used (g = {g:.3g})")
                return "facet", notes
            notes.append(
                f"{what}: {self.kind} answers with the diffuse light the map resolves "
                f"(g = {g:.3g} < {FACET_MIN_HANDOVER_G:g}: the facet model would miss the "
                "coherent beam)"
            )
            break
        return "self", notes

    def _alternative(self, theta_i_deg: float, lam_nm: float, g: float) -> str:
        """The model that answers outside this model's validity: another model's kind,
        ``"facet"``, or ``"self"`` when none does better (:attr:`_why_self` says why)."""
        return "facet"

    #: the note's ending when this model answers outside its validity (no better model)
    _why_self: str = "used all the same (no model of this map does better)"

    def _sibling(self, kind: str) -> PhysicalOpticsModel:
        """The other wave model of the same map, index, wavelength and options."""
        key = (kind, self.n, self.wavelength_nm, self.gloss_weighting, self.masking)
        with self._shared.lock:
            found = self._shared.siblings.get(key)
        if found is not None:
            return found
        if kind == "kirchhoff":
            from goniolab.optics.kirchhoff import KirchhoffModel

            cls: type[PhysicalOpticsModel] = KirchhoffModel
        else:
            from goniolab.optics.rayleigh_rice import RayleighRiceModel

            cls = RayleighRiceModel
        out = cls(
            n=self.n,
            wavelength_nm=self.wavelength_nm,
            gloss_weighting=self.gloss_weighting,
            masking=self.masking,
            backend=self.backend,
            progress=self.progress,
            shared=self._shared,
        )
        with self._shared.lock:
            self._shared.siblings[key] = out
        return out

    def provenance(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        source: Aperture,
        receptor: Aperture,
        *,
        wavelengths_nm: Sequence[float] | None = None,
    ) -> Provenance:
        """The model that computes this geometry's number and the notes that go with it."""
        lams = [self.wavelength_nm] if wavelengths_nm is None else list(wavelengths_nm)
        who, notes = self._route(theta_i_deg, theta_r_deg, source, receptor, lams)
        if who == "facet":
            return Provenance("facet", tuple(notes))
        if who != "self":
            sub = self._sibling(who).provenance(
                theta_i_deg, theta_r_deg, source, receptor, wavelengths_nm=wavelengths_nm
            )
            return Provenance(sub.model, tuple(notes) + sub.notes)
        if solid_angle_sr(receptor) > 0.0 or isinstance(receptor, Rect):
            _, cap = self._oversampling(max(lams) * 1e-3, receptor, np.array([theta_r_deg]))
            if cap is not None:
                notes.append(cap)
        energy = self._energy_note(theta_i_deg, lams)
        if energy is not None:
            notes.append(energy)
        return Provenance(self.kind, tuple(notes))

    def coverage(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        source: Aperture,
        receptor: Aperture,
        *,
        wavelengths_nm: Sequence[float] | None = None,
    ) -> str | None:
        """Why this geometry is read from the facet model (None when a wave model answers):
        the first note of :meth:`provenance` when its model is ``facet``."""
        p = self.provenance(
            theta_i_deg, theta_r_deg, source, receptor, wavelengths_nm=wavelengths_nm
        )
        if p.model != "facet":
            return None
        return p.notes[-1] if p.notes else "facet model"

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
        os: tuple[int, int] = (1, 1),
        shadow: bool = True,
    ) -> FloatArray:
        """Aperture sums of the diffuse cell powers ``p`` at each detector angle (times the
        diffuse shadowing :meth:`_diffuse_g2` of the detector's direction when ``shadow``)."""
        wox, woy = self._wo_axes(theta_i_deg, lam_um, box, os)
        tr = np.radians(theta_r_deg)
        if (
            isinstance(source, Cone)
            and isinstance(receptor, Cone)
            and self._split_source(theta_i_deg, source)
        ):
            return self._clipped_cone_sums(
                theta_i_deg, lam_um, wox, woy, p, tr, source, receptor, shadow
            )
        if isinstance(source, Cone) and isinstance(receptor, Cone):
            table, g0, g1, o_in, _ = cone_table(
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
        result: FloatArray = np.asarray(out, dtype=np.float64)
        if shadow:
            ti = math.radians(theta_i_deg)
            wi = np.array([math.sin(ti), 0.0, math.cos(ti)])
            d = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
            result = result * self._diffuse_g2(np.broadcast_to(wi, d.shape), d, lam_um)
        return result

    def _split_source(self, theta_i_deg: float, source: Aperture) -> bool:
        """Whether a source cone is summed over sub-cones (:meth:`_clipped_cone_sums`): when it
        reaches the horizon, and, when the diffuse sums carry Smith's G2, from where the facet
        model splits it too (:data:`goniolab.optics.facet_apertures.SPLIT_SOURCE_RINGS`), so that G2 is
        that of each source direction (at grazing incidence it varies several-fold across a
        6 deg cone)."""
        if not isinstance(source, Cone) or source.half_angle_deg == 0.0:
            return False
        if reaches_horizon(theta_i_deg, source):
            return True
        edge = min(e for e, _ in SPLIT_SOURCE_RINGS)
        return self._g2_per_source and theta_i_deg + source.half_angle_deg >= edge

    def _clipped_cone_sums(
        self,
        theta_i_deg: float,
        lam_um: float,
        wox: FloatArray,
        woy: FloatArray,
        p: FloatArray,
        tr: FloatArray,
        source: Cone,
        receptor: Cone,
        shadow: bool = True,
    ) -> FloatArray:
        """Diffuse cone sums over the source's sub-cones (:meth:`_split_source`), clipped at
        the horizon when the cone reaches it.

        The source is split as in the facet model (:func:`clipped_source_parts`: sub-cones
        of the part above the horizon, shares over the whole cone). The scattered diffuse
        pattern is that of the nominal incidence, carried over the source (zeroth order in
        the source direction): a sub-cone centred at polar angle ``theta_i + delta`` and
        azimuth ``phi`` turns the pattern about z by phi and shifts it by delta in plane, so
        it reads the nominal pattern through the receptor turned back,
        ``R_y(-delta) R_z(-phi) d``, with the sub-cone's own cap-overlap table and the
        shadowing of its own direction. (The coherent beam is summed exactly per source
        direction, :meth:`_coherent_sums`.)
        """
        a_d = math.radians(receptor.half_angle_deg)
        d = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
        fn = CK.cone_cells_numba if self.backend == "numba" else CK.cone_cells_numpy
        out = np.zeros(tr.size)
        ti = math.radians(theta_i_deg)
        for c, sub, share in clipped_source_parts(theta_i_deg, source):
            delta = math.acos(min(1.0, float(c[2]))) - ti
            phi = math.atan2(float(c[1]), float(c[0]))
            cp, sp = math.cos(phi), math.sin(phi)
            # R_z(-phi) d, then R_y(-delta): alpha = atan2(-x, z) decreases by delta
            x1, y1 = cp * d[:, 0] + sp * d[:, 1], -sp * d[:, 0] + cp * d[:, 1]
            cd, sd = math.cos(delta), math.sin(delta)
            dirs = np.stack([cd * x1 + sd * d[:, 2], y1, -sd * x1 + cd * d[:, 2]], axis=-1)
            table, g0, g1, o_in, _ = cone_table(math.radians(sub.half_angle_deg), a_d)
            part = fn(wox, woy, p, np.ascontiguousarray(dirs), table, g0, g1, o_in)
            g2 = self._diffuse_g2(np.broadcast_to(c, d.shape), d, lam_um) if shadow else 1.0
            out += share * np.asarray(part, dtype=np.float64) * g2
        return out

    # ------------------------------------------------------------------ the coherent beam
    def _coherent_reflectance(
        self, cos_s: FloatArray, theta_i_deg: float, c_nominal: float, n: complex | None = None
    ) -> FloatArray:
        """``R(theta_s) C(theta_s)`` of the coherent beam for source directions of cosine
        ``cos_s``: Fresnel per direction and the coherent factor carried from the nominal
        incidence as for Gaussian heights, ``C(theta_s) = C(ti)^((cos ts / cos ti)^2)``
        (``exp(-g)`` with ``g ~ cos^2``)."""
        ci = math.cos(math.radians(theta_i_deg))
        cs = np.clip(np.asarray(cos_s, dtype=np.float64), 0.0, 1.0)
        if c_nominal <= 0.0:
            return np.zeros_like(cs)
        c = np.exp(math.log(min(c_nominal, 1.0)) * (cs / ci) ** 2)
        out: FloatArray = np.where(cs > 0.0, fresnel(cs, self.n if n is None else n) * c, 0.0)
        return out

    def _coherent_sums(
        self,
        theta_i_deg: float,
        c_nominal: float,
        theta_r_deg: FloatArray,
        source: Aperture,
        receptor: Aperture,
        n: complex | None = None,
    ) -> FloatArray:
        """Flux fraction of the coherent specular beam reaching the receptor at each angle
        (of a surface of index ``n``, default the model's).

        Analytic, whatever the FFT cell: every source direction ``s`` sends
        ``R(s) C(s)`` (:meth:`_coherent_reflectance`) to its mirror direction, which the
        receptor collects when it lies inside it, so the reading is the integral over the
        source of that product, normalised by the source's solid angle (Mihalik eq. 15).
        Cones: the source's mirror cap in polar coordinates about its centre, Gauss-Legendre
        in the polar angle (split where the circle meets the receptor's rim) and, on each
        circle, over the arc inside the receptor (spherical law of cosines); source
        directions below the horizon send nothing. Rectangles: the product of the in-plane
        and out-of-plane intervals, Gauss-Legendre over their intersection with the mirror
        image, as the rectangle sums measure them (:mod:`._cell_kernels`).
        """
        tr = np.radians(np.asarray(theta_r_deg, dtype=np.float64))
        ti = math.radians(theta_i_deg)
        out = np.zeros(tr.size)
        if isinstance(source, Rect) and isinstance(receptor, Rect):
            a_s, b_s = math.radians(source.in_plane_deg), math.radians(source.perp_deg)
            a_r, b_r = math.radians(receptor.in_plane_deg), math.radians(receptor.perp_deg)
            xb, wb = np.polynomial.legendre.leggauss(8)
            xa, wa = np.polynomial.legendre.leggauss(12)
            # out of plane: the mirror image of beta is -beta, inside when |beta| <= b_r / 2
            if b_s == 0.0:
                bb, wbb, norm_b = np.zeros(1), np.ones(1), 1.0
            else:
                hb = 0.5 * min(b_s, b_r)
                bb, wbb = hb * xb, hb * wb * np.cos(hb * xb)
                norm_b = 2.0 * math.sin(0.5 * b_s)
            for k, a_c in enumerate(tr):
                # in plane: source offset a, mirror at ti + a, inside when |ti + a - tr| <= a_r/2
                if a_s == 0.0:
                    if abs(ti - a_c) > 0.5 * a_r + 1e-15:
                        continue
                    aa, waa, norm_a = np.zeros(1), np.ones(1), 1.0
                else:
                    lo = max(-0.5 * a_s, a_c - ti - 0.5 * a_r)
                    hi = min(0.5 * a_s, a_c - ti + 0.5 * a_r)
                    if hi <= lo:
                        continue
                    aa, waa = 0.5 * (hi + lo) + 0.5 * (hi - lo) * xa, 0.5 * (hi - lo) * wa
                    norm_a = a_s
                cos_s = np.cos(ti + aa)[:, None] * np.cos(bb)[None, :]
                f = self._coherent_reflectance(cos_s, theta_i_deg, c_nominal, n)
                out[k] = float(waa @ f @ wbb) / (norm_a * norm_b)
            return out
        assert isinstance(source, Cone) and isinstance(receptor, Cone)
        a_s, a_d = math.radians(source.half_angle_deg), math.radians(receptor.half_angle_deg)
        m0 = np.array([-math.sin(ti), 0.0, math.cos(ti)])  # the specular direction
        e1 = np.array([-math.cos(ti), 0.0, -math.sin(ti)])  # in plane, towards larger theta
        e2 = np.array([0.0, 1.0, 0.0])
        d = np.stack([-np.sin(tr), np.zeros_like(tr), np.cos(tr)], axis=-1)
        cg = np.clip(d @ m0, -1.0, 1.0)
        gam = np.arccos(cg)
        psi = np.arctan2(d @ e2, d @ e1)
        if a_s == 0.0:
            r0 = float(self._coherent_reflectance(np.array([m0[2]]), theta_i_deg, c_nominal, n)[0])
            return np.where(gam < a_d, r0, np.where(gam == a_d, 0.5 * r0, 0.0))
        xu, wu = np.polynomial.legendre.leggauss(12)
        xv, wv = np.polynomial.legendre.leggauss(16)
        omega_s = 2.0 * math.pi * (1.0 - math.cos(a_s))
        # the horizon cuts circles of polar radius u > pi/2 - ti about the mirror centre:
        # z = cos u cos ti - sin u sin ti cos v > 0 leaves |v| > acos(cos u cos ti / (sin u sin ti))
        u_h = 0.5 * math.pi - ti
        for k in range(tr.size):
            g = float(gam[k])
            if g >= a_s + a_d:
                continue
            kinks = (abs(g - a_d), g + a_d, u_h)
            cuts = sorted({0.0, a_s, *(c for c in kinks if 0.0 < c < a_s)})
            acc = 0.0
            for u0, u1 in itertools.pairwise(cuts):
                u = 0.5 * (u0 + u1) + 0.5 * (u1 - u0) * xu
                wuu = 0.5 * (u1 - u0) * wu * np.sin(u)
                su, cu = np.sin(u), np.cos(u)
                if g < 1e-12:
                    half = np.where(u < a_d, math.pi, 0.0)
                else:
                    cc = (math.cos(a_d) - cu * math.cos(g)) / (su * math.sin(g))
                    half = np.arccos(np.clip(cc, -1.0, 1.0))
                with np.errstate(divide="ignore", invalid="ignore"):
                    hh = np.where(
                        su * math.sin(ti) > 0, cu * math.cos(ti) / (su * math.sin(ti)), 2.0
                    )
                a_h = np.arccos(np.clip(hh, -1.0, 1.0))
                lo, hi = float(psi[k]) - half, float(psi[k]) + half
                for i_lo, i_hi in (
                    (np.maximum(lo, a_h - 2.0 * math.pi), np.minimum(hi, -a_h)),
                    (np.maximum(lo, a_h), np.minimum(hi, 2.0 * math.pi - a_h)),
                ):
                    hw = 0.5 * np.maximum(i_hi - i_lo, 0.0)
                    v = (0.5 * (i_lo + i_hi))[:, None] + hw[:, None] * xv[None, :]
                    z = cu[:, None] * m0[2] + su[:, None] * (np.cos(v) * e1[2])
                    f = self._coherent_reflectance(np.where(z > 0, z, 0.0), theta_i_deg, c_nominal)
                    acc += float(np.sum(wuu[:, None] * (hw[:, None] * wv[None, :]) * f))
            out[k] = acc / omega_s
        return out

    # ------------------------------------------------------------------ fractions
    def _fractions(
        self,
        theta_i_deg: float,
        theta_r_deg: FloatArray,
        source: Aperture,
        receptor: Aperture,
        lams_nm: Sequence[float],
    ) -> FloatArray:
        """Flux fractions ``(n_lambda, n_points)``: the coherent beam (analytic) plus the
        diffuse cells the map resolves, on a grid refined by zero padding until the
        receptor spans :data:`CELLS_ACROSS` cells."""
        ra, rb = self._reach(source, receptor)
        if isinstance(source, Cone) and self._split_source(theta_i_deg, source):
            # the turned-back receptors of the source's sub-cones reach one source half
            # angle further
            ra = rb = ra + math.radians(source.half_angle_deg)
        tr = np.radians(theta_r_deg)
        os, _ = self._oversampling(max(lams_nm) * 1e-3, receptor, theta_r_deg)
        boxes: list[_Box] = []
        for lam_nm in lams_nm:
            box, _ = self._box_for(
                theta_i_deg, lam_nm * 1e-3, float(tr.min()) - ra, float(tr.max()) + ra, rb, os
            )
            boxes.append(box)
        lams_um = [lam * 1e-3 for lam in lams_nm]
        powers, coh = self._cell_powers(theta_i_deg, lams_um, boxes, os)
        out = np.empty((len(lams_nm), theta_r_deg.size))
        for k, (lam, box, p, c) in enumerate(zip(lams_um, boxes, powers, coh, strict=True)):
            out[k] = self._sum_apertures(
                theta_i_deg, lam, box, p, theta_r_deg, source, receptor, os
            ) + self._coherent_sums(theta_i_deg, c, theta_r_deg, source, receptor)
        return out

    def _evaluate(
        self,
        theta_i_deg: float,
        theta_r_deg: FloatArray,
        source: Aperture,
        receptor: Aperture,
        lams_nm: Sequence[float],
    ) -> tuple[FloatArray, list[str]]:
        """Flux fractions ``(n_lambda, n_points)`` and, per point, the model that computed
        it (:meth:`_route`: this model, the other wave model, or the facet model)."""
        routes = [
            self._route(theta_i_deg, float(t), source, receptor, lams_nm)[0] for t in theta_r_deg
        ]
        out = np.empty((len(lams_nm), theta_r_deg.size))
        names = [self.kind] * theta_r_deg.size
        for who in sorted(set(routes)):
            idx = np.array([k for k, r in enumerate(routes) if r == who], dtype=np.int64)
            sel = theta_r_deg[idx]
            if who == "self":
                out[:, idx] = self._fractions(theta_i_deg, sel, source, receptor, lams_nm)
                continue
            if who == "facet":
                fm = self.facet_model
                if isinstance(source, Cone) and isinstance(receptor, Cone):
                    vals = fm.luminance_pct(theta_i_deg, sel, source=source, detector=receptor)
                    vals = np.asarray(vals, dtype=np.float64) / 100.0
                else:
                    vals = np.array(
                        [
                            fm.reflected_fraction(theta_i_deg, float(t), source, receptor)
                            for t in sel
                        ]
                    )
                out[:, idx] = vals[None, :]
                for k in idx:
                    names[int(k)] = "facet"
                continue
            sub, sub_names = self._sibling(who)._evaluate(
                theta_i_deg, sel, source, receptor, lams_nm
            )
            out[:, idx] = sub
            for k, name in zip(idx, sub_names, strict=True):
                names[int(k)] = name
        return out, names

    def _check_apertures(self, theta_i_deg: float, source: Aperture, receptor: Aperture) -> None:
        self._reach(source, receptor)
        if isinstance(source, Rect) and reaches_horizon(theta_i_deg, source):
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
        """Fraction of the flux from ``source`` (centred on theta_i) reaching ``receptor``
        (:meth:`provenance` names the model that computes it)."""
        ti = _check_theta_i(theta_i_deg)
        tr = float(theta_r_deg)
        if not (math.isfinite(tr) and -90.0 < tr < 90.0):
            raise ValueError(f"theta_r_deg must be in (-90, 90) deg, got {theta_r_deg!r}")
        self._check_apertures(ti, source, receptor)
        vals, _ = self._evaluate(ti, np.array([tr]), source, receptor, [self.wavelength_nm])
        return float(vals[0, 0])

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = GONIO_CONE,
        detector: Aperture = GONIO_CONE,
    ) -> FloatArray:
        """Goniometer reading in % of a mirror at the signed detector angles.

        One cell-power map serves every angle; :meth:`provenance` names the model of each.
        """
        ti = _check_theta_i(theta_i_deg)
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        if np.any(~np.isfinite(tr)) or np.any(np.abs(tr) >= 90.0):
            raise ValueError("theta_r_deg must be in (-90, 90) deg")
        self._check_apertures(ti, source, detector)
        flat = tr.ravel()
        if flat.size == 0:
            return np.empty(tr.shape)
        vals, _ = self._evaluate(ti, flat, source, detector, [self.wavelength_nm])
        result: FloatArray = 100.0 * vals[0].reshape(tr.shape)
        return result

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """In-plane BRDF (sr^-1), averaged over a :data:`POINT_BRDF_BOX_DEG` square receptor.

        A single map's wave-optics BRDF is speckle at the resolution ``lambda / field``; its
        average over the 1 deg x 1 deg box (a point source) is the BRDF an instrument with
        that aperture sees. The diffuse part is the mean cell BRDF ``P / (cell area)`` over
        the cells inside the box (sum of their powers over the sum of their areas in
        direction cosines, ``dOmega cos ts``), on a grid refined by zero padding until the
        box spans :data:`CELLS_ACROSS` cells at every angle; the coherent beam, when the box
        holds it, is spread over the box's exact projected solid angle
        (:func:`box_projected_solid_angle_sr`).
        """
        ti = _check_theta_i(theta_i_deg)
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        if np.any(~np.isfinite(tr)) or np.any(np.abs(tr) >= 90.0):
            raise ValueError("theta_r_deg must be in (-90, 90) deg")
        flat = tr.ravel()
        out, _ = self._brdf_inplane(ti, flat)
        result: FloatArray = out.reshape(tr.shape)
        return result

    def _brdf_inplane(self, ti: float, flat: FloatArray) -> tuple[FloatArray, list[str]]:
        src, box = Rect(0.0, 0.0), Rect(POINT_BRDF_BOX_DEG, POINT_BRDF_BOX_DEG)
        lams = [self.wavelength_nm]
        routes = [self._route(ti, float(t), src, box, lams)[0] for t in flat]
        out = np.zeros(flat.size)
        names = [self.kind] * flat.size
        for who in sorted(set(routes)):
            idx = np.array([k for k, r in enumerate(routes) if r == who], dtype=np.int64)
            sel = flat[idx]
            if who == "facet":
                out[idx] = self.facet_model.brdf_inplane(ti, sel)
                for k in idx:
                    names[int(k)] = "facet"
            elif who == "self":
                out[idx] = self._box_brdf(ti, sel, src, box)
            else:
                vals, sub = self._sibling(who)._brdf_inplane(ti, sel)
                out[idx] = vals
                for k, name in zip(idx, sub, strict=True):
                    names[int(k)] = name
        return out, names

    def _box_brdf(self, ti: float, tr_deg: FloatArray, src: Rect, box: Rect) -> FloatArray:
        lam = self.wavelength_nm * 1e-3
        ra, rb = self._reach(src, box)
        tr = np.radians(tr_deg)
        out = np.zeros(tr_deg.size)
        # one block of cells per stretch of angles (a wide curve near grazing needs a fine
        # grid only where the box is narrow: the padding is set per angle group)
        for k0 in range(0, tr_deg.size, 16):
            sel = slice(k0, min(k0 + 16, tr_deg.size))
            ts = tr_deg[sel]
            os, _ = self._oversampling(lam, box, ts)
            rs = tr[sel]
            b, _ = self._box_for(ti, lam, float(rs.min()) - ra, float(rs.max()) + ra, rb, os)
            powers, coh = self._cell_powers(ti, [lam], [b], os)
            _, _, _, ok = self._geometry(ti, lam, b, os)
            cx, cy = self._cell_size(lam, os)
            area = np.where(ok, cx * cy, 0.0)
            flux = self._sum_apertures(ti, lam, b, powers[0], ts, src, box, os)
            cells = self._sum_apertures(ti, lam, b, area, ts, src, box, os, shadow=False)
            diffuse = np.where(cells > 0, flux / np.where(cells > 0, cells, 1.0), 0.0)
            beam = self._coherent_sums(ti, coh[0], ts, src, box)
            proj = np.array([box_projected_solid_angle_sr(box, float(t)) for t in ts])
            out[sel] = diffuse + np.where(proj > 0, beam / np.where(proj > 0, proj, 1.0), 0.0)
        return out

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        """BRDF (sr^-1) towards ``(theta_r, phi_r)``: in the plane of incidence the
        :meth:`brdf_inplane` box average; out of it, the same average over a cone of the
        box's solid angle (1.128 deg) centred on the direction: the mean cell BRDF of the
        cells inside it, plus the coherent beam over the cone's projected solid angle when
        the cone holds the specular direction."""
        ti = _check_theta_i(theta_i_deg)
        phi = float(phi_r_deg) % 360.0
        tr = float(theta_r_deg)
        if not (math.isfinite(tr) and 0.0 <= tr < 90.0):
            raise ValueError(f"theta_r_deg must be in [0, 90) deg, got {theta_r_deg!r}")
        if phi in (0.0, 180.0):
            signed = tr if phi == 180.0 else -tr
            return float(self.brdf_inplane(ti, np.array([signed]))[0])
        box = Rect(POINT_BRDF_BOX_DEG, POINT_BRDF_BOX_DEG)
        cone = Cone(2.0 * math.degrees(math.acos(1.0 - solid_angle_sr(box) / (2.0 * math.pi))))
        t, p = math.radians(tr), math.radians(phi)
        wo = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
        lam = self.wavelength_nm * 1e-3
        a_d = math.radians(cone.half_angle_deg)
        os, _ = self._oversampling(lam, cone, np.array([tr]))
        cx, cy = self._cell_size(lam, os)
        sx = math.sin(math.radians(ti))
        reach = 2.0 * math.sin(0.5 * a_d) + 1e-9
        nx0, nx1, ny0, ny1 = self._nyquist(os)
        ix0 = math.floor((wo[0] - reach + sx) / cx) - 1
        ix1 = math.ceil((wo[0] + reach + sx) / cx) + 1
        iy0 = math.floor((wo[1] - reach) / cy) - 1
        iy1 = math.ceil((wo[1] + reach) / cy) + 1
        inside = ix0 >= nx0 and ix1 <= nx1 and iy0 >= ny0 and iy1 <= ny1
        g = self.rayleigh_factor(ti)
        if not inside and g >= FACET_MIN_HANDOVER_G:
            return self.facet_model.brdf_point(ti, tr, phi)
        b = _Box(max(ix0, nx0), min(ix1, nx1), max(iy0, ny0), min(iy1, ny1))
        if b.ix1 < b.ix0 or b.iy1 < b.iy0:
            return 0.0
        powers, coh = self._cell_powers(ti, [lam], [b], os)
        _, _, _, ok = self._geometry(ti, lam, b, os)
        wox, woy = self._wo_axes(ti, lam, b, os)
        table, g0, g1, o_in, _ = cone_table(0.0, a_d)
        fn = CK.cone_cells_numba if self.backend == "numba" else CK.cone_cells_numpy
        d = np.ascontiguousarray(wo[None, :])
        flux = float(fn(wox, woy, powers[0], d, table, g0, g1, o_in)[0])
        cells = float(fn(wox, woy, np.where(ok, cx * cy, 0.0), d, table, g0, g1, o_in)[0])
        wi = np.array([[sx, 0.0, math.cos(math.radians(ti))]])
        flux *= float(np.asarray(self._diffuse_g2(wi, d, lam)).ravel()[0])
        out = flux / cells if cells > 0.0 else 0.0
        m0 = np.array([-sx, 0.0, math.cos(math.radians(ti))])
        if float(np.clip(m0 @ wo, -1.0, 1.0)) >= math.cos(a_d):
            beam = float(fresnel(m0[2], self.n)) * coh[0]
            out += beam / (math.pi * math.sin(a_d) ** 2 * wo[2])
        return out

    def curve_provenance(
        self, theta_i_deg: float, theta_r_deg: ArrayLike, source: Aperture, receptor: Aperture
    ) -> list[Provenance]:
        """:meth:`provenance` of every angle of a curve (a point source and
        ``Rect(POINT_BRDF_BOX_DEG, POINT_BRDF_BOX_DEG)`` for :meth:`brdf_inplane`)."""
        flat = np.asarray(theta_r_deg, dtype=np.float64).ravel()
        return [self.provenance(theta_i_deg, float(t), source, receptor) for t in flat]

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        """ISO 2813 gloss in GU, weighted over wavelength by C x V(lambda) (or one wavelength).

        ``G = 100 sum_l w_l Phi_l / Phi_std`` with ``Phi_l`` the flux fraction from the ISO
        source into the ISO receptor at wavelength l and ``Phi_std`` that of the polished
        black glass (n = 1.567) through the same apertures, as the instrument is calibrated:
        every source direction with its own Fresnel reflectance (within 3e-5 of the nominal
        ``F(1.567, t)``), so that the standard reads 100 exactly. :meth:`gloss_provenance`
        names the model of each geometry.
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
            who, _ = self._route(key, key, ISO2813_SOURCE, rec, self._lams_for_checks())
            if who == "facet":
                out[key] = self.facet_model.gloss((key,))[key]
                continue
            if who != "self":
                out[key] = self._sibling(who).gloss((key,))[key]
                continue
            frac = self._fractions(key, np.array([float(key)]), ISO2813_SOURCE, rec, list(lams))
            ref = self._coherent_sums(
                key, 1.0, np.array([float(key)]), ISO2813_SOURCE, rec, ISO2813_BLACK_GLASS_N
            )[0]
            out[key] = 100.0 * float(np.sum(w * frac[:, 0]) / np.sum(w)) / ref
        return out

    def gloss_provenance(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, Provenance]:
        """Per ISO 2813 geometry: the model that computes it and the notes (validity
        checked over the wavelengths that carry the reading, :meth:`_lams_for_checks`)."""
        lams = self._lams_for_checks()
        return {
            int(t): self.provenance(
                int(t), int(t), ISO2813_SOURCE, ISO2813_RECEPTOR[int(t)],
                wavelengths_nm=lams,
            )
            for t in angles_deg
        }  # fmt: skip

    def gloss_fallbacks(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, str]:
        """Geometries whose gloss comes from the facet model, with the reason."""
        out: dict[int, str] = {}
        for t, p in self.gloss_provenance(angles_deg).items():
            if p.model == "facet":
                out[t] = p.notes[-1] if p.notes else "facet model"
        return out

    def albedo_tis(self, theta_i_deg: float) -> tuple[float, float, Provenance]:
        """Directional-hemispherical reflectance, total integrated scatter (ISO 13696
        sense: the diffusely scattered flux over the incident flux) and the model that
        computed them, at ``wavelength_nm`` for a collimated beam.

        The coherent beam ``R(ti) C`` plus the diffuse cells over the whole Nyquist window
        of the map, each with its shadowing (:meth:`_diffuse_g2`) and the energy scale
        (:meth:`_energy_scales`); light the map cannot resolve (beyond ``lambda / (2
        step)``) is not counted. Outside this model's validity the model it hands over to
        answers (:meth:`_route`); the facet model's albedo is its hemisphere sum, all of it
        diffuse.
        """
        ti = _check_theta_i(theta_i_deg)
        why = self._validity(ti, self.wavelength_nm)
        g = self.rayleigh_factor(ti)
        alt = "self" if why is None else self._alternative(ti, self.wavelength_nm, g)
        if alt != "self":
            note = f"{self.kind} {why}: {alt} used"
            if alt == "facet":
                a = float(self.facet_model.brdf_hemisphere(ti).albedo)
                return a, a, Provenance("facet", (note,))
            a, tis, sub = self._sibling(alt).albedo_tis(ti)
            return a, tis, Provenance(sub.model, (note, *sub.notes))
        nx0, nx1, ny0, ny1 = self._nyquist()
        box = _Box(nx0, nx1, ny0, ny1)
        lam = self.wavelength_nm * 1e-3
        powers, coh = self._cell_powers(ti, [lam], [box])
        p = powers[0]
        x, y, z, ok = self._geometry(ti, lam, box)
        t = math.radians(ti)
        wo = np.stack([x, y, np.where(ok, z, 1.0)], axis=-1).reshape(-1, 3)
        wi = np.broadcast_to(np.array([math.sin(t), 0.0, math.cos(t)]), wo.shape)
        g2 = self._diffuse_g2(wi, wo, lam)
        shadow = g2 if isinstance(g2, float) else np.asarray(g2).reshape(p.shape)
        tis = float(np.sum(np.where(ok, p * shadow, 0.0)))
        beam = float(fresnel(math.cos(t), self.n)) * coh[0]
        notes = [] if why is None else [f"{self.kind} {why}: {self._why_self}"]
        energy = self._energy_note(ti, [self.wavelength_nm])
        if energy is not None:
            notes.append(energy)
        return beam + tis, tis, Provenance(self.kind, tuple(notes))

    def albedo(self, theta_i_deg: float) -> float:
        """Directional albedo (:meth:`albedo_tis`)."""
        return self.albedo_tis(theta_i_deg)[0]


def box_projected_solid_angle_sr(box: Rect, theta_r_deg: float) -> float:
    """``int cos(theta) dOmega`` over a rectangle ``box`` centred on the signed in-plane
    angle ``theta_r_deg`` (its part above the horizon), in sr.

    In the aperture frame (:func:`goniolab.optics.apertures.sample_aperture`) a direction
    of in-plane offset ``a`` and out-of-plane angle ``b`` has ``cos theta = cos(tr + a)
    cos b`` and ``dOmega = cos b da db``, so the integral is
    ``[sin(min(|tr| + A/2, pi/2)) - sin(|tr| - A/2)] (B/2 + sin(B)/2)``.
    """
    t = abs(math.radians(theta_r_deg))
    ha, b = 0.5 * math.radians(box.in_plane_deg), math.radians(box.perp_deg)
    return (math.sin(min(t + ha, 0.5 * math.pi)) - math.sin(t - ha)) * (0.5 * b + 0.5 * math.sin(b))
