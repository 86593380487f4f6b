"""The model in the loop: predictions for each plan geometry, computed off the event loop.

The prediction for plan point (theta_i, theta_r) is what the goniospectrophotometer of
Wittmann et al. (2021, sec. 2.3) would read from the modelled surface: relative luminance in
% of a mirror, ``100 x`` the flux reaching the detector cone (6 deg opening), averaged over
the lamp's source cone (6 deg divergence) -- ``ReflectanceModel.luminance_pct`` with the
configured cones (docs/PHYSICS.md, "What the instruments see"; Mihalik eqs. 15-17 for the
source-and-receptor integration).

Evaluating the model is numeric work (an aperture quadrature per geometry), so it runs in a
worker thread through :func:`asyncio.to_thread`; the runner and any UI keep their loop free.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.colour.spectral import SpectralPredictor
from goniolab.config import LabConfig
from goniolab.optics.apertures import Cone
from goniolab.optics.models import ReflectanceModel
from goniolab.scan.colour import PointColour
from goniolab.store import PredictedColour

__all__ = ["Predictor"]


@dataclass(frozen=True, slots=True)
class Predictor:
    """Evaluate ``model.luminance_pct`` for a plan's geometries in a worker thread.

    Parameters
    ----------
    model
        Any :class:`~goniolab.optics.models.ReflectanceModel` (the lab's facet model of
        the sample under the instruments, or one built from ``--sample``).
    source
        Lamp divergence cone (config ``[goniometer] source_cone_deg``).
    detector
        Detector opening cone (config ``[spectro] detector_cone_deg``).
    chunk
        Geometries per worker call: predictions are published chunk by chunk so that a
        live plot fills while the scan runs.
    """

    model: ReflectanceModel
    source: Cone
    detector: Cone
    chunk: int = 8
    #: The spectral prediction (coat surface + paint) giving each geometry's predicted
    #: colour; ``None``: luminance only.
    spectral: SpectralPredictor | None = None
    #: How spectra become colour (illuminant, observer, scale) for the predicted colour.
    point_colour: PointColour | None = None
    #: predicted spectra per geometry (theta_i, theta_r): the luminance and the colour of a
    #: run's geometries come from one evaluation
    _spectra: dict[tuple[float, float], NDArray[np.float64]] = field(
        default_factory=dict, repr=False, compare=False
    )

    @classmethod
    def from_config(cls, model: ReflectanceModel, config: LabConfig) -> Predictor:
        """Predictions through a lab config's lamp cone (``[goniometer] source_cone_deg``)
        and detector cone (``[spectro] detector_cone_deg``), with the predicted colour of
        every geometry (the sample's paint, the config's ``[colour]``)."""
        from goniolab.model_cache import spectral_for

        return cls(
            model,
            Cone(config.goniometer.source_cone_deg),
            Cone(config.spectro.detector_cone_deg),
            spectral=spectral_for(
                model,
                source_cone_deg=config.goniometer.source_cone_deg,
                detector_cone_deg=config.spectro.detector_cone_deg,
            ),
            point_colour=PointColour.from_config(config),
        )

    def predict_sync(self, theta_i_deg: float, theta_r_deg: Sequence[float]) -> NDArray[np.float64]:
        """Predicted luminance in % of a mirror at ``theta_r_deg`` (blocking; for threads).

        With a spectral prediction, the luminance *is* the Y of the predicted spectrum (coat
        surface + paint body, ``SpectralPredictor.spectrum_pct``) under the run's
        ``[colour]`` illuminant and observer: ``Y = sum_l W_Y(l) S(l) / 100`` with the
        ASTM E308 weights (Y = 100 for R = 1, so Y in %), the spectrum the predicted colour
        is computed from. Luminance and colour cannot disagree by construction (issue 21:
        white at theta_r 0 predicted 0.000 % while its spectrum held the body; at the peak
        the coat term read 3.09 % through the lab's n = 1.55 while the spectrum's coat,
        the sample's Cauchy clear coat of n(550 nm) = 1.505, gave 2.77 %: two coat
        indices; :meth:`provenance` says when they differ). Without one, the model's own
        ``luminance_pct``."""
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        if self.spectral is not None:
            spectra = self.spectra_pct(theta_i_deg, tr.ravel())
            lum: NDArray[np.float64] = (spectra @ self._y_weights()) / 100.0
            return lum.reshape(tr.shape)
        out = self.model.luminance_pct(theta_i_deg, tr, source=self.source, detector=self.detector)
        return np.asarray(out, dtype=np.float64).reshape(tr.shape)

    def spectra_pct(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> NDArray[np.float64]:
        """The predicted spectra (% of the mirror, ``(n_geometries, n_wavelengths)``) of
        :attr:`spectral`, each geometry evaluated once per predictor (blocking)."""
        assert self.spectral is not None
        tr = np.atleast_1d(np.asarray(theta_r_deg, dtype=np.float64))
        ti = float(theta_i_deg)
        missing = sorted({float(t) for t in tr if (ti, float(t)) not in self._spectra})
        if missing:
            new = self.spectral.spectrum_pct(ti, missing)
            for t, row in zip(missing, new, strict=True):
                self._spectra[(ti, t)] = np.asarray(row, dtype=np.float64)
        return np.stack([self._spectra[(ti, float(t))] for t in tr])

    def _y_weights(self) -> NDArray[np.float64]:
        """The Y row of the ASTM E308 weights of the run's ``[colour]`` settings."""
        from goniolab.colour.spectra import xyz_weights

        assert self.spectral is not None
        settings = (self.point_colour or PointColour()).settings
        return np.asarray(xyz_weights(self.spectral.wavelengths_nm, settings)[1], dtype=np.float64)

    async def predict(
        self, theta_i_deg: float, theta_r_deg: Sequence[float]
    ) -> NDArray[np.float64]:
        """Same as :meth:`predict_sync`, computed in a worker thread (never on the loop)."""
        return await asyncio.to_thread(self.predict_sync, theta_i_deg, list(theta_r_deg))

    def predict_colour_sync(
        self, theta_i_deg: float, theta_r_deg: Sequence[float]
    ) -> list[PredictedColour] | None:
        """Predicted L*a*b* and spectrum per geometry (blocking), ``None`` without spectra."""
        if self.spectral is None:
            return None
        from goniolab.colour.spectra import spectra_to_xyz, xyz_to_colour

        pc = self.point_colour or PointColour(detector_cone_deg=self.detector.full_angle_deg)
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        spectra = self.spectra_pct(theta_i_deg, tr)
        factors = np.stack([pc.factors(s, float(t)) for s, t in zip(spectra, tr, strict=True)])
        lab = xyz_to_colour(
            spectra_to_xyz(self.spectral.wavelengths_nm, factors, pc.settings), pc.settings
        )[:, 3:6]
        return [
            PredictedColour(float(c[0]), float(c[1]), float(c[2]), tuple(float(v) for v in s))
            for c, s in zip(lab, spectra, strict=True)
        ]

    async def predict_colour(
        self, theta_i_deg: float, theta_r_deg: Sequence[float]
    ) -> list[PredictedColour] | None:
        """Same as :meth:`predict_colour_sync`, in a worker thread."""
        if self.spectral is None:
            return None
        return await asyncio.to_thread(self.predict_colour_sync, theta_i_deg, list(theta_r_deg))

    def describe(self) -> dict[str, object]:
        """Model parameters stored with a run (model class, its ``model_for`` name, apertures,
        and the spectral prediction's paint and colour settings)."""
        out: dict[str, object] = {
            "model": type(self.model).__name__,
            "model_name": model_name(self.model),
            "source_cone_deg": self.source.full_angle_deg,
            "detector_cone_deg": self.detector.full_angle_deg,
            **_model_params(self.model),
        }
        if self.spectral is not None:
            out["spectral"] = self.spectral.describe()
        if self.point_colour is not None:
            out["colour"] = self.point_colour.describe()
        return out

    def provenance(self, theta_i_deg: float, theta_r_deg: Sequence[float]) -> dict[str, Any]:
        """Which model computes the prediction at each geometry of a scan, and the notes
        the user must see (issue 20: a number never carries another model's name):
        ``{"computed_by": {model: [theta_r, ...]}, "warnings": [...]}``
        (:func:`goniolab.optics.provenance.provenance_of`; blocking, call from a thread)."""
        from goniolab.optics.provenance import provenance_of

        computed_by: dict[str, list[float]] = {}
        warnings: list[str] = []
        for tr in sorted({float(t) for t in theta_r_deg}):
            p = provenance_of(self.model, theta_i_deg, tr, self.source, self.detector)
            computed_by.setdefault(p.model, []).append(tr)
            warnings.extend(n for n in p.notes if n not in warnings)
        note = self.coat_index_note()
        if note is not None:
            warnings.append(note)
        if self.spectral is not None and self.spectral.surface is not None:
            # a predicted colour whose coat surface has no wavelength in it says so
            from goniolab.colour.spectral import surface_colour_note, wavelength_free

            warnings.extend(
                surface_colour_note(m, trs) for m, trs in computed_by.items() if wavelength_free(m)
            )
        if self.spectral is not None:
            # computed in a thread before the run starts (session.prepare): the Y weights
            # (colour-science's import and integration, ~2.6 s the first time) are then
            # ready, and the first reading does not race ahead of its prediction
            self._y_weights()
        return {"computed_by": computed_by, "warnings": warnings}

    def coat_index_note(self) -> str | None:
        """What the user must know when the coat index of the spectral prediction is not the
        model's ``n`` (``[sample] n``): a sample whose paint table names its own clear coat
        (``configs/samples.toml``) is predicted with that coat's n(lambda), unless the
        surface model cannot be rebuilt per index (then ``n`` stays, the paint's coat enters
        the body term only). ``None`` when they agree within 0.001."""
        if self.spectral is None or self.spectral.surface is None:
            return None
        n_model = getattr(self.model, "n", None)
        if n_model is None:
            return None
        n_coat = complex(self.spectral.paint.coat.index(np.array([550.0]))[0])
        n_lab = complex(n_model)
        if abs(n_coat - n_lab) <= 1e-3:
            return None
        if self.spectral.surface.name.endswith("(fixed n)"):
            return (
                f"the coat surface is predicted with [sample] n = {n_lab.real:.4g} at every "
                f"wavelength ({self.spectral.surface.name} is not rebuilt per index); the "
                f"paint's clear coat (n(550 nm) = {n_coat.real:.4g}) enters the body only"
            )
        return (
            f"the coat surface is predicted with the sample paint's clear coat n(lambda) "
            f"(n(550 nm) = {n_coat.real:.4g}), not [sample] n = {n_lab.real:.4g}"
        )


def model_name(model: ReflectanceModel) -> str:
    """The :func:`goniolab.model_cache.model_for` name of ``model`` (``facet``, ``kirchhoff``,
    ``rayleigh-rice``, ``auto``), else its class name."""
    from goniolab.model_registry import model_names
    from goniolab.optics.facet import FacetModel

    kind = getattr(model, "kind", None)
    if isinstance(kind, str) and kind in model_names():
        return kind
    return "facet" if isinstance(model, FacetModel) else type(model).__name__


def _model_params(model: ReflectanceModel) -> dict[str, object]:
    """Public scalar attributes of a model (refractive index, weighting, alpha, source)."""
    out: dict[str, object] = {}
    for name in ("n", "weighting", "masking", "kind", "alpha", "wavelength_nm"):
        v = getattr(model, name, None)
        if isinstance(v, complex):
            out[name] = [v.real, v.imag]
        elif isinstance(v, str | int | float | bool):
            out[name] = v
    surface = getattr(model, "surface", None)
    src = getattr(surface, "source", None)
    if isinstance(src, str):
        out["surface_source"] = src
    return out
