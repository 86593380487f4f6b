"""A controller alarm latched before a scan is cleared from the CLI (issue 23.15).

On the wire sim the controllers keep their state between commands, as real ones do: the
first scan trips a (once-only) injected overload alarm on the detector arm at 47.2 deg and
fails; ``scan resume`` then meets the alarm before any move and fails the same way; both
failures say how to clear it; ``goniolab lab reset-alarm`` clears it (nothing moves) and
the resumed run completes. The alarm code is the AZ overload, 0x30 (sim/motion.py, after
Oriental Motor HM-60262E).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from goniolab.scan.alarm import ArmAlarm, alarm_hint, reset_alarms
from goniolab.scan.plans import DEFAULT_REPEATS
from goniolab.store import RunStore
from tests._cli import run_cli
from tests.scan.test_integration import lab_config

ROOT = Path(__file__).resolve().parents[1]


def _cli(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    """``goniolab ARGS`` in this process (tests/_cli.py); the simulated controllers that
    keep the alarm between the commands are the ``goniolab sim serve`` process."""
    return run_cli(*args, cwd=ROOT)


@pytest.mark.wire
@pytest.mark.timeout(600)  # three scans and two resets over the wire on a loaded machine
def test_an_alarm_before_a_scan_is_cleared_from_the_cli(tmp_path: Path) -> None:
    server_cfg = lab_config(
        tmp_path, base="lab-sim-wire.toml", faults={"detector_alarm_at_deg": "47.2"},
        name="server.toml",
    )  # fmt: skip
    client_cfg = tmp_path / "client.toml"
    client_cfg.write_text(
        server_cfg.read_text().replace("start_sim_servers = true", "start_sim_servers = false")
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    server = subprocess.Popen(
        [sys.executable, "-m", "goniolab.cli", "sim", "serve", "--config", str(server_cfg),
         "--json", "--time-scale", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        assert server.stdout is not None
        json.loads(server.stdout.readline())  # the endpoints: the server is up
        store = tmp_path / "s.sqlite"
        common = ["--config", str(client_cfg), "--store", str(store), "--time-scale", "0"]
        first = _cli("scan", "--theta-r", "40:55:1", "--json", *common, env=env)
        assert first.returncode == 1, first.stderr
        doc = json.loads(first.stdout)
        assert doc["state"] == "failed" and "0x30" in doc["reason"]
        assert "goniolab lab reset-alarm --config" in doc["reason"]
        again = _cli("scan", "resume", str(doc["run_id"]), *common, env=env)
        assert again.returncode == 1
        with RunStore(store, readonly=True) as s:
            reason = s.get_run(doc["run_id"]).reason or ""
        assert "alarm 48 (0x30)" in reason and "goniolab lab reset-alarm" in reason
        reset = _cli("lab", "reset-alarm", "--config", str(client_cfg), env=env)
        assert reset.returncode == 0, reset.stderr
        assert reset.stdout.splitlines() == [
            "lamp: no alarm",
            "detector: alarm 48 (0x30) cleared",
        ]
        done = _cli("scan", "resume", str(doc["run_id"]), *common, env=env)
        assert done.returncode == 0, done.stderr
        with RunStore(store, readonly=True) as s:
            assert s.get_run(doc["run_id"]).status == "done"
            assert s.count_points(doc["run_id"]) == 16 * DEFAULT_REPEATS  # 40..55 deg
        quiet = _cli("lab", "reset-alarm", "--config", str(client_cfg), "--json", env=env)
        assert json.loads(quiet.stdout) == [
            {"arm": "lamp", "before": None, "after": None},
            {"arm": "detector", "before": None, "after": None},
        ]
    finally:
        server.send_signal(signal.SIGINT)
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:  # pragma: no cover - a stuck server
            server.kill()


class _Axis:
    def __init__(self, before: int | None, sticky: bool) -> None:
        self.code, self.sticky, self.resets = before, sticky, 0

    async def status(self) -> object:
        from drivers.base import AxisStatus

        return AxisStatus(position_deg=0.0, alarm_code=self.code)

    async def reset_alarm(self) -> None:
        self.resets += 1
        if not self.sticky:
            self.code = None


async def test_an_alarm_whose_cause_remains_is_reported_not_hidden() -> None:
    class G:
        lamp = _Axis(None, False)
        detector = _Axis(0x66, True)  # hardware overtravel: the limit switch still pressed

    out = await reset_alarms(G())
    assert out == [ArmAlarm("lamp", None, None), ArmAlarm("detector", 0x66, 0x66)]
    assert G.lamp.resets == 0 and G.detector.resets == 1  # only the alarmed arm is reset
    assert "still active after the reset" in out[1].describe()


def test_only_controller_alarms_get_the_hint() -> None:
    from drivers.base import DeviceFault, DeviceTimeout, StallError

    assert "reset-alarm" in alarm_hint(DeviceFault("alarm", device="lamp", code=0x30))
    assert alarm_hint(DeviceFault("no code", device="lamp")) == ""
    assert alarm_hint(DeviceTimeout("slow", device="lamp")) == ""
    assert "reset-alarm" in alarm_hint(StallError("stall", device="lamp", code=0x10))
