"""Shared pieces of the lab contract suite (imported by conftest.py and the tests).

Backends: ``inproc`` (``mode = "sim"``, the simulated instruments themselves), ``wire``
(``mode = "drivers"`` with ``start_sim_servers = true``: the real drivers over Modbus TCP
and ptys to the simulated lab) and ``wire-rtu`` (the same with the arms on Modbus RTU,
framed over ``socket://``). Both come from ``configs/lab-sim-wire.toml`` with
``port = 0`` (the server binds a free port and the lab hands it to the drivers: no race
between parallel test workers), ptys under tmp_path, a scale-0 clock and no noise, and
read a fast analytic model (GGX, alpha 0.08).
"""

from __future__ import annotations

from pathlib import Path

from goniolab.config import configs_dir
from goniolab.optics.analytic import AnalyticModel
from tests.twin_configs import ideal

MODEL = AnalyticModel("ggx", alpha=0.08, n=1.55)


def lab_toml(
    tmp_path: Path, backend: str, *, faults: str = "", extra: dict[str, str] | None = None
) -> Path:
    """The wire config adapted for a test; ``faults`` lines go under ``[sim.faults]``."""
    text = ideal((configs_dir() / "lab-sim-wire.toml").read_text())
    text = (
        text.replace("port = 5020", "port = 0")
        .replace("/tmp/goniolab-sim", str(tmp_path / "sim"))
        .replace("time_scale = 1.0", "time_scale = 0.0")
        .replace("noise_pct = 0.5", "noise_pct = 0.0")
        .replace("[sim.faults]", "[sim.faults]\n" + faults)
    )
    if backend == "wire-rtu":
        text = text.replace(
            'transport = "tcp"', 'transport = "rtu"\nserial_port = "socket://127.0.0.1:0"'
        )
    if backend == "inproc":
        text = text.replace('mode = "drivers"', 'mode = "sim"').replace(
            "start_sim_servers = true", "start_sim_servers = false"
        )
    for old, new in (extra or {}).items():
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / f"lab-{backend}.toml"
    path.write_text(text)
    return path
