"""The TUI's comparison bookkeeping against analytic truths."""

from __future__ import annotations

import math

import pytest

from goniolab.errors import UserError
from goniolab.scan.events import PointMeasured, PointPredicted
from goniolab.tui.comparison import Comparison
from goniolab.tui.view_model import ScanSetup


def _meas(index: int, repeat: int, tr: float, value: float) -> PointMeasured:
    return PointMeasured(
        run_id=1,
        index=index,
        repeat=repeat,
        theta_i_deg=20.0,
        theta_r_deg=tr,
        luminance_pct=value,
        measured_theta_i_deg=20.0,
        measured_theta_r_deg=tr,
    )


def _pred(index: int, tr: float, value: float) -> PointPredicted:
    return PointPredicted(
        run_id=1, index=index, theta_i_deg=20.0, theta_r_deg=tr, predicted_pct=value
    )


def test_comparison_repeats_residuals_and_rmse() -> None:
    c = Comparison()
    # Points arrive out of theta order; repeats 1, 2, 6 -> mean 3, min 1, max 6.
    for rep, v in enumerate((1.0, 2.0, 6.0)):
        c.add_measured(_meas(1, rep, 25.0, v))
    c.add_measured(_meas(0, 0, 15.0, 10.0))
    c.add_predicted(_pred(0, 15.0, 9.0))
    c.add_predicted(_pred(1, 25.0, 5.0))
    c.add_predicted(_pred(2, 35.0, 1.0))  # no reading yet
    a = c.arrays()
    assert a.theta_r_deg.tolist() == [15.0, 25.0, 35.0]
    assert a.mean_pct[:2].tolist() == [10.0, 3.0]
    assert a.min_pct[1] == 1.0 and a.max_pct[1] == 6.0
    assert a.n_readings.tolist() == [1, 3, 0]
    assert math.isnan(a.mean_pct[2])
    assert a.residual_pct[:2].tolist() == [1.0, -2.0]
    m = c.metrics()
    assert m.n_compared == 2
    assert m.rmse_pct == pytest.approx(math.sqrt((1.0**2 + 2.0**2) / 2))
    # Fewer than three measured geometries: no peak metrics yet (shown as "-").
    assert math.isnan(m.measured.amplitude) and math.isnan(m.measured.fwhm_deg)
    assert c.n_readings == 4


def test_comparison_metrics_of_triangle_and_mirror_skipped() -> None:
    # A piecewise-linear peak 0, 2, 4, 2, 0 at 10..30 deg: half max 2 crossed at 15 and
    # 25 deg exactly, so FWHM = 10 deg; the parabola through 2, 4, 2 peaks at 20 deg, 4.
    c = Comparison()
    c.add_measured(_meas(-1, 0, 20.0, 100.0))  # mirror reference: not part of the curve
    for i, (tr, v) in enumerate(
        zip((10.0, 15.0, 20.0, 25.0, 30.0), (0.0, 2.0, 4.0, 2.0, 0.0), strict=True)
    ):
        c.add_measured(_meas(i, 0, tr, v))
        c.add_predicted(_pred(i, tr, v / 2))
    m = c.metrics()
    assert c.n_readings == 5
    assert m.measured.amplitude == pytest.approx(4.0)
    assert m.measured.position_deg == pytest.approx(20.0)
    assert m.measured.fwhm_deg == pytest.approx(10.0)
    assert m.predicted.amplitude == pytest.approx(2.0)
    assert m.predicted.fwhm_deg == pytest.approx(10.0)
    # residuals v/2 -> RMSE = sqrt((1 + 4 + 1) / 5)
    assert m.rmse_pct == pytest.approx(math.sqrt(6.0 / 5.0))


def test_scan_setup_validation_names_the_field() -> None:
    ok = ScanSetup("sample:flat", 20.0, -10.0, 10.0, 2.5, 2)
    ok.validate()
    assert ok.theta_r_values_deg() == [-10.0, -7.5, -5.0, -2.5, 0.0, 2.5, 5.0, 7.5, 10.0]
    with pytest.raises(UserError, match="θr step"):
        ScanSetup("sample:flat", 20.0, 0.0, 10.0, 0.0, 1).validate()
    with pytest.raises(UserError, match="θr to must"):
        ScanSetup("sample:flat", 20.0, 10.0, 0.0, 1.0, 1).validate()
    with pytest.raises(UserError, match="repeats"):
        ScanSetup("sample:flat", 20.0, 0.0, 10.0, 1.0, 0).validate()


def test_repeats_are_averaged_as_spectra() -> None:
    # two repeats of very different spectra: the comparison's L*a*b* is the colour of
    # their mean spectrum (computed here from the spectra, independently of the events'
    # XYZ), not the mean of their L*a*b*; without XYZ it falls back to the mean L*a*b*
    import dataclasses

    import numpy as np

    from goniolab.colour.spectra import ColourSettings, spectrum_to_colour, white_xyz

    settings = ColourSettings("D65", "10")
    wl = np.arange(400.0, 701.0, 10.0)
    spectra = [0.05 + 0.8 * (wl > 600), 0.6 - 0.5 * (wl > 500)]  # a red, then a blue-green
    colours = [spectrum_to_colour(wl, r, settings) for r in spectra]
    white = tuple(float(v) for v in white_xyz(settings))
    c, plain = Comparison(), Comparison()
    for rep, col in enumerate(colours):
        ev = PointMeasured(
            run_id=1, index=0, repeat=rep, theta_i_deg=45.0, theta_r_deg=30.0,
            luminance_pct=1.0, measured_theta_i_deg=45.0, measured_theta_r_deg=30.0,
            lab=col.lab, xyz=(col.X, col.Y, col.Z), white_xyz=white,  # type: ignore[arg-type]
        )  # fmt: skip
        c.add_measured(ev)
        plain.add_measured(dataclasses.replace(ev, xyz=None, white_xyz=None))
    truth = spectrum_to_colour(wl, np.mean(spectra, axis=0), settings).lab
    mean_of_labs = np.mean([col.lab for col in colours], axis=0)
    assert float(np.max(np.abs(np.subtract(truth, mean_of_labs)))) > 3.0  # the test can fail
    np.testing.assert_allclose(c.colour_arrays().measured_lab[0], truth, atol=1e-9)
    np.testing.assert_allclose(c.current_lab(), truth, atol=1e-9)  # type: ignore[arg-type]
    np.testing.assert_allclose(plain.colour_arrays().measured_lab[0], mean_of_labs, atol=1e-12)
