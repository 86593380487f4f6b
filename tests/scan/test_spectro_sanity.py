"""An implausible spectro value is refused, reported with its value and read again; a
spectro that keeps answering so fails the run with the message; nothing absurd is stored
(issue 23.13: Y = -50 was stored as -50 %, Y = 1e300 made the RMSE infinite and ``runs show
--json`` print ``Infinity``).

The truth: the plausible range of a reading in % of the mirror reference, [-1, 1000] %
(:mod:`goniolab.scan.sanity`), and the JSON standard (RFC 8259 has no NaN or Infinity).
"""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from drivers.base import SpectroReading
from goniolab.scan.events import InstrumentError, RunState
from goniolab.scan.plans import BrdfPlan, parse_angles
from goniolab.scan.sanity import ImplausibleReading, check_reading
from goniolab.store import RunStore

from .conftest import FakeLab
from .test_runner import drive, make_runner

BAD = [-50.0, 1e300, math.inf, -math.inf, math.nan, 1000.5, -1.01]
GOOD = [-1.0, -0.02, 0.0, 4.9, 100.0, 250.0, 1000.0]


@pytest.mark.parametrize("y", BAD)
def test_implausible_values_are_refused_naming_them(y: float) -> None:
    reading = SpectroReading((380.0, 385.0), (1.0, 1.0), y)
    with pytest.raises(ImplausibleReading, match="implausible reading: Y = "):
        check_reading(reading)


@pytest.mark.parametrize("y", GOOD)
def test_plausible_values_pass_unchanged(y: float) -> None:
    reading = SpectroReading((380.0, 385.0), (1.0, 1.0), y)
    assert check_reading(reading) is reading


class _Spoiling:
    """The fake spectro, with the readings of the calls in ``bad`` given luminance ``y``."""

    def __init__(self, inner: object, bad: set[int], y: float) -> None:
        self.inner, self.bad, self.y, self.calls = inner, bad, y, 0

    def __getattr__(self, name: str) -> object:
        return getattr(self.inner, name)

    async def measure(self) -> SpectroReading:
        self.calls += 1
        r: SpectroReading = await self.inner.measure()  # type: ignore[attr-defined]
        return dataclasses.replace(r, luminance_pct=self.y) if self.calls in self.bad else r


@pytest.mark.parametrize("y", [-50.0, 1e300])
async def test_one_implausible_reading_is_read_again(
    fake_lab: FakeLab, store: RunStore, y: float
) -> None:
    spectro = _Spoiling(fake_lab.spectro, {2}, y)
    fake_lab.spectro = spectro  # type: ignore[assignment]
    plan = BrdfPlan(45.0, parse_angles("44:46:1"), repeats=1)
    runner, bus = make_runner(fake_lab, store, plan, reading_retries=2)
    events = await drive(runner, bus, lambda ev: None)
    assert runner.state is RunState.DONE
    lum = [p.luminance_pct for p in store.points(runner.run_id)]
    assert len(lum) == 3 and all(0.0 < v < 100.0 for v in lum)  # the re-read value stored
    (warning,) = [e for e in events if isinstance(e, InstrumentError)]
    assert not warning.fatal
    assert f"Y = {y:.6g} % of the mirror" in warning.message and "retry 1 of 2" in warning.message


async def test_a_spectro_that_keeps_answering_absurdly_fails_the_run(
    fake_lab: FakeLab, store: RunStore
) -> None:
    spectro = _Spoiling(fake_lab.spectro, {2, 3, 4}, -50.0)
    fake_lab.spectro = spectro  # type: ignore[assignment]
    plan = BrdfPlan(45.0, parse_angles("44:46:1"), repeats=1)
    runner, bus = make_runner(fake_lab, store, plan, reading_retries=2)
    await drive(runner, bus, lambda ev: None)
    assert runner.state is RunState.FAILED
    assert store.count_points(runner.run_id) == 1  # the first reading only; -50 never stored
    assert "Y = -50 % of the mirror" in (store.get_run(runner.run_id).reason or "")


def test_runs_show_and_export_json_of_an_old_absurd_run_are_valid_json(
    tmp_path: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    """A store written before the check holds Y = 1e300 and -50: the RMSE overflows to inf.
    ``runs show --json`` and ``runs export --format json`` stay RFC 8259 JSON (``null``)."""
    from pathlib import Path

    from goniolab.cli import main

    path = Path(str(tmp_path)) / "old.sqlite"
    plan = BrdfPlan(45.0, (40.0, 45.0, 50.0), repeats=1, sample="sample:x")
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample="sample:x",
                           model={}, version="t")  # fmt: skip
        for k, (tr, y) in enumerate(zip(plan.theta_r_deg, (1e300, -50.0, 1e300), strict=True)):
            s.add_point(rid, index=k, repeat=0, theta_i_deg=45.0, theta_r_deg=tr,
                        measured_theta_i_deg=45.0, measured_theta_r_deg=tr, luminance_pct=y,
                        raw={}, timestamp=1.0 + k)  # fmt: skip
        s.add_predictions(rid, [(0, 45.0, 40.0, 1.0), (1, 45.0, 45.0, 2.0), (2, 45.0, 50.0, 1.0)])
        s.set_status(rid, "done")

    def strict(text: str) -> object:
        def refuse(word: str) -> None:
            raise ValueError(f"not JSON: {word}")

        return json.loads(text, parse_constant=refuse)

    assert main(["runs", "show", "1", "--json", "--store", str(path)]) == 0
    doc = strict(capsys.readouterr().out)
    assert isinstance(doc, dict)
    assert main(["runs", "export", "1", "--format", "json", "--store", str(path)]) == 0
    strict(capsys.readouterr().out)
    assert main(["runs", "list", "--json", "--store", str(path)]) == 0
    strict(capsys.readouterr().out)
