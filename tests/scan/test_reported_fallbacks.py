"""Fallbacks of the scan and the alignment that used to be silent are said (issue 4 of the
lab-fix brief, "no silent substitution"): an alignment move made without its approach from
below is published and counted in the stored result; a fit parameter whose variance came
out negative is an unknown uncertainty (refused), not an exact one."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest

from drivers.arm_limits import geometry_problem
from drivers.base import InterlockError, LimitError
from goniolab.scan.align import AlignResult, AlignRunner
from goniolab.scan.black_glass_fit import (
    AlignGates,
    AlignRefused,
    StandardFit,
    check_standard,
    parameter_sigmas,
)
from goniolab.scan.events import EventBus, InstrumentError


class _Arms:
    """Two arms that move at once; limits lamp 0..85, detector 20..70 deg, 10 deg apart."""

    def __init__(self, at: tuple[float, float]) -> None:
        self.at = at
        self.moves: list[tuple[float, float]] = []

    async def positions_deg(self) -> tuple[float, float]:
        return self.at

    def check_geometry(self, theta_i_deg: float, theta_r_deg: float) -> None:
        problem = geometry_problem(
            theta_i_deg, theta_r_deg, lamp_limits_deg=(0.0, 85.0),
            detector_limits_deg=(20.0, 70.0), min_separation_deg=10.0,
        )  # fmt: skip
        if problem is not None:
            error = LimitError if problem.kind == "limit" else InterlockError
            raise error(problem.message, device=problem.device)

    async def move_to(self, theta_i_deg: float, theta_r_deg: float, timeout_s: float) -> None:
        self.check_geometry(theta_i_deg, theta_r_deg)
        self.at = (theta_i_deg, theta_r_deg)
        self.moves.append(self.at)


def _runner(arms: _Arms, bus: EventBus) -> AlignRunner:
    # only what AlignRunner._go reads: the arms, the events, the move timeout
    runner = object.__new__(AlignRunner)
    runner.goniometer = arms  # type: ignore[assignment]
    runner.bus, runner.run_id, runner.move_timeout_s = bus, 7, 30.0
    runner._position, runner.approaches_skipped, runner.motion = None, 0, None
    return runner


def test_an_alignment_move_without_its_approach_from_below_is_said_and_counted() -> None:
    async def go() -> tuple[_Arms, AlignRunner, list[InstrumentError]]:
        bus = EventBus()
        q = bus.subscribe()
        arms = _Arms((30.0, 40.0))
        runner = _runner(arms, bus)
        # down to (25, 21): the approach point (24.5, 20.5) is within reach: taken
        await runner._go(25.0, 21.0)
        # down to (24, 20): the approach point (23.5, 19.5) is below the detector's 20 deg
        await runner._go(24.0, 20.0)
        events = []
        while not q.empty():
            ev = q.get_nowait()
            if isinstance(ev, InstrumentError):
                events.append(ev)
        return arms, runner, events

    arms, runner, events = asyncio.run(go())
    assert arms.moves == [(24.5, 20.5), (25.0, 21.0), (24.0, 20.0)]
    assert runner.approaches_skipped == 1
    (ev,) = events
    assert not ev.fatal and ev.device == "goniometer" and ev.run_id == 7
    assert ev.message == (
        "approach from below skipped: theta_i 23.5, theta_r 19.5 deg: detector: "
        "theta_r=19.5 deg outside the detector arm limits [20.0, 70.0] deg; moving to "
        "theta_i 24, theta_r 20 deg directly (the arms' backlash is not taken out there)"
    )
    # the stored result carries the count
    result = AlignResult(0.0, 0.0, 0.0, 0.0, approaches_skipped=runner.approaches_skipped)
    assert result.as_dict()["approaches_skipped"] == 1


def test_a_negative_variance_is_an_unknown_uncertainty_not_zero() -> None:
    sd = parameter_sigmas(np.array([4.0, -1e-12, math.nan, 0.25, math.inf]))
    np.testing.assert_array_equal(sd, [2.0, math.inf, math.inf, 0.5, math.inf])
    # a fit whose lamp-zero variance came out negative is refused by the sigma gate (it
    # was clipped to 0 and passed as an exact zero)
    fit = StandardFit(
        lamp_zero_deg=0.1, detector_zero_deg=-0.1, scale=1.0, floor_pct=0.0, rms_rel=0.001,
        lamp_zero_sigma_deg=float(parameter_sigmas(np.array([-1e-9]))[0]),
        detector_zero_sigma_deg=0.01, geometric_difference_deg=math.nan,
    )  # fmt: skip
    peaks = [{"theta_i_deg": t, "peak_deg": t, "amplitude_pct": 100 * r}
             for t, r in ((20.0, 0.04908), (40.0, 0.05494), (60.0, 0.10006))]  # fmt: skip
    with pytest.raises(AlignRefused, match=r"the zeros are uncertain to inf deg"):
        check_standard(fit, peaks, AlignGates(), n=1.567, certificate="G", saturated=0)
