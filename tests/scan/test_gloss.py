"""The gloss logger: readings stored as they come, garbled lines and disconnects survived."""

from __future__ import annotations

import asyncio

import pytest

from drivers.base import Disconnected, GlossReading, ProtocolError
from drivers.timing import SimClock
from goniolab.scan.events import EventBus, GlossRead, InstrumentError, RunState
from goniolab.scan.gloss_logger import GlossLogger, predict_gloss
from goniolab.scan.plans import GlossPlan
from goniolab.store import RunStore

from .conftest import FakeGlossmeter, FakeModel


def reading(g20: float, g60: float, g85: float, t: float) -> GlossReading:
    return GlossReading(values_gu={20: g20, 60: g60, 85: g85}, temperature_c=25.0, timestamp=t,
                        raw=f"1| 401120999|xy|{round(g20 * 10)}|...")  # fmt: skip


def make(store: RunStore, script: list[GlossReading | Exception], count: int, **kw: object
         ) -> tuple[GlossLogger, FakeGlossmeter, EventBus, SimClock]:  # fmt: skip
    meter = FakeGlossmeter(script)
    bus = EventBus()
    clock = SimClock(0)
    rid = store.create_run(kind="gloss", plan={}, config={}, sample="", model={}, version="t")
    logger = GlossLogger(meter=meter, store=store, run_id=rid, bus=bus, clock=clock,
                         plan=GlossPlan(count=count), predicted_gu={20: 80.0, 60: 90.0, 85: 95.0},
                         **kw)  # type: ignore[arg-type]  # fmt: skip
    return logger, meter, bus, clock


async def test_garble_and_disconnect_lose_nothing(store: RunStore) -> None:
    script: list[GlossReading | Exception] = [
        reading(80.1, 90.0, 95.2, 1.0),
        ProtocolError("garbled reply '1| 4011x0999|xy|9'", device="glossmeter"),
        reading(80.3, 90.2, 95.0, 2.0),
        Disconnected("port closed", device="glossmeter"),
        Disconnected("port closed", device="glossmeter"),
        reading(80.5, 90.4, 94.8, 3.0),
    ]
    logger, meter, bus, clock = make(store, script, 3)
    q = bus.subscribe()
    result = await logger.run()
    assert result.state is RunState.DONE and result.readings == 3
    # two reconnects with exponential backoff on the lab clock: 0.5 s then 1.0 s
    assert result.reconnects == 2 and meter.connects == 2 and meter.closes == 2
    assert clock.now() == pytest.approx(1.5, abs=1e-12)
    rows = store.gloss_readings(result.run_id)
    assert [r.values_gu[60] for r in rows] == [90.0, 90.2, 90.4]
    assert rows[0].predicted_gu == {20: 80.0, 60: 90.0, 85: 95.0}
    events = []
    while not q.empty():
        events.append(q.get_nowait())
    errors = [e for e in events if isinstance(e, InstrumentError)]
    assert len(errors) == 3 and not any(e.fatal for e in errors)
    assert "garbled" in errors[0].message
    assert len([e for e in events if isinstance(e, GlossRead)]) == 3
    # mean and sample std of 90.0, 90.2, 90.4: 90.2 and 0.2
    assert result.stats.mean_gu[60] == pytest.approx(90.2, abs=1e-9)
    assert result.stats.std_gu[60] == pytest.approx(0.2, abs=1e-9)
    assert store.get_run(result.run_id).status == "done"


async def test_too_many_failures_fail_but_keep_readings(store: RunStore) -> None:
    script: list[GlossReading | Exception] = [reading(80.0, 90.0, 95.0, 1.0)]
    script += [ProtocolError("garbled", device="glossmeter")] * 3
    logger, _, _, _ = make(store, script, 5, max_failures=3)
    result = await logger.run()
    assert result.state is RunState.FAILED and "3 consecutive failures" in result.reason
    assert len(store.gloss_readings(result.run_id)) == 1
    assert store.get_run(result.run_id).status == "failed"


async def test_predicted_gloss_runs_in_a_thread() -> None:
    model = FakeModel()
    assert await predict_gloss(model, (20, 60)) == {20: 80.0, 60: 90.0}


async def test_push_mode_reopens_the_stream_after_a_disconnect(store: RunStore) -> None:
    script: list[GlossReading | Exception] = [
        reading(70.0, 80.0, 90.0, 1.0),
        Disconnected("USB cable pulled", device="glossmeter"),
        reading(71.0, 81.0, 91.0, 2.0),
    ]
    logger, _, _, clock = make(store, script, 2, mode="push")
    result = await logger.run()
    assert result.state is RunState.DONE and result.readings == 2
    assert result.reconnects == 1 and clock.now() == pytest.approx(0.5, abs=1e-12)
    assert [r.values_gu[85] for r in store.gloss_readings(result.run_id)] == [90.0, 91.0]


async def test_stop_ends_an_open_ended_session(store: RunStore) -> None:
    script: list[GlossReading | Exception] = [reading(70.0 + k, 80.0, 90.0, k) for k in range(10)]
    logger, _, bus, _ = make(store, script, 0)  # count 0: until stopped
    q = bus.subscribe()

    async def stop_after_three() -> None:
        n = 0
        while (ev := await q.get()) is not None:
            if isinstance(ev, GlossRead):
                n += 1
                if n == 3:
                    logger.stop()
                    return

    watcher = asyncio.create_task(stop_after_three())
    result = await logger.run()
    await watcher
    # the subscriber reads at its own pace: the stop lands after the 3rd or 4th reading
    n = result.readings
    assert n in (3, 4) and result.state is RunState.DONE
    assert len(store.gloss_readings(result.run_id)) == n
    assert result.stats.mean_gu[20] == pytest.approx(70.0 + (n - 1) / 2, abs=1e-12)


async def test_stop_ends_the_wait_for_a_pushed_reading(store: RunStore) -> None:
    script: list[GlossReading | Exception] = [reading(70.0, 80.0, 90.0, 1.0)]
    logger, meter, bus, _ = make(store, script, 5, mode="push")
    meter.wait_when_empty = True
    q = bus.subscribe()

    async def stop_after_the_first() -> None:
        while not isinstance(await q.get(), GlossRead):
            pass
        logger.stop()  # Ctrl-C while the meter waits for its button

    watcher = asyncio.create_task(stop_after_the_first())
    result = await logger.run()
    await watcher
    assert result.state is RunState.ABORTED and result.reason == "stopped by the operator"
    assert result.readings == 1 and len(store.gloss_readings(result.run_id)) == 1


async def test_stop_ends_a_reconnect_backoff(store: RunStore) -> None:
    script: list[GlossReading | Exception] = [
        reading(70.0, 80.0, 90.0, 1.0),
        Disconnected("USB cable pulled", device="glossmeter"),
    ]
    logger, meter, bus, clock = make(store, script, 0, backoff_s=60.0)
    q = bus.subscribe()

    async def stop_on_the_disconnect() -> None:
        while not isinstance(await q.get(), InstrumentError):
            pass
        logger.stop()

    watcher = asyncio.create_task(stop_on_the_disconnect())
    result = await logger.run()
    await watcher
    # the 60 s backoff was cut short: no lab time passed, no reconnect was made
    assert clock.now() == 0.0 and result.reconnects == 0 and meter.connects == 0
    assert result.state is RunState.DONE and result.readings == 1
