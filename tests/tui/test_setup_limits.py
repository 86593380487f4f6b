"""The TUI's scan form refuses an incidence the lamp arm cannot reach, as the dry run does:
the limits are the lab config's ``goniometer.lamp.limits_deg`` (defaults: drivers.arm_limits,
the one place of them), not a literal 90 deg."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from drivers.arm_limits import LAMP_LIMITS_DEG
from goniolab.errors import UserError
from goniolab.optics.analytic import AnalyticModel
from goniolab.tui.session_backend import SessionBackend
from goniolab.tui.view_model import ScanSetup
from tests.test_session import sim_config


def _setup(theta_i_deg: float) -> ScanSetup:
    return ScanSetup("sample:flat", theta_i_deg, 0.0, 10.0, 5.0, 1)


def test_the_form_refuses_above_the_default_lamp_limit() -> None:
    assert LAMP_LIMITS_DEG == (0.0, 85.0)  # ISO 2813's 85 deg geometry is the last one
    _setup(85.0).validate()
    for theta in (85.5, 87.0, 89.9, -1.0):
        with pytest.raises(UserError, match=r"θi must lie within the lamp arm's limits \[0, 85\]"):
            _setup(theta).validate()


def test_the_backend_checks_its_configs_lamp_limits(tmp_path: Path) -> None:
    cfg = sim_config(tmp_path)
    text = cfg.read_text()
    assert "limits_deg = [0.0, 85.0]" in text  # the lamp's, the first limits_deg
    cfg.write_text(text.replace("limits_deg = [0.0, 85.0]", "limits_deg = [0.0, 80.0]", 1))
    backend = SessionBackend(cfg, model=AnalyticModel("beckmann", alpha=0.1))
    backend.check_setup(_setup(80.0))
    with pytest.raises(
        UserError, match=r"limits \[0, 80\] deg \(the lab config's \[goniometer.lamp\] limits\)"
    ):
        backend.check_setup(_setup(82.0))
    # the prediction and the start refuse it before anything is opened or moved
    with pytest.raises(UserError, match=r"limits \[0, 80\]"):
        asyncio.run(backend.predict_curve(_setup(82.0)))
    with pytest.raises(UserError, match=r"limits \[0, 80\]"):
        asyncio.run(backend.start(_setup(82.0)))
