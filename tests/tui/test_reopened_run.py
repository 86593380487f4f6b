"""A run re-opened in the TUI's Runs screen shows the colour table it showed live.

Live readings carry their CIE XYZ and the white their L*a*b* is relative to, so the
comparison averages a point's repeats *as spectra* (the colour of the mean XYZ; XYZ is
linear in the spectrum, CIE 15:2004 eq. 7.1). A stored run replayed without them was
averaged as L*a*b* instead: another number for the same readings (issue 25).
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import numpy as np

from goniolab.optics.analytic import AnalyticModel
from goniolab.scan.events import ColourPredicted, PointMeasured, PointPredicted, RunFinished
from goniolab.tui.comparison import Comparison
from goniolab.tui.session_backend import SessionBackend
from goniolab.tui.view_model import ScanSetup
from tests.test_session import SETUP, sim_config  # the ideal twin, seeded noise kept


async def _live_scan(backend: SessionBackend) -> tuple[int, Comparison]:
    """Run the scan and fold its live events into a comparison, as the live view does."""
    live = Comparison()
    q = backend.bus.subscribe()
    run_id = await backend.start(ScanSetup(sample=backend.sample, **SETUP))
    while True:
        ev: Any = await asyncio.wait_for(q.get(), timeout=60)
        if isinstance(ev, PointMeasured):
            live.add_measured(ev)
        elif isinstance(ev, PointPredicted):
            live.add_predicted(ev)
        elif isinstance(ev, ColourPredicted):
            live.add_colour(ev)
        elif isinstance(ev, RunFinished) and ev.run_id == run_id:
            return run_id, live


def test_a_reopened_run_averages_repeats_as_spectra_like_the_live_one(tmp_path: Path) -> None:
    backend = SessionBackend(
        sim_config(tmp_path),
        model=AnalyticModel("beckmann", alpha=0.1),
        store_path=str(tmp_path / "runs.sqlite"),
    )

    async def scan() -> tuple[int, Comparison]:
        await backend.open()
        try:
            return await _live_scan(backend)
        finally:
            await backend.close()

    run_id, live = asyncio.run(scan())
    stored = backend.load_run(run_id)
    reopened = Comparison()
    for m in stored.measured:  # as the Runs screen replays it (screens.RunsScreen._show_run)
        reopened.add_measured(m)
    for c in stored.colours:
        reopened.add_colour(c)

    assert all(m.xyz is not None and m.white_xyz is not None for m in stored.measured)
    a, b = live.colour_arrays(), reopened.colour_arrays()
    assert a.measured_lab.shape == (5, 3) and not np.isnan(a.measured_lab).any()
    np.testing.assert_array_equal(b.theta_r_deg, a.theta_r_deg)
    np.testing.assert_array_equal(b.measured_lab, a.measured_lab)
    np.testing.assert_array_equal(b.predicted_lab, a.predicted_lab)
    # the two averages differ for these noisy repeats: the test tells them apart
    as_lab = np.array([np.mean(live.lab[i], axis=0) for i in sorted(live.lab)])
    assert not np.array_equal(as_lab, a.measured_lab)
