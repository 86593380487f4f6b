"""One contract, two backends: the simulated lab in-process and the real drivers against
the wire simulators must behave the same (see conftest.py for the backends)."""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.base import (
    DeviceError,
    DeviceFault,
    DeviceTimeout,
    Disconnected,
    InterlockError,
    LimitError,
    ProtocolError,
    StallError,
)
from drivers.timing import SimClock
from goniolab.config import ConfigError, load_lab_config
from goniolab.lab_wiring import Lab, build_sim_instruments, build_sim_server
from goniolab.optics.apertures import Cone
from sim.motion import ALARM_OVERLOAD
from sim.wire import SimLabServer
from tests.contract.contract_support import MODEL, lab_toml

STEP_DEG = 1e-3  # 1000 steps/deg on the wire


async def test_move_and_positions(lab: Lab) -> None:
    g = lab.goniometer
    assert await g.positions_deg() == pytest.approx((45.0, 45.0))  # power-up at park
    reached = await g.move_to(30.0, 12.5, timeout_s=30.0)
    assert reached == pytest.approx((30.0, 12.5), abs=STEP_DEG)
    st = await g.lamp.status()
    assert st.in_position and not st.moving and st.alarm_code is None


async def test_limits_and_interlock_refuse_before_moving(lab: Lab) -> None:
    g = lab.goniometer
    with pytest.raises(LimitError, match="lamp"):
        await g.move_to(90.0, 45.0, timeout_s=30.0)
    with pytest.raises(LimitError, match="detector"):
        await g.move_to(20.0, -15.0, timeout_s=30.0)  # detector arm spans 0..70 deg
    with pytest.raises(InterlockError, match="below the minimum 10"):
        await g.move_to(2.0, 3.0, timeout_s=30.0)  # both arms near the normal: 5 deg apart
    assert await g.positions_deg() == pytest.approx((45.0, 45.0))


async def test_home_then_park(lab: Lab) -> None:
    g = lab.goniometer
    await g.home(timeout_s=30.0)
    # both homes are 0 deg, closer than min_separation_deg: the lamp homes, moves clear to
    # its park coordinate, then the detector homes (issue 10, defect 1)
    assert await g.positions_deg() == pytest.approx((45.0, 0.0))
    assert all([(await g.lamp.status()).homed, (await g.detector.status()).homed])
    await g.park(timeout_s=30.0)
    assert await g.positions_deg() == pytest.approx((45.0, 45.0), abs=STEP_DEG)


async def test_stop_halts_a_running_move(make_lab: Callable[..., Lab]) -> None:
    # a clock at 1e-9 x real time keeps the arm at the start of its move
    async with make_lab(extra={"time_scale = 0.0": "time_scale = 1e-9"}) as lab:
        lamp = lab.goniometer.lamp
        await lamp.move_to(80.0)
        assert (await lamp.status()).moving
        await lab.goniometer.stop()
        st = await lamp.status()
        assert not st.moving and st.position_deg == pytest.approx(45.0, abs=STEP_DEG)


async def test_alarm_mid_move_then_reset(lab: Lab) -> None:
    assert lab.sims is not None
    lab.sims.lamp.motor.inject_alarm(35.0)
    g = lab.goniometer
    with pytest.raises(DeviceFault) as err:
        await g.move_to(20.0, 45.0, timeout_s=30.0)
    assert err.value.code == ALARM_OVERLOAD and err.value.device == "lamp"
    assert await g.lamp.position_deg() == pytest.approx(35.0, abs=STEP_DEG)
    lamp, detector = await g.lamp.status(), await g.detector.status()
    assert lamp.alarm_code == ALARM_OVERLOAD and not lamp.moving  # left standing, alarm latched
    assert not detector.moving and detector.position_deg == pytest.approx(45.0, abs=STEP_DEG)
    await g.lamp.reset_alarm()
    assert await g.move_to(20.0, 45.0, timeout_s=30.0) == pytest.approx((20.0, 45.0), abs=STEP_DEG)


async def test_stall_is_detected(lab: Lab) -> None:
    assert lab.sims is not None
    lab.sims.detector.motor.inject_stall(30.0)
    with pytest.raises(StallError) as err:
        await lab.goniometer.move_to(45.0, 20.0, timeout_s=30.0)
    assert err.value.device == "detector"


@pytest.mark.parametrize("theta_r_deg", [45.0, 47.5, 30.0, 5.0])
async def test_spectro_reads_the_model_at_the_geometry(lab: Lab, theta_r_deg: float) -> None:
    await lab.goniometer.move_to(45.0, theta_r_deg, timeout_s=30.0)
    reading = await lab.spectro.measure()
    expected = float(
        MODEL.luminance_pct(45.0, [theta_r_deg], source=Cone(6.0), detector=Cone(6.0))[0]
    )
    assert reading.luminance_pct == pytest.approx(expected, abs=1e-4)  # 4 decimals on the wire
    assert len(reading.values) == len(reading.wavelengths_nm) == 41
    assert reading.wavelengths_nm[0] == 380.0 and reading.wavelengths_nm[-1] == 780.0


async def test_glossmeter_reads_the_model_gloss(lab: Lab) -> None:
    expected = {a: round(v, 1) for a, v in MODEL.gloss((20, 60, 85)).items()}
    reading = await lab.glossmeter.measure()
    assert reading.values_gu == expected
    assert reading.overflow_deg == ()
    only60 = await lab.glossmeter.measure([60])
    assert only60.values_gu == {20: None, 60: expected[60], 85: None}


async def test_garbled_spectro_reply_is_a_protocol_error(make_lab: Callable[..., Lab]) -> None:
    # on the wire the driver's first command (set exposure on connect) already fails
    with pytest.raises(ProtocolError) as err:
        async with make_lab(faults='devices = ["spectro"]\ngarble_rate = 1.0') as lab:
            await lab.spectro.measure()
    assert err.value.device == "spectro"


FAST_REPLIES = {"timeout_s = 1.0": "timeout_s = 0.2"}  # the arms' per-request timeout


@pytest.mark.parametrize(
    ("fault", "error", "message"),
    [
        ("garble_rate = 1.0", ProtocolError, "garbled"),
        ("timeout_rate = 1.0", DeviceTimeout, "no answer"),
    ],
)
async def test_arm_fault_is_reported_and_nothing_moves(
    make_lab: Callable[..., Lab], fault: str, error: type[DeviceError], message: str
) -> None:
    faults = f'devices = ["lamp"]\n{fault}'
    async with make_lab(faults=faults, extra=FAST_REPLIES) as lab:
        with pytest.raises(error, match=message) as err:
            await lab.goniometer.move_to(30.0, 30.0, timeout_s=30.0)
        assert err.value.device == "lamp"
        assert lab.sims is not None
        assert (lab.sims.lamp.actual_deg(), lab.sims.detector.actual_deg()) == (45.0, 45.0)


async def test_disconnected_glossmeter(make_lab: Callable[..., Lab]) -> None:
    async with make_lab(faults='devices = ["glossmeter"]\ndisconnect_after = 1') as lab:
        await lab.glossmeter.measure()
        with pytest.raises(DeviceError) as err:
            await lab.glossmeter.measure()
        assert err.value.device == "glossmeter"


async def test_out_of_limits_geometry_from_config_is_refused(lab: Lab) -> None:
    with pytest.raises(LimitError, match=r"theta_r=85.0 deg outside the detector arm limits"):
        lab.goniometer.check_geometry(45.0, 85.0)
    assert np.isfinite(lab.source.full_angle_deg)


# ------------------------------------------------------------------ wire only: bad endpoints
NO_SERVERS = {"start_sim_servers = true": "start_sim_servers = false"}


async def test_unreachable_controller(tmp_path: Path) -> None:
    with socket.socket() as held:  # bound, never listening: connections are refused
        held.bind(("127.0.0.1", 0))
        port = held.getsockname()[1]
        path = lab_toml(tmp_path, "wire", extra={**NO_SERVERS, "port = 0": f"port = {port}"})
        with pytest.raises(Disconnected) as err:
            async with Lab.from_config(path, model=MODEL):
                pass
    assert err.value.device == "lamp" and f"127.0.0.1:{port}" in str(err.value)


async def test_port_zero_needs_the_lab_to_serve_the_sim(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"goniometer\.lamp\.port: port 0 \(any free port\)"):
        load_lab_config(lab_toml(tmp_path, "wire", extra=NO_SERVERS))


async def test_missing_serial_port(tmp_path: Path) -> None:
    cfg = load_lab_config(lab_toml(tmp_path, "wire"))
    arms_only = build_sim_server(cfg, build_sim_instruments(cfg, MODEL, SimClock(0))).modbus
    async with SimLabServer(arms_only):
        spectro_line = 'port = "' + str(tmp_path / "sim" / "spectro")
        path = lab_toml(
            tmp_path,
            "wire",
            extra={
                **NO_SERVERS,
                "port = 0": f"port = {arms_only[0].port}",
                spectro_line: 'port = "/nonexistent/ttyX',
            },
        )
        with pytest.raises(Disconnected) as err:
            async with Lab.from_config(path, model=MODEL):
                pass
    assert err.value.device == "spectro" and "/nonexistent/ttyX" in str(err.value)


async def test_geared_arms_reach_the_commanded_angles(make_lab: Callable[..., Lab]) -> None:
    geared = {"steps_per_deg = 1000.0": "steps_per_deg = 10.0\ngear_ratio = 100.0"}
    async with make_lab(extra=geared) as lab:
        assert await lab.goniometer.move_to(30.0, 40.0, timeout_s=30.0) == (30.0, 40.0)
        assert lab.sims is not None
        assert (lab.sims.lamp.actual_deg(), lab.sims.detector.actual_deg()) == (30.0, 40.0)


async def _watch_separation(lab: Lab, done: asyncio.Event) -> float:
    """Smallest |theta_i + theta_r| of the simulated arms' encoders, sampled every 10 ms of
    the lab clock while the moves run (the arms' truth, not the drivers' bookkeeping)."""
    assert lab.sims is not None
    lamp, det = lab.sims.lamp.motor, lab.sims.detector.motor
    smallest = float("inf")
    while not done.is_set():
        now = lab.clock.now()
        smallest = min(smallest, abs(lamp.position_deg(now) + det.position_deg(now)))
        await lab.clock.sleep(0.01)
    return smallest


@pytest.mark.parametrize(
    "batch",
    [
        [("lamp", 5.0), ("detector", 3.0)],  # bluesky's bps.mv(lamp, 5, detector, 3)
        [("detector", 4.0), ("lamp", 4.0)],  # the last step of bp.scan(lamp 20->4, det 20->4)
        [("move_to", 20.0, 5.0), ("lamp", 3.0), ("detector", 30.0)],
    ],
)
async def test_concurrent_moves_never_pass_the_separation_minimum(
    lab: Lab, batch: list[tuple[Any, ...]]
) -> None:
    # issue 22 item 1: moves from several callers at once (bluesky devices, a jog beside a
    # scan) reserve the goniometer in turn; each is checked where the others left the arms
    g = lab.goniometer
    minimum = g.min_separation_deg
    done = asyncio.Event()
    watch = asyncio.ensure_future(_watch_separation(lab, done))

    async def op(spec: tuple[Any, ...]) -> None:
        if spec[0] == "move_to":
            await g.move_to(spec[1], spec[2], timeout_s=60.0)
        else:
            await g.move_arm(spec[0], spec[1], timeout_s=60.0)

    results = await asyncio.gather(*(op(s) for s in batch), return_exceptions=True)
    done.set()
    smallest = await watch
    for r in results:
        assert r is None or isinstance(r, InterlockError), repr(r)
    assert any(isinstance(r, InterlockError) for r in results)  # each batch has a refusal
    ti, tr = await g.positions_deg()
    assert abs(ti + tr) >= minimum - STEP_DEG
    assert smallest >= minimum - 2 * STEP_DEG, smallest
