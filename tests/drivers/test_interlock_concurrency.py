"""The separation interlock under concurrent moves (issue 22, item 1).

Every face ends in :class:`drivers.goniometer.TwoArmGoniometer`: the CLI, TUI and API through
the runner's ``move_to``/``home``/``park``, bluesky through ``move_arm`` (one arm per
device, both set at once by ``bps.mv(lamp, a, detector, b)``) and ``move_to`` (the two-arm
device). A hypothesis state machine fires random batches of those calls *at the same time*
and a monitor records ``|theta_i + theta_r|`` after every step of either arm: the
separation must never drop below ``min_separation_deg``, whatever the order the event loop
runs them in. The independent truth is the geometry itself (the monitor sees the fake
arms' positions, not the goniometer's bookkeeping).

Before the motion lock, ``bps.mv(lamp, 5, detector, 3)`` from (45, 45) ended at (5, 3):
each single-arm move was checked against the other arm's position read before the other
move ran.
"""

from __future__ import annotations

import asyncio
from typing import Any

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

from drivers.base import DeviceError, InterlockError
from tests.drivers.test_goniometer import rig

MIN_SEP = 10.0

angle_i = st.floats(0.0, 85.0, allow_nan=False).map(lambda v: round(v, 1))
angle_r = st.floats(-85.0, 85.0, allow_nan=False).map(lambda v: round(v, 1))
operation = st.one_of(
    st.tuples(st.just("move_to"), angle_i, angle_r),
    st.tuples(st.just("lamp"), angle_i),
    st.tuples(st.just("detector"), angle_r),
    st.tuples(st.just("park")),
    st.tuples(st.just("home")),
)


async def run_op(g: Any, op: tuple[Any, ...]) -> None:
    kind = op[0]
    if kind == "move_to":
        await g.move_to(op[1], op[2], timeout_s=60.0)
    elif kind in ("lamp", "detector"):
        await g.move_arm(kind, op[1], timeout_s=60.0)
    elif kind == "park":
        await g.park(timeout_s=60.0)
    else:
        await g.home(timeout_s=60.0)


class ConcurrentMoves(RuleBasedStateMachine):
    """Random concurrent batches on one goniometer (arms of different speeds)."""

    def __init__(self) -> None:
        super().__init__()
        self.g, self.m = rig(45.0, 45.0, lamp_step=0.7, det_step=0.3, min_sep=MIN_SEP)
        self.refused = 0

    @rule(batch=st.lists(operation, min_size=1, max_size=4))
    def concurrent_batch(self, batch: list[tuple[Any, ...]]) -> None:
        async def go() -> list[Any]:
            return await asyncio.gather(
                *(run_op(self.g, op) for op in batch), return_exceptions=True
            )

        for result in asyncio.run(go()):
            if isinstance(result, BaseException):
                # refusals are the interlock doing its job; nothing else may go wrong
                assert isinstance(result, DeviceError), repr(result)
                self.refused += 1

    @invariant()
    def separation_never_below_minimum(self) -> None:
        assert self.m.min_separation_seen >= MIN_SEP - 1e-9, self.m.min_separation_seen
        lamp, det = self.m.arms["lamp"].pos, self.m.arms["detector"].pos
        assert lamp + det >= MIN_SEP - 1e-9  # and never crossed (the start side is +)


ConcurrentMoves.TestCase.settings = settings(
    max_examples=60,
    stateful_step_count=8,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
TestConcurrentMoves = ConcurrentMoves.TestCase


async def test_bluesky_pair_of_single_arm_moves_is_refused_in_order() -> None:
    # the case: from (45, 45), lamp -> 5 and detector -> 3 at once (8 deg apart)
    g, m = rig(45.0, 45.0, min_sep=MIN_SEP)
    results = await asyncio.gather(
        g.move_arm("lamp", 5.0, 60.0), g.move_arm("detector", 3.0, 60.0), return_exceptions=True
    )
    assert results[0] == (5.0, 45.0)  # the first one runs: 50 deg apart
    assert isinstance(results[1], InterlockError)  # checked against the lamp at 5, not 45
    assert "8.000 deg apart" in str(results[1])
    assert (m.arms["lamp"].pos, m.arms["detector"].pos) == (5.0, 45.0)
    assert m.min_separation_seen >= MIN_SEP


async def test_the_other_arm_is_never_sent_back_to_a_stale_position() -> None:
    # a single-arm move keeps the other arm where it stands *when the move starts*: the
    # detector's move must not drag the lamp back to where it stood before the lamp's move
    g, m = rig(45.0, 45.0, min_sep=MIN_SEP)
    await asyncio.gather(g.move_arm("lamp", 30.0, 60.0), g.move_arm("detector", 20.0, 60.0))
    assert (m.arms["lamp"].pos, m.arms["detector"].pos) == (30.0, 20.0)
    assert [e for e in m.events if e[0] == "move"] == [
        ("move", "lamp", 30.0),
        ("move", "detector", 20.0),
    ]


async def test_pending_target_is_visible_while_a_move_runs() -> None:
    g, _ = rig(45.0, 45.0, lamp_step=0.1, min_sep=MIN_SEP)
    assert g.pending_deg is None and not g.busy
    task = asyncio.ensure_future(g.move_to(30.0, 45.0, 60.0))
    for _ in range(5):
        await asyncio.sleep(0)
    assert g.pending_deg == (30.0, 45.0) and g.busy
    await task
    assert g.pending_deg is None and not g.busy
