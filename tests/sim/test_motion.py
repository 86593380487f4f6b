"""Motion model against the analytic trapezoid, limit switches, homing, stall, alarm."""

from __future__ import annotations

import math

import pytest

from drivers.timing import MoveProfile, trapezoid_duration_s
from sim.motion import (
    ALARM_HW_OVERTRAVEL,
    ALARM_OVERLOAD,
    ALARM_SW_OVERTRAVEL,
    MotorFault,
    SimMotor,
)


def test_long_move_duration_is_d_over_v_plus_v_over_a() -> None:
    # d = 60, v = 20, a = 40: full speed reached (v^2/a = 10 <= 60); T = 3 + 0.5
    assert trapezoid_duration_s(60.0, 20.0, 40.0) == pytest.approx(3.5)
    p = MoveProfile(10.0, 70.0, 20.0, 40.0, t0_s=2.0)
    assert p.duration_s == pytest.approx(3.5)
    assert p.end_s == pytest.approx(5.5)


def test_short_move_is_triangular() -> None:
    # d = 4 < v^2/a = 10: T = 2 sqrt(d/a) = 2 sqrt(0.1); peak speed sqrt(a d) = sqrt(160)
    assert trapezoid_duration_s(4.0, 20.0, 40.0) == pytest.approx(2 * math.sqrt(0.1))
    p = MoveProfile(0.0, -4.0, 20.0, 40.0, t0_s=0.0)
    assert p.peak_speed_deg_s == pytest.approx(math.sqrt(160.0))
    # at half time the arm is half way, at full (negative) peak speed
    assert p.position_at(math.sqrt(0.1)) == pytest.approx(-2.0)
    assert p.velocity_at(math.sqrt(0.1)) == pytest.approx(-math.sqrt(160.0))


@pytest.mark.parametrize(
    ("t", "expected"),
    [
        (0.0, 10.0),
        (0.25, 10.0 + 0.5 * 40 * 0.25**2),  # accelerating: s = a t^2 / 2
        (0.5, 15.0),  # end of acceleration: v^2 / 2a = 5
        (2.0, 15.0 + 20 * 1.5),  # cruising at v
        (3.25, 70.0 - 0.5 * 40 * 0.25**2),  # decelerating, symmetric to the start
        (3.5, 70.0),
        (9.0, 70.0),
    ],
)
def test_position_follows_the_analytic_trapezoid(t: float, expected: float) -> None:
    p = MoveProfile(10.0, 70.0, 20.0, 40.0, t0_s=0.0)
    assert p.position_at(t) == pytest.approx(expected)


def test_time_at_inverts_position_at() -> None:
    p = MoveProfile(10.0, 70.0, 20.0, 40.0, t0_s=1.0)
    for pos in (10.0, 12.0, 15.0, 40.0, 68.0, 70.0):
        t = p.time_at(pos)
        assert t is not None
        assert p.position_at(t) == pytest.approx(pos)
    assert p.time_at(80.0) is None


def motor(**kw: float) -> SimMotor:
    args: dict[str, object] = {
        "speed_deg_s": 20.0,
        "accel_deg_s2": 40.0,
        "soft_limits_deg": (0.0, 85.0),
        "hard_margin_deg": 1.0,
        "homed": True,
    }
    args.update(kw)
    return SimMotor("lamp", **args)  # type: ignore[arg-type]


def test_motor_move_is_analytic_in_time() -> None:
    m = motor()
    m.start_move(60.0, now_s=0.0)
    assert m.is_moving(1.0)
    assert m.position_deg(2.0) == pytest.approx(5.0 + 20 * 1.5)
    assert m.command_deg(2.0) == pytest.approx(35.0)
    assert m.next_event_s(2.0) == pytest.approx(3.5)
    assert not m.is_moving(3.5)
    assert m.position_deg(10.0) == 60.0


def test_soft_limit_raises_software_overtravel_without_moving() -> None:
    m = motor()
    with pytest.raises(MotorFault) as err:
        m.start_move(90.0, now_s=0.0)
    assert err.value.code == ALARM_SW_OVERTRAVEL
    assert m.position_deg(5.0) == 0.0
    assert m.alarm_code(5.0) == ALARM_SW_OVERTRAVEL


def test_limit_switch_stops_the_arm_slightly_beyond_the_soft_limit() -> None:
    # unhomed arm standing at physical 80 (encoder reads 0): a 10 deg move crosses the
    # upper switch at 85 + 1 = 86 deg physical
    m = SimMotor(
        "lamp", speed_deg_s=20.0, accel_deg_s2=40.0, soft_limits_deg=(0.0, 85.0), start_deg=80.0
    )
    p = m.start_move(10.0, now_s=0.0)
    t_hit = p.time_at(86.0)
    assert t_hit is not None
    assert m.next_event_s(0.0) == pytest.approx(t_hit)
    assert m.alarm_code(t_hit + 1.0) == ALARM_HW_OVERTRAVEL
    assert m.physical_deg(t_hit + 1.0) == pytest.approx(86.0)
    with pytest.raises(MotorFault):
        m.start_move(0.0, now_s=t_hit + 1.0)
    m.reset_alarm(t_hit + 1.0)
    m.start_move(0.0, now_s=t_hit + 2.0)  # accepted once reset


def test_homing_moves_to_the_switch_and_zeroes_the_encoder() -> None:
    m = SimMotor(
        "lamp", speed_deg_s=20.0, accel_deg_s2=40.0, soft_limits_deg=(-5.0, 85.0), start_deg=30.0
    )
    assert not m.homed and m.position_deg(0.0) == 0.0  # encoder reads 0 where it powered up
    p = m.start_home(now_s=0.0)
    assert p.distance_deg == 30.0
    assert m.is_homing(0.1)
    assert m.position_deg(0.5) == pytest.approx(0.0 - 5.0)  # 5 deg travelled toward the switch
    end = p.end_s
    assert m.homed is False
    assert m.position_deg(end) == 0.0 and m.physical_deg(end) == 0.0
    assert m.homed is True


def test_stall_freezes_feedback_while_command_runs_on() -> None:
    m = motor()
    m.inject_stall(30.0)
    p = m.start_move(60.0, now_s=0.0)
    assert m.position_deg(2.5) == 30.0
    assert m.command_deg(2.5) == pytest.approx(p.position_at(2.5))
    assert m.is_moving(2.5)
    assert not m.is_moving(p.end_s)
    assert m.position_deg(p.end_s) == 30.0 and m.command_deg(p.end_s) == 60.0
    assert m.alarm_code(p.end_s) is None


def test_alarm_mid_move_stops_and_latches_code() -> None:
    m = motor()
    m.inject_alarm(20.0, code=ALARM_OVERLOAD)
    p = m.start_move(60.0, now_s=0.0)
    t = p.time_at(20.0)
    assert t is not None
    assert m.alarm_code(t - 1e-6) is None
    assert m.alarm_code(t) == ALARM_OVERLOAD
    assert m.position_deg(t + 5.0) == pytest.approx(20.0)
    m.reset_alarm(t + 5.0)
    m.start_move(60.0, now_s=t + 5.0)  # one-shot: the next move runs through
    assert m.position_deg(t + 100.0) == 60.0


def test_stop_halts_where_the_arm_is() -> None:
    m = motor()
    m.start_move(60.0, now_s=0.0)
    m.stop(2.0)
    assert m.position_deg(5.0) == pytest.approx(35.0)
    assert m.command_deg(5.0) == pytest.approx(35.0)
    assert not m.is_moving(2.0)
