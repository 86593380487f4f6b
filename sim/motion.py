"""Stepper-arm motion model: trapezoidal moves, limit switches, homing, stall and alarm.

The idea follows ophyd-async's ``sim/_motor.py``: a simulated motor is not an instant
setter, it moves along a velocity profile that respects speed and acceleration, so that
timeouts, ETAs and "read while moving" behave as on the bench. Unlike a polled
simulation, every quantity here is an analytic function of time: the motor stores the
current :class:`MoveProfile` and answers ``position_deg(now_s)`` exactly, so the same
model runs at any clock speed (see :mod:`drivers.timing`).

Coordinates
-----------
* *physical* degrees: where the arm really is; the home switch sits at
  ``home_switch_deg`` and the hard limit switches at the soft limits widened by
  ``hard_margin_deg``.
* *encoder* degrees: what the controller reports. At power-up the encoder reads 0
  wherever the arm stands (``start_deg``); homing drives to the home switch and zeroes
  the encoder there, after which encoder = physical - ``home_switch_deg``.

Alarm codes are those of the Oriental Motor AZ series (manual HM-60262E, alarm list):
0x10 excessive position deviation, 0x30 overload, 0x66 hardware overtravel,
0x67 software overtravel.

References
----------
.. [1] Trapezoidal velocity profile: e.g. L. Biagiotti, C. Melchiorri, "Trajectory
   Planning for Automatic Machines and Robots", Springer 2008, sec. 3.2 (constant
   acceleration, "trapezoidal speed" law) -- duration d/v + v/a when d >= v^2/a,
   else 2 sqrt(d/a) with peak speed sqrt(a d).
"""

from __future__ import annotations

from dataclasses import dataclass

from drivers.timing import MoveProfile

__all__ = [
    "ALARM_EXCESSIVE_DEVIATION",
    "ALARM_HW_OVERTRAVEL",
    "ALARM_OVERLOAD",
    "ALARM_SW_OVERTRAVEL",
    "MotorFault",
    "SimMotor",
]

#: Oriental AZ alarm: excessive position deviation (the motor could not follow).
ALARM_EXCESSIVE_DEVIATION = 0x10
#: Oriental AZ alarm: overload (used as the default injected mid-move alarm).
ALARM_OVERLOAD = 0x30
#: Oriental AZ alarm: hardware overtravel (a limit switch was hit).
ALARM_HW_OVERTRAVEL = 0x66
#: Oriental AZ alarm: software overtravel (a target outside the soft limits).
ALARM_SW_OVERTRAVEL = 0x67


class MotorFault(Exception):
    """The motor refuses a command (alarm active); ``code`` is the alarm code."""

    def __init__(self, message: str, code: int) -> None:
        self.code = code
        super().__init__(message)


@dataclass(frozen=True, slots=True)
class _Stop:
    """Where and when the current move ends early, and the alarm it raises."""

    t_s: float
    physical_deg: float
    alarm_code: int | None


class SimMotor:
    """One simulated closed-loop stepper arm (Oriental AZ-like), analytic in time.

    Parameters
    ----------
    name
        Arm name for messages.
    speed_deg_s, accel_deg_s2
        Operating speed and acceleration of moves.
    soft_limits_deg
        Allowed encoder range (checked by the controller: a target outside raises
        software-overtravel alarm 0x67 without moving).
    hard_margin_deg
        The limit switches sit this far beyond the soft limits (physical frame);
        crossing one stops the arm there with hardware-overtravel alarm 0x66.
    home_switch_deg
        Physical position of the home switch.
    start_deg
        Physical position at power-up (the encoder reads 0 there until homed).
    homing_speed_deg_s
        Speed of the homing move (default: ``speed_deg_s``).
    homed
        Start already homed (encoder = physical - ``home_switch_deg``), as a lab that
        keeps its controllers powered would.
    """

    def __init__(
        self,
        name: str,
        *,
        speed_deg_s: float,
        accel_deg_s2: float,
        soft_limits_deg: tuple[float, float],
        hard_margin_deg: float = 1.0,
        home_switch_deg: float = 0.0,
        start_deg: float = 0.0,
        homing_speed_deg_s: float | None = None,
        homed: bool = False,
    ) -> None:
        lo, hi = soft_limits_deg
        if not lo < hi:
            raise ValueError(f"{name}: soft limits {soft_limits_deg} must be increasing")
        if not (speed_deg_s > 0 and accel_deg_s2 > 0):
            raise ValueError(f"{name}: speed and acceleration must be > 0")
        self.name = name
        self.speed_deg_s = float(speed_deg_s)
        self.accel_deg_s2 = float(accel_deg_s2)
        self.soft_limits_deg = (float(lo), float(hi))
        self.hard_margin_deg = float(hard_margin_deg)
        self.home_switch_deg = float(home_switch_deg)
        self.homing_speed_deg_s = float(homing_speed_deg_s or speed_deg_s)
        self.homed = bool(homed)
        # physical = encoder + offset; unhomed, the encoder reads 0 where the arm stands
        self._offset_deg = self.home_switch_deg if homed else float(start_deg)
        self._physical_deg = float(start_deg)
        self._command_deg = self._physical_deg - self._offset_deg  # encoder frame
        self._move: MoveProfile | None = None  # physical frame
        self._stop: _Stop | None = None
        self._homing = False
        self._alarm: int | None = None
        self._stall_at_physical_deg: float | None = None
        self._alarm_at: tuple[float, int] | None = None  # (physical deg, code), one-shot
        #: Sense of the last move (+1 / -1): where the gears' backlash sits (SimAxis).
        self.last_direction = 1.0

    # ------------------------------------------------------------------ limits
    @property
    def hard_limits_physical_deg(self) -> tuple[float, float]:
        """Physical positions of the two limit switches."""
        lo, hi = self.soft_limits_deg
        return (
            lo + self._home_offset() - self.hard_margin_deg,
            hi + self._home_offset() + self.hard_margin_deg,
        )

    def _home_offset(self) -> float:
        """Encoder-to-physical offset once homed (limits are defined in that frame)."""
        return self.home_switch_deg

    # ------------------------------------------------------------------ state
    def _settle(self, now_s: float) -> None:
        """Retire the current move if it has ended at ``now_s`` (apply its consequences)."""
        move = self._move
        if move is None:
            return
        if self._stop is not None and now_s >= self._stop.t_s:
            self._physical_deg = self._stop.physical_deg
            if self._stop.alarm_code is not None:
                self._alarm = self._stop.alarm_code
                self._command_deg = self._physical_deg - self._offset_deg
                self._finish(homing_ok=False)
                return
            # stall without alarm: the command profile runs on to its end
            if now_s >= move.end_s:
                self._finish(homing_ok=False)
            return
        if now_s >= move.end_s:
            self._physical_deg = move.target_deg
            self._finish(homing_ok=True)

    def _finish(self, *, homing_ok: bool) -> None:
        if self._homing and homing_ok:
            self._offset_deg = self.home_switch_deg
            self._command_deg = 0.0
            self.homed = True
        self._homing = False
        self._move = None
        self._stop = None

    def physical_deg(self, now_s: float) -> float:
        """Where the arm really is (physical frame)."""
        self._settle(now_s)
        if self._move is None:
            return self._physical_deg
        if self._stop is not None and now_s >= self._stop.t_s:
            return self._stop.physical_deg
        return self._move.position_at(now_s)

    def position_deg(self, now_s: float) -> float:
        """Feedback (encoder) position."""
        return self.physical_deg(now_s) - self._offset_deg

    def command_deg(self, now_s: float) -> float:
        """Commanded position: follows the move profile, also when the arm stalls."""
        self._settle(now_s)
        if self._move is None:
            return self._command_deg
        return self._move.position_at(now_s) - self._offset_deg

    def is_moving(self, now_s: float) -> bool:
        """The controller reports motion (MOVE): a profile is being executed."""
        self._settle(now_s)
        return self._move is not None

    def is_homing(self, now_s: float) -> bool:
        """A homing move is in progress."""
        self._settle(now_s)
        return self._homing

    def alarm_code(self, now_s: float) -> int | None:
        """The active alarm code, ``None`` when no alarm."""
        self._settle(now_s)
        return self._alarm

    def next_event_s(self, now_s: float) -> float | None:
        """Clock time of the next state change (stop or end of move), ``None`` if idle."""
        self._settle(now_s)
        if self._move is None:
            return None
        if self._stop is not None and self._stop.t_s > now_s:
            return self._stop.t_s
        return self._move.end_s

    def target_deg(self) -> float:
        """The encoder target of the current (or last) move."""
        return self._command_deg

    # ------------------------------------------------------------------ commands
    def start_move(
        self,
        target_deg: float,
        now_s: float,
        *,
        speed_deg_s: float | None = None,
        accel_deg_s2: float | None = None,
    ) -> MoveProfile:
        """Start an absolute move to encoder position ``target_deg``.

        ``speed_deg_s`` / ``accel_deg_s2`` override the motor's defaults for this move
        (a controller takes them from the move command).

        Raises
        ------
        MotorFault
            An alarm is active (code unchanged), or the target lies outside the soft
            limits (software overtravel: alarm 0x67 is raised, nothing moves).
        """
        self._settle(now_s)
        if self._alarm is not None:
            raise MotorFault(f"{self.name}: alarm 0x{self._alarm:02X} active", self._alarm)
        lo, hi = self.soft_limits_deg
        if not lo <= target_deg <= hi:
            self._alarm = ALARM_SW_OVERTRAVEL
            raise MotorFault(
                f"{self.name}: target {target_deg:g} deg outside soft limits [{lo:g}, {hi:g}]",
                ALARM_SW_OVERTRAVEL,
            )
        start = self.physical_deg(now_s)
        self._homing = False
        return self._begin(
            start,
            target_deg + self._offset_deg,
            speed_deg_s or self.speed_deg_s,
            now_s,
            target_deg,
            accel_deg_s2=accel_deg_s2,
        )

    def start_home(self, now_s: float) -> MoveProfile:
        """Drive to the home switch at homing speed; the encoder zeroes on arrival."""
        self._settle(now_s)
        if self._alarm is not None:
            raise MotorFault(f"{self.name}: alarm 0x{self._alarm:02X} active", self._alarm)
        start = self.physical_deg(now_s)
        profile = self._begin(
            start,
            self.home_switch_deg,
            self.homing_speed_deg_s,
            now_s,
            self.home_switch_deg - self._offset_deg,
        )
        self._homing = True
        return profile

    def _begin(
        self,
        start_phys: float,
        target_phys: float,
        speed: float,
        now_s: float,
        command_enc: float,
        *,
        accel_deg_s2: float | None = None,
    ) -> MoveProfile:
        # A command during a move replaces it from the current position; the new profile
        # starts from rest (the model does not blend velocities: a simplification that
        # only matters for moves re-targeted while running).
        if self._move is not None:
            self._physical_deg = start_phys
        move = MoveProfile(start_phys, target_phys, speed, accel_deg_s2 or self.accel_deg_s2, now_s)
        if target_phys != start_phys:
            self.last_direction = 1.0 if target_phys > start_phys else -1.0
        self._move = move
        self._command_deg = command_enc
        self._stop = self._first_stop(move)
        return move

    def _first_stop(self, move: MoveProfile) -> _Stop | None:
        """The earliest event that ends ``move`` early: stall, injected alarm, limit switch."""
        candidates: list[_Stop] = []
        if self._stall_at_physical_deg is not None:
            t = move.time_at(self._stall_at_physical_deg)
            if (
                t is not None
                and move.distance_deg > 0
                and self._stall_at_physical_deg != move.start_deg
            ):
                candidates.append(_Stop(t, self._stall_at_physical_deg, None))
        if self._alarm_at is not None:
            t = move.time_at(self._alarm_at[0])
            if t is not None:
                candidates.append(_Stop(t, self._alarm_at[0], self._alarm_at[1]))
        lo_sw, hi_sw = self.hard_limits_physical_deg
        for switch in (lo_sw, hi_sw):
            t = move.time_at(switch)
            if t is not None:
                candidates.append(_Stop(t, switch, ALARM_HW_OVERTRAVEL))
        if not candidates:
            return None
        first = min(candidates, key=lambda s: s.t_s)
        if self._alarm_at is not None and first.physical_deg == self._alarm_at[0]:
            self._alarm_at = None  # one-shot
        return first

    def stop(self, now_s: float) -> None:
        """Quick stop: the arm halts where it is (command := feedback)."""
        self._settle(now_s)
        if self._move is None:
            return
        self._physical_deg = self.physical_deg(now_s)
        self._command_deg = self._physical_deg - self._offset_deg
        self._homing = False
        self._move = None
        self._stop = None

    def reset_alarm(self, now_s: float) -> None:
        """ALM-RST: clear the active alarm (the cause must be gone to move again)."""
        self._settle(now_s)
        if self._move is None:
            self._alarm = None
            self._command_deg = self.position_deg(now_s)

    # ------------------------------------------------------------------ faults
    def inject_stall(self, at_deg: float | None) -> None:
        """An obstacle at encoder angle ``at_deg``: moves across it stop there, the
        command runs on (feedback != command). ``None`` removes it."""
        self._stall_at_physical_deg = None if at_deg is None else at_deg + self._offset_deg

    def inject_alarm(self, at_deg: float, code: int = ALARM_OVERLOAD) -> None:
        """Raise alarm ``code`` when the next move passes encoder angle ``at_deg`` (once)."""
        self._alarm_at = (at_deg + self._offset_deg, int(code))
