"""Run summary: peak comparison only where the measured range brackets the specular peak.

Truth: a Gaussian lobe ``A exp(-(tr - ti - shift)^2 / (2 sigma^2))`` sampled every 1 deg;
its peak is at ``ti + shift`` and its FWHM is ``2 sqrt(2 ln 2) sigma``. A sample tilt tau
moves the specular peak by 2 tau (Wittmann et al. 2021, sec. 5.2-5.3).
"""

from __future__ import annotations

import math

import pytest

from goniolab.scan.plans import BrdfPlan, parse_angles
from goniolab.scan.summary import summarize_brdf
from goniolab.store import PointRow

from .conftest import LOBE_AMPLITUDE_PCT, LOBE_SIGMA_DEG, lobe_pct

PLAN = BrdfPlan(45.0, parse_angles("0:70:1"))


def _rows(plan: BrdfPlan, n_geometries: int, shift_deg: float) -> list[PointRow]:
    """The first ``n_geometries`` readings of ``plan`` on a lobe shifted by ``shift_deg``."""
    return [
        PointRow(
            index=i,
            repeat=0,
            theta_i_deg=plan.theta_i_deg,
            theta_r_deg=tr,
            measured_theta_i_deg=plan.theta_i_deg,
            measured_theta_r_deg=tr,
            luminance_pct=float(lobe_pct(plan.theta_i_deg, tr, shift_deg)),
            raw={},
            timestamp=0.0,
        )
        for i, tr in enumerate(plan.theta_r_deg[:n_geometries])
    ]


def _predictions(plan: BrdfPlan) -> dict[int, float]:
    return {i: float(lobe_pct(plan.theta_i_deg, tr)) for i, tr in enumerate(plan.theta_r_deg)}


def test_complete_run_compares_the_peaks() -> None:
    s = summarize_brdf(PLAN, _rows(PLAN, 71, 2.0), _predictions(PLAN))
    assert s["complete"] is True and s["peak_note"] is None
    # the parabola through the three largest 1-deg samples of a sigma = 3 deg Gaussian
    # finds its vertex within 0.05 deg
    assert s["peak_offset_deg"] == pytest.approx(2.0, abs=0.05)
    assert s["amplitude_ratio"] == pytest.approx(1.0, abs=1e-3)
    assert s["predicted_peak"]["fwhm_deg"] == pytest.approx(
        2 * math.sqrt(2 * math.log(2)) * LOBE_SIGMA_DEG, abs=0.1
    )
    assert s["hint"] is not None and "tilted by about 1.0" in s["hint"]


def test_interrupted_run_before_the_peak_gives_no_offset_and_no_hint() -> None:
    # Ctrl-C after 9 readings of 0..70: only the off-specular floor was measured
    s = summarize_brdf(PLAN, _rows(PLAN, 9, 0.0), _predictions(PLAN))
    assert s["readings"] == 9 and s["complete"] is False
    assert s["peak_offset_deg"] is None and s["amplitude_ratio"] is None and s["hint"] is None
    assert "0..8 deg does not contain the specular direction theta_r = 45 deg" in s["peak_note"]


def test_interrupted_run_past_the_peak_compares_on_the_measured_geometries() -> None:
    # stopped at 52 deg: the lobe (peak 45 + 1.5) is measured on both sides
    s = summarize_brdf(PLAN, _rows(PLAN, 53, 1.5), _predictions(PLAN))
    assert s["complete"] is False and s["peak_note"] is None
    assert s["peak_offset_deg"] == pytest.approx(1.5, abs=0.05)
    assert s["measured_peak"]["amplitude_pct"] == pytest.approx(LOBE_AMPLITUDE_PCT, rel=2e-3)


def test_measured_maximum_at_the_end_of_the_range_is_not_a_peak() -> None:
    # stopped at 46 deg with the lobe shifted by +5 deg: the measured curve still rises
    s = summarize_brdf(PLAN, _rows(PLAN, 47, 5.0), _predictions(PLAN))
    assert s["peak_offset_deg"] is None and s["hint"] is None
    assert "measured maximum at 46.00 deg" in s["peak_note"]


def test_a_bump_of_the_off_specular_floor_is_not_a_peak() -> None:
    # a complete 0..20 deg scan at theta_i = 45 deg: measured and predicted curves each have
    # a small interior maximum (1 deg apart), but no specular peak lies in the range
    plan = BrdfPlan(45.0, parse_angles("0:20:1"))
    floor = {
        i: 0.005 * math.exp(-0.5 * ((tr - 5.0) / 2.0) ** 2) for i, tr in enumerate(plan.theta_r_deg)
    }
    rows = [
        PointRow(
            index=i, repeat=0, theta_i_deg=45.0, theta_r_deg=tr, measured_theta_i_deg=45.0,
            measured_theta_r_deg=tr, luminance_pct=floor[min(i + 1, 20)], raw={}, timestamp=0.0,
        )
        for i, tr in enumerate(plan.theta_r_deg)
    ]  # fmt: skip
    s = summarize_brdf(plan, rows, floor)
    assert s["complete"] is True
    assert s["peak_offset_deg"] is None and s["hint"] is None
    assert "does not contain the specular direction theta_r = 45 deg" in s["peak_note"]
