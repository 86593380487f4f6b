"""A store with a multi-angle run whose readings and predictions carry spectra (issue 25)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from goniolab.colour.multiangle import E2194_ASPECULAR_DEG, theta_r_for_aspecular
from goniolab.scan.colour import PointColour
from goniolab.scan.plans import BrdfPlan
from goniolab.store import PredictedColour, RunStore

WL = np.arange(400.0, 701.0, 10.0)  # a BYK-mac-like 400-700 nm grid
PRED_WL = np.linspace(380.0, 780.0, 41)
CONE_DEG = 6.0
CONFIG = {"colour": {"illuminant": "D65", "observer": "10", "scale": "diffuser"},
          "spectro": {"detector_cone_deg": CONE_DEG}}  # fmt: skip


def factor_spectrum(wl: np.ndarray, aspecular: float, shift: float = 0.0) -> np.ndarray:
    """A silver-ish multi-angle reflectance factor: bright near specular, with a blue tilt."""
    level = 0.05 + 1.5 * np.exp(-aspecular / 20.0)
    return level * (1.0 + 0.1 * (wl - 550.0) / 150.0 + shift * np.exp(-(((wl - 620) / 30) ** 2)))


def make_spectral_store(path: Path, *, shift: float = 0.0, with_predictions: bool = True,
                        repeats: int = 2, scale: str = "diffuser",
                        model: dict | None = None) -> Path:  # fmt: skip
    """Run 1: the six E2194 angles at 45 deg, ``repeats`` readings each, spectra stored in
    % of the mirror (the runner's form); predictions = the same factors with ``shift``;
    ``model``: the run's model column (the predictor's provenance)."""
    tr = tuple(sorted((theta_r_for_aspecular(a) for a in E2194_ASPECULAR_DEG), reverse=True))
    plan = BrdfPlan(45.0, tr, repeats=repeats, sample="sample:x")
    pc = PointColour(detector_cone_deg=CONE_DEG)
    with RunStore(path) as s:
        config = {**CONFIG, "colour": {**CONFIG["colour"], "scale": scale}}
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config=config, sample="sample:x",
                           model=model or {}, version="t")  # fmt: skip
        preds = []
        for k, t in enumerate(tr):
            a = 45.0 - t
            scale = float(pc.factors([100.0], t)[0])  # factor of a 100 % reading
            for r in range(repeats):
                factors = factor_spectrum(WL, a) * (1.0 + 0.002 * r)
                values = factors / scale * 100.0
                c = pc.measured(WL, values, t)
                s.add_point(rid, index=k, repeat=r, theta_i_deg=45.0, theta_r_deg=t,
                            measured_theta_i_deg=45.0, measured_theta_r_deg=t,
                            luminance_pct=1.0, raw={"wavelengths_nm": list(WL),
                            "values": list(values), "mirror_pct": None},
                            timestamp=1.0 + k, colour=c.as_dict())  # fmt: skip
            if with_predictions:
                pf = factor_spectrum(PRED_WL, a, shift)
                lab = pc.settings and _lab(PRED_WL, pf)
                preds.append((k, PredictedColour(*lab, tuple(pf / scale * 100.0))))
        s.add_predictions(rid, [(k, 45.0, t, 1.0) for k, t in enumerate(tr)])
        if preds:
            s.add_predicted_colours(rid, preds)
    return path


def _lab(wl: np.ndarray, factors: np.ndarray) -> tuple[float, float, float]:
    from goniolab.colour.spectra import spectrum_to_colour

    c = spectrum_to_colour(wl, factors)
    return (c.L, c.a, c.b)
