"""A short soak (issue 10): bench/soak_wire.py at a few dozen readings with high fault rates.

The real drivers talk to the simulated lab over Modbus TCP and ptys while every device
gets timeouts, garbled frames and links that drop and come back (readings, moves, homing,
the park, the arms' status and the exposure are retried, a lost link reopened);
nothing may be lost, no run left ``running``, and every kind of fault must actually have
been met (or the test would prove nothing). The figures of the full soak (1,000 gloss
readings, a 500-point scan) are in the README; speed is the bench's, never asserted here.
"""

from __future__ import annotations

import asyncio
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

pytestmark = [pytest.mark.wire, pytest.mark.slow]

BENCH = Path(__file__).resolve().parents[2] / "bench" / "soak_wire.py"


def _bench() -> ModuleType:
    spec = importlib.util.spec_from_file_location("soak_wire", BENCH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["soak_wire"] = module
    spec.loader.exec_module(module)
    return module


def test_short_soak_loses_nothing(tmp_path: Path) -> None:
    soak = _bench().soak
    out = asyncio.run(
        soak(
            readings=30,
            points=12,
            seed=4,
            timeout_rate=0.02,
            garble_rate=0.05,
            disconnect_rate=0.03,
            workdir=tmp_path,
        )
    )
    gloss, scan = out["gloss"], out["scan"]
    assert (gloss["requested"], gloss["stored"], gloss["lost"], gloss["state"]) == (
        30,
        30,
        0,
        "done",
    ), gloss
    assert (scan["requested"], scan["stored"], scan["lost"], scan["state"]) == (
        12,
        12,
        0,
        "done",
    ), scan
    assert out["runs_left_running"] == 0
    kinds = out["faults_injected"]["by_kind"]
    assert {"timeout", "garble", "drop"} <= set(kinds), kinds
    # the drivers saw them: serial faults were retried (or reconnected), none was fatal
    errors = out["instrument_errors"]
    assert not any(key.endswith("fatal") for key in errors), errors
    assert gloss["reconnects"] + sum(errors.values()) > 0
    # every stored reading is the STIL's answer given at its own geometry
    assert scan["readings_off_geometry"] == 0 and scan["readings_unmatched"] == 0, scan


def test_soak_with_late_replies_and_a_frozen_store(tmp_path: Path) -> None:
    """Issue 23: the soak extended with late replies (the STIL and the glossmeter answer
    1.5 s after the request, past the drivers' 1 s timeout, the commands behind waiting)
    and a frozen store (another program holds the SQLite write lock for 11 s, past the
    store's 10 s busy timeout, after the scan's second point). Nothing is lost, nothing is
    stored twice, and every reading is the answer given at its own geometry."""
    soak = _bench().soak
    out = asyncio.run(
        soak(
            readings=12,
            points=12,
            seed=2,
            timeout_rate=0.0,
            garble_rate=0.0,
            disconnect_rate=0.0,
            late_rate=0.15,
            late_s=1.5,
            freeze_store_s=11.0,
            workdir=tmp_path,
        )
    )
    gloss, scan = out["gloss"], out["scan"]
    assert (gloss["stored"], gloss["lost"], gloss["state"]) == (12, 0, "done"), gloss
    assert (scan["stored"], scan["lost"], scan["state"]) == (12, 0, "done"), scan
    assert out["faults_injected"]["by_kind"].get("late", 0) >= 2, out["faults_injected"]
    assert scan["readings_off_geometry"] == 0 and scan["readings_unmatched"] == 0, scan
    assert out["runs_left_running"] == 0
    # the store's outage was met and said (the run paused, then went on)
    assert any("store" in key for key in out["instrument_errors"]), out["instrument_errors"]
