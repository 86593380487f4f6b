"""Which scattering model a geometry needs, and the ``auto`` model that applies the rule.

Regime rule (per geometry, not per surface)
-------------------------------------------
For incidence ``theta`` at wavelength ``lambda`` and a map of rms height ``Sq``, rms gradient
``Sdq``, correlation length ``l`` and step ``dx``, the specular Rayleigh factor is

.. math:: g = (4 \\pi\\, Sq \\cos\\theta / \\lambda)^2

(the coherent specular beam is ``F exp(-g)``). ``auto`` picks, in this order:

1. ``rayleigh-rice`` when ``g <= 0.15`` and ``Sdq <= 0.15``: first-order perturbation holds
   (its second-order terms are ~ g/2 of the diffuse part, a few % of it; the coherent beam
   carries ``> 86 %``). Also when the correlation length is below the wavelength and
   ``g <= 1`` (tangent planes are then meaningless, heights still small).
2. ``facet`` when ``g >= 20``: the coherent beam is below ``exp(-20)`` and diffraction
   widens the geometric lobe by ~``1/g <= 5 %`` (Kirchhoff -> facet, tested).
3. ``kirchhoff`` otherwise, provided the map samples the phase screen: neighbouring
   points must differ in phase by well under pi, ``(4 pi cos theta / lambda) (Sdq/sqrt 2)
   dx <= 1.2`` rad rms (3 sigma near pi; the facet-limit test runs at 0.9); on a coarser
   map ``rayleigh-rice`` while ``g < 1`` and ``Sdq <= 0.3`` (the facet model has no
   coherent beam), else ``facet`` (stated).

Because ``g`` scales with ``cos^2 theta``, one coating can need three models: for a Gaussian
map of Sq 177 nm, l 5 um at 550 nm, ``g`` is 14.4 at 20 deg (Kirchhoff), 4.1 at 60 deg
(Kirchhoff) and 0.12 at 85 deg (Rayleigh-Rice), where the facet model reads a G85 of a
third of the physical one. Within the chosen wave model, a field too small for the
aperture is sampled finer (zero padding) and the coherent beam is summed analytically;
directions beyond ``lambda / (2 dx)`` of specular are read from the facet model only when
``g >= 1`` (:mod:`goniolab.optics.physical`); every reading names the model that computed
it (:meth:`AutoModel.provenance`).

:class:`AutoModel` implements ``ReflectanceModel``; the models it delegates to share the
map. It keeps the facet model's masking on by default (Smith G2 from the measured
slopes), which keeps the facet directional albedo at or below the Fresnel reflectance at
grazing incidence.

References
----------
.. [1] PHYSICS.md, "Where the facet model stops: physical optics" and "Regimes of the three
   scattering models".
.. [2] J. C. Stover, "Optical Scattering", 3rd ed., SPIE 2012, ch. 2 and 5 (TIS, the
   smooth-surface limit of Rayleigh-Rice).
.. [3] P. Beckmann, A. Spizzichino, "The Scattering of Electromagnetic Waves from Rough
   Surfaces", 1963 (the Kirchhoff series and its geometric-optics limit).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.optics.apertures import (
    GONIO_CONE,
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Aperture,
)
from goniolab.optics.facet import FacetModel
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.physical import (
    FACET_MIN_HANDOVER_G,
    MAX_PHASE_STEP_RAD,
    RR_VALID_SDQ,
    GlossWeighting,
    MapStats,
    PhysicalOpticsModel,
    Progress,
)
from goniolab.optics.provenance import Provenance
from goniolab.optics.psd import DEFAULT_TAPER, DEFAULT_TILE
from goniolab.optics.shared_map import SharedMap

if TYPE_CHECKING:
    from goniolab.optics.kirchhoff import KirchhoffModel
    from goniolab.optics.rayleigh_rice import RayleighRiceModel

__all__ = [
    "FACET_MIN_G",
    "RR_MAX_G",
    "RR_MAX_SDQ",
    "AutoModel",
    "Choice",
    "ModelName",
    "choose_model",
    "rayleigh_g",
]

#: The models the rule chooses from (each a name of :mod:`goniolab.model_registry`, which
#: lists the names ``--model`` accepts; tests/test_model_registry.py keeps them registered).
ModelName = Literal["facet", "kirchhoff", "rayleigh-rice"]
#: Rayleigh-Rice when g is at most this ...
RR_MAX_G: float = 0.15
#: ... and the rms gradient at most this.
RR_MAX_SDQ: float = 0.15
#: Facet model from this g on.
FACET_MIN_G: float = 20.0

FloatArray = NDArray[np.float64]


def rayleigh_g(sq_um: float, theta_deg: float, wavelength_nm: float) -> float:
    """``g = (4 pi Sq cos theta / lambda)^2`` of the specular beam."""
    lam = wavelength_nm * 1e-3
    return (4.0 * math.pi * sq_um * math.cos(math.radians(theta_deg)) / lam) ** 2


@dataclass(frozen=True)
class Choice:
    """The model picked for one geometry, and why (the rule of the module docstring)."""

    model: ModelName
    g: float
    reason: str

    def as_dict(self) -> dict[str, Any]:
        return {"model": self.model, "g": self.g, "reason": self.reason}


def choose_model(stats: MapStats, theta_deg: float, wavelength_nm: float) -> Choice:
    """Apply the regime rule (module docstring) at incidence ``theta_deg``."""
    g = rayleigh_g(stats.sq_um, theta_deg, wavelength_nm)
    lam_um = wavelength_nm * 1e-3
    if g <= RR_MAX_G and stats.sdq <= RR_MAX_SDQ:
        return Choice("rayleigh-rice", g, f"g = {g:.3g} <= {RR_MAX_G:g}, Sdq {stats.sdq:.3g}")
    if g <= 1.0 and stats.corr_length_below(lam_um):  # g first: the length costs FFTs
        return Choice(
            "rayleigh-rice",
            g,
            f"correlation length {stats.corr_length_um:.3g} um < lambda, g = {g:.3g} <= 1",
        )
    if g >= FACET_MIN_G:
        return Choice("facet", g, f"g = {g:.3g} >= {FACET_MIN_G:g}: geometric optics")
    phase = (
        (4.0 * math.pi * math.cos(math.radians(theta_deg)) / lam_um)
        * (stats.sdq / math.sqrt(2.0))
        * stats.step_um
    )
    if phase > MAX_PHASE_STEP_RAD:
        unsampled = (
            f"g = {g:.3g} needs Kirchhoff, but the map step {stats.step_um:g} um samples the "
            f"phase screen at {phase:.2g} rad rms per point (> {MAX_PHASE_STEP_RAD:g})"
        )
        if g < FACET_MIN_HANDOVER_G and stats.sdq <= RR_VALID_SDQ:
            # no hand-over to the facet model while the coherent beam carries > exp(-1)
            return Choice("rayleigh-rice", g, f"{unsampled}: Rayleigh-Rice used (g < 1)")
        return Choice("facet", g, f"{unsampled}: facet model used")
    return Choice("kirchhoff", g, f"{RR_MAX_G:g} < g = {g:.3g} < {FACET_MIN_G:g}")


class AutoModel:
    """The ``auto`` model: per geometry, the model :func:`choose_model` names.

    The rule reads only the map's statistics (:attr:`stats`: Sq, Sdq, correlation length
    and step, numpy only), so building the model and choosing cost no model: the facet
    model (given as a factory) and the wave models (:mod:`goniolab.optics.kirchhoff`,
    :mod:`goniolab.optics.rayleigh_rice`, their FFTs) are built the first time a geometry
    needs them. A map that needs only the facet model imports no wave-optics module, and
    one that needs only the wave models never forms the facet slopes, unless a geometry
    hands over to the facet model.

    Parameters
    ----------
    hm : HeightMap
        The map.
    facet : FacetModel or callable
        The facet model of the same map (its index is used everywhere), or a function
        that builds it (called once, on first use); ``n`` is then required.
    n : complex, optional
        Refractive index when ``facet`` is a factory (default: ``facet.n``).
    wavelength_nm, gloss_weighting, masking, tile, taper, progress
        As in :class:`~goniolab.optics.physical.PhysicalOpticsModel`; the rule is applied at
        ``wavelength_nm`` (550 nm by default, near the peak of the ISO 2813 weighting).
    backend : {"numpy", "numba"}
        Aperture-sum kernels of the wave models (numpy by default: no JIT start-up).
    """

    kind = "auto"

    def __init__(
        self,
        hm: HeightMap,
        facet: FacetModel | Callable[[], FacetModel],
        *,
        n: complex | float | None = None,
        wavelength_nm: float = 550.0,
        gloss_weighting: GlossWeighting = "iso2813",
        masking: bool = True,
        tile: int = DEFAULT_TILE,
        taper: float = DEFAULT_TAPER,
        progress: Progress | None = None,
        backend: Literal["numpy", "numba"] = "numpy",
    ) -> None:
        if isinstance(facet, FacetModel):
            built = facet
            self._facet_factory: Callable[[], FacetModel] = lambda: built
            self.n = facet.n
        else:
            if n is None:
                raise TypeError("AutoModel needs n when the facet model is given as a factory")
            self._facet_factory = facet
            self.n = complex(n)
        self.masking = bool(masking)
        self.wavelength_nm = float(wavelength_nm)
        self._shared = SharedMap(hm, tile, taper)
        self._shared.adopt_facet_factory(self.n, self.masking, lambda: self.facet)
        self._opts: dict[str, Any] = {
            "n": self.n,
            "wavelength_nm": wavelength_nm,
            "gloss_weighting": gloss_weighting,
            "masking": masking,
            "progress": progress,
            "shared": self._shared,
            "backend": backend,
        }

    @cached_property
    def facet(self) -> FacetModel:
        """The facet model (built on first use); its walks over a large map report to
        :attr:`progress` (:meth:`SharedMap.adopt_facet`)."""
        facet = self._facet_factory()
        self._shared.adopt_facet(facet)
        return facet

    @cached_property
    def kirchhoff(self) -> KirchhoffModel:
        """The Kirchhoff model of the map (its module imported on first use)."""
        from goniolab.optics.kirchhoff import KirchhoffModel

        return KirchhoffModel(**self._opts)

    @cached_property
    def rayleigh_rice(self) -> RayleighRiceModel:
        """The Rayleigh-Rice model of the map (its module imported on first use)."""
        from goniolab.optics.rayleigh_rice import RayleighRiceModel

        return RayleighRiceModel(**self._opts)

    @property
    def surface(self) -> Any:
        """The facet set of the map (:attr:`facet`'s surface)."""
        return self.facet.surface

    @property
    def source(self) -> str:
        """Where the map came from."""
        return self._shared.tiled.source

    @property
    def progress(self) -> Progress | None:
        """``progress(done, total, what)`` of the wave models' long transforms (set here, it
        reaches the models built so far and those built later)."""
        out: Progress | None = self._opts["progress"]
        return out

    @progress.setter
    def progress(self, value: Progress | None) -> None:
        self._opts["progress"] = value
        if value is not None:  # the facet model's walks too
            self._shared.report_to(value)
        for name in ("kirchhoff", "rayleigh_rice"):
            m = self.__dict__.get(name)
            if m is not None:
                m.progress = value

    def __repr__(self) -> str:
        return f"AutoModel({self.source!r}, n={self.n}, wavelength_nm={self.wavelength_nm:g})"

    @property
    def stats(self) -> MapStats:
        """The map's roughness, which the rule reads (numpy only, no model built)."""
        return self._shared.stats

    def choice(self, theta_deg: float) -> Choice:
        """The model for incidence ``theta_deg``."""
        return choose_model(self.stats, float(theta_deg), self.wavelength_nm)

    def model_at(self, theta_deg: float) -> FacetModel | PhysicalOpticsModel:
        name = self.choice(theta_deg).model
        if name == "facet":
            return self.facet
        return self.kirchhoff if name == "kirchhoff" else self.rayleigh_rice

    def explain(
        self,
        theta_i_deg: float,
        theta_r_deg: Sequence[float] = (),
        source: Aperture = GONIO_CONE,
        receptor: Aperture = GONIO_CONE,
    ) -> dict[str, Any]:
        """The choice at theta_i and the detector angles that fall back to the facet model."""
        ch = self.choice(theta_i_deg)
        out: dict[str, Any] = ch.as_dict()
        fb, models, notes = {}, {}, {}
        for t in theta_r_deg:
            p = self.provenance(theta_i_deg, float(t), source, receptor)
            models[f"{float(t):g}"] = p.model
            if p.notes:
                notes[f"{float(t):g}"] = list(p.notes)
            if p.model == "facet" and ch.model != "facet":
                fb[f"{float(t):g}"] = p.notes[-1] if p.notes else "facet model"
        if models:
            out["models"] = models
        if notes:
            out["warnings"] = notes
        if fb:
            out["fallback_facet"] = fb
        return out

    def explain_gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[str, Any]:
        """Per ISO geometry: the model that computed it (``model``), the rule's choice
        (``rule``), g, the reason, the notes (``warnings``) and any facet hand-over."""
        out: dict[str, Any] = {}
        prov = self.gloss_provenance(angles_deg)
        for t in angles_deg:
            ch = self.choice(t)
            d = ch.as_dict()
            p = prov[int(t)]
            d["rule"], d["model"] = ch.model, p.model
            if p.notes:
                d["warnings"] = list(p.notes)
            if p.model == "facet" and ch.model != "facet":
                d["fallback_facet"] = p.notes[-1] if p.notes else "facet model"
            out[str(int(t))] = d
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
        """The model that computes this geometry (the rule's choice, then that model's own
        hand-overs) and the notes."""
        m = self.model_at(theta_i_deg)
        if isinstance(m, PhysicalOpticsModel):
            return m.provenance(
                theta_i_deg, theta_r_deg, source, receptor, wavelengths_nm=wavelengths_nm
            )
        ch = self.choice(theta_i_deg)
        notes: tuple[str, ...] = ()
        if ch.g < FACET_MIN_HANDOVER_G:
            notes = (f"facet model at g = {ch.g:.3g} < 1: no coherent beam ({ch.reason})",)
        return Provenance("facet", notes)

    def gloss_provenance(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, Provenance]:
        """:meth:`provenance` of each ISO 2813 geometry over the gloss wavelengths."""
        out: dict[int, Provenance] = {}
        for t in angles_deg:
            m = self.model_at(int(t))
            if isinstance(m, PhysicalOpticsModel):
                out[int(t)] = m.gloss_provenance((int(t),))[int(t)]
            else:
                out[int(t)] = self.provenance(
                    int(t), int(t), ISO2813_SOURCE, ISO2813_RECEPTOR[int(t)]
                )
        return out

    def curve_provenance(
        self, theta_i_deg: float, theta_r_deg: ArrayLike, source: Aperture, receptor: Aperture
    ) -> list[Provenance]:
        """:meth:`provenance` of every angle of a curve."""
        flat = np.asarray(theta_r_deg, dtype=np.float64).ravel()
        return [self.provenance(theta_i_deg, float(t), source, receptor) for t in flat]

    def albedo_tis(self, theta_i_deg: float) -> tuple[float, float, Provenance]:
        """Directional albedo, TIS and provenance of the model the rule picks at theta_i
        (:meth:`PhysicalOpticsModel.albedo_tis`; the facet model: its hemisphere sum)."""
        m = self.model_at(theta_i_deg)
        if isinstance(m, PhysicalOpticsModel):
            return m.albedo_tis(theta_i_deg)
        a = float(m.brdf_hemisphere(theta_i_deg).albedo)
        return a, a, self.provenance(theta_i_deg, theta_i_deg, GONIO_CONE, GONIO_CONE)

    # ------------------------------------------------------------------ ReflectanceModel
    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        return self.model_at(theta_i_deg).brdf_point(theta_i_deg, theta_r_deg, phi_r_deg)

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> FloatArray:
        return self.model_at(theta_i_deg).brdf_inplane(theta_i_deg, theta_r_deg)

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = GONIO_CONE,
        detector: Aperture = GONIO_CONE,
    ) -> FloatArray:
        return self.model_at(theta_i_deg).luminance_pct(
            theta_i_deg, theta_r_deg, source=source, detector=detector
        )

    def reflected_fraction(
        self, theta_i_deg: float, theta_r_deg: float, source: Aperture, receptor: Aperture
    ) -> float:
        return self.model_at(theta_i_deg).reflected_fraction(
            theta_i_deg, theta_r_deg, source, receptor
        )

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        out: dict[int, float] = {}
        for t in angles_deg:
            key = int(t)
            if key not in ISO2813_RECEPTOR:
                raise ValueError(
                    f"no ISO 2813 geometry at {t} deg; known: {sorted(ISO2813_RECEPTOR)}"
                )
            out[key] = self.model_at(key).gloss((key,))[key]
        return out
