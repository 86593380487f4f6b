"""The ETA from measured rates of a reading's parts (issue 27).

The truth is a fake wall clock whose moves, dwells, readings and loop overhead take known
durations (a move ``0.3 s + 1.5 x`` for a motion-model time ``x``: arms slower than their
config and a bus overhead); the time left after reading k is then the analytic sum of the
remaining parts' durations, which the estimate must reach once it has measured two move
sizes, whatever time the run spent paused, and also on an instant sim clock
(``--time-scale 0``: the lab's sleeps take no wall time, the readings' computing does).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest

from goniolab.scan.dryrun import ArmMotion
from goniolab.scan.eta import EtaEstimator, PartRate, PointParts, WallTime

MOTION = ArmMotion(20.0, 40.0, 20.0, 40.0)
GEOMETRIES = [(45.0, 10.0 + 5.0 * k) for k in range(7)]  # 10..40 deg in 5 deg steps
START, PARK = (0.0, 0.0), (45.0, 45.0)
DWELL_S, EXPOSURE_S = 0.25, 0.02


class FakeWall:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t


@dataclass(frozen=True)
class Truth:
    """How long each part really takes on the fake wall clock."""

    move_fixed_s: float
    move_per_x: float
    dwell_per_s: float
    reading_s: float
    other_s: float

    def move(self, x: float) -> float:
        return self.move_fixed_s + self.move_per_x * x

    def point(self, p: PointParts) -> float:
        t = self.reading_s + self.other_s
        if p.move_x is not None:
            t += self.move(p.move_x) + self.dwell_per_s * p.dwell_lab_s
        return t


SLOW_ARMS = Truth(0.3, 1.5, 1.0, EXPOSURE_S + 0.05, 0.02)
INSTANT_CLOCK = Truth(0.002, 0.0, 0.0, 0.4, 0.01)  # --time-scale 0: computing only


def parts() -> tuple[list[PointParts], float]:
    """Each reading's model sizes (move, dwell, exposure) and the park move's."""
    out, pos = [], START
    for g in GEOMETRIES:
        out.append(PointParts(MOTION.move_time_s(pos, g), DWELL_S, EXPOSURE_S))
        pos = g
    return out, MOTION.move_time_s(pos, PARK)


def run(
    truth: Truth, per_lab_s: float, pause_after: int | None = None, pause_s: float = 0.0
) -> tuple[EtaEstimator, list[float], list[float]]:
    """Drive an estimator through the run on the fake clock: the ETA after each reading and
    the analytic time left then. From reading ``pause_after`` on, a pause (an operator's,
    then a store outage inside the next reading) follows every reading: more than the
    estimator's trimming of a one-off slow part could hide."""
    wall = FakeWall()
    points, park_x = parts()
    eta = EtaEstimator(points, park_x, WallTime(wall.now, per_lab_s))
    etas, truths = [], []
    eta.begin_point()
    for k, p in enumerate(points):
        if pause_after is not None and k > pause_after:
            eta.pause()
            wall.t += pause_s
            eta.resume()
        assert p.move_x is not None
        with eta.part("move", p.move_x):
            wall.t += truth.move(p.move_x)
        with eta.part("dwell", p.dwell_lab_s):
            wall.t += truth.dwell_per_s * p.dwell_lab_s
        with eta.part("reading", p.reading_lab_s):
            wall.t += truth.reading_s / 2
            if pause_after is not None and k > pause_after:
                eta.pause()  # the store is away: the run waits with the arms parked
                wall.t += pause_s
                eta.resume()
            wall.t += truth.reading_s / 2
        wall.t += truth.other_s
        etas.append(eta.end_point(k))
        truths.append(math.fsum(truth.point(q) for q in points[k + 1 :]) + truth.move(park_x))
    return eta, etas, truths


def test_the_eta_reaches_the_analytic_time_left_once_two_move_sizes_were_timed() -> None:
    points, park_x = parts()
    eta = EtaEstimator(points, park_x, WallTime(FakeWall().now, 1.0))
    # before any reading: the motion model's own sum (lab seconds at real time)
    model = math.fsum(p.move_x + p.dwell_lab_s + p.reading_lab_s for p in points if p.move_x)
    assert eta.total_s == pytest.approx(model + park_x, rel=1e-12)
    _, etas, truths = run(SLOW_ARMS, per_lab_s=1.0)
    # after reading 0 only one move size is known: not yet right, but already moving
    assert abs(etas[0] - truths[0]) > 0.1
    # from reading 1 on (the 45 deg first move and a 5 deg step timed): the analytic time
    for k in range(1, len(etas)):
        assert etas[k] == pytest.approx(truths[k], rel=1e-9), k
    assert etas[-1] == pytest.approx(SLOW_ARMS.move(park_x), rel=1e-9)  # the park move
    assert etas == sorted(etas, reverse=True)


def test_a_pause_leaves_the_eta_unchanged() -> None:
    _, plain, _ = run(SLOW_ARMS, per_lab_s=1.0)
    _, paused, truths = run(SLOW_ARMS, per_lab_s=1.0, pause_after=1, pause_s=100.0)
    assert paused == pytest.approx(plain, rel=1e-12)
    assert paused[3] == pytest.approx(truths[3], rel=1e-9)  # not 100 s longer, not doubled


def test_an_instant_clock_gets_the_computing_time_not_zero() -> None:
    """--time-scale 0: the motion model's lab seconds take no wall time; the ETA is "?"
    (NaN) before two readings were timed, then the readings' computing, not "ETA 0 s"."""
    points, park_x = parts()
    eta = EtaEstimator(points, park_x, WallTime(FakeWall().now, 0.0))
    assert math.isnan(eta.total_s)
    _, etas, truths = run(INSTANT_CLOCK, per_lab_s=0.0)
    assert math.isnan(etas[0])  # one reading alone may be the warm-up: still "?"
    for k in range(1, len(etas)):
        assert etas[k] == pytest.approx(truths[k], rel=1e-9), k
    assert etas[1] > 0.4 * (len(points) - 2)  # the readings' computing


def test_a_part_rate_is_the_least_squares_line_and_never_negative() -> None:
    rate = PartRate(prior_per_x=1.0)
    assert rate.predict(2.0) == 2.0  # the prior
    rate.add(1.0, 3.0)
    assert rate.predict(2.0) == pytest.approx(4.0)  # the prior slope, the measured excess
    rate.add(3.0, 7.0)
    assert rate.predict(5.0) == pytest.approx(11.0)  # the line w = 1 + 2 x
    faster = PartRate(prior_per_x=1.0)
    faster.add(2.0, 0.5)
    assert faster.predict(0.1) == 0.0  # clamped, not negative
    warm = PartRate(prior_per_x=1.0)
    warm.add(0.02, 3.0)  # the first reading: 3 s of JIT compilation on a 20 ms exposure
    assert warm.predict(0.02) == pytest.approx(0.02)  # a warm-up: the prior still holds
    warm.add(0.02, 0.05)
    assert warm.predict(0.02) == pytest.approx(0.05)  # the warm-up left out of the pace
    unknown = PartRate(prior_per_x=None)
    assert math.isnan(unknown.predict(1.0))
    unknown.add(4.0, 2.0)
    assert math.isnan(unknown.predict(9.0))  # one part alone: not a pace yet
    unknown.add(4.0, 2.2)
    assert unknown.predict(9.0) == pytest.approx(4.5)  # one size, no model: proportional
