"""The serial instruments on the wire: pseudo-terminals speaking the STIL and ZGM1120 protocols.

* :class:`StilPtyDevice`: the STIL line protocol of a ``stil-spectro`` profile
  (``configs/profiles/stil-ruby.toml``).
* :class:`ZgmPtyDevice`: the Zehntner ZGM1120 protocol (Technical Manual rev. 3.0, 2021,
  section 6), interpreted by :mod:`sim.wire.zgm` (docs/PROTOCOLS.md).

Injected faults (:mod:`sim.faults`): a timed-out request gets no answer, a garbled one has
one byte of the reply flipped, a disconnected device closes its port. A recoverable drop
closes the pty and removes the link (a USB adapter unplugged); ``recover_after_s`` of lab
clock later a fresh pty is published at the same link path, where a driver reopening the
port finds the device again.
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import os
import termios
import tty
from pathlib import Path
from typing import Any

from drivers.profiles import StilProfile, ZgmProfile, template_regex
from drivers.timing import Clock
from sim.faults import Fault, FaultInjector
from sim.instruments import SimGlossmeter, SimSpectro
from sim.wire.zgm import ZgmProtocol

__all__ = ["MAX_LINE_BYTES", "MAX_PENDING_LINES", "StilPtyDevice", "ZgmPtyDevice"]

#: Unread output a pty device keeps before it drops further replies (bytes).
_PTY_OUTPUT_LIMIT = 64 * 1024
#: Longest command line a pty device buffers; the rest of a longer line is discarded up to
#: its terminator (a device's input buffer overflows) and the STIL answers it with an error.
MAX_LINE_BYTES = 4096
#: Command lines a pty device queues while it works on one (one at a time, in order);
#: lines beyond are dropped, as a real device overruns its input buffer.
MAX_PENDING_LINES = 64
#: Queued in place of a line that was longer than :data:`MAX_LINE_BYTES`.
_OVERLONG = b"\x00overlong"


class PtyDevice(abc.ABC):
    """A line-oriented device on the master side of a pseudo-terminal.

    The slave side (what a driver opens) is put in raw mode and published through a
    symlink at ``link_path`` (replacing a stale link, never a regular file). Command lines
    are answered one at a time by one worker task, from a queue of at most
    :data:`MAX_PENDING_LINES`; a line is at most :data:`MAX_LINE_BYTES` long. Garbage,
    floods and unterminated input therefore cost bounded memory and work.
    """

    name = "device"
    #: The device's fault injector and lab clock (set by the subclasses).
    faults: FaultInjector
    clock: Clock

    def __init__(self, link_path: str | Path, *, terminator: bytes) -> None:
        self.link_path = Path(link_path)
        self.terminator = terminator
        self._master = -1
        self._slave = -1
        self._buf = b""
        self._out = b""
        self._writer_armed = False
        self._drained = asyncio.Event()
        self._drained.set()
        self._tasks: set[asyncio.Task[None]] = set()
        self._stopped = False
        self._discarding = False  # inside a line longer than MAX_LINE_BYTES
        self._lines: asyncio.Queue[bytes] = asyncio.Queue(MAX_PENDING_LINES)
        self._worker: asyncio.Task[None] | None = None
        #: Command lines dropped because the queue was full (input overrun), and lines
        #: discarded for being longer than MAX_LINE_BYTES.
        self.dropped_lines = 0
        self.overlong_lines = 0
        self.slave_name = ""

    @property
    def buffered_bytes(self) -> int:
        """Bytes received and not yet part of a complete line."""
        return len(self._buf)

    @property
    def pending_lines(self) -> int:
        """Complete command lines waiting for the device (at most MAX_PENDING_LINES)."""
        return self._lines.qsize()

    @property
    def open(self) -> bool:
        """The device is serving."""
        return self._master >= 0

    async def start(self) -> None:
        """Create the pty, set raw mode, publish the symlink, start reading.

        Raises
        ------
        FileExistsError
            ``link_path`` exists and is not a symlink (we never delete real files).
        """
        self._stopped = False
        self._buf = b""
        master, slave = os.openpty()
        tty.setraw(slave, termios.TCSANOW)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.slave_name = os.ttyname(slave)
        link = self.link_path
        link.parent.mkdir(parents=True, exist_ok=True)
        if link.is_symlink():
            link.unlink()
        elif link.exists():
            self._close_fds()
            raise FileExistsError(f"{link}: exists and is not a symlink; not replacing it")
        link.symlink_to(self.slave_name)
        loop = asyncio.get_running_loop()
        loop.add_reader(master, self._on_readable)
        if self._worker is None or self._worker.done():
            self._worker = loop.create_task(self._work(), name=f"{self.name}-pty-worker")
            self._tasks.add(self._worker)
            self._worker.add_done_callback(self._tasks.discard)

    def _on_readable(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            return
        self._buf += data
        term = self.terminator
        while (end := self._buf.find(term)) >= 0:
            line, self._buf = self._buf[:end], self._buf[end + len(term) :]
            if self._discarding:  # the end of a line that overflowed the input buffer
                self._discarding = False
                line = _OVERLONG
            self._enqueue(line)
        if self._discarding or len(self._buf) > MAX_LINE_BYTES:
            self._discarding = True
            self._buf = b""

    def _enqueue(self, line: bytes) -> None:
        try:
            self._lines.put_nowait(line)
        except asyncio.QueueFull:
            self.dropped_lines += 1

    async def _work(self) -> None:
        """Answer the queued lines one at a time; a failing line is reported, not fatal."""
        while True:
            line = await self._lines.get()
            try:
                if line == _OVERLONG:
                    await self._handle_overlong()
                else:
                    await self._handle_line(line)
            except Exception as exc:  # a bug in a handler must not silence the device
                asyncio.get_running_loop().call_exception_handler(
                    {"message": f"{self.name} pty: error answering {line[:40]!r}",
                     "exception": exc}
                )  # fmt: skip
            finally:
                self._lines.task_done()

    @abc.abstractmethod
    async def _handle_line(self, line: bytes) -> None:
        """Answer one command line (without its terminator)."""

    async def _handle_overlong(self) -> None:
        """A line longer than :data:`MAX_LINE_BYTES` ended: counted (and dropped)."""
        self.overlong_lines += 1

    async def idle(self) -> None:
        """Return once every queued command line has been answered."""
        await self._lines.join()

    def write(self, data: bytes) -> None:
        """Queue bytes for the driver; flushed as the pty accepts them (no-op once closed).

        Output beyond :data:`_PTY_OUTPUT_LIMIT` unread bytes is dropped, as a device's
        transmit buffer overflows when nobody reads the line.
        """
        if self._master < 0:
            return
        if len(self._out) + len(data) > _PTY_OUTPUT_LIMIT:
            return
        was_empty = not self._out
        self._out += data
        if was_empty:
            self._flush()

    def _flush(self) -> None:
        if self._master < 0:
            self._out = b""
            return
        loop = asyncio.get_running_loop()
        try:
            n = os.write(self._master, self._out)
        except BlockingIOError:
            n = 0
        except OSError:
            self._out = b""
            n = 0
        self._out = self._out[n:]
        if self._out:
            self._drained.clear()
        else:
            self._drained.set()
        if self._out and not self._writer_armed:
            loop.add_writer(self._master, self._flush)
            self._writer_armed = True
        elif not self._out and self._writer_armed:
            loop.remove_writer(self._master)
            self._writer_armed = False

    def disconnect(self) -> None:
        """Drop off the line: stop reading and close the pty (the driver sees EOF/EIO)."""
        if self._master >= 0:
            with contextlib.suppress(Exception):
                loop = asyncio.get_running_loop()
                loop.remove_reader(self._master)
                loop.remove_writer(self._master)
        self._writer_armed = False
        self._out = b""
        self._buf = b""
        self._discarding = False
        while not self._lines.empty():  # what was queued is lost with the line
            self._lines.get_nowait()
            self._lines.task_done()
        self._drained.set()
        self._close_fds()

    def drop(self) -> None:
        """A recoverable disconnect: close the pty and remove the link now, publish a fresh
        pty at the same path ``recover_after_s`` of lab clock later."""
        self.faults.drop(self.clock.now())
        self.disconnect()
        if self.link_path.is_symlink():
            with contextlib.suppress(OSError):
                self.link_path.unlink()
        self._spawn(self._come_back())

    async def _come_back(self) -> None:
        delay_s = self.faults.down_until_s - self.clock.now()
        if delay_s > 0:
            await self.clock.sleep(delay_s)
        if not self._stopped and not self.open:
            await self.start()

    def _spawn(self, coro: Any) -> None:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _close_fds(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1

    async def stop(self) -> None:
        """Stop serving, close the pty and remove the symlink."""
        self._stopped = True
        for task in list(self._tasks):
            task.cancel()
        self.disconnect()
        if self.link_path.is_symlink():
            with contextlib.suppress(OSError):
                self.link_path.unlink()


class StilPtyDevice(PtyDevice):
    """The simulated STIL spectro-colorimeter behind a pty, speaking a ``stil-spectro`` profile.

    Commands and reply lines are the profile's templates (``[commands]``, ``[replies]``);
    readings come from the in-process :class:`sim.instruments.SimSpectro`.
    """

    name = "spectro"

    def __init__(self, spectro: SimSpectro, profile: StilProfile, link_path: str | Path) -> None:
        super().__init__(link_path, terminator=profile.command_terminator.encode(profile.encoding))
        self.spectro = spectro
        self.faults = spectro.faults
        self.clock = spectro.clock
        self.profile = profile
        self._exposure_re = template_regex(profile.cmd_set_exposure)
        #: Every measurement answered: (effective theta_i, theta_r, the reply's first line).
        self.answered: list[tuple[float, float, str]] = []

    def _reply(self, lines: list[str], fault: Fault) -> None:
        p = self.profile
        data = "".join(line + p.reply_terminator for line in lines).encode(
            p.encoding, errors="replace"
        )
        if fault is Fault.GARBLE:
            data = self.spectro.faults.garble(data, keep=p.reply_terminator.encode(p.encoding))
        self.write(data)

    def _error(self, code: int, message: str) -> list[str]:
        return [self.profile.reply_error.format(code=code, message=message)]

    async def _handle_line(self, line: bytes) -> None:
        p = self.profile
        # garbage bytes are echoed escaped (b"\xff" -> "\\xff") in the error reply, so the
        # reply is always in the profile's encoding
        text = line.decode(p.encoding, errors="backslashreplace").strip("\r\n")
        if not text:
            return
        fault = self.faults.decide()
        if fault is Fault.DISCONNECT:
            self.disconnect()
            return
        if fault is Fault.DROP:
            self.drop()
            return
        if fault is Fault.TIMEOUT:
            return
        if text == p.cmd_identify:
            lines = [p.reply_identify.format(ident="STIL RUBY SN 000000 (goniolab simulator)")]
        elif (m := self._exposure_re.match(text)) is not None:
            exposure = int(m.group("exposure_us"))
            if not p.exposure_min_us <= exposure <= p.exposure_max_us:
                lines = self._error(
                    2, f"exposure out of range {p.exposure_min_us}..{p.exposure_max_us} us"
                )
            else:
                self.spectro.exposure_us = exposure
                lines = [p.reply_set_exposure.format(exposure_us=exposure)]
        elif text == p.cmd_measure:
            lines = await self._measure_lines()
            # what was answered at which geometry (the soak checks each stored reading
            # against it: a reading stored at the wrong angle cannot hide)
            self.answered.append((*self.spectro.geometry_deg(), lines[0]))
        else:
            lines = self._error(1, f"unknown command {text[:40]}")
        if fault is Fault.LATE:  # busy: the answer, and every command behind it, waits
            await asyncio.sleep(self.faults.spec.late_s)
        self._reply(lines, fault)

    async def _handle_overlong(self) -> None:
        await super()._handle_overlong()
        self._reply(
            self._error(
                1, f"line too long (more than {MAX_LINE_BYTES} bytes without a terminator)"
            ),
            Fault.NONE,
        )

    async def _measure_lines(self) -> list[str]:
        """The twin's own reading (its spectrum, not one synthesised from the luminance:
        issue 21 found colour over the wire grey), and its signal level for a profile whose
        reply carries ``{peak_fraction}`` (-1 when the twin has no detector model)."""
        reading = await self.spectro.reading()
        values = reading.values
        wl = reading.wavelengths_nm
        fields: dict[str, Any] = {
            "luminance_pct": reading.luminance_pct,
            "start_nm": int(wl[0]),
            "step_nm": int(wl[1] - wl[0]),
            "count": len(values),
            "values": ",".join(f"{v:.6g}" for v in values),
            "exposure_us": self.spectro.exposure_us,
            "ident": "STIL RUBY",
            "peak_fraction": -1 if reading.peak_fraction is None else reading.peak_fraction,
        }
        return [t.format(**fields) for t in self.profile.reply_measure]


class ZgmPtyDevice(PtyDevice):
    """The simulated Zehntner ZGM1120 glossmeter behind a pty.

    The protocol is :class:`sim.wire.zgm.ZgmProtocol`, written from the ZGM 1120 Technical
    Manual rev 3.0 (section 6; docs/PROTOCOLS.md) independently of the driver: command
    strings end with ``:``, return strings with the profile's ``reply_terminator``.
    Requests for another serial number are ignored (RS-232 multi-drop behaviour). While
    AutoSend is on, the measure button is "pressed" every ``autosend_interval_s`` of lab
    clock and the meter pushes a reading.
    """

    name = "glossmeter"

    def __init__(
        self,
        gloss: SimGlossmeter,
        profile: ZgmProfile,
        link_path: str | Path,
        *,
        serial_number: str,
    ) -> None:
        super().__init__(link_path, terminator=b":")
        self.gloss = gloss
        self.faults = gloss.faults
        self.clock = gloss.clock
        self.profile = profile
        self.serial_number = serial_number.strip()
        self.protocol = ZgmProtocol(gloss, self.serial_number)
        self._autosend: asyncio.Task[None] | None = None

    async def _handle_line(self, line: bytes) -> None:
        try:
            text = line.decode("ascii").strip("\r\n ")
        except UnicodeDecodeError:
            return  # not the protocol's alphabet: a real meter ignores the line
        if not self.protocol.addressed(text):
            return
        fault = self.faults.decide()
        if fault is Fault.DISCONNECT:
            self.disconnect()
            return
        if fault is Fault.DROP:
            self.drop()
            return
        if fault is Fault.TIMEOUT:
            return
        reply = await self.protocol.handle(text)
        self._sync_autosend()
        if reply is None:
            return
        if fault is Fault.LATE:  # busy: the answer, and every command behind it, waits
            await asyncio.sleep(self.faults.spec.late_s)
        data = reply.encode("ascii")
        if fault is Fault.GARBLE:
            data = self.gloss.faults.garble(data)
        self.write(data + self.profile.reply_terminator.encode("ascii"))

    def _sync_autosend(self) -> None:
        """Start or stop the button-press task to match the protocol's AutoSend state."""
        wanted = self.protocol.autosend is not None and self.gloss.autosend_interval_s > 0
        running = self._autosend is not None and not self._autosend.done()
        if wanted and not running:
            self._autosend = asyncio.get_running_loop().create_task(self._push())
        elif not wanted and self._autosend is not None:
            self._autosend.cancel()
            self._autosend = None

    async def _push(self) -> None:
        while self.open:
            await self.gloss.clock.sleep(self.gloss.autosend_interval_s)
            await self._drained.wait()  # back-pressure: the line took the last reading
            reply = await self.protocol.pushed()
            if reply is None:
                return
            self.write(reply.encode("ascii") + self.profile.reply_terminator.encode("ascii"))

    async def stop(self) -> None:
        """Stop auto-send and the pty."""
        self.protocol.autosend = None
        self._sync_autosend()
        await super().stop()
