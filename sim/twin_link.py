"""What every simulated instrument shares: its link's connection state and fault injection.

:class:`SimLink` is the base of :class:`sim.twin_axis.SimAxis`,
:class:`sim.twin_spectro.SimSpectro` and :class:`sim.twin_gloss.SimGlossmeter`.
"""

from __future__ import annotations

from drivers.base import Disconnected
from drivers.timing import Clock
from sim.faults import Fault, FaultInjector

__all__ = ["SimLink"]


class SimLink:
    """The connection state and fault injection every simulated instrument shares.

    Operations on a closed link raise :class:`drivers.base.Disconnected`; each operation
    then passes the fault injector (timeouts, garbled replies, disconnects). A recoverable
    drop (:attr:`sim.faults.Fault.DROP`) closes the link; :meth:`connect` succeeds again
    once the device is back (``recover_after_s`` of lab clock later).
    """

    name: str
    faults: FaultInjector
    clock: Clock
    _connected: bool = False

    async def connect(self) -> None:
        """Open the (simulated) link.

        Raises
        ------
        drivers.base.Disconnected
            The device dropped off the line and is not back yet.
        """
        now = self.clock.now()
        if self.faults.is_down(now):
            raise Disconnected(
                f"no answer: the device dropped off the line and is back in "
                f"{self.faults.down_until_s - now:.3g} s",
                device=self.name,
            )
        self._connected = True

    async def close(self) -> None:
        """Close the link."""
        self._connected = False

    def _op(self, operation: str) -> None:
        if not self._connected:
            raise Disconnected(f"not connected ({operation})", device=self.name)
        fault = self.faults.decide()
        if fault is Fault.DROP:
            self._connected = False
            self.faults.drop(self.clock.now())
            raise Disconnected(
                f"simulated link drop during {operation}: reconnect after "
                f"{self.faults.spec.recover_after_s:g} s",
                device=self.name,
            )
        if fault is Fault.DISCONNECT:
            raise Disconnected(
                f"simulated disconnect after {self.faults.spec.disconnect_after} operations "
                f"({operation})",
                device=self.name,
            )
        error = self.faults.error_for(fault, operation)
        if error is not None:
            raise error
