"""``Lab(instruments=...)``: a glossmeter session must not need the goniometer."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from drivers.base import Disconnected
from goniolab.config import configs_dir, load_lab_config
from goniolab.lab_wiring import INSTRUMENTS, Lab
from goniolab.optics.analytic import AnalyticModel
from tests.twin_configs import ideal, ideal_config

MODEL = AnalyticModel("beckmann", alpha=0.1, n=1.55)


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])  # closed again on exit: nothing listens there


def _unreachable_lab_config(tmp_path: Path) -> Path:
    """The wire config with no simulated lab behind it: every endpoint is dead."""
    text = ideal((configs_dir() / "lab-sim-wire.toml").read_text())
    text = text.replace("start_sim_servers = true", "start_sim_servers = false")
    text = text.replace("port = 5020", f"port = {_closed_port()}")
    text = text.replace("/tmp/goniolab-sim", str(tmp_path / "no-such-dir"))
    path = tmp_path / "dead-lab.toml"
    path.write_text(text)
    assert "start_sim_servers = false" in text and str(tmp_path) in text
    return path


async def test_sim_lab_with_only_the_glossmeter_leaves_the_arms_unconnected(
    tmp_path: Path,
) -> None:
    cfg = load_lab_config(ideal_config(tmp_path))
    async with Lab(cfg, time_scale=0, model=MODEL, instruments=("glossmeter",)) as lab:
        reading = await lab.glossmeter.measure()
        expected = MODEL.gloss((20, 60, 85))[60]
        noise_pct = cfg.sim.noise_pct  # relative 1-sigma noise of the simulated meter
        # within 4 sigma of the noise plus the meter's 0.1 GU rounding
        tol = 4 * noise_pct / 100 * expected + 0.05
        assert reading.values_gu[60] == pytest.approx(expected, abs=tol)
        with pytest.raises(RuntimeError, match="without the goniometer"):
            _ = lab.goniometer
        with pytest.raises(RuntimeError, match="without the spectro"):
            _ = lab.spectro
        assert lab.sims is not None
        with pytest.raises(Disconnected):  # never connected: the arm refuses to talk
            await lab.sims.lamp.position_deg()


async def test_dead_lab_fails_on_the_first_instrument_it_opens(tmp_path: Path) -> None:
    cfg = load_lab_config(_unreachable_lab_config(tmp_path))
    with pytest.raises(Disconnected) as all_err:
        async with Lab(cfg, model=MODEL):
            pass
    assert all_err.value.device == "lamp"  # the goniometer comes first
    with pytest.raises(Disconnected) as gloss_err:
        async with Lab(cfg, model=MODEL, instruments=("glossmeter",)):
            pass
    assert gloss_err.value.device == "glossmeter"  # the arms were never tried
    assert "no-such-dir" in str(gloss_err.value)


def test_instrument_names_are_checked() -> None:
    cfg = load_lab_config(configs_dir() / "lab-sim.toml")
    with pytest.raises(ValueError, match="subset"):
        Lab(cfg, instruments=("goniometer", "camera"))
    with pytest.raises(ValueError, match="subset"):
        Lab(cfg, instruments=())
    assert INSTRUMENTS == ("goniometer", "spectro", "glossmeter")
