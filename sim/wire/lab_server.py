"""The whole simulated lab on the wire: Modbus servers and pty devices as one context manager.

:class:`SimLabServer` starts the :mod:`sim.wire.modbus` servers and the :mod:`sim.wire.serial`
ptys, with stable symlinks to the ptys at configured paths (``/tmp/goniolab-sim/spectro`` ...);
``goniolab sim serve`` runs it.
"""

from __future__ import annotations

import contextlib
from types import TracebackType
from typing import Any

from sim.wire.modbus import ModbusAxisServer
from sim.wire.serial import PtyDevice, StilPtyDevice, ZgmPtyDevice

__all__ = ["SimLabServer"]


class SimLabServer:
    """The whole simulated lab on the wire; ``async with`` starts and stops it.

    Parameters
    ----------
    modbus
        Modbus servers (one per host:port; usually one with both arms).
    spectro, glossmeter
        pty devices (either may be ``None``).
    """

    def __init__(
        self,
        modbus: list[ModbusAxisServer],
        spectro: StilPtyDevice | None = None,
        glossmeter: ZgmPtyDevice | None = None,
    ) -> None:
        self.modbus = modbus
        self.spectro = spectro
        self.glossmeter = glossmeter
        self._started: list[ModbusAxisServer | PtyDevice] = []

    async def start(self) -> None:
        """Warm the models up, then start every server.

        The spectro's and glossmeter's models are evaluated once *before* any endpoint
        accepts a connection (:meth:`SimSpectro.warm_up`, :meth:`SimGlossmeter.warm_up`),
        so a driver's first reading is not held up by kernel loading and table building
        and fits its ordinary reply timeout. On failure, the servers already started are
        stopped and the error re-raised.
        """
        if self.spectro is not None:
            await self.spectro.spectro.warm_up()
        if self.glossmeter is not None:
            await self.glossmeter.gloss.warm_up()
        parts: list[ModbusAxisServer | PtyDevice] = [*self.modbus]
        parts += [d for d in (self.spectro, self.glossmeter) if d is not None]
        try:
            for part in parts:
                await part.start()
                self._started.append(part)
        except BaseException:
            await self.stop()
            raise

    async def stop(self) -> None:
        """Stop everything started (in reverse order); safe to call twice."""
        while self._started:
            part = self._started.pop()
            with contextlib.suppress(Exception):
                await part.stop()

    async def __aenter__(self) -> SimLabServer:
        await self.start()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()

    def endpoints(self) -> dict[str, Any]:
        """Where each simulated instrument can be reached."""
        out: dict[str, Any] = {}
        for srv in self.modbus:
            for unit, wire in srv.axes.items():
                ep: dict[str, Any] = {"transport": srv.transport, "host": srv.host}
                ep |= {"port": srv.port} if srv.transport == "tcp" else {"serial_port": srv.url}
                out[wire.axis.name] = ep | {"unit_id": unit, "profile": wire.profile.name}
        for dev in (self.spectro, self.glossmeter):
            if dev is not None:
                out[dev.name] = {
                    "port": str(dev.link_path),
                    "pty": dev.slave_name,
                    "profile": dev.profile.name,
                }
        return out
