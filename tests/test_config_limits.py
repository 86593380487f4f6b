"""Numbers that switch a safety off or hang a run are refused at load (issue 23, Low):
``stall_tolerance_deg = 1e9`` disabled stall detection, a timeout of 1e9 s would wait
forever, ``--dwell 1e300`` printed a 300-digit ETA. Each message names the file, the key
and the bound."""

from __future__ import annotations

from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.config import STALL_TOLERANCE_MAX_DEG, ConfigError, load_lab_config
from goniolab.scan.plans import MAX_DWELL_S, BrdfPlan, PlanError

ROOT = Path(__file__).resolve().parents[1]


def _with(tmp_path: Path, section: str, key: str, value: str) -> Path:
    """configs/lab-sim.toml with ``key = value`` in ``[section]`` (set once)."""
    out, inside = [], False
    for line in (ROOT / "configs" / "lab-sim.toml").read_text().splitlines():
        header = line.split("#")[0].strip()
        if line.startswith("["):
            inside = header == f"[{section}]"
        if inside and line.split("=")[0].strip() == key:
            continue  # the shipped value, replaced below
        out.append(line)
        if header == f"[{section}]":
            out.append(f"{key} = {value}")
    p = tmp_path / "x.toml"
    p.write_text("\n".join(out) + "\n")
    return p


@pytest.mark.parametrize(
    ("section", "key", "value", "bound"),
    [
        ("goniometer.detector", "stall_tolerance_deg", "1e9", f"{STALL_TOLERANCE_MAX_DEG:g}"),
        ("goniometer.lamp", "stall_tolerance_deg", "5.5", f"{STALL_TOLERANCE_MAX_DEG:g}"),
        ("goniometer", "move_timeout_s", "1e9", "3600"),
        ("goniometer.lamp", "timeout_s", "86400.0", "3600"),
        ("spectro", "timeout_s", "1e300", "3600"),
    ],
)
def test_unbounded_numbers_are_refused(
    tmp_path: Path, section: str, key: str, value: str, bound: str
) -> None:
    path = _with(tmp_path, section, key, value)
    with pytest.raises(ConfigError) as info:
        load_lab_config(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and f"{section}.{key}" in message
    assert bound in message


def test_the_bounds_themselves_load(tmp_path: Path) -> None:
    path = _with(tmp_path, "goniometer.detector", "stall_tolerance_deg", "5.0")
    cfg = load_lab_config(path)
    assert cfg.goniometer.detector.stall_tolerance_deg == STALL_TOLERANCE_MAX_DEG


@pytest.mark.parametrize("dwell", [1e300, 600.5, float("inf"), -1.0])
def test_dwell_beyond_ten_minutes_is_refused(dwell: float) -> None:
    with pytest.raises(PlanError, match=r"dwell_s must be in 0\.\.600 s"):
        BrdfPlan(45.0, (40.0,), dwell_s=dwell)
    assert BrdfPlan(45.0, (40.0,), dwell_s=MAX_DWELL_S).dwell_s == 600.0


def test_scan_dwell_1e300_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "s.sqlite"
    code = main(["scan", "--config", str(ROOT / "configs" / "lab-sim.toml"), "--theta-r",
                 "40:42:1", "--dwell", "1e300", "--time-scale", "0", "--store", str(store)])  # fmt: skip
    assert code == 2
    assert "dwell_s must be in 0..600 s" in capsys.readouterr().err
    assert not store.exists()  # no run recorded
