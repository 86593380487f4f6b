"""Random concurrent moves on the lab, in-process and on the wire (issue 22 item 1).

Hypothesis draws batches of moves fired at the same time through the goniometer's entry
points every face uses (``move_to``: CLI, TUI, API, bluesky's two-arm device;
``move_arm``: bluesky's single-arm devices; ``park``), runs them on a freshly opened lab
(the twin in-process, and the real drivers over Modbus TCP to the simulated controllers)
and samples the simulated motors' encoders every 10 ms of the lab clock: the arms'
separation must never drop below ``min_separation_deg``. The truth is the motors' own
positions, not what the goniometer believes."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.base import DeviceError
from goniolab.lab_wiring import Lab
from tests.contract.contract_support import MODEL, lab_toml

pytestmark = pytest.mark.wire

angle_i = st.integers(0, 85).map(float)
angle_r = st.integers(0, 70).map(float)  # the detector arm spans 0..70 deg
operation = st.one_of(
    st.tuples(st.just("move_to"), angle_i, angle_r),
    st.tuples(st.just("lamp"), angle_i),
    st.tuples(st.just("detector"), angle_r),
    st.tuples(st.just("park")),
)
batches = st.lists(st.lists(operation, min_size=2, max_size=4), min_size=1, max_size=3)


async def _run(lab: Lab, plan: list[list[tuple[Any, ...]]]) -> float:
    g = lab.goniometer
    assert lab.sims is not None
    lamp, det = lab.sims.lamp.motor, lab.sims.detector.motor
    smallest = float("inf")
    done = asyncio.Event()

    async def watch() -> None:
        nonlocal smallest
        while not done.is_set():
            now = lab.clock.now()
            smallest = min(smallest, abs(lamp.position_deg(now) + det.position_deg(now)))
            await lab.clock.sleep(0.01)

    async def op(spec: tuple[Any, ...]) -> None:
        if spec[0] == "move_to":
            await g.move_to(spec[1], spec[2], timeout_s=60.0)
        elif spec[0] == "park":
            await g.park(timeout_s=60.0)
        else:
            await g.move_arm(spec[0], spec[1], timeout_s=60.0)

    watcher = asyncio.ensure_future(watch())
    for batch in plan:
        results = await asyncio.gather(*(op(s) for s in batch), return_exceptions=True)
        for r in results:  # refusals are the interlock's; nothing else may go wrong
            assert r is None or isinstance(r, DeviceError), repr(r)
    done.set()
    await watcher
    return smallest


@pytest.mark.parametrize(("backend", "examples"), [("inproc", 25), ("wire", 25)])
def test_random_concurrent_moves_keep_the_arms_apart(
    tmp_path_factory: pytest.TempPathFactory, backend: str, examples: int
) -> None:
    @settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    )
    @given(plan=batches)
    def check(plan: list[list[tuple[Any, ...]]]) -> None:
        tmp: Path = tmp_path_factory.mktemp(backend)

        async def go() -> tuple[float, float]:
            async with Lab.from_config(lab_toml(tmp, backend), model=MODEL) as lab:
                smallest = await _run(lab, plan)
                return smallest, lab.goniometer.min_separation_deg

        smallest, minimum = asyncio.run(go())
        assert smallest >= minimum - 2e-3, (smallest, plan)

    check()
