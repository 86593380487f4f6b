"""Events the scan runner and the gloss logger publish.

The runner never calls into a UI: it publishes these immutable events on an
:class:`EventBus`; subscribers (the run store, the prediction worker, the CLI progress
bar, the TUI) each get their own queue and consume at their own pace. A slow
subscriber never stalls the runner (its queue is unbounded; the runner only ``put``s).
"""

from __future__ import annotations

import asyncio
import enum
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from drivers.base import DeviceError

__all__ = [
    "ArmsMoved",
    "ColourPredicted",
    "Event",
    "EventBus",
    "GlossRead",
    "InstrumentError",
    "PointMeasured",
    "PointPredicted",
    "Progress",
    "RecordingBus",
    "RunFinished",
    "RunStarted",
    "RunState",
    "StateChanged",
    "WarningLog",
]


class RunState(enum.StrEnum):
    """Explicit states of a run (DESIGN.md: idle, running, paused, done, aborted, failed)."""

    IDLE = "idle"
    RUNNING = "running"
    PAUSED = "paused"
    DONE = "done"
    ABORTED = "aborted"
    FAILED = "failed"


@dataclass(frozen=True, slots=True, kw_only=True)
class Event:
    """Base of all events; ``run_id`` is the store's run id (0 when not stored)."""

    run_id: int
    timestamp: float = field(default_factory=time.time)


@dataclass(frozen=True, slots=True, kw_only=True)
class RunStarted(Event):
    kind: str  # "brdf" | "gloss"
    total_points: int
    plan: dict[str, Any]
    sample: str


@dataclass(frozen=True, slots=True, kw_only=True)
class StateChanged(Event):
    state: RunState
    reason: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class ArmsMoved(Event):
    theta_i_deg: float
    theta_r_deg: float
    moving: bool


@dataclass(frozen=True, slots=True, kw_only=True)
class PointMeasured(Event):
    """One reading: point ``index`` of the plan, repeat ``repeat`` (0-based)."""

    index: int
    repeat: int
    theta_i_deg: float
    theta_r_deg: float
    luminance_pct: float
    measured_theta_i_deg: float
    measured_theta_r_deg: float
    #: The model's prediction for this geometry when already computed (else ``None``);
    #: the residual is ``luminance_pct - predicted_pct``.
    predicted_pct: float | None = None
    #: Measured CIE L*a*b* of the reading's spectrum (``None``: no colour, see the
    #: InstrumentError published before it).
    lab: tuple[float, float, float] | None = None
    #: Its CIE XYZ (Y = 100 scale) and the white its L*a*b* is relative to (``None``
    #: without colour). XYZ is linear in the spectrum (CIE 15:2004 eq. 7.1): the mean XYZ
    #: of the repeats is the XYZ of their mean spectrum, so a face averages repeats *as
    #: spectra* by averaging XYZ (:func:`goniolab.colour.spectra.xyz_to_colour_of_white`).
    xyz: tuple[float, float, float] | None = None
    white_xyz: tuple[float, float, float] | None = None
    #: The reading's quality flag (:func:`goniolab.scan.exposure.reading_quality`): a
    #: ``saturated`` or ``under_noise_floor`` reading is stored but not averaged or fitted.
    quality: str = "unknown"


@dataclass(frozen=True, slots=True, kw_only=True)
class PointPredicted(Event):
    """The model's prediction for the geometry and aperture of plan point ``index``."""

    index: int
    theta_i_deg: float
    theta_r_deg: float
    predicted_pct: float


@dataclass(frozen=True, slots=True, kw_only=True)
class ColourPredicted(Event):
    """The predicted colour (CIE L*a*b*) of plan point ``index`` (spectral prediction)."""

    index: int
    theta_r_deg: float
    lab: tuple[float, float, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class Progress(Event):
    """How far a run is: ``done`` of ``total`` readings, ``eta_s`` the wall seconds left
    (what the user waits, from the measured rates of moves, dwells and readings:
    :class:`goniolab.scan.eta.EtaEstimator`; NaN while not known, at an instant sim clock
    before a reading was timed)."""

    done: int
    total: int
    eta_s: float


@dataclass(frozen=True, slots=True, kw_only=True)
class GlossRead(Event):
    values_gu: dict[int, float | None]
    predicted_gu: dict[int, float] | None
    temperature_c: float | None = None
    #: the model that computed each predicted gloss (``{85: "kirchhoff"}``)
    predicted_models: dict[int, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, kw_only=True)
class InstrumentError(Event):
    """A recoverable or fatal instrument problem, shown to the user as it happens."""

    device: str
    message: str
    fatal: bool

    @classmethod
    def reconnect_failed(cls, run_id: int, exc: DeviceError, device: str) -> InstrumentError:
        """A link that could not be reopened (non-fatal: the next attempt tries again);
        ``device`` names it when the error does not."""
        return cls(
            run_id=run_id,
            device=exc.device or device,
            message=f"reconnect failed: {exc.message}",
            fatal=False,
        )

    @classmethod
    def state_not_recorded(cls, run_id: int, state: RunState, exc: Exception) -> InstrumentError:
        """The store could not take the run's new state (non-fatal: the run's own state
        holds, and the store says the run was interrupted until it is written)."""
        return cls(
            run_id=run_id,
            device="store",
            message=f"the run's state ({state.value}) could not be recorded: {exc}",
            fatal=False,
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class RunFinished(Event):
    state: RunState
    reason: str
    summary: dict[str, Any]


class EventBus:
    """Fan-out of events to any number of subscribers, each with its own queue."""

    def __init__(self) -> None:
        self._queues: list[asyncio.Queue[Event | None]] = []

    def subscribe(self) -> asyncio.Queue[Event | None]:
        """Return a new queue that receives every event published from now on.

        ``None`` is put on the queue when the bus closes.
        """
        q: asyncio.Queue[Event | None] = asyncio.Queue()
        self._queues.append(q)
        return q

    def unsubscribe(self, q: asyncio.Queue[Event | None]) -> None:
        if q in self._queues:
            self._queues.remove(q)

    def publish(self, event: Event) -> None:
        """Deliver ``event`` to every subscriber without waiting on any of them."""
        for q in self._queues:
            q.put_nowait(event)

    def close(self) -> None:
        for q in self._queues:
            q.put_nowait(None)

    async def stream(self) -> AsyncIterator[Event]:
        """Iterate over events until the bus closes."""
        q = self.subscribe()
        try:
            while (ev := await q.get()) is not None:
                yield ev
        finally:
            self.unsubscribe(q)


class WarningLog:
    """The warnings of one run (its non-fatal :class:`InstrumentError` events) in the order
    they came, a repeated one counted: what the run's stored record and ``--json`` carry
    beside the live messages (no fallback said on stderr only)."""

    #: The most distinct warnings kept (a reconnect storm is counted, not listed).
    MAX_LINES = 100

    def __init__(self, run_id: int) -> None:
        self.run_id = run_id
        self._counts: dict[str, int] = {}
        self.dropped = 0

    def add(self, event: Event) -> None:
        """Record ``event`` if it is a warning of this run."""
        if not isinstance(event, InstrumentError) or event.fatal or event.run_id != self.run_id:
            return
        text = f"{event.device}: {event.message}"
        if text in self._counts:
            self._counts[text] += 1
        elif len(self._counts) < self.MAX_LINES:
            self._counts[text] = 1
        else:
            self.dropped += 1

    def lines(self) -> list[str]:
        """Each warning once, ``(N times)`` after a repeated one."""
        out = [t if n == 1 else f"{t} ({n} times)" for t, n in self._counts.items()]
        if self.dropped:
            out.append(f"... and {self.dropped} more warnings (see the run's log)")
        return out


class RecordingBus(EventBus):
    """``inner`` itself (its subscribers, its ``publish``), with every event published
    here also offered to a :class:`WarningLog`: a runner publishes through it, so that its
    warnings are kept with its result."""

    def __init__(self, inner: EventBus, log: WarningLog) -> None:
        super().__init__()
        self.inner = inner
        self.log = log

    def subscribe(self) -> asyncio.Queue[Event | None]:
        return self.inner.subscribe()

    def unsubscribe(self, q: asyncio.Queue[Event | None]) -> None:
        self.inner.unsubscribe(q)

    def publish(self, event: Event) -> None:
        self.log.add(event)
        self.inner.publish(event)

    def close(self) -> None:
        self.inner.close()
