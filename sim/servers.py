"""The simulated lab on the wire: Modbus TCP stepper controllers and pty serial devices.

The same simulated instruments as :mod:`sim.instruments`, reachable the way real ones
are, so the real drivers in :mod:`drivers` can be tested end to end:

* :class:`ModbusAxisServer`: one Modbus TCP server (pymodbus 3.16
  ``ModbusTcpServer`` with :class:`pymodbus.simulator.SimDevice` devices), or a Modbus
  RTU one framed over a TCP socket (``ModbusSerialServer`` on ``socket://host:port``),
  with one unit id per arm, implementing a ``direct-data`` stepper profile (Oriental Motor AZ register map,
  manual HM-60262E, see ``configs/profiles/oriental-az.toml``). Writing the 18-register
  direct-data block with trigger = 1 starts a move of the simulated arm; the status,
  alarm, feedback and command registers are refreshed from the arm on every request;
  rising edges of ZHOME / STOP / ALM-RST in the latched input-command word act.
* :class:`StilPtyDevice`: a pseudo-terminal speaking the STIL line protocol of a
  ``stil-spectro`` profile (``configs/profiles/stil-ruby.toml``).
* :class:`ZgmPtyDevice`: a pseudo-terminal speaking the Zehntner ZGM1120 protocol
  (Technical Manual rev. 3.0, 2021, pp. 16-28).
* :class:`SimLabServer`: all of them, as an async context manager, with stable symlinks
  to the ptys at configured paths (``/tmp/goniolab-sim/spectro`` ...).

Injected faults (:mod:`sim.faults`) act on the wire: a timed-out request gets no answer
(Modbus: not executed, no reply sent), a garbled one gets corrupted bytes (pty: one byte
of the reply flipped; Modbus TCP: a corrupted MBAP header, RTU: a wrong CRC, which a
master's framer rejects), a disconnected device stops answering (Modbus: gateway exception 0x0B, "target
device failed to respond"; pty: the port is closed).
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import errno
import os
import termios
import tty
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.profiles import StepperProfile, StilProfile, ZgmProfile, template_regex
from sim.faults import Fault
from sim.instruments import SPECTRUM_WAVELENGTHS_NM, SimAxis, SimGlossmeter, SimSpectro
from sim.motion import MotorFault

__all__ = [
    "ModbusAxisServer",
    "SimLabServer",
    "StilPtyDevice",
    "WireAxis",
    "ZgmPtyDevice",
]

#: Size of the simulated register space (covers every address of the AZ map).
_REGISTER_SPACE = 0x0200

#: Unread output a pty device keeps before it drops further replies (bytes).
_PTY_OUTPUT_LIMIT = 64 * 1024


def _split32(value: int) -> tuple[int, int]:
    """A signed/unsigned 32-bit value as (high word, low word)."""
    v = int(value) & 0xFFFFFFFF
    return v >> 16, v & 0xFFFF


def _join32(hi: int, lo: int, *, signed: bool = True) -> int:
    v = ((hi & 0xFFFF) << 16) | (lo & 0xFFFF)
    if signed and v & 0x80000000:
        v -= 1 << 32
    return v


# =========================================================================== Modbus
@dataclass
class WireAxis:
    """One simulated arm behind a Modbus unit id.

    Attributes
    ----------
    axis
        The simulated arm.
    profile
        A ``direct-data`` stepper profile (register map, bits, units).
    steps_per_deg
        Steps per degree, as configured for the driver.
    unit_id
        Modbus device id.
    """

    axis: SimAxis
    profile: StepperProfile
    steps_per_deg: float
    unit_id: int
    _input_word: int = field(default=0, repr=False)

    def __post_init__(self) -> None:
        if self.profile.move_style != "direct-data":
            raise ValueError(
                f"{self.profile.path}: the wire simulator implements move_style "
                f"'direct-data' only, got {self.profile.move_style!r}"
            )
        regs = self.profile.registers
        for name in (
            "output_status",
            "alarm_code",
            "feedback_position",
            "input_command",
            "direct_data",
        ):
            addr = getattr(regs, name)
            if addr is not None and addr + (18 if name == "direct_data" else 2) > _REGISTER_SPACE:
                raise ValueError(
                    f"{self.profile.path}: registers.{name} 0x{addr:04X} beyond the simulated space"
                )

    # --------------------------------------------------------------- registers
    def status_word(self) -> int:
        """The 32-bit output status word from the arm's state (bits from the profile)."""
        st = self.axis.snapshot()
        sb = self.profile.status_bits
        bits: list[tuple[int | None, bool]] = [
            (sb.in_position, st.in_position),
            (sb.moving, st.moving),
            (sb.alarm, st.alarm_code is not None),
            (sb.ready, st.ready),
            (sb.busy, st.moving),
            (
                sb.home_end,
                st.homed and not st.moving and abs(st.position_deg) < 0.5 / self.steps_per_deg,
            ),
            (sb.fault, st.alarm_code is not None),
            (sb.homing, self.axis.motor.is_homing(self.axis.clock.now())),
        ]
        word = 0
        for bit, on in bits:
            if bit is not None and on:
                word |= 1 << bit
        return word

    def refresh(self, registers: list[int], start_address: int) -> None:
        """Write the live status/alarm/position registers into the register image."""
        regs = self.profile.registers
        st = self.axis.snapshot()
        values: list[tuple[int | None, int]] = [
            (regs.output_status, self.status_word()),
            (regs.alarm_code, st.alarm_code or 0),
            (regs.feedback_position, round(st.position_deg * self.steps_per_deg)),
            (regs.command_position, round((st.command_deg or 0.0) * self.steps_per_deg)),
            (regs.input_command, self._input_word),
        ]
        for addr, value in values:
            if addr is None:
                continue
            hi, lo = _split32(value)
            registers[addr - start_address] = hi
            registers[addr - start_address + 1] = lo

    def apply_write(
        self, registers: list[int], start_address: int, address: int, values: list[int]
    ) -> None:
        """Act on a register write (direct-data trigger, input-command edges)."""
        image = list(registers)
        image[address - start_address : address - start_address + len(values)] = values
        written = range(address, address + len(values))
        regs = self.profile.registers
        now = self.axis.clock.now()
        motor = self.axis.motor
        if regs.input_command is not None and (
            regs.input_command in written or regs.input_command + 1 in written
        ):
            off = regs.input_command - start_address
            word = _join32(image[off], image[off + 1], signed=False)
            rising = word & ~self._input_word
            self._input_word = word
            bits = self.profile.input_bits
            assert bits is not None
            if rising >> bits.stop & 1:
                motor.stop(now)
            if rising >> bits.alarm_reset & 1:
                motor.reset_alarm(now)
            if rising >> bits.zhome & 1:
                with contextlib.suppress(MotorFault):  # alarm active: the AZ ignores ZHOME
                    motor.start_home(now)
                    self.axis.ensure_tracker()
        dd = self.profile.direct_data
        if regs.direct_data is not None and dd is not None:
            trigger_addr = regs.direct_data + 14
            if trigger_addr + 1 in written:
                off = regs.direct_data - start_address
                fields = [_join32(image[off + 2 * k], image[off + 2 * k + 1]) for k in range(9)]
                _, op_type, position, speed, accel, _decel, _current, trigger, _dest = fields
                if trigger == dd.trigger:
                    self._start_move(op_type, position, speed, accel)

    def _start_move(
        self, op_type: int, position_steps: int, speed_counts: int, accel_counts: int
    ) -> None:
        p = self.profile
        now = self.axis.clock.now()
        motor = self.axis.motor
        spd = self.steps_per_deg
        if op_type == 1:
            target_deg = position_steps / spd
        elif op_type == 2:
            target_deg = motor.command_deg(now) + position_steps / spd
        elif op_type == 3:
            target_deg = motor.position_deg(now) + position_steps / spd
        else:
            return  # continuous operation etc.: not simulated, ignored
        speed_deg_s = speed_counts / p.speed_counts_per_step_s / spd
        accel_deg_s2 = accel_counts / p.accel_counts_per_step_s2 / spd
        if speed_deg_s <= 0 or accel_deg_s2 <= 0:
            return
        with contextlib.suppress(MotorFault):  # the alarm is now visible in the registers
            motor.start_move(target_deg, now, speed_deg_s=speed_deg_s, accel_deg_s2=accel_deg_s2)
        self.axis.ensure_tracker()


class ModbusAxisServer:
    """A Modbus server with one simulated stepper controller per unit id.

    Parameters
    ----------
    axes
        The arms, each with its unit id and profile.
    host, port
        Listening address (port 0 = the kernel picks a free port when binding; see
        :attr:`port` after start, :attr:`requested_port` keeps the configured one).
    transport
        ``"tcp"``: Modbus TCP (MBAP framing, pymodbus ``ModbusTcpServer``). ``"rtu"``:
        Modbus RTU framing (unit id, PDU, CRC-16) over a TCP socket (pymodbus
        ``ModbusSerialServer`` on ``socket://host:port``), which a master reaches as the
        serial URL ``socket://host:port`` -- an RTU line without a serial cable.

    Notes
    -----
    Injected faults act per request of a unit: a timed-out request is not executed and
    its reply is never sent (the master sees silence); a garbled reply is sent with its
    framing corrupted -- TCP: the MBAP length field, RTU: the CRC -- so a master's framer
    rejects it; a disconnected unit answers exception 0x0B (gateway target failed to
    respond).
    """

    def __init__(
        self,
        axes: list[WireAxis],
        *,
        host: str = "127.0.0.1",
        port: int = 5020,
        transport: Literal["tcp", "rtu"] = "tcp",
    ) -> None:
        ids = [a.unit_id for a in axes]
        if len(set(ids)) != len(ids):
            raise ValueError(f"duplicate Modbus unit ids {ids} on {host}:{port}")
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"transport must be 'tcp' or 'rtu', got {transport!r}")
        self.axes = {a.unit_id: a for a in axes}
        self.host = host
        self.requested_port = port
        self.port = port
        self.transport = transport
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self._pending: dict[int, list[Fault]] = {unit: [] for unit in self.axes}

    @property
    def url(self) -> str:
        """Where a master connects: ``host:port`` (TCP) or ``socket://host:port`` (RTU)."""
        where = f"{self.host}:{self.port}"
        return where if self.transport == "tcp" else f"socket://{where}"

    def _device(self, wire: WireAxis) -> SimDevice:
        async def action(
            function_code: int,
            start_address: int,
            address: int,
            count: int,
            registers: list[int],
            set_values: list[int] | list[bool] | None,
        ) -> ExcCodes | None:
            fault = wire.axis.faults.decide()
            if fault is Fault.DISCONNECT:
                return ExcCodes.GATEWAY_NO_RESPONSE
            if fault is not Fault.NONE:
                self._pending[wire.unit_id].append(fault)
            if set_values is not None and fault is not Fault.TIMEOUT:
                wire.apply_write(registers, start_address, address, [int(v) for v in set_values])
            wire.refresh(registers, start_address)
            return None

        return SimDevice(
            id=wire.unit_id,
            simdata=[
                SimData(address=0, count=_REGISTER_SPACE, values=0, datatype=DataType.REGISTERS)
            ],
            action=action,
        )

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        """Act out a pending fault on the reply frame of its unit."""
        unit_at = 6 if self.transport == "tcp" else 0  # MBAP unit id / RTU address
        if not sending or len(data) <= unit_at:
            return data
        pending = self._pending.get(data[unit_at])
        if not pending:
            return data
        fault = pending.pop(0)
        if fault is Fault.TIMEOUT:
            return b""  # no answer at all
        out = bytearray(data)
        out[5 if self.transport == "tcp" else -1] ^= 0x3C  # MBAP length / CRC high byte
        return bytes(out)

    async def start(self) -> None:
        """Bind and serve in the background.

        Raises
        ------
        OSError
            The address is in use or cannot be bound (message names host:port).
        """
        devices = [self._device(w) for w in self.axes.values()]
        server: ModbusTcpServer | ModbusSerialServer
        if self.transport == "tcp":
            server = ModbusTcpServer(
                devices, address=(self.host, self.requested_port), trace_packet=self._trace_packet
            )
        else:
            server = ModbusSerialServer(
                devices,
                framer=FramerType.RTU,
                port=f"socket://{self.host}:{self.requested_port}",
                trace_packet=self._trace_packet,
            )
        try:
            await server.serve_forever(background=True)
        except (RuntimeError, OSError) as exc:
            raise OSError(
                errno.EADDRINUSE,
                f"cannot listen on {self.host}:{self.requested_port} (in use?): {exc}",
            ) from None
        self._server = server
        sockets = getattr(server.transport, "sockets", None) or ()
        if sockets:  # port 0: the port the kernel picked, bound race-free
            self.port = int(sockets[0].getsockname()[1])

    async def stop(self) -> None:
        """Stop serving and close every connection."""
        if self._server is not None:
            await self._server.shutdown()
            self._server = None


# =========================================================================== ptys
class _PtyDevice(abc.ABC):
    """A line-oriented device on the master side of a pseudo-terminal.

    The slave side (what a driver opens) is put in raw mode and published through a
    symlink at ``link_path`` (replacing a stale link, never a regular file).
    """

    name = "device"

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
        self.slave_name = ""

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
        asyncio.get_running_loop().add_reader(master, self._on_readable)

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
        while self.terminator in self._buf:
            line, self._buf = self._buf.split(self.terminator, 1)
            task = asyncio.get_running_loop().create_task(self._handle_line(line))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)

    @abc.abstractmethod
    async def _handle_line(self, line: bytes) -> None:
        """Answer one command line (without its terminator)."""

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
        self._drained.set()
        self._close_fds()

    def _close_fds(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1

    async def stop(self) -> None:
        """Stop serving, close the pty and remove the symlink."""
        for task in list(self._tasks):
            task.cancel()
        self.disconnect()
        if self.link_path.is_symlink():
            with contextlib.suppress(OSError):
                self.link_path.unlink()


class StilPtyDevice(_PtyDevice):
    """The simulated STIL spectro-colorimeter behind a pty, speaking a ``stil-spectro`` profile.

    Commands and reply lines are the profile's templates (``[commands]``, ``[replies]``);
    readings come from the in-process :class:`sim.instruments.SimSpectro`.
    """

    name = "spectro"

    def __init__(self, spectro: SimSpectro, profile: StilProfile, link_path: str | Path) -> None:
        super().__init__(link_path, terminator=profile.command_terminator.encode(profile.encoding))
        self.spectro = spectro
        self.profile = profile
        self._exposure_re = template_regex(profile.cmd_set_exposure)

    def _reply(self, lines: list[str], fault: Fault) -> None:
        p = self.profile
        data = "".join(line + p.reply_terminator for line in lines).encode(p.encoding)
        if fault is Fault.GARBLE:
            data = self.spectro.faults.garble(data, keep=p.reply_terminator.encode(p.encoding))
        self.write(data)

    def _error(self, code: int, message: str) -> list[str]:
        return [self.profile.reply_error.format(code=code, message=message)]

    async def _handle_line(self, line: bytes) -> None:
        p = self.profile
        text = line.decode(p.encoding, errors="replace").strip("\r\n")
        if not text:
            return
        fault = self.spectro.faults.decide()
        if fault is Fault.DISCONNECT:
            self.disconnect()
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
        else:
            lines = self._error(1, f"unknown command {text[:40]}")
        self._reply(lines, fault)

    async def _measure_lines(self) -> list[str]:
        from sim.instruments import spectrum_for_luminance

        lum = await self.spectro.read_luminance_pct()
        values = spectrum_for_luminance(lum)
        wl = SPECTRUM_WAVELENGTHS_NM
        fields: dict[str, Any] = {
            "luminance_pct": lum,
            "start_nm": int(wl[0]),
            "step_nm": int(wl[1] - wl[0]),
            "count": len(values),
            "values": ",".join(f"{v:.4f}" for v in values),
            "exposure_us": self.spectro.exposure_us,
            "ident": "STIL RUBY",
        }
        return [t.format(**fields) for t in self.profile.reply_measure]


class ZgmPtyDevice(_PtyDevice):
    """The simulated Zehntner ZGM1120 glossmeter behind a pty.

    Protocol (Technical Manual rev. 3.0, 2021, pp. 16-28): ASCII fields separated by
    ``|``, commands end with ``:``, replies end with the profile's ``reply_terminator``.
    Measure request ``1| SN|xy|mask|count|tempflag:`` (mask bit0 20 deg, bit1 60 deg,
    bit2 85 deg); reply ``1| SN|xy|v20|a20|v60|a60|v85|a85|count|temp`` with values in
    0.1 GU, -1 = not measured, -2 = overflow; the ``a`` fields are raw ADC readings.
    Opcode 6 AutoSend (``6| SN|xy|mask|count|tempflag:``, not acknowledged): the meter
    then pushes a reply ``6| SN|xy|...`` (measure-reply fields, the request's transaction
    id) for every reading -- simulated as a button press every ``autosend_interval_s``;
    mask 0 switches it off.
    Requests for another serial number are ignored (RS-232 multi-drop behaviour).
    """

    name = "glossmeter"

    #: Raw ADC counts per GU of the simulated photodiode chain (any positive number).
    ADC_PER_GU = 10.0

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
        self.profile = profile
        self.serial_number = serial_number.strip()
        self._autosend: asyncio.Task[None] | None = None

    async def _reading_fields(self, angles: list[int]) -> list[str]:
        values, overflow = await self.gloss.read_values_gu(angles)
        out: list[str] = []
        for a in (20, 60, 85):
            v = values.get(a)
            if a in overflow:
                out += ["-2", "-2"]
            elif v is None:
                out += ["-1", "-1"]
            else:
                out += [str(round(v * 10)), str(round(v * self.ADC_PER_GU))]
        return out

    async def _measure_reply(self, tid: str, mask: int, count: int, *, opcode: str = "1") -> str:
        angles = [a for bit, a in enumerate((20, 60, 85)) if mask >> bit & 1]
        fields = await self._reading_fields(angles)
        return "|".join(
            [
                opcode,
                f" {self.serial_number}",
                tid,
                *fields,
                str(count),
                str(round(self.gloss.temperature_c)),
            ]
        )

    async def _handle_line(self, line: bytes) -> None:
        text = line.decode("ascii", errors="replace").strip("\r\n ")
        parts = text.split("|")
        if len(parts) < 3 or parts[1].strip() != self.serial_number:
            return
        fault = self.gloss.faults.decide()
        if fault is Fault.DISCONNECT:
            self.disconnect()
            return
        if fault is Fault.TIMEOUT:
            return
        opcode, tid, args = parts[0].strip(), parts[2], parts[3:]
        reply: str
        if opcode == "1":
            try:
                mask = int(args[0]) if args else 7
                count = int(args[1]) if len(args) > 1 else 1
            except ValueError:
                return
            reply = await self._measure_reply(tid, mask & 7, count)
        elif opcode == "6":
            try:
                mask = int(args[0]) if args else 7
            except ValueError:
                return
            self._set_autosend(tid, mask & 7)
            return  # AutoSend is not acknowledged: readings follow as they are taken
        elif opcode == "36":
            reply = "|".join(
                ["36", f" {self.serial_number}", tid, str(round(self.gloss.temperature_c))]
            )
        elif opcode in ("28", "48", "52", "64", "72"):
            reply = "|".join([opcode, f" {self.serial_number}", tid, "0"])
        else:
            return
        data = reply.encode("ascii")
        if fault is Fault.GARBLE:
            data = self.gloss.faults.garble(data)
        self.write(data + self.profile.reply_terminator.encode("ascii"))

    def _set_autosend(self, tid: str, mask: int) -> None:
        if self._autosend is not None:
            self._autosend.cancel()
            self._autosend = None
        if mask and self.gloss.autosend_interval_s > 0:
            self._autosend = asyncio.get_running_loop().create_task(self._push(tid, mask))

    async def _push(self, tid: str, mask: int) -> None:
        while self.open:
            await self.gloss.clock.sleep(self.gloss.autosend_interval_s)
            await self._drained.wait()  # back-pressure: the line took the last reading
            reply = await self._measure_reply(tid, mask, 1, opcode="6")
            self.write(reply.encode("ascii") + self.profile.reply_terminator.encode("ascii"))

    async def stop(self) -> None:
        """Stop auto-send and the pty."""
        self._set_autosend("", 0)
        await super().stop()


# =========================================================================== the lab
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
        self._started: list[ModbusAxisServer | _PtyDevice] = []

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
        parts: list[ModbusAxisServer | _PtyDevice] = [*self.modbus]
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
