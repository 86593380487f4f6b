"""In-process simulated instruments: arms on the sim clock, spectro and glossmeter physics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.base import (
    Axis,
    DeviceFault,
    DeviceTimeout,
    Disconnected,
    Glossmeter,
    LimitError,
    ProtocolError,
    Spectrocolorimeter,
    StallError,
)
from drivers.timing import SimClock, trapezoid_duration_s
from goniolab.optics.apertures import Cone
from sim.faults import FaultInjector, FaultSpec
from sim.instruments import (
    SimAxis,
    SimGlossmeter,
    SimSpectro,
    effective_angles,
    spectrum_for_luminance,
)
from sim.motion import ALARM_OVERLOAD, SimMotor
from tests.sim.lobe import LobeModel

CONE6 = Cone(6.0)


def make_axis(
    clock: SimClock, name: str = "lamp", *, start_deg: float = 45.0, **kw: object
) -> SimAxis:
    motor = SimMotor(
        name,
        speed_deg_s=20.0,
        accel_deg_s2=40.0,
        soft_limits_deg=(-80.0, 85.0),
        start_deg=start_deg,
        homed=True,
    )
    return SimAxis(name, motor, clock, **kw)  # type: ignore[arg-type]


async def test_axis_move_takes_the_trapezoid_time_in_virtual_seconds() -> None:
    clock = SimClock(0)
    axis = make_axis(clock)
    assert isinstance(axis, Axis)
    await axis.connect()
    await axis.move_to(15.0)
    pos = await axis.wait_in_position(timeout_s=30.0)
    assert pos == 15.0
    assert clock.now() == pytest.approx(
        trapezoid_duration_s(30.0, 20.0, 40.0)
    )  # 30/20 + 20/40 = 2.0
    st = await axis.status()
    assert st.in_position and not st.moving and st.alarm_code is None


async def test_axis_limits_alarm_stall_timeout() -> None:
    clock = SimClock(0)
    axis = make_axis(clock)
    await axis.connect()
    with pytest.raises(LimitError, match=r"lamp: target 90 deg outside limits \[-80, 85\]"):
        await axis.move_to(90.0)
    # timeout: a 40 deg move needs 2.5 s
    await axis.move_to(5.0)
    with pytest.raises(DeviceTimeout, match="not in position after 1 s"):
        await axis.wait_in_position(1.0)
    assert clock.now() == pytest.approx(1.0)
    await axis.wait_in_position(10.0)
    # alarm mid-move
    axis.motor.inject_alarm(20.0)
    await axis.move_to(40.0)
    with pytest.raises(DeviceFault) as err:
        await axis.wait_in_position(10.0)
    assert err.value.code == ALARM_OVERLOAD and "alarm 0x30 at 20.000 deg" in str(err.value)
    with pytest.raises(DeviceFault):
        await axis.move_to(10.0)
    await axis.reset_alarm()
    # stall
    axis.motor.inject_stall(30.0)
    await axis.move_to(40.0)
    with pytest.raises(StallError, match=r"stalled at 30\.000 deg, commanded 40\.000 deg"):
        await axis.wait_in_position(10.0)


async def test_axis_home_and_stop() -> None:
    clock = SimClock(0)
    axis = make_axis(clock, start_deg=30.0)
    await axis.connect()
    await axis.home(timeout_s=10.0)
    assert await axis.position_deg() == 0.0
    assert (await axis.status()).homed
    await axis.move_to(60.0)
    await clock.sleep(1.0)  # virtual: 0.5 s accelerating (5 deg) + 0.5 s at 20 deg/s
    await axis.stop()
    assert await axis.position_deg() == pytest.approx(15.0)


async def test_fault_injection_is_seeded_and_reproducible() -> None:
    def run(seed: int) -> list[str]:
        inj = FaultInjector(
            "spectro", FaultSpec(timeout_rate=0.3, garble_rate=0.3), np.random.default_rng(seed)
        )
        return [inj.decide().value for _ in range(20)]

    assert run(7) == run(7)
    assert {"timeout", "garble", "none"} == set(run(7))
    clock = SimClock(0)
    axis = make_axis(clock, faults=FaultInjector("lamp", FaultSpec(disconnect_after=2)))
    await axis.connect()
    await axis.status()
    await axis.status()
    with pytest.raises(Disconnected, match="lamp: simulated disconnect after 2 operations"):
        await axis.status()
    spectro = SimSpectro(
        LobeModel(),
        make_axis(clock),
        make_axis(clock, "detector"),
        clock,
        faults=FaultInjector("spectro", FaultSpec(garble_rate=1.0)),
    )
    await spectro.connect()
    with pytest.raises(ProtocolError, match="spectro: simulated garbled reply to measure"):
        await spectro.measure()


def test_effective_angles_tilt_and_offsets() -> None:
    # tilt tau: normal at +tau, so ti_eff = ti + tau, tr_eff = tr - tau
    assert effective_angles(45.0, 45.0, sample_tilt_deg=1.0) == (46.0, 44.0)
    assert effective_angles(
        45.0, 45.0, lamp_zero_offset_deg=0.5, detector_zero_offset_deg=-0.25
    ) == (
        45.5,
        44.75,
    )


async def test_spectro_reads_the_model_at_the_actual_geometry() -> None:
    clock = SimClock(0)
    lamp, det = (
        make_axis(clock, "lamp", start_deg=45.0),
        make_axis(clock, "detector", start_deg=47.0),
    )
    model = LobeModel(width_deg=4.0)
    spectro = SimSpectro(
        model, lamp, det, clock, source_cone_deg=6.0, detector_cone_deg=3.0, noise_pct=0.0
    )
    assert isinstance(spectro, Spectrocolorimeter)
    await spectro.connect()
    reading = await spectro.measure()
    assert reading.luminance_pct == pytest.approx(100.0 * math.exp(-((2.0 / 4.0) ** 2)), rel=1e-12)
    assert model.calls[-1][2:] == (Cone(6.0), Cone(3.0))
    assert clock.now() == pytest.approx(0.01)  # the 10 ms exposure, in virtual time


async def test_sample_tilt_moves_the_specular_peak_by_twice_the_tilt() -> None:
    clock = SimClock(0)
    lamp, det = (
        make_axis(clock, "lamp", start_deg=40.0),
        make_axis(clock, "detector", start_deg=0.0),
    )
    spectro = SimSpectro(LobeModel(), lamp, det, clock, sample_tilt_deg=1.5)
    await lamp.connect()
    await det.connect()
    await spectro.connect()
    peak_deg, peak = 0.0, -1.0
    for tr in np.arange(36.0, 48.01, 0.5):
        await det.move_to(float(tr))
        await det.wait_in_position(10.0)
        lum = (await spectro.measure()).luminance_pct
        if lum > peak:
            peak_deg, peak = float(tr), lum
    assert peak_deg == pytest.approx(40.0 + 2 * 1.5)
    assert peak == pytest.approx(100.0)


async def test_spectro_noise_is_relative_and_seeded() -> None:
    clock = SimClock(0)
    lamp, det = make_axis(clock, start_deg=45.0), make_axis(clock, "detector", start_deg=45.0)
    values = []
    for _ in range(2):
        s = SimSpectro(LobeModel(), lamp, det, clock, noise_pct=1.0, rng=np.random.default_rng(3))
        await s.connect()
        values.append([(await s.measure()).luminance_pct for _ in range(400)])
    assert values[0] == values[1]
    v = np.asarray(values[0])
    assert v.mean() == pytest.approx(100.0, abs=0.2)  # 1 % of 100, /sqrt(400) = 0.05 sigma
    assert v.std() == pytest.approx(1.0, rel=0.15)


@pytest.mark.filterwarnings("ignore")  # colour-science shape-alignment notices
def test_spectrum_luminance_matches_colour_science_y() -> None:
    import colour

    values = spectrum_for_luminance(37.5)
    sd = colour.SpectralDistribution(dict(zip(range(380, 781, 10), values, strict=True)))
    cmfs = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"]
    xyz = colour.sd_to_XYZ(sd, cmfs, colour.SDS_ILLUMINANTS["D65"])  # Y = 100 for R = 100 %
    assert xyz[1] / 100.0 == pytest.approx(37.5, rel=2e-3)
    assert max(values) / min(values) == pytest.approx((1 + 1.5e-4 * 200) / (1 - 1.5e-4 * 200))


async def test_glossmeter_rounds_model_gloss_flags_overflow_and_streams() -> None:
    clock = SimClock(0)
    gm = SimGlossmeter(LobeModel(), clock, noise_pct=0.0, autosend_interval_s=5.0)
    assert isinstance(gm, Glossmeter)
    await gm.connect()
    r = await gm.measure()
    assert r.values_gu == {20: 81.3, 60: 93.0, 85: None}
    assert r.overflow_deg == (85,)
    r60 = await gm.measure([60])
    assert r60.values_gu == {20: None, 60: 93.0, 85: None}
    t0 = clock.now()
    stream = gm.readings()
    first = await anext(stream)
    assert first.values_gu[60] == 93.0
    assert clock.now() - t0 == pytest.approx(5.0 + gm.measure_time_s)
    with pytest.raises(ValueError, match="geometry 45 deg"):
        await gm.measure([45])


async def test_glossmeter_reads_the_new_sample_after_a_swap() -> None:
    """Putting another sample under the meter (``model = ...``) drops the cached gloss."""
    gm = SimGlossmeter(LobeModel(), SimClock(0), noise_pct=0.0)
    await gm.connect()
    assert (await gm.measure([60])).values_gu[60] == 93.0
    gm.model = LobeModel(gloss_gu={20: 10.0, 60: 42.04, 85: 50.0})
    assert (await gm.measure([60])).values_gu[60] == 42.0
