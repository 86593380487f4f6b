"""The run's ETA leaves a pause out of its pace (issue 27: the ETA doubled after a pause).

The truth is the dry run's own arithmetic: readings of 10 s each and a 5 s park; a run
that keeps to the estimate has, after reading k, the sum of the remaining estimates left,
whatever time it spent paused in between."""

from __future__ import annotations

import pytest

from goniolab.scan.dryrun import RunEta


def test_a_pause_does_not_stretch_the_eta() -> None:
    eta = RunEta([10.0, 10.0, 10.0, 10.0], 5.0)
    eta.start(0.0)
    assert eta.left_after(0, 10.0) == pytest.approx(35.0)
    eta.pause(10.0)  # paused for 100 s of lab clock between readings 0 and 1
    eta.resume(110.0)
    assert eta.left_after(1, 120.0) == pytest.approx(25.0)  # was 25 x 120/20 = 150 s
    assert eta.left_after(2, 130.0) == pytest.approx(15.0)


def test_a_slow_run_still_stretches_it() -> None:
    eta = RunEta([10.0, 10.0, 10.0], 5.0)
    eta.start(0.0)
    assert eta.left_after(0, 20.0) == pytest.approx(2.0 * 25.0)  # twice as slow as estimated
    eta.pause(20.0)
    eta.resume(20.0)  # a pause of no time changes nothing
    assert eta.left_after(1, 40.0) == pytest.approx(2.0 * 15.0)
