"""A small async line transport over a serial port (pyserial-asyncio-fast).

Shared by :mod:`drivers.stil` and :mod:`drivers.glossmeter`. ``port`` is anything
:func:`serial.serial_for_url` accepts: a device (``/dev/ttyUSB0``, a pty path) or
``socket://host:port``. (pyserial-asyncio-fast cannot open ``loop://``.)

Every failure is mapped onto :mod:`drivers.base` errors naming the device and the port:
a missing or busy port -> :class:`~drivers.base.Disconnected` (ports are opened with an
exclusive lock, as pymodbus does: a port another program holds is refused, not shared), no complete line in time ->
:class:`~drivers.base.DeviceTimeout`, undecodable bytes -> :class:`~drivers.base.ProtocolError`.
"""

from __future__ import annotations

import asyncio
import contextlib

import serial
import serial_asyncio_fast

from drivers.base import DeviceTimeout, Disconnected, ProtocolError
from drivers.profiles import SerialSettings

__all__ = ["LineTransport", "busy_hint", "quote"]


#: After a line overran the read buffer: how long the link must stay silent before it
#: counts as drained, and the longest the drain goes on (a device streaming garbage).
FLOOD_QUIET_S = 0.1
FLOOD_DRAIN_MAX_S = 10.0


def busy_hint(exc: BaseException) -> str:
    """The open error, with the likely cause spelled out when the port is locked."""
    text = str(exc)
    if "exclusively lock" in text:
        return f"port busy: another program holds it open ({text})"
    return text


def quote(raw: str | bytes, limit: int = 80) -> str:
    """``repr`` of a raw line, truncated to ``limit`` characters (for error messages)."""
    text = repr(raw)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class LineTransport:
    """Write commands and read terminated lines on one serial port.

    Parameters
    ----------
    port
        Device path or pyserial URL.
    settings
        Baud rate, byte size, parity, stop bits.
    device
        The instrument's configured name (used in error messages).
    encoding
        Text encoding of commands and replies.
    """

    def __init__(
        self, port: str, settings: SerialSettings, *, device: str, encoding: str = "ascii"
    ) -> None:
        self.port = port
        self.settings = settings
        self.device = device
        self.encoding = encoding
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None

    @property
    def is_open(self) -> bool:
        """Whether :meth:`open` succeeded and :meth:`close` was not called since."""
        return self._writer is not None

    async def open(self) -> None:
        """Open the port; raise :class:`Disconnected` naming the port when that fails."""
        if not self.port:
            raise Disconnected("no serial port configured", device=self.device)
        try:
            self._reader, self._writer = await serial_asyncio_fast.open_serial_connection(
                url=self.port,
                baudrate=self.settings.baudrate,
                bytesize=self.settings.bytesize,
                parity=self.settings.parity,
                stopbits=self.settings.stopbits,
                exclusive=True,  # flock: a port another program holds is refused, not shared
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise Disconnected(
                f"cannot open serial port {self.port!r}: {busy_hint(exc)}", device=self.device
            ) from exc

    async def close(self) -> None:
        """Close the port (idempotent)."""
        writer, self._writer, self._reader = self._writer, None, None
        if writer is not None:
            writer.close()
            with contextlib.suppress(OSError, serial.SerialException):
                await writer.wait_closed()

    def _streams(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        if self._reader is None or self._writer is None:
            raise Disconnected(f"serial port {self.port!r} is not open", device=self.device)
        return self._reader, self._writer

    async def write(self, text: str) -> None:
        """Encode and send ``text`` as is (the caller appends any terminator)."""
        _, writer = self._streams()
        try:
            writer.write(text.encode(self.encoding))
            await writer.drain()
        except (serial.SerialException, OSError) as exc:
            raise Disconnected(f"write to {self.port!r} failed: {exc}", device=self.device) from exc

    def discard_input(self) -> int:
        """Drop bytes already received but not read (stale replies); return how many."""
        reader, _ = self._streams()
        buffered = getattr(reader, "_buffer", None)
        if isinstance(buffered, bytearray):
            dropped = len(buffered)
            buffered.clear()
            return dropped
        return 0

    async def drain_quiet(self, quiet_s: float, max_s: float) -> int:
        """Read and drop everything that arrives until the line has been quiet for
        ``quiet_s`` (at most ``max_s`` in all); return the number of bytes dropped.

        Used after a request went unanswered: the late answer may still be on its way, and
        would otherwise be read as the answer to the next request.
        """
        reader, _ = self._streams()
        loop = asyncio.get_running_loop()
        deadline = loop.time() + max(0.0, max_s)
        dropped = 0
        buffered = getattr(reader, "_buffer", None)
        if isinstance(buffered, bytearray):
            dropped += len(buffered)
            buffered.clear()
        while True:
            wait_s = min(quiet_s, deadline - loop.time())
            if wait_s <= 0.0:
                return dropped
            try:
                chunk = await asyncio.wait_for(reader.read(65536), wait_s)
            except TimeoutError:
                return dropped  # quiet for quiet_s: whatever was late has arrived
            except (serial.SerialException, OSError) as exc:
                raise Disconnected(
                    f"read from {self.port!r} failed: {exc}", device=self.device
                ) from exc
            if not chunk:  # end of stream: the port closed
                raise Disconnected(f"port {self.port!r} closed", device=self.device)
            dropped += len(chunk)

    async def drain_until_quiet(
        self, quiet_s: float = FLOOD_QUIET_S, max_s: float = FLOOD_DRAIN_MAX_S
    ) -> tuple[int, bool]:
        """Read and drop input until none arrives for ``quiet_s`` (or ``max_s`` passed).

        Returns the bytes dropped and whether the line went quiet.
        """
        reader, _ = self._streams()
        buffered = getattr(reader, "_buffer", None)
        dropped = len(buffered) if isinstance(buffered, bytearray) else 0
        self.discard_input()
        loop = asyncio.get_running_loop()
        deadline = loop.time() + max_s
        while (left := deadline - loop.time()) > 0:
            try:
                chunk = await asyncio.wait_for(reader.read(1 << 16), min(quiet_s, left))
            except TimeoutError:
                return dropped, True
            except (serial.SerialException, OSError) as exc:
                raise Disconnected(
                    f"read from {self.port!r} failed: {exc}", device=self.device
                ) from exc
            if not chunk:  # end of file: the port closed
                return dropped, True
            dropped += len(chunk)
        return dropped, False

    async def read_line(self, terminator: str, timeout_s: float | None) -> str:
        """Read one line ending in ``terminator``; return it without the terminator.

        ``timeout_s`` ``None`` waits forever (pushed readings).
        """
        reader, _ = self._streams()
        term = terminator.encode(self.encoding)
        try:
            raw = await asyncio.wait_for(reader.readuntil(term), timeout_s)
        except TimeoutError:
            raise DeviceTimeout(
                f"no reply on {self.port!r} within {timeout_s} s", device=self.device
            ) from None
        except asyncio.IncompleteReadError as exc:
            raise Disconnected(
                f"port {self.port!r} closed (partial line {quote(exc.partial)})",
                device=self.device,
            ) from exc
        except asyncio.LimitOverrunError as exc:
            # a flood (megabytes without the terminator): drop it until the line goes
            # quiet, or every retry meets the rest of the same flood
            dropped, quiet = await self.drain_until_quiet()
            raise ProtocolError(
                f"line on {self.port!r} longer than the buffer without terminator "
                f"{terminator!r}: {dropped} bytes dropped"
                + ("" if quiet else f", still arriving after {FLOOD_DRAIN_MAX_S:g} s"),
                device=self.device,
            ) from exc
        except (serial.SerialException, OSError) as exc:
            raise Disconnected(
                f"read from {self.port!r} failed: {exc}", device=self.device
            ) from exc
        try:
            return raw[: -len(term)].decode(self.encoding)
        except UnicodeDecodeError:
            raise ProtocolError(
                f"undecodable bytes {quote(raw)} on {self.port!r}", device=self.device
            ) from None
