"""Seeded fault injection for the simulated instruments (in-process and on the wire).

A :class:`FaultInjector` is consulted before every operation of one simulated device
and decides, from a seeded :class:`numpy.random.Generator`, whether that operation
times out, returns a garbled frame, or finds the device disconnected. The in-process
instruments turn a decision into the :mod:`drivers.base` error a real driver would
raise; the wire servers act it out on the bytes (no reply, corrupted reply, closed
port), so the real drivers meet the same faults.

A late reply (``late_rate``, ``late_s``): the device answers, but ``late_s`` seconds of wall
time after the request, past the driver's timeout, and answers the requests behind it only
after that (an instrument busy with a slow measurement). Only the serial devices (STIL,
ZGM1120) act it out on the wire; in-process it changes nothing (a call has no timeout to
miss), and the Modbus sim answers on time (Modbus TCP matches replies by transaction id;
RTU's late replies are tested against a fake controller, tests/drivers).

Two kinds of disconnect:

* ``disconnect_after = N``: the device is gone for good after N operations (a cable cut).
* ``disconnect_rate = p``: each operation drops the link with probability p (a loose
  connector, a USB adapter re-enumerating): the driver sees the link close, and the
  device accepts a new connection ``recover_after_s`` seconds of lab clock later
  (:meth:`FaultInjector.drop`, :meth:`FaultInjector.is_down`). A driver that reopens
  the port after that carries on.
"""

from __future__ import annotations

import enum
import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from drivers.base import DeviceTimeout, Disconnected, ProtocolError

__all__ = ["Fault", "FaultInjector", "FaultSpec"]


class Fault(enum.Enum):
    """What happens to one operation."""

    NONE = "none"
    TIMEOUT = "timeout"
    GARBLE = "garble"
    DISCONNECT = "disconnect"
    #: The link drops, the device comes back after ``recover_after_s`` (a recoverable disconnect).
    DROP = "drop"
    #: The answer comes ``late_s`` after the request (past the driver's timeout).
    LATE = "late"


@dataclass(frozen=True, slots=True)
class FaultSpec:
    """Fault rates of one device (all off by default).

    Attributes
    ----------
    timeout_rate
        Probability in [0, 1] that an operation gets no answer.
    garble_rate
        Probability in [0, 1] that an answer is corrupted.
    disconnect_after
        The device drops off for good after this many operations (0 = never).
    disconnect_rate
        Probability in [0, 1] that an operation drops the link; the device is back
        ``recover_after_s`` later (a disconnect that recovers).
    recover_after_s
        Lab-clock seconds a dropped device stays unreachable (>= 0).
    late_rate
        Probability in [0, 1] that an answer comes ``late_s`` late (serial devices).
    late_s
        How late, in wall seconds (> 0): more than the driver's timeout to test its
        resynchronisation.
    """

    timeout_rate: float = 0.0
    garble_rate: float = 0.0
    disconnect_after: int = 0
    disconnect_rate: float = 0.0
    recover_after_s: float = 0.5
    late_rate: float = 0.0
    late_s: float = 1.5

    def __post_init__(self) -> None:
        for name in ("timeout_rate", "garble_rate", "disconnect_rate", "late_rate"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {v}")
        total = self.timeout_rate + self.garble_rate + self.disconnect_rate + self.late_rate
        if total > 1.0:
            raise ValueError(
                "timeout_rate + garble_rate + disconnect_rate + late_rate must be <= 1, "
                f"got {total:g}"
            )
        if not (self.late_s > 0.0 and math.isfinite(self.late_s)):
            raise ValueError(f"late_s must be finite and > 0, got {self.late_s}")
        if self.disconnect_after < 0:
            raise ValueError(f"disconnect_after must be >= 0, got {self.disconnect_after}")
        if not (self.recover_after_s >= 0.0 and math.isfinite(self.recover_after_s)):
            raise ValueError(f"recover_after_s must be finite and >= 0, got {self.recover_after_s}")

    @property
    def active(self) -> bool:
        """Any fault configured."""
        return bool(
            self.timeout_rate
            or self.garble_rate
            or self.disconnect_after
            or self.disconnect_rate
            or self.late_rate
        )


class FaultInjector:
    """Decides the fate of each operation of one device, reproducibly.

    Parameters
    ----------
    device
        Device name used in error messages.
    spec
        The fault rates.
    rng
        Seeded generator (one per device keeps devices independent of each other's
        operation counts).
    """

    def __init__(
        self, device: str, spec: FaultSpec | None = None, rng: np.random.Generator | None = None
    ):
        self.device = device
        self.spec = spec or FaultSpec()
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self.operations = 0
        self.disconnected = False
        #: Recoverable drops so far, and the lab-clock time the last one ends.
        self.drops = 0
        self.down_until_s = -math.inf
        #: How many operations met each fault (by :class:`Fault` value).
        self.injected: Counter[str] = Counter()

    def decide(self) -> Fault:
        """Count one operation and return what happens to it."""
        fault = self._decide()
        if fault is not Fault.NONE:
            self.injected[fault.value] += 1
        return fault

    def _decide(self) -> Fault:
        self.operations += 1
        spec = self.spec
        if self.disconnected or (spec.disconnect_after and self.operations > spec.disconnect_after):
            self.disconnected = True
            return Fault.DISCONNECT
        if not spec.active:
            return Fault.NONE
        u = float(self._rng.random())
        if u < spec.timeout_rate:
            return Fault.TIMEOUT
        if u < spec.timeout_rate + spec.garble_rate:
            return Fault.GARBLE
        if u < spec.timeout_rate + spec.garble_rate + spec.disconnect_rate:
            return Fault.DROP
        if u < spec.timeout_rate + spec.garble_rate + spec.disconnect_rate + spec.late_rate:
            return Fault.LATE
        return Fault.NONE

    def drop(self, now_s: float) -> None:
        """Record a recoverable drop at lab-clock ``now_s``: down for ``recover_after_s``."""
        self.drops += 1
        self.down_until_s = now_s + self.spec.recover_after_s

    def is_down(self, now_s: float) -> bool:
        """The device dropped off and is not back yet at lab-clock ``now_s``."""
        return now_s < self.down_until_s

    def error_for(self, fault: Fault, operation: str) -> DeviceTimeout | ProtocolError | None:
        """In-process use: the driver error a timeout or garbled reply turns into."""
        if fault is Fault.TIMEOUT:
            return DeviceTimeout(f"simulated timeout: no answer to {operation}", device=self.device)
        if fault is Fault.GARBLE:
            return ProtocolError(f"simulated garbled reply to {operation}", device=self.device)
        return None

    def check(self, operation: str) -> None:
        """In-process use: raise the driver error for this operation's fault, if any.

        Raises
        ------
        drivers.base.Disconnected, drivers.base.DeviceTimeout, drivers.base.ProtocolError
        """
        fault = self.decide()
        if fault is Fault.DISCONNECT:
            raise Disconnected(
                f"simulated disconnect after {self.spec.disconnect_after} operations ({operation})",
                device=self.device,
            )
        if fault is Fault.DROP:
            raise Disconnected(
                f"simulated link drop during {operation} (back after "
                f"{self.spec.recover_after_s:g} s)",
                device=self.device,
            )
        error = self.error_for(fault, operation)
        if error is not None:
            raise error

    def garble(self, frame: bytes, *, keep: bytes = b"\r\n") -> bytes:
        """Corrupt a reply frame reproducibly: flip bits (XOR 0x5A) in one byte.

        Bytes in ``keep`` (line terminators) are never chosen, so the frame still ends
        where the original did and a reader sees one bad line, not a hang. XOR 0x5A maps
        every digit, sign, separator and letter of the ASCII protocols to a character
        their grammars reject.
        """
        candidates = [i for i, b in enumerate(frame) if b not in keep]
        if not candidates:
            return frame
        i = candidates[int(self._rng.integers(0, len(candidates)))]
        out = bytearray(frame)
        out[i] ^= 0x5A
        return bytes(out)
