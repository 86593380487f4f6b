"""Peak amplitude, position and FWHM against analytic line shapes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from goniolab.optics.metrics import peak_metrics


def test_gaussian_fwhm_and_refined_peak() -> None:
    sigma, mu, amp = 4.0, 45.3, 2.5
    x = np.arange(0.0, 90.5, 0.5)
    y = amp * np.exp(-0.5 * ((x - mu) / sigma) ** 2)
    m = peak_metrics(x, y)
    assert m.fwhm_deg == pytest.approx(2 * math.sqrt(2 * math.log(2)) * sigma, rel=2e-3)
    # parabolic refinement recovers the off-grid position and height
    assert m.position_deg == pytest.approx(mu, abs=0.01)
    assert m.amplitude == pytest.approx(amp, rel=1e-3)


def test_lorentzian_fwhm() -> None:
    gamma, mu = 3.0, -10.0
    x = np.linspace(-60.0, 40.0, 1001)
    y = 1.0 / (1.0 + ((x - mu) / gamma) ** 2)
    m = peak_metrics(x, y)
    assert m.fwhm_deg == pytest.approx(2 * gamma, rel=1e-3)
    assert m.position_deg == pytest.approx(mu, abs=1e-6)


def test_fwhm_nan_when_a_crossing_is_outside_the_range() -> None:
    x = np.linspace(0.0, 10.0, 51)
    y = np.exp(-0.5 * ((x - 1.0) / 2.0) ** 2)  # left half-max crossing at 1 - 2.35 < 0
    m = peak_metrics(x, y)
    assert math.isnan(m.fwhm_deg)
    assert m.position_deg == pytest.approx(1.0, abs=0.01)


def test_peak_at_the_edge_keeps_the_sample() -> None:
    x = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.array([4.0, 3.0, 1.0, 0.5])
    m = peak_metrics(x, y)
    assert (m.amplitude, m.position_deg) == (4.0, 0.0)
    assert math.isnan(m.fwhm_deg)


def test_triangle_exact() -> None:
    # linear flanks: linear interpolation of the crossings is exact
    x = np.arange(-5.0, 6.0)
    y = np.maximum(0.0, 4.0 - np.abs(x))
    m = peak_metrics(x, y)
    assert m.fwhm_deg == pytest.approx(4.0, abs=1e-12)
    assert m.amplitude == 4.0


@pytest.mark.parametrize(
    ("x", "y", "msg"),
    [
        ([0, 1], [1, 2], "at least 3"),
        ([0, 1, 1], [1, 2, 1], "strictly increasing"),
        ([0, 1, 2], [1, np.nan, 1], "finite"),
        ([0, 1, 2], [1, 2], "equal length"),
    ],
)
def test_bad_input(x: list[float], y: list[float], msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        peak_metrics(x, y)
