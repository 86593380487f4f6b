"""The TUI's comparison bookkeeping against analytic truths."""

from __future__ import annotations

import math

import numpy as np
import pytest

from goniolab.errors import UserError
from goniolab.scan.events import PointMeasured, PointPredicted
from goniolab.tui.backend import ScanSetup
from goniolab.tui.comparison import Comparison, peak_metrics


def test_peak_metrics_triangle_is_exact() -> None:
    # Linear interpolation is exact on a piecewise-linear peak: half max 1 at 1 and 3.
    m = peak_metrics(np.array([4.0, 0.0, 2.0, 1.0, 3.0]), np.array([0.0, 0.0, 2.0, 1.0, 1.0]))
    assert m.amplitude == 2.0
    assert m.position_deg == 2.0
    assert m.fwhm_deg == pytest.approx(2.0, abs=1e-12)


def test_peak_metrics_gaussian_fwhm() -> None:
    # FWHM of a Gaussian = 2 sqrt(2 ln 2) sigma.
    theta = np.arange(-20.0, 20.0 + 1e-9, 0.01)
    sigma = 2.5
    vals = 30.0 * np.exp(-((theta - 1.0) ** 2) / (2 * sigma**2))
    m = peak_metrics(theta, vals)
    assert m.amplitude == pytest.approx(30.0, rel=1e-9)
    assert m.position_deg == pytest.approx(1.0, abs=1e-9)
    assert m.fwhm_deg == pytest.approx(2 * math.sqrt(2 * math.log(2)) * sigma, abs=1e-4)


def test_peak_metrics_open_side_gives_nan_width() -> None:
    m = peak_metrics(np.array([0.0, 1.0, 2.0]), np.array([1.0, 2.0, 3.0]))
    assert m.amplitude == 3.0
    assert math.isnan(m.fwhm_deg)
    assert math.isnan(peak_metrics(np.array([]), np.array([])).amplitude)


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
    assert m.measured.amplitude == 10.0 and m.measured.position_deg == 15.0
    assert c.n_readings == 4


def test_scan_setup_validation_names_the_field() -> None:
    ok = ScanSetup("sample:flat", 20.0, -10.0, 10.0, 2.5, 2)
    ok.validate()
    assert ok.theta_r_values_deg() == [-10.0, -7.5, -5.0, -2.5, 0.0, 2.5, 5.0, 7.5, 10.0]
    with pytest.raises(UserError, match="theta_r_step_deg"):
        ScanSetup("sample:flat", 20.0, 0.0, 10.0, 0.0, 1).validate()
    with pytest.raises(UserError, match="theta_i_deg"):
        ScanSetup("sample:flat", 95.0, 0.0, 10.0, 1.0, 1).validate()
    with pytest.raises(UserError, match="theta_r_stop_deg"):
        ScanSetup("sample:flat", 20.0, 10.0, 0.0, 1.0, 1).validate()
    with pytest.raises(UserError, match="repeats"):
        ScanSetup("sample:flat", 20.0, 0.0, 10.0, 1.0, 0).validate()
