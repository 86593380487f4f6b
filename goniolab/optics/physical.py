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

- **the coherent beam is analytic** (:func:`goniolab.optics.coherent_beam.coherent_sums`): every
  source direction sends ``R(theta_s) C(theta_s)`` (its own Fresnel reflectance and
  coherent factor) to its mirror direction, and the receptor collects the part of the
  source's mirror image inside it, whatever the FFT cell size;
- **the diffuse part at a resolution that fits the aperture**: the tile's transform is
  zero-padded (the windowed patch's far field sampled on a finer grid of directions)
  until the receptor spans :data:`~goniolab.optics.cell_apertures.CELLS_ACROSS` cells (:meth:`~goniolab.optics.cell_apertures.CellApertures._oversampling`), so a 50 um
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
  coherent beam leaves (:mod:`goniolab.optics.energy_budget`; docs/PHYSICS.md, "Energy").

Wavelength and index per call (for the colour and spectral code): a model is built for
``(height map, n, wavelength_nm)``. ``model.with_optics(n=..., wavelength_nm=...)`` returns
a sibling model for another index (real or complex ``n + ik``) and wavelength that shares
the tiled map, its FFT caches and its fallback facet model, so a spectral loop costs no
re-levelling. ``gloss()`` weights over wavelength as ISO 2813 does (CIE illuminant C x
V(lambda), :func:`goniolab.optics.iso2813_weighting.iso2813_weights`) unless
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

import functools
import math
from collections.abc import Sequence
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics import _cell_kernels as CK
from goniolab.optics.apertures import (
    GONIO_CONE,
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Aperture,
    Cone,
    Rect,
    solid_angle_sr,
)
from goniolab.optics.cell_apertures import (
    CellApertures,
    CellBox,
    box_projected_solid_angle_sr,
)
from goniolab.optics.coherent_beam import coherent_sums
from goniolab.optics.energy_budget import ENERGY_CHECK_FROM_DEG, EnergyBudget
from goniolab.optics.facet import FacetModel
from goniolab.optics.facet_apertures import cone_table, reaches_horizon
from goniolab.optics.fresnel import fresnel
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.provenance import Provenance
from goniolab.optics.psd import DEFAULT_TAPER, DEFAULT_TILE
from goniolab.optics.shared_map import MapStats, SharedMap
from goniolab.optics.wave_tasks import GlossTasks, Progress, row_parts, run_reporting, task_progress

__all__ = [
    "ENERGY_CHECK_FROM_DEG",
    "FACET_MIN_HANDOVER_G",
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
#: Full width of the square receptor the point BRDF is averaged over (deg).
POINT_BRDF_BOX_DEG: float = 1.0
#: Largest incidence angle accepted (deg).
MAX_THETA_I_DEG: float = 89.0


def check_theta_i(theta_i_deg: float) -> float:
    v = float(theta_i_deg)
    if not (math.isfinite(v) and 0.0 <= v <= MAX_THETA_I_DEG):
        raise ValueError(
            f"theta_i_deg must be in [0, {MAX_THETA_I_DEG:g}] deg, got {theta_i_deg!r}"
        )
    return v


class PhysicalOpticsModel(EnergyBudget, CellApertures, GlossTasks):
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
    backend : {"numpy", "numba"}
        Aperture sums: numpy (default: no JIT start-up) or numba (:mod:`._cell_kernels_numba`).
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
        backend: Backend = "numpy",
        tile: int = DEFAULT_TILE,
        taper: float = DEFAULT_TAPER,
        progress: Progress | None = None,
        shared: SharedMap | None = None,
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
            shared = SharedMap(hm, int(tile), float(taper))
        self._shared = shared
        self.n = eta
        self.wavelength_nm = lam
        self.gloss_weighting: GlossWeighting = gloss_weighting
        self.masking = bool(masking)
        self.backend: Backend = backend
        self.progress = progress

    @property
    def progress(self) -> Progress | None:
        """``progress(done, total, what)`` or None; setting it also makes the facet work
        on the same map report there (:meth:`SharedMap.report_to`: a large map's slopes,
        walked block by block). Within a task of :func:`run_reporting`, that task's slot
        of the joint report."""
        if self._progress is None:
            return None
        fn = task_progress()
        return self._progress if fn is None else fn

    @progress.setter
    def progress(self, fn: Progress | None) -> None:
        self._progress = fn
        if fn is not None:
            self._shared.report_to(fn)

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
        boxes: Sequence[CellBox],
        os: tuple[int, int] = (1, 1),
    ) -> tuple[list[FloatArray], list[float]]:
        """Diffuse flux fraction per cell (rows iy, columns ix of each box, on the grid
        refined ``os`` times by zero padding), one array per wavelength, and the coherent
        factor ``C`` of the specular beam (``R(ti) C`` is its reflectance) per wavelength."""
        raise NotImplementedError

    def specular_reflectance(self, theta_i_deg: float) -> float:
        """Reflectance of the coherent specular beam at ``wavelength_nm``."""
        raise NotImplementedError

    # ------------------------------------------------------------------ routing and provenance
    def _lams_for_gloss(self) -> tuple[FloatArray, FloatArray]:
        if self.gloss_weighting == "single":
            return np.array([self.wavelength_nm]), np.array([1.0])
        from goniolab.optics.iso2813_weighting import iso2813_weights

        return iso2813_weights()

    def _lams_for_checks(self) -> list[float]:
        """The gloss wavelengths the validity checks look at: those carrying at least 1 % of
        the peak ISO 2813 weight (440-680 nm; 400 and 420 nm weigh 0.02 and 0.4 %)."""
        lams, w = self._lams_for_gloss()
        return [float(v) for v, wi in zip(lams, w, strict=True) if wi >= 0.01 * float(w.max())]

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
        receptor spans :data:`~goniolab.optics.cell_apertures.CELLS_ACROSS` cells."""
        ra, rb = self._reach(source, receptor)
        if isinstance(source, Cone) and self._split_source(theta_i_deg, source):
            # the turned-back receptors of the source's sub-cones reach one source half
            # angle further
            ra = rb = ra + math.radians(source.half_angle_deg)
        tr = np.radians(theta_r_deg)
        os, _ = self._oversampling(max(lams_nm) * 1e-3, receptor, theta_r_deg)
        boxes: list[CellBox] = []
        for lam_nm in lams_nm:
            box, _ = self._box_for(
                theta_i_deg, lam_nm * 1e-3, float(tr.min()) - ra, float(tr.max()) + ra, rb, os
            )
            boxes.append(box)
        lams_um = [lam * 1e-3 for lam in lams_nm]
        powers, coh = self._cell_powers(theta_i_deg, lams_um, boxes, os)
        out = np.empty((len(lams_nm), theta_r_deg.size))

        def sums(a: int, b: int) -> None:
            for k in range(a, b):
                out[k] = self._sum_apertures(
                    theta_i_deg, lams_um[k], boxes[k], powers[k], theta_r_deg, source, receptor, os
                ) + coherent_sums(theta_i_deg, coh[k], theta_r_deg, source, receptor, self.n)

        # the wavelengths in two parts (tasks: each wavelength's sums on one thread)
        run_reporting([functools.partial(sums, a, b) for a, b in row_parts(0, len(lams_um), 1, 2)])
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
        return float(self.reflected_fractions(theta_i_deg, theta_r_deg, source, receptor))

    def reflected_fractions(
        self, theta_i_deg: float, theta_r_deg: ArrayLike, source: Aperture, receptor: Aperture
    ) -> FloatArray:
        """:meth:`reflected_fraction` at the signed detector angles (any shape): one
        cell-power map serves every angle (a curve, the E430 haze pairs and DOI)."""
        ti = check_theta_i(theta_i_deg)
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        if np.any(~np.isfinite(tr)) or np.any(np.abs(tr) >= 90.0):
            raise ValueError(f"theta_r_deg must be in (-90, 90) deg, got {theta_r_deg!r}")
        self._check_apertures(ti, source, receptor)  # (no angle: an empty result)
        vals, _ = self._evaluate(ti, tr.ravel(), source, receptor, [self.wavelength_nm])
        return vals[0].reshape(tr.shape)

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = GONIO_CONE,
        detector: Aperture = GONIO_CONE,
    ) -> FloatArray:
        """Goniometer reading in % of a mirror at the signed detector angles (one
        cell-power map for all; :meth:`provenance` names the model of each)."""
        out: FloatArray = 100.0 * self.reflected_fractions(
            theta_i_deg, theta_r_deg, source, detector
        )
        return out

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        """In-plane BRDF (sr^-1), averaged over a :data:`POINT_BRDF_BOX_DEG` square receptor.

        A single map's wave-optics BRDF is speckle at the resolution ``lambda / field``; its
        average over the 1 deg x 1 deg box (a point source) is the BRDF an instrument with
        that aperture sees. The diffuse part is the mean cell BRDF ``P / (cell area)`` over
        the cells inside the box (sum of their powers over the sum of their areas in
        direction cosines, ``dOmega cos ts``), on a grid refined by zero padding until the
        box spans :data:`~goniolab.optics.cell_apertures.CELLS_ACROSS` cells at every angle; the coherent beam, when the box
        holds it, is spread over the box's exact projected solid angle
        (:func:`box_projected_solid_angle_sr`).
        """
        ti = check_theta_i(theta_i_deg)
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
            beam = coherent_sums(ti, coh[0], ts, src, box, self.n)
            proj = np.array([box_projected_solid_angle_sr(box, float(t)) for t in ts])
            out[sel] = diffuse + np.where(proj > 0, beam / np.where(proj > 0, proj, 1.0), 0.0)
        return out

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        """BRDF (sr^-1) towards ``(theta_r, phi_r)``: in the plane of incidence the
        :meth:`brdf_inplane` box average; out of it, the same average over a cone of the
        box's solid angle (1.128 deg) centred on the direction: the mean cell BRDF of the
        cells inside it, plus the coherent beam over the cone's projected solid angle when
        the cone holds the specular direction."""
        ti = check_theta_i(theta_i_deg)
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
        b = CellBox(max(ix0, nx0), min(ix1, nx1), max(iy0, ny0), min(iy1, ny1))
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
        ti = check_theta_i(theta_i_deg)
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
        box = CellBox(nx0, nx1, ny0, ny1)
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
