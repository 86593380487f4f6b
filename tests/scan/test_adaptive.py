"""Adaptive sampling (goniolab/scan/adaptive.py): the same number of readings, placed where
the curve bends, reconstruct it better than a uniform grid."""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.config import configs_dir
from goniolab.scan.adaptive import adaptive_angles, reconstruction_error, sampling_density
from goniolab.scan.plans import BrdfPlan, PlanError
from goniolab.store import RunStore
from tests.twin_configs import ideal


def peak(x: np.ndarray, centre_deg: float = 45.0, sigma_deg: float = 2.0) -> np.ndarray:
    """A specular lobe on a diffuse floor: 5 exp(-(x - c)^2 / 2 s^2) + 0.05 (% of a mirror)."""
    return np.asarray(5.0 * np.exp(-0.5 * ((x - centre_deg) / sigma_deg) ** 2) + 0.05)


def test_same_count_same_ends_increasing_and_dense_at_the_peak() -> None:
    angles = np.array(adaptive_angles(0.0, 70.0, 71, peak))
    assert angles.size == 71 and angles[0] == 0.0 and angles[-1] == 70.0
    assert np.all(np.diff(angles) >= 0.05 - 1e-9)
    near = np.count_nonzero(np.abs(angles - 45.0) <= 5.0)
    assert near >= 3 * 11  # the uniform 1-deg grid has 11 in 40..50 deg
    assert np.count_nonzero(angles <= 30.0) >= 0.1 * 31  # the floor keeps the flank sampled


def test_a_curve_without_curvature_keeps_the_uniform_grid() -> None:
    angles = adaptive_angles(10.0, 30.0, 11, lambda x: 2.0 * x + 1.0)
    assert angles == pytest.approx(tuple(np.linspace(10.0, 30.0, 11)), abs=1e-3)
    rho = sampling_density(np.linspace(0, 1, 50), np.zeros(50))
    assert np.all(rho == 1.0)


@pytest.mark.parametrize("shift_deg", [0.0, 0.37, -1.2])
def test_adaptive_reconstructs_an_analytic_lobe_better_than_uniform(shift_deg: float) -> None:
    # planned on the lobe at 45 deg; the measured one stands shift_deg away (misalignment)
    dense = np.linspace(0.0, 70.0, 7001)
    truth = peak(dense, 45.0 + shift_deg)
    uniform = np.linspace(0.0, 70.0, 36)
    adaptive = np.array(adaptive_angles(0.0, 70.0, 36, peak))
    rms_u, max_u = reconstruction_error(uniform, peak(uniform, 45.0 + shift_deg), dense, truth)
    rms_a, max_a = reconstruction_error(adaptive, peak(adaptive, 45.0 + shift_deg), dense, truth)
    assert rms_a < 0.5 * rms_u
    assert max_a < max_u


def test_reconstruction_error_of_linear_interpolation() -> None:
    # x^2 sampled at 0, 1, 2: the chord's error peaks at h^2/4 = 0.25 mid-interval
    x = np.linspace(0.0, 2.0, 2001)
    rms, worst = reconstruction_error([0.0, 1.0, 2.0], [0.0, 1.0, 4.0], x, x**2)
    assert worst == pytest.approx(0.25, abs=1e-6)
    assert rms == pytest.approx(math.sqrt(1.0 / 30.0), rel=1e-3)  # mean of (t - t^2)^2 = 1/30


def test_bad_requests_are_errors() -> None:
    with pytest.raises(ValueError, match=r"0\.05 deg apart"):
        adaptive_angles(0.0, 1.0, 100, peak)
    with pytest.raises(ValueError, match="n >= 2"):
        adaptive_angles(0.0, 1.0, 1, peak)
    with pytest.raises(ValueError, match="not finite"):
        adaptive_angles(0.0, 10.0, 5, lambda x: np.full_like(x, np.nan))
    with pytest.raises(PlanError, match="sampling"):
        BrdfPlan(45.0, (1.0, 2.0), sampling="clever")
    plan = BrdfPlan(45.0, (1.0, 2.5), sampling="adaptive")
    assert BrdfPlan.from_dict(plan.to_dict()) == plan


def test_scan_adaptive_on_the_sim_lab(tmp_path: Path) -> None:
    text = ideal((configs_dir() / "lab-sim.toml").read_text())
    text = re.sub(r"(?m)^store = .*$", f'store = "{tmp_path / "runs.sqlite"}"', text)
    cfg = tmp_path / "lab.toml"
    cfg.write_text(text)
    out, err = io.StringIO(), io.StringIO()
    args = ["scan", "--config", str(cfg), "--theta-r", "30:60:1", "--adaptive",
            "--time-scale", "0", "--model", "facet", "--json"]  # fmt: skip
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main(args) == 0
    assert "adaptive sampling: 31 angles 30..60 deg" in err.getvalue()
    run_id = json.loads(out.getvalue())["run_id"]
    with RunStore(tmp_path / "runs.sqlite") as store:
        plan = BrdfPlan.from_dict(store.get_run(run_id).plan)
        assert plan.sampling == "adaptive" and plan.n_geometries == 31
        assert store.count_points(run_id) == 31
    angles = np.array(plan.theta_r_deg)
    assert (angles[0], angles[-1]) == (30.0, 60.0)
    assert np.count_nonzero(np.abs(angles - 45.0) <= 5.0) > 11  # uniform: 11
    with contextlib.redirect_stderr(io.StringIO()):
        assert main(["scan", "--config", str(cfg), "--plan", "e2194", "--adaptive"]) == 2
