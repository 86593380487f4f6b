"""The scan runner's device operations: arm moves, homing, parking, and retries through faults.

Every device operation of a run goes through :meth:`DeviceOps._retry`: a transient fault
(:class:`drivers.base.DeviceTimeout`, :class:`drivers.base.ProtocolError`) is tried again up
to a number of retries, a lost link (:class:`drivers.base.Disconnected`) is reopened again
and again within a reconnect window; each retry is published as a non-fatal
:class:`~goniolab.scan.events.InstrumentError`. An abort interrupts a move or homing
(:meth:`DeviceOps._abortable` raises :class:`Aborted`): the arms are stopped where they are,
then parked (:meth:`DeviceOps._park`, best effort), or only stopped after an interrupted
homing (the arms are then unreferenced).

:class:`DeviceOps` is a base of :class:`goniolab.scan.runner.ScanRunner`, which sets the
attributes declared here.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Callable
from typing import TypeVar

from drivers.base import (
    DeviceError,
    DeviceTimeout,
    Disconnected,
    Goniometer,
    ProtocolError,
    Spectrocolorimeter,
)
from drivers.timing import Clock
from goniolab.scan.events import ArmsMoved, EventBus, InstrumentError

__all__ = ["Aborted", "DeviceOps", "describe_error"]

_T = TypeVar("_T")


def describe_error(exc: BaseException) -> str:
    """``Type: message`` of an unexpected error (``struct.error: argument out of range``),
    the message alone for a :class:`~drivers.base.DeviceError` (it names its device)."""
    if isinstance(exc, DeviceError):
        return str(exc)
    kind = type(exc)
    name = (
        kind.__qualname__
        if kind.__module__ == "builtins"
        else f"{kind.__module__}.{kind.__qualname__}"
    )
    text = str(exc)
    return f"{name}: {text}" if text else name


class Aborted(Exception):
    """An abort ends the run's readings; ``reason`` says where it arrived."""

    def __init__(self, during: str = "") -> None:
        super().__init__(during)
        self.reason = "aborted by the operator" + (f" {during}" if during else "")


class DeviceOps:
    """Moves, homing, parking and the retry loop of a run's devices (a base of
    :class:`~goniolab.scan.runner.ScanRunner`, which sets these attributes)."""

    goniometer: Goniometer
    spectro: Spectrocolorimeter
    clock: Clock
    bus: EventBus
    run_id: int
    move_timeout_s: float
    home_timeout_s: float
    move_retries: int
    reconnect_backoff_s: float
    reconnect_window_s: float
    position_tolerance_deg: float
    _abort_event: asyncio.Event
    _homing_interrupted: bool
    _verify_position: bool
    _target: tuple[float, float] | None
    _measured_deg: tuple[float, float]
    _exposure_us: int

    async def _abortable(self, aw: Awaitable[_T], during: str) -> _T:
        """Await ``aw`` unless :meth:`abort` is called first: then cancel it and raise
        :class:`Aborted` saying ``during`` what."""
        work = asyncio.ensure_future(aw)
        aborted = asyncio.ensure_future(self._abort_event.wait())
        try:
            await asyncio.wait({work, aborted}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            aborted.cancel()
            if not work.done():  # an abort, or a cancellation from outside
                work.cancel()
                with contextlib.suppress(asyncio.CancelledError, DeviceError):
                    await work
        if work.cancelled():
            raise Aborted(during)
        return work.result()

    async def _retry(
        self,
        what: str,
        op: Callable[[], Awaitable[_T]],
        reconnect: Callable[[int], Awaitable[None]],
        retries: int,
        device: str,
    ) -> _T:
        """``await op()``, again after a transient fault (:class:`DeviceTimeout`,
        :class:`ProtocolError`, :class:`Disconnected`: then ``reconnect(attempt)`` first) up
        to ``retries`` times, each retry published as a non-fatal :class:`InstrumentError`
        saying ``what`` was being done; the last failure propagates (and fails the run)."""
        attempt = 0
        lost_since: float | None = None
        reconnects = 0
        while True:
            try:
                return await op()
            except (DeviceTimeout, ProtocolError, Disconnected) as exc:
                lost = isinstance(exc, Disconnected)
                now = self.clock.now()
                if lost:
                    lost_since = now if lost_since is None else lost_since
                    away_s = now - lost_since
                    if reconnects and away_s >= self.reconnect_window_s:
                        raise Disconnected(
                            f"{exc.message} (link away {away_s:.3g} s, longer than the "
                            f"reconnect window of {self.reconnect_window_s:g} s)",
                            device=exc.device or device,
                        ) from exc
                    note = (
                        f"reconnecting, link lost {away_s:.3g} s ago, waiting up to "
                        f"{self.reconnect_window_s:g} s"
                        if reconnects
                        else f"retry {attempt + 1} of {retries}, reconnecting"
                    )
                    self.bus.publish(
                        InstrumentError(
                            run_id=self.run_id,
                            device=exc.device or device,
                            message=f"{exc} ({what}: {note})",
                            fatal=False,
                        )
                    )
                    await reconnect(reconnects)
                    reconnects += 1
                    continue
                if attempt == retries:
                    raise
                self.bus.publish(
                    InstrumentError(
                        run_id=self.run_id,
                        device=exc.device or device,
                        message=f"{exc} ({what}: retry {attempt + 1} of {retries})",
                        fatal=False,
                    )
                )
                attempt += 1

    async def _reconnect_arms(self, attempt: int) -> None:
        """Reopen both arms' links after a lost one (on the wire they share a server, a
        dropped link may take both) after ``reconnect_backoff_s`` (doubling) of lab clock;
        a failed reopen is reported and the next attempt finds the link closed."""
        await self.clock.sleep(min(2.0, self.reconnect_backoff_s * 2**attempt))
        for axis in (self.goniometer.lamp, self.goniometer.detector):
            with contextlib.suppress(DeviceError):
                await axis.close()
            try:
                await axis.connect()
            except DeviceError as exc:
                self.bus.publish(InstrumentError.reconnect_failed(self.run_id, exc, "goniometer"))

    async def _reconnect_spectro(self, attempt: int) -> None:
        """Close the spectro's link, wait (``reconnect_backoff_s``, doubling with each
        attempt, on the lab clock), reopen it and set the exposure again (the plan's, or the
        one auto-exposure arrived at). A failed
        reopen is reported; the next attempt finds the link closed and tries again."""
        with contextlib.suppress(DeviceError):
            await self.spectro.close()
        await self.clock.sleep(min(2.0, self.reconnect_backoff_s * 2**attempt))
        try:
            await self.spectro.connect()
            await self.spectro.set_exposure_us(self._exposure_us)  # the plan's, or auto's
        except DeviceError as exc:
            self.bus.publish(InstrumentError.reconnect_failed(self.run_id, exc, "spectro"))

    async def _move(self, target: tuple[float, float]) -> None:
        """Move to ``target``; a move that meets a transient fault (an arm's timeout or
        garbled frame, or a lost link: then the arms' connections are reopened first) is
        made again from where the arms stopped, up to ``move_retries`` times (see
        :meth:`_retry`). The goniometer stops both arms on any error and plans every move
        from the positions it reads, so a retry keeps the interlock."""
        self.bus.publish(
            ArmsMoved(run_id=self.run_id, theta_i_deg=target[0], theta_r_deg=target[1], moving=True)
        )
        self._target = None  # somewhere between two geometries until the move is done
        measured = await self._retry(
            f"moving to theta_i={target[0]:g}, theta_r={target[1]:g} deg",
            lambda: self._abortable(
                self.goniometer.move_to(target[0], target[1], self.move_timeout_s),
                "during a move",
            ),
            self._reconnect_arms,
            self.move_retries,
            "goniometer",
        )
        self._measured_deg = (float(measured[0]), float(measured[1]))
        self._target = target
        self.bus.publish(
            ArmsMoved(
                run_id=self.run_id,
                theta_i_deg=self._measured_deg[0],
                theta_r_deg=self._measured_deg[1],
                moving=False,
            )
        )

    async def _ensure_position(self, target: tuple[float, float]) -> bool:
        """Move to ``target`` if needed; return True when a move happened."""
        if self._target != target:
            await self._move(target)
            return True
        if self._verify_position:
            self._verify_position = False
            ti, tr = await self._arm_positions("checking the arm positions")
            if (
                abs(ti - target[0]) > self.position_tolerance_deg
                or abs(tr - target[1]) > self.position_tolerance_deg
            ):
                await self._move(target)
                return True
            self._measured_deg = (float(ti), float(tr))
        return False

    async def _arm_positions(self, what: str) -> tuple[float, float]:
        """Both arms' positions, read again after a transient fault (see :meth:`_retry`)."""
        return await self._retry(
            what, self.goniometer.positions_deg, self._reconnect_arms, self.move_retries,
            "goniometer",
        )  # fmt: skip

    async def _arms_homed(self) -> bool:
        lamp = await self.goniometer.lamp.status()
        det = await self.goniometer.detector.status()
        return lamp.homed and det.homed

    async def _ensure_homed(self) -> None:
        homed = await self._retry(
            "reading the arms' status", self._arms_homed, self._reconnect_arms,
            self.move_retries, "goniometer",
        )  # fmt: skip
        if not homed:  # the goniometer plans homing from where the arms stand: a retry is safe
            await self._retry(
                "homing", lambda: self.goniometer.home(self.home_timeout_s),
                self._reconnect_arms, self.move_retries, "goniometer",
            )  # fmt: skip

    async def _park(self) -> str:
        """Stop and park the arms, best effort (each step retried after a transient fault,
        :meth:`_retry`); returns "" or what went wrong.

        After an interrupted homing the arms are only stopped: their positions are not
        referenced, so no move is made.
        """
        problems: list[str] = []
        # a timeout, a garbled frame or a lost link (reopened first) is tried again, as in
        # a move: a link that dropped just before the end must not leave the arms unparked
        try:
            await self._retry(
                "stopping the arms", self.goniometer.stop, self._reconnect_arms,
                self.move_retries, "goniometer",
            )  # fmt: skip
        except Exception as exc:  # best effort: any failure is reported, never raised
            problems.append(f"stopping the arms failed: {describe_error(exc)}")
        if self._homing_interrupted:
            self._target = None
            problems.append("homing interrupted: arms stopped, not parked; home them before use")
            return "; ".join(problems)
        try:
            await self._retry(
                "parking the arms", lambda: self.goniometer.park(self.home_timeout_s),
                self._reconnect_arms, self.move_retries, "goniometer",
            )  # fmt: skip
        except Exception as exc:  # a bug or a dead link must not leave the run 'running'
            problems.append(
                f"parking failed: {describe_error(exc)}; arms not parked: check them before use"
            )
        self._target = None
        return "; ".join(problems)
