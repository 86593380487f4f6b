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
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

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

        The coat surface's reading (``model.luminance_pct``) plus, with a spectral
        prediction, the paint body's: ``sum_l W_Y(l) f_body(l)`` (the Y row of the
        ASTM E308 weights of the ``[colour]`` settings, Y = 100 for R = 1, so Y in %), the same body
        the predicted colour includes (issue 21: white at theta_r 0 predicted 0.000 %
        against 0.23 % measured)."""
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        out = self.model.luminance_pct(theta_i_deg, tr, source=self.source, detector=self.detector)
        lum = np.asarray(out, dtype=np.float64).reshape(tr.shape)
        if self.spectral is not None:
            from goniolab.colour.spectra import xyz_weights

            settings = (self.point_colour or PointColour()).settings
            y = np.asarray(xyz_weights(self.spectral.wavelengths_nm, settings)[1])
            body = np.asarray(self.spectral.paint_fraction(theta_i_deg, tr), dtype=np.float64)
            lum = lum + (body @ y).reshape(tr.shape)  # W_Y @ fraction is Y in %
        return lum

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
        spectra = self.spectral.spectrum_pct(theta_i_deg, tr)
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
        return {"computed_by": computed_by, "warnings": warnings}


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
