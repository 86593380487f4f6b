"""The predicted luminance is the Y of the predicted spectrum (issue 21, item 6 and "Left").

Before: the luminance prediction took the coat term from the model at the lab's single
``[sample] n = 1.55`` while the predicted spectrum (hence the predicted colour) took it from
the sample paint's Cauchy clear coat (n(550 nm) = 1.505): at the specular peak of
sample:white (theta_i 45, theta_r 45) the luminance read 3.09 % and the spectrum's Y 2.77 %
(Fresnel at 45 deg: R(1.55) / R(1.505) = 1.117). The truth here is colour-science's own
ASTM E308 integration of the predicted spectrum the run stores, not goniolab's weights.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from goniolab.config import configs_dir, load_lab_config
from goniolab.optics.fresnel import fresnel

ANGLES = [-20.0, 0.0, 20.0, 40.0, 43.0, 45.0, 47.0, 50.0, 60.0, 70.0]


def _y_colour_science(wl: list[float], spectrum_pct: tuple[float, ...], settings: object) -> float:
    import colour

    s = settings.validated()  # type: ignore[attr-defined]
    sd = colour.SpectralDistribution(dict(zip(wl, np.asarray(spectrum_pct) / 100.0, strict=True)))
    xyz = colour.sd_to_XYZ(
        sd,
        colour.MSDS_CMFS[s.observer],
        colour.SDS_ILLUMINANTS[s.illuminant],
        method=s.method,
    )
    return float(xyz[1])


@pytest.mark.parametrize("sample", ["white", "solid-red"])
@pytest.mark.parametrize("illuminant", ["D65", "A"])
def test_predicted_luminance_is_y_of_the_stored_predicted_spectrum(
    sample: str, illuminant: str
) -> None:
    import dataclasses

    from goniolab.model_cache import model_for
    from goniolab.scan.colour import PointColour
    from goniolab.scan.prediction import Predictor

    cfg = load_lab_config(configs_dir() / "lab-sim.toml")
    model = model_for(f"sample:{sample}", n=cfg.sample.n, model="facet")
    pred = Predictor.from_config(model, cfg)
    pc = pred.point_colour or PointColour()
    pred = dataclasses.replace(
        pred,
        point_colour=dataclasses.replace(
            pc, settings=dataclasses.replace(pc.settings, illuminant=illuminant)
        ),
    )
    assert pred.spectral is not None and pred.point_colour is not None
    lum = pred.predict_sync(45.0, ANGLES)
    colours = pred.predict_colour_sync(45.0, ANGLES)
    assert colours is not None
    wl = [float(w) for w in pred.spectral.wavelengths_nm]
    y = [_y_colour_science(wl, c.spectrum_pct, pred.point_colour.settings) for c in colours]
    assert lum == pytest.approx(y, abs=1e-6)
    # the peak is the peak (not a vanishing number compared with itself)
    assert float(lum[ANGLES.index(45.0)]) > 2.0


def test_coat_term_at_the_peak_is_the_paint_coat_fresnel_and_the_run_is_told() -> None:
    # independent truth: at the peak of a smooth-ish coat the coat term scales with the
    # Fresnel reflectance of the coat index it uses; the paint coat is Cauchy A 1.49,
    # B 0.0045 um^2 (configs/samples.toml), not the lab's n = 1.55
    from goniolab.model_cache import model_for
    from goniolab.scan.prediction import Predictor

    cfg = load_lab_config(configs_dir() / "lab-sim.toml")
    model = model_for("sample:white", n=1.55, model="facet")
    pred = Predictor.from_config(model, cfg)
    assert pred.spectral is not None
    coat = pred.spectral.surface_fraction(45.0, [45.0])[0]  # per wavelength, fraction
    lab_n = (
        float(
            model.luminance_pct(45.0, np.array([45.0]), source=pred.source, detector=pred.detector)[
                0
            ]
        )
        / 100
    )
    c45 = math.cos(math.radians(45.0))
    for i, wl in enumerate(pred.spectral.wavelengths_nm):
        n = 1.49 + 0.0045 / (wl / 1000.0) ** 2
        want = lab_n * float(fresnel(c45, n)) / float(fresnel(c45, 1.55))
        assert coat[i] == pytest.approx(want, rel=2e-3)
    note = pred.coat_index_note()
    assert note is not None and "1.505" in note and "1.55" in note
    assert note in pred.provenance(45.0, [45.0])["warnings"]
    # a sample with no paint table keeps the lab's n: no note
    plain = Predictor.from_config(model_for("sample:wittmann-3", n=1.55, model="facet"), cfg)
    assert plain.coat_index_note() is None


def test_a_run_stores_a_predicted_luminance_equal_to_y_of_its_stored_spectrum(
    tmp_path: Path,
) -> None:
    # the same through a scan of the in-process twin: what the store holds (the predicted
    # luminance per geometry, the predicted spectrum per geometry) agrees at the peak too
    import contextlib
    import io
    import json

    from goniolab.cli import main
    from goniolab.store import RunStore

    store = tmp_path / "s.sqlite"
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = main(["scan", "--config", str(configs_dir() / "lab-sim.toml"), "--sample",
                     "sample:white", "--model", "facet", "--theta-r", "0,30,44,45,46,60",
                     "--repeats", "1", "--time-scale", "0", "--json", "--store", str(store)])  # fmt: skip
    assert code == 0
    run_id = int(json.loads(out.getvalue())["run_id"])
    with RunStore(store, readonly=True) as s:
        lum = s.predictions(run_id)
        colours = s.predicted_colours(run_id)
    assert sorted(lum) == sorted(colours) == list(range(6))
    from goniolab.scan.colour import PointColour

    settings = PointColour.from_config(load_lab_config(configs_dir() / "lab-sim.toml")).settings
    wl = [float(w) for w in np.arange(380.0, 781.0, 10.0)]
    for i in range(6):
        spectrum = colours[i].spectrum_pct
        assert spectrum is not None and len(spectrum) == len(wl)
        assert lum[i] == pytest.approx(_y_colour_science(wl, spectrum, settings), abs=1e-6)
    assert lum[3] > 2.0  # 45 deg: the peak
