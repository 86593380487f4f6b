"""Seeded fault injection for the simulated instruments (in-process and on the wire).

A :class:`FaultInjector` is consulted before every operation of one simulated device
and decides, from a seeded :class:`numpy.random.Generator`, whether that operation
times out, returns a garbled frame, or finds the device disconnected. The in-process
instruments turn a decision into the :mod:`drivers.base` error a real driver would
raise; the wire servers act it out on the bytes (no reply, corrupted reply, closed
port), so the real drivers meet the same faults.
"""

from __future__ import annotations

import enum
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
        The device drops off after this many operations (0 = never).
    """

    timeout_rate: float = 0.0
    garble_rate: float = 0.0
    disconnect_after: int = 0

    def __post_init__(self) -> None:
        for name in ("timeout_rate", "garble_rate"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {v}")
        if self.disconnect_after < 0:
            raise ValueError(f"disconnect_after must be >= 0, got {self.disconnect_after}")

    @property
    def active(self) -> bool:
        """Any fault configured."""
        return bool(self.timeout_rate or self.garble_rate or self.disconnect_after)


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

    def decide(self) -> Fault:
        """Count one operation and return what happens to it."""
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
        return Fault.NONE

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
        if fault is Fault.TIMEOUT:
            raise DeviceTimeout(f"simulated timeout: no answer to {operation}", device=self.device)
        if fault is Fault.GARBLE:
            raise ProtocolError(f"simulated garbled reply to {operation}", device=self.device)

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
