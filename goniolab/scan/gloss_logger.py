"""The glossmeter logger: every reading committed to the store as it arrives, robust to faults.

A glossmeter session (:class:`~goniolab.scan.plans.GlossPlan`) takes ``count`` readings
(0 = until stopped) either by asking the meter (``measure``, the ZGM1120 opcode 1) or by
listening to the readings it pushes (button presses / auto-send, ``readings()``).

Faults do not end a session and never lose a reading already taken:

* a garbled reply (:class:`~drivers.base.ProtocolError`) is reported and the next reading
  is taken;
* a timeout or a lost connection (:class:`~drivers.base.DeviceTimeout`,
  :class:`~drivers.base.Disconnected`) is reported, the port is closed and reopened with an
  exponential backoff (``backoff_s``, doubling up to ``max_backoff_s``, on the lab clock);
* after ``max_failures`` consecutive failures the session ends ``failed`` with the last
  reason; everything read before stays in the store.

Each reading is shown beside the model's ISO 2813 gloss when the sample has a height map
(``ReflectanceModel.gloss``, Mihalik eqs. 15-17 over the ISO 2813 apertures, normalised by
the black-glass standard n = 1.567), computed once in a worker thread.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable
from dataclasses import dataclass
from typing import TypeVar

from drivers.base import (
    DeviceError,
    DeviceTimeout,
    Disconnected,
    Glossmeter,
    GlossReading,
    ProtocolError,
)
from drivers.timing import Clock
from goniolab.optics.models import ReflectanceModel
from goniolab.scan.events import EventBus, GlossRead, InstrumentError, RunState, StateChanged
from goniolab.scan.plans import GlossPlan, GlossStats, gloss_statistics
from goniolab.store import RunStore, StoreError, StoreUnavailable

__all__ = ["GlossLogger", "GlossResult", "predict_gloss"]

_T = TypeVar("_T")


class _Stopped(Exception):
    """:meth:`GlossLogger.stop` ended a wait."""


async def predict_gloss(model: ReflectanceModel, angles_deg: tuple[int, ...]) -> dict[int, float]:
    """ISO 2813 gloss of ``model`` at ``angles_deg``, computed in a worker thread."""
    values = await asyncio.to_thread(model.gloss, angles_deg)
    return {int(a): float(values[a]) for a in angles_deg}


@dataclass(slots=True)
class GlossResult:
    """End of a gloss session: final state, reason, statistics, reconnect count."""

    run_id: int
    state: RunState
    reason: str
    stats: GlossStats
    readings: int
    reconnects: int


class GlossLogger:
    """Log glossmeter readings into the store.

    Parameters
    ----------
    meter
        A connected :class:`~drivers.base.Glossmeter`.
    store, run_id
        Where readings go (the caller created the ``gloss`` run).
    bus
        Events: :class:`GlossRead` per reading, :class:`InstrumentError` per fault.
    clock
        Lab clock (backoff waits and the measure interval run on it).
    plan
        Count and geometries.
    predicted_gu, predicted_models
        Model gloss per geometry, shown beside each reading (``None``: no height map).
    mode
        ``"measure"``: ask for each reading; ``"push"``: take the meter's pushed readings.
    interval_s
        Pause between two requested readings (``"measure"`` mode).
    backoff_s, max_backoff_s, max_failures
        Reconnect policy (see the module docstring).
    """

    def __init__(
        self,
        *,
        meter: Glossmeter,
        store: RunStore,
        run_id: int,
        bus: EventBus,
        clock: Clock,
        plan: GlossPlan,
        predicted_gu: dict[int, float] | None = None,
        predicted_models: dict[int, str] | None = None,
        mode: str = "measure",
        interval_s: float = 0.0,
        backoff_s: float = 0.5,
        max_backoff_s: float = 8.0,
        max_failures: int = 10,
        keep_running: bool = False,
    ) -> None:
        # keep_running: a log that goes on after this call (the TUI's one gloss run per
        # sample) stays "running" when the call's readings are in; its owner ends it
        self.keep_running = keep_running
        if mode not in ("measure", "push"):
            raise ValueError(f"gloss mode must be 'measure' or 'push', got {mode!r}")
        self.meter = meter
        self.store = store
        self.run_id = run_id
        self.bus = bus
        self.clock = clock
        self.plan = plan
        self.predicted_gu = predicted_gu
        #: the model that computed each predicted gloss (shown beside it, issue 20)
        self.predicted_models = dict(predicted_models or {})
        self.mode = mode
        self.interval_s = interval_s
        self.backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        self.max_failures = max_failures
        self._stop = False
        self._stop_by = ""
        self._stop_event = asyncio.Event()
        self._values: list[dict[int, float | None]] = []
        self.reconnects = 0

    def stop(self, by: str = "") -> None:
        """End the session: a requested reading is completed and stored; a wait for a
        pushed reading, the interval between readings or a reconnect backoff ends now.
        ``by`` says who asked when it was not the operator (``"SIGTERM"``)."""
        if by and not self._stop:
            self._stop_by = by
        self._stop = True
        self._stop_event.set()

    async def _until_stop(self, aw: Awaitable[_T]) -> _T:
        """Await ``aw`` unless :meth:`stop` comes first: then cancel it, raise _Stopped."""
        work = asyncio.ensure_future(aw)
        stopped = asyncio.ensure_future(self._stop_event.wait())
        try:
            await asyncio.wait({work, stopped}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            stopped.cancel()
            if not work.done():
                work.cancel()
                with contextlib.suppress(asyncio.CancelledError, DeviceError):
                    await work
        if work.cancelled():
            raise _Stopped
        return work.result()

    #: How long a reading the store cannot take (a full disk, a database down) is kept and
    #: tried again (backoff 0.5 s doubling to 10 s) before the log fails, in one line.
    store_outage_s: float = 600.0

    async def _record(self, reading: GlossReading) -> None:
        values = {a: reading.values_gu.get(a) for a in self.plan.angles_deg}

        def write() -> None:
            self.store.add_gloss_reading(
                self.run_id,
                values_gu=values,
                temperature_c=reading.temperature_c,
                predicted_gu=self.predicted_gu,
                raw=reading.raw,
                timestamp=reading.timestamp,
            )

        try:
            write()
        except StoreUnavailable as exc:
            self.bus.publish(
                InstrumentError(
                    run_id=self.run_id,
                    device="store",
                    message=f"{exc}; the reading is kept and stored when the store is back",
                    fatal=False,
                )
            )
            loop = asyncio.get_running_loop()
            deadline, delay = loop.time() + self.store_outage_s, 0.5
            while True:
                if loop.time() >= deadline:
                    raise StoreUnavailable(f"{exc} (for {self.store_outage_s:g} s)") from None
                await self._until_stop(asyncio.sleep(delay))
                delay = min(10.0, 2 * delay)
                try:
                    await asyncio.to_thread(write)
                    break
                except StoreUnavailable as again:
                    exc = again
        self._values.append(values)
        self.bus.publish(
            GlossRead(
                run_id=self.run_id,
                timestamp=reading.timestamp,
                values_gu=values,
                predicted_gu=self.predicted_gu,
                temperature_c=reading.temperature_c,
                predicted_models=self.predicted_models,
            )
        )

    def _done(self) -> bool:
        return self._stop or (self.plan.count > 0 and len(self._values) >= self.plan.count)

    async def _reconnect(self, attempt: int) -> None:
        delay = min(self.max_backoff_s, self.backoff_s * 2 ** max(0, attempt - 1))
        with contextlib.suppress(DeviceError):
            await self.meter.close()
        await self._until_stop(self.clock.sleep(delay))
        await self.meter.connect()
        self.reconnects += 1

    async def _next_reading(self, stream: AsyncIterator[GlossReading] | None) -> GlossReading:
        if stream is None:
            return await self.meter.measure(self.plan.angles_deg)
        return await self._until_stop(anext(stream))

    async def run(self) -> GlossResult:
        """Log readings until ``count`` are stored, :meth:`stop` is called, or the meter is lost."""
        self.store.set_status(self.run_id, RunState.RUNNING.value)
        self.bus.publish(StateChanged(run_id=self.run_id, state=RunState.RUNNING))
        failures = 0
        state, reason = RunState.DONE, ""
        stream = self.meter.readings() if self.mode == "push" else None
        while not self._done():
            try:
                reading = await self._next_reading(stream)
            except _Stopped:
                break
            except StopAsyncIteration:
                state, reason = RunState.DONE, "the meter stopped sending"
                break
            except (ProtocolError, DeviceTimeout, Disconnected) as exc:
                failures += 1
                fatal = failures >= self.max_failures
                self.bus.publish(
                    InstrumentError(
                        run_id=self.run_id,
                        device=exc.device or "glossmeter",
                        message=f"{exc.message} ({type(exc).__name__}, failure {failures})",
                        fatal=fatal,
                    )
                )
                if fatal:
                    state, reason = RunState.FAILED, f"{failures} consecutive failures, last: {exc}"
                    break
                if isinstance(exc, ProtocolError):
                    continue
                try:
                    await self._reconnect(failures)
                except _Stopped:
                    break
                except DeviceError as exc2:
                    self.bus.publish(
                        InstrumentError.reconnect_failed(self.run_id, exc2, "glossmeter")
                    )
                    continue
                if stream is not None:
                    stream = self.meter.readings()
                continue
            except DeviceError as exc:
                state, reason = RunState.FAILED, str(exc)
                self.bus.publish(
                    InstrumentError(
                        run_id=self.run_id,
                        device=exc.device or "glossmeter",
                        message=exc.message,
                        fatal=True,
                    )
                )
                break
            failures = 0
            try:
                await self._record(reading)
            except _Stopped:
                state, reason = RunState.ABORTED, "stopped while the store was unavailable"
                break
            except StoreError as exc:
                state, reason = RunState.FAILED, f"store: {exc}"
                self.bus.publish(
                    InstrumentError(
                        run_id=self.run_id, device="store", message=str(exc), fatal=True
                    )
                )
                break
            if stream is None and self.interval_s > 0 and not self._done():
                with contextlib.suppress(_Stopped):
                    await self._until_stop(self.clock.sleep(self.interval_s))
        if (
            self._stop
            and state is RunState.DONE
            and (self._stop_by or (self.plan.count and len(self._values) < self.plan.count))
        ):
            # a count cut short, or any session ended by a signal (SIGTERM, SIGHUP): the
            # run did not end the way it was meant to
            state, reason = RunState.ABORTED, f"stopped by {self._stop_by or 'the operator'}"
        try:
            if not (self.keep_running and state is RunState.DONE):
                self.store.set_status(self.run_id, state.value, reason)
        except StoreError as exc:  # the store is still away: say so, never a traceback
            self.bus.publish(InstrumentError.state_not_recorded(self.run_id, state, exc))
        self.bus.publish(StateChanged(run_id=self.run_id, state=state, reason=reason))
        stats = gloss_statistics(self._values, self.plan.angles_deg)
        return GlossResult(
            run_id=self.run_id,
            state=state,
            reason=reason,
            stats=stats,
            readings=len(self._values),
            reconnects=self.reconnects,
        )
