"""The colour fit (issue 11, item 5): synthetic multi-angle data from a paint with known
parameters + noise; the fit must recover them within its reported uncertainties, and those
uncertainties must match the scatter of repeated fits."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.colour.multiangle import E2194_ASPECULAR_DEG, theta_r_for_aspecular
from goniolab.colour.paint import Paint, paint_from_dict, paint_to_dict
from goniolab.colour.paint_fit import (
    FitError,
    _Model,
    default_parameters,
    fit_paint,
    paint_with,
    parameter_values,
)
from goniolab.colour.spectra import ColourSettings, delta_e, standard_grid_nm
from goniolab.colour.spectral import SpectralPredictor
from goniolab.model_cache import paint_for

WL = standard_grid_nm(20.0)  # 21 wavelengths: fast
TR = np.array([theta_r_for_aspecular(a) for a in E2194_ASPECULAR_DEG])
SILVER_TRUTH = {
    "body.ks_scale": 1.6,
    "metallic.area_fraction": 0.45,
    "metallic.spread_deg": 9.0,
    "coat.n": 1.53,
}


def _truth_lab(paint0: Paint, truth: dict[str, float], tr: np.ndarray = TR) -> np.ndarray:
    """L*a*b* of the paint with the true parameters (D65, 10 deg, diffuser scale)."""
    names = list(truth)
    painted = paint_with(paint0, parameter_values(paint0, names), truth)
    sp = SpectralPredictor(None, painted, wavelengths_nm=WL)
    model = _Model(sp, 45.0, tr, ColourSettings().validated(), "diffuser", None, None)
    return model.lab(painted)


def test_lab_of_the_fit_model_is_colour_sciences() -> None:
    # the fit's written-out L*a*b* against colour.XYZ_to_Lab through spectra.xyz_to_colour
    from goniolab.colour.spectra import spectra_to_xyz, xyz_to_colour
    from goniolab.colour.spectral import reflectance_factor_scale

    paint = paint_for("sample:silver-metallic")
    sp = SpectralPredictor(None, paint, wavelengths_nm=WL)
    mine = _Model(sp, 45.0, TR, ColourSettings().validated(), "diffuser", None, None).lab(paint)
    factors = sp.spectrum_pct(45.0, TR) / 100.0 * reflectance_factor_scale(TR, 6.0)[:, None]
    ref = xyz_to_colour(spectra_to_xyz(WL, factors))[:, 3:6]
    assert mine == pytest.approx(ref, abs=1e-9)


def test_fit_recovers_a_metallic_paint_within_its_uncertainties() -> None:
    paint0 = paint_for("sample:silver-metallic")
    assert default_parameters(paint0) == list(SILVER_TRUTH)
    lab = _truth_lab(paint0, SILVER_TRUTH)
    noisy = lab + np.random.default_rng(0).normal(0.0, 0.3, lab.shape)
    fit = fit_paint(SpectralPredictor(None, paint0, wavelengths_nm=WL), 45.0, TR, noisy)
    for p in fit.parameters:
        truth = SILVER_TRUTH[p.name]
        assert not p.at_bound and math.isfinite(p.sigma) and p.sigma > 0, p
        assert abs(p.value - truth) < 4.0 * p.sigma, p
    # and the uncertainties are informative, not huge
    assert fit.sigma("metallic.area_fraction") < 0.05
    assert fit.sigma("metallic.spread_deg") < 1.5
    assert fit.sigma("coat.n") < 0.1
    assert fit.sigma("body.ks_scale") < 0.2 * fit.value("body.ks_scale")
    assert fit.start_mean_dE2000 > 5.0  # the start is far off
    assert fit.mean_dE2000 < 0.6  # the fit is down to the noise (0.3 per L*, a*, b*)
    assert fit.dE2000 == pytest.approx(delta_e(fit.fitted_lab, noisy, "CIE 2000"))
    assert fit.dof == 3 * TR.size - 4


def test_noise_free_pearl_is_recovered_exactly() -> None:
    paint0 = paint_for("sample:pearl")
    truth = {"body.ks_scale": 0.7, "pearl.area_fraction": 0.4, "pearl.spread_deg": 10.0,
             "pearl.film_nm": 150.0, "coat.n": 1.52}  # fmt: skip
    assert default_parameters(paint0) == list(truth)
    lab = _truth_lab(paint0, truth)
    fit = fit_paint(SpectralPredictor(None, paint0, wavelengths_nm=WL), 45.0, TR, lab)
    for name, v in truth.items():
        assert fit.value(name) == pytest.approx(v, rel=1e-4), name
    assert fit.mean_dE2000 < 1e-3


@pytest.mark.slow
def test_uncertainties_match_the_scatter_of_repeated_fits() -> None:
    # 24 noise draws of a solid red: the reported 1-sigma equals the spread of the estimates
    paint0 = paint_for("sample:solid-red")
    truth = {"body.ks_scale": 1.5, "coat.n": 1.55}
    lab = _truth_lab(paint0, truth)
    est, sig = [], []
    for seed in range(24):
        noisy = lab + np.random.default_rng(seed).normal(0.0, 0.3, lab.shape)
        fit = fit_paint(SpectralPredictor(None, paint0, wavelengths_nm=WL), 45.0, TR, noisy)
        est.append([fit.value(n) for n in truth])
        sig.append([fit.sigma(n) for n in truth])
    ratio = np.std(est, axis=0, ddof=1) / np.mean(sig, axis=0)
    assert np.all((ratio > 0.6) & (ratio < 1.6)), ratio
    assert np.mean(est, axis=0) == pytest.approx(list(truth.values()), rel=0.02)


def test_k_and_s_of_an_opaque_body_are_not_determined_separately() -> None:
    # an opaque layer shows K/S only (Durikovic eq. 4): K and S scaled together leave the
    # colour unchanged, so their uncertainties are infinite, not a made-up number
    paint0 = paint_for("sample:solid-red")
    lab = _truth_lab(paint0, {"body.ks_scale": 1.3})
    fit = fit_paint(
        SpectralPredictor(None, paint0, wavelengths_nm=WL),
        45.0,
        TR,
        lab + np.random.default_rng(3).normal(0.0, 0.2, lab.shape),
        parameters=["body.ks_scale", "body.s_scale"],
    )
    assert all(not math.isfinite(p.sigma) for p in fit.parameters)
    assert fit.mean_dE2000 < 0.5
    ks = fit.value("body.ks_scale") / fit.value("body.s_scale")
    assert ks == pytest.approx(1.3, rel=0.05)


def test_bad_fit_requests_are_one_clear_error() -> None:
    paint0 = paint_for("sample:silver-metallic")
    sp = SpectralPredictor(None, paint0, wavelengths_nm=WL)
    lab = _truth_lab(paint0, {"coat.n": 1.5})
    with pytest.raises(FitError, match="4 parameters needs at least 2"):
        fit_paint(sp, 45.0, TR[:1], lab[:1])
    with pytest.raises(FitError, match="NaN or infinite"):
        fit_paint(sp, 45.0, TR, np.where(np.arange(18).reshape(6, 3) == 4, np.nan, lab))
    with pytest.raises(FitError, match=r"unknown fit parameter 'body\.k'"):
        fit_paint(sp, 45.0, TR, lab, parameters=["body.k"])
    with pytest.raises(FitError, match=r"the paint has no \[pearl\]"):
        fit_paint(sp, 45.0, TR, lab, parameters=["pearl.film_nm"])
    with pytest.raises(FitError, match="5 measured colours for 6 geometries"):
        fit_paint(sp, 45.0, TR, lab[:5])


def test_paint_to_dict_round_trips() -> None:
    for name in ("silver-metallic", "pearl", "solid-red", "white"):
        paint = paint_for(f"sample:{name}")
        doc, tables = paint_to_dict(paint)
        assert tables == {}
        assert paint_from_dict(doc) == paint


# ------------------------------------------------------------------ the command
def _store_with_run(path: Path, lab: np.ndarray, tr: np.ndarray, sample: str) -> Path:
    from goniolab.scan.plans import BrdfPlan
    from goniolab.store import RunStore

    plan = BrdfPlan(45.0, tuple(float(t) for t in tr), repeats=2, sample=sample)
    rng = np.random.default_rng(7)
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample=sample,
                           model={"source_cone_deg": 6.0, "detector_cone_deg": 6.0,
                                  "colour": {"illuminant": "D65", "observer": "10",
                                             "scale": "diffuser"}},
                           version="t")  # fmt: skip
        for k, t in enumerate(tr):
            for r in range(2):
                L, a, b = lab[k] + rng.normal(0.0, 0.3, 3)
                c = {"X": 0.0, "Y": 0.0, "Z": 0.0, "L": L, "a": a, "b": b,
                     "C": math.hypot(a, b), "h_deg": 0.0}  # fmt: skip
                s.add_point(rid, index=k, repeat=r, theta_i_deg=45.0, theta_r_deg=float(t),
                            measured_theta_i_deg=45.0, measured_theta_r_deg=float(t),
                            luminance_pct=1.0, raw={}, timestamp=1.0 + k, colour=c)  # fmt: skip
        s.set_status(rid, "done")
        # run 2: no colour; run 3: a gloss log
        bare = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample=sample,
                            model={}, version="t")  # fmt: skip
        s.add_point(bare, index=0, repeat=0, theta_i_deg=45.0, theta_r_deg=float(tr[0]),
                    measured_theta_i_deg=45.0, measured_theta_r_deg=float(tr[0]),
                    luminance_pct=1.0, raw={}, timestamp=1.0, colour_error="NaN at 400 nm")  # fmt: skip
        s.create_run(kind="gloss", plan={"kind": "gloss", "angles_deg": [60]}, config={},
                     sample=sample, model={}, version="t")  # fmt: skip
    return path


def test_fit_colour_command_recovers_the_paint_and_saves_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paint0 = paint_for("sample:silver-metallic")
    lab = _truth_lab(paint0, SILVER_TRUTH)
    store = _store_with_run(tmp_path / "s.sqlite", lab, TR, "sample:silver-metallic")
    out = tmp_path / "fitted.toml"
    args = ["fit", "colour", "1", "--store", str(store), "--no-surface", "--step-nm", "20"]
    assert main([*args, "--save", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [g["aspecular_deg"] for g in doc["geometries"]] == [-15, 15, 25, 45, 75, 110]
    for p in doc["parameters"]:
        assert p["determined"] and abs(p["value"] - SILVER_TRUTH[p["name"]]) < 4 * p["sigma"]
    assert doc["mean_dE2000"] < 0.6 < 5.0 < doc["start_mean_dE2000"]
    # it says what it minimised, and dE2000 before and after (issue 25)
    assert doc["minimised"] == "sum of squared CIE 1976 L*a*b* differences (dE*ab^2)"
    assert doc["dE2000_worse_after_fit"] is False
    assert doc["dof"] == 18 - 4
    # the saved paint is what --paint reads, with the fitted values
    saved = paint_from_dict(tomllib.loads(out.read_text()))
    fitted = {p["name"]: p["value"] for p in doc["parameters"]}
    assert saved.metallic is not None
    assert saved.metallic.area_fraction == pytest.approx(fitted["metallic.area_fraction"])
    assert float(saved.coat.index(589.3).real) == pytest.approx(fitted["coat.n"])
    # the table prints one row per geometry and the mean
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "metallic.spread_deg" in text and "mean dE2000" in text


def test_fit_colour_command_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    paint0 = paint_for("sample:silver-metallic")
    lab = _truth_lab(paint0, SILVER_TRUTH)
    store = _store_with_run(tmp_path / "s.sqlite", lab, TR, "sample:silver-metallic")
    base = ["fit", "colour", "--store", str(store), "--no-surface", "--step-nm", "20"]
    cases = [
        (["2"], "run 2 has no measured colour"),
        (["3"], "run 3 is a gloss run"),
        (["9"], "9"),
        (["1", "--min-aspecular", "100"], "needs at least 2"),
        (["1", "--params", "pearl.film_nm"], "the paint has no [pearl]"),
        (["1", "--save", str(tmp_path / "x.txt")], "written as TOML"),
    ]
    for extra, message in cases:
        assert main([*base[:2], *extra, *base[2:]]) == 2, extra
        err = capsys.readouterr().err
        assert err.startswith("goniolab: error:") and message in err, (extra, err)
        assert err.count("\n") == 1
    flat = _store_with_run(tmp_path / "f.sqlite", lab, TR, "sample:flat")
    assert main(["fit", "colour", "1", "--store", str(flat), "--no-surface"]) == 2
    assert "has no paint" in capsys.readouterr().err


def test_de2000_metric_is_colour_sciences_de2000_for_small_differences() -> None:
    from goniolab.colour.paint_fit import de2000_metric

    rng = np.random.default_rng(5)
    lab = np.array([[36.8, 45.6, 25.5], [50.0, 0.0, 0.0], [40.0, 0.2, -0.3], [60.0, -20.0, -40.0]])
    r = de2000_metric(lab)
    for _ in range(5):
        d = rng.normal(0.0, 0.05, lab.shape)
        mine = np.linalg.norm(np.einsum("gij,gj->gi", r, d), axis=-1)
        assert mine == pytest.approx(delta_e(lab, lab + d, "CIE 2000"), rel=0.01)


def test_the_de2000_fit_lowers_the_de2000_of_a_model_error() -> None:
    # data the model cannot match (another hue): minimising dE2000 gives a smaller sum of
    # dE2000^2 than minimising dE*ab, and no larger than the start
    paint0 = paint_for("sample:solid-red")
    lab = _truth_lab(paint0, {"body.ks_scale": 1.4}) + np.array([0.5, -2.0, 3.0])
    sp = SpectralPredictor(None, paint0, wavelengths_nm=WL)
    by_lab = fit_paint(sp, 45.0, TR, lab)
    by_de = fit_paint(sp, 45.0, TR, lab, metric="de2000")
    assert np.sum(by_de.dE2000**2) < np.sum(by_lab.dE2000**2)
    assert np.sum(by_de.dE2000**2) < np.sum(by_de.start_dE2000**2)
    with pytest.raises(FitError, match="unknown fit metric 'cmc'"):
        fit_paint(sp, 45.0, TR, lab, metric="cmc")  # type: ignore[arg-type]


def test_fit_with_a_glossy_coat_surface_in_the_model() -> None:
    # a rough coat (Beckmann, alpha 0.1: its gloss reaches the 15 deg aspecular reading):
    # the surface term, tabulated over n once, matches the predictor's own evaluation, and
    # the fit of n through it recovers the truth made with the predictor itself
    from goniolab.colour.paint_fit import _SurfaceInN
    from goniolab.colour.spectral import SurfaceFactory
    from goniolab.optics.analytic import AnalyticModel

    rough = SurfaceFactory(lambda n, wl: AnalyticModel("beckmann", alpha=0.1, n=n), name="b")
    paint0 = paint_for("sample:solid-red")
    truth = {"body.ks_scale": 1.3, "coat.n": 1.56}
    painted = paint_with(paint0, parameter_values(paint0, list(truth)), truth)
    sp_true = SpectralPredictor(rough, painted, wavelengths_nm=WL)
    table = _SurfaceInN(sp_true, 45.0, TR, 1.35, 1.85)
    direct = sp_true.surface_fraction(45.0, TR)
    # the gloss is larger than the paint at -15 and 15 deg aspecular
    assert np.all(direct[:2].mean(axis=1) > sp_true.paint_fraction(45.0, TR)[:2].mean(axis=1))
    assert table.at(painted.coat_n(WL)) == pytest.approx(direct, rel=2e-3, abs=1e-9)
    model = _Model(sp_true, 45.0, TR, ColourSettings().validated(), "diffuser", direct, None)
    lab = model.lab(painted) + np.random.default_rng(11).normal(0.0, 0.2, (TR.size, 3))
    fit = fit_paint(SpectralPredictor(rough, paint0, wavelengths_nm=WL), 45.0, TR, lab)
    for name, v in truth.items():
        assert abs(fit.value(name) - v) < 4.0 * fit.sigma(name), (name, fit.value(name))
    assert fit.mean_dE2000 < 0.5
