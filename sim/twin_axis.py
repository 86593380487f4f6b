"""A simulated goniometer arm: the :class:`drivers.base.Axis` of the twin, over :mod:`sim.motion`.

The simulated goniometer is the project's own
``drivers.goniometer.TwoArmGoniometer(SimAxis, SimAxis)`` (built by :mod:`sim.assembly`):
one interlock for real and simulated arms. The realistic twin's arms have backlash,
invisible to the feedback, seen only by the optics (:meth:`SimAxis.actual_deg`).
"""

from __future__ import annotations

import asyncio

from drivers.base import AxisStatus, DeviceFault, DeviceTimeout, LimitError, StallError
from drivers.timing import Clock
from sim.faults import FaultInjector
from sim.motion import MotorFault, SimMotor
from sim.twin_link import SimLink

__all__ = ["SimAxis"]


class SimAxis(SimLink):
    """A simulated goniometer arm (implements :class:`drivers.base.Axis`).

    Parameters
    ----------
    name
        Arm name (``"lamp"``, ``"detector"``), used in every error.
    motor
        The motion model; its soft limits are this axis' ``limits_deg``.
    clock
        The lab clock (:class:`sim.clock.SimClock` or :class:`sim.clock.RealClock`).
    stall_tolerance_deg
        Largest allowed |command - feedback| once a move has ended; more is a stall.
    faults
        Fault injector for this arm (timeouts, disconnects); ``None`` = no faults.
    backlash_deg
        Play in the gears between the motor (whose encoder the controller reports) and the
        arm: after a move in the + direction the arm stands ``backlash_deg / 2`` behind
        the motor, after a move in the - direction as far ahead (``SimMotor.last_direction``,
        also for moves commanded over the wire). Invisible to the feedback; only the
        optics see it.
    """

    def __init__(
        self,
        name: str,
        motor: SimMotor,
        clock: Clock,
        *,
        stall_tolerance_deg: float = 0.5,
        faults: FaultInjector | None = None,
        backlash_deg: float = 0.0,
    ) -> None:
        self.name = name
        self.motor = motor
        self.clock = clock
        self.limits_deg: tuple[float, float] = motor.soft_limits_deg
        self.stall_tolerance_deg = stall_tolerance_deg
        self.faults = faults or FaultInjector(name)
        self.backlash_deg = float(backlash_deg)
        self._connected = False
        self._tracker: asyncio.Task[None] | None = None

    # -------------------------------------------------------------- connection
    async def close(self) -> None:
        """Close the link; a running move continues (as on a real controller)."""
        await super().close()
        if self._tracker is not None and not self._tracker.done():
            self._tracker.cancel()
        self._tracker = None

    # -------------------------------------------------------------- time keeping
    def ensure_tracker(self) -> None:
        """Keep virtual time flowing until the current move ends (needed at scale 0
        when nobody waits in-process, e.g. a wire server polled over the network)."""
        if self._tracker is None or self._tracker.done():
            self._tracker = asyncio.get_running_loop().create_task(
                self._track(), name=f"SimAxis-{self.name}-tracker"
            )

    async def _track(self) -> None:
        while True:
            now = self.clock.now()
            nxt = self.motor.next_event_s(now)
            if nxt is None:
                return
            await self.clock.sleep(max(nxt - now, 1e-9))

    # -------------------------------------------------------------- Axis protocol
    async def status(self) -> AxisStatus:
        """Controller state at the current clock time."""
        self._op("status")
        return self.snapshot()

    def snapshot(self) -> AxisStatus:
        """Status without counting an operation (used by the wire servers)."""
        now = self.clock.now()
        m = self.motor
        alarm = m.alarm_code(now)
        moving = m.is_moving(now)
        pos = m.position_deg(now)
        cmd = m.command_deg(now)
        return AxisStatus(
            position_deg=pos,
            command_deg=cmd,
            moving=moving,
            in_position=(not moving)
            and alarm is None
            and abs(cmd - pos) <= self.stall_tolerance_deg,
            homed=m.homed,
            alarm_code=alarm,
            ready=alarm is None and not moving,
        )

    async def position_deg(self) -> float:
        """Feedback position in degrees."""
        self._op("position")
        return self.motor.position_deg(self.clock.now())

    def actual_deg(self) -> float:
        """Where the arm truly is, in degrees from its mechanical zero (physics input),
        backlash included."""
        motor = self.motor.physical_deg(self.clock.now()) - self.motor.home_switch_deg
        return motor - 0.5 * self.backlash_deg * self.motor.last_direction

    async def move_to(self, target_deg: float) -> None:
        """Start an absolute move; returns once accepted.

        Raises
        ------
        LimitError
            ``target_deg`` outside ``limits_deg`` (checked before anything moves).
        DeviceFault
            An alarm is active.
        """
        self._op("move_to")
        lo, hi = self.limits_deg
        if not lo <= target_deg <= hi:
            raise LimitError(
                f"target {target_deg:g} deg outside limits [{lo:g}, {hi:g}] deg", device=self.name
            )
        try:
            self.motor.start_move(target_deg, self.clock.now())
        except MotorFault as exc:
            raise DeviceFault(str(exc), device=self.name, code=exc.code) from exc
        self.ensure_tracker()

    async def wait_in_position(self, timeout_s: float) -> float:
        """Wait (on the lab clock) until the move ends; return the feedback position.

        Raises
        ------
        DeviceFault
            An alarm occurred (e.g. mid-move or at a limit switch).
        StallError
            The move ended with feedback and command more than ``stall_tolerance_deg``
            apart.
        DeviceTimeout
            Still moving after ``timeout_s`` (clock seconds).
        """
        self._op("wait_in_position")
        deadline = self.clock.now() + timeout_s
        while True:
            now = self.clock.now()
            m = self.motor
            alarm = m.alarm_code(now)
            if alarm is not None:
                raise DeviceFault(
                    f"alarm 0x{alarm:02X} at {m.position_deg(now):.3f} deg",
                    device=self.name,
                    code=alarm,
                )
            nxt = m.next_event_s(now)
            if nxt is None:
                pos, cmd = m.position_deg(now), m.command_deg(now)
                if abs(cmd - pos) > self.stall_tolerance_deg:
                    raise StallError(
                        f"stalled at {pos:.3f} deg, commanded {cmd:.3f} deg "
                        f"(tolerance {self.stall_tolerance_deg:g} deg)",
                        device=self.name,
                    )
                return pos
            remaining = deadline - now
            if remaining <= 0.0:
                raise DeviceTimeout(
                    f"not in position after {timeout_s:g} s (at {m.position_deg(now):.3f} deg, "
                    f"target {m.target_deg():.3f} deg)",
                    device=self.name,
                )
            await self.clock.sleep(max(min(nxt - now, remaining), 1e-9))

    async def home(self, timeout_s: float) -> None:
        """Return to the home switch and zero the encoder there.

        Raises
        ------
        DeviceFault, DeviceTimeout
            As :meth:`wait_in_position`.
        """
        self._op("home")
        try:
            self.motor.start_home(self.clock.now())
        except MotorFault as exc:
            raise DeviceFault(str(exc), device=self.name, code=exc.code) from exc
        self.ensure_tracker()
        await self.wait_in_position(timeout_s)

    async def stop(self) -> None:
        """Quick stop where the arm is."""
        self._op("stop")
        self.motor.stop(self.clock.now())

    async def reset_alarm(self) -> None:
        """Clear the active alarm."""
        self._op("reset_alarm")
        self.motor.reset_alarm(self.clock.now())
