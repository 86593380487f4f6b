"""The arms on the wire: Modbus TCP / RTU stepper-controller servers over the simulated axes.

:class:`ModbusAxisServer`: one Modbus TCP server (pymodbus 3.16 ``ModbusTcpServer`` with
:class:`pymodbus.simulator.SimDevice` devices), or a Modbus RTU one framed over a TCP socket
(``ModbusSerialServer`` on ``socket://host:port``), with one unit id per arm, implementing either stepper profile style of
:mod:`drivers.profiles`:

* ``direct-data`` (Oriental Motor AZ register map, manual HM-60262E,
  ``configs/profiles/oriental-az.toml``): writing the 18-register direct-data block with
  trigger = 1 starts a move of the simulated arm; rising edges of ZHOME / STOP / ALM-RST in
  the latched input-command word act.
* ``command-opcode`` (Applied Motion ST-Q register table 920-0072,
  ``configs/profiles/applied-motion-stq.toml``, or the MDX+ map
  ``configs/profiles/applied-motion-mdx.toml``): accel, decel, velocity (one register
  each, 1/6 rps/s and 1/240 rps) and the int32 target position are latched; an opcode
  written to the command register acts: absolute (FP) or relative (FL) move with them,
  enable (ME), disable (MD: stops, later moves ignored), stop (SK), seek home (SH),
  alarm reset (AR). The status code's ``ready`` bit is the enable state.

The status, alarm, feedback (and command) registers are refreshed from the arm on every
request.

Unit ids and function codes: over RTU a request for a unit id that no arm answers to gets
no reply at all (a real AZ on the line stays silent; MBS section 2.1), over TCP the gateway
exception 0Bh; function 04h (read input registers), which the AZ does not support, gets
exception 01h (illegal function) from a direct-data (AZ) unit. 16-bit fields (profile ``single_register_fields``: the
ST-Q's alarm and status codes) are served as one register. Sources: docs/PROTOCOLS.md.

Injected faults (:mod:`sim.faults`): a timed-out request gets no answer (not executed, no
reply sent); a garbled one a corrupted MBAP header (TCP) or a wrong CRC (RTU), which a
master's framer rejects; a disconnected device gateway exception 0x0B ("target device
failed to respond"); a recoverable drop closes the masters' connections (no reply), and
until the unit is back (``recover_after_s``) a master that reconnects is dropped again at
its first request to that unit.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
from dataclasses import dataclass, field
from typing import Literal

from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.profiles import StepperProfile
from sim.faults import Fault
from sim.instruments import SimAxis
from sim.motion import MotorFault

__all__ = ["ModbusAxisServer", "WireAxis"]

#: Size of the simulated register space (covers every address of the AZ map).
_REGISTER_SPACE = 0x0200


#: The registers :meth:`WireAxis.refresh` writes, in its order.
_REFRESHED = (
    "output_status",
    "alarm_code",
    "feedback_position",
    "command_position",
    "input_command",
)
#: 04h (read input registers) is not in the AZ's function-code list (HM-60262E: 03h, 06h,
#: 08h, 10h, 17h): the simulated AZ answers it with exception 01h, illegal function
#: (docs/PROTOCOLS.md). The Applied Motion pages retrieved do not list the function codes;
#: the simulated AMP drives answer 04h from the holding registers (pymodbus' default).
_UNSUPPORTED_FUNCTIONS = frozenset({0x04})


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
    #: command-opcode drives: enabled (ME) -- a disabled drive ignores moves.
    enabled: bool = field(default=False, repr=False)

    def __post_init__(self) -> None:
        if self.profile.move_style not in ("direct-data", "command-opcode"):
            raise ValueError(
                f"{self.profile.path}: the wire simulator implements move_style "
                f"'direct-data' and 'command-opcode', got {self.profile.move_style!r}"
            )
        regs = self.profile.registers
        sizes = {
            "output_status": 2,
            "alarm_code": 2,
            "feedback_position": 2,
            "command_position": 2,
            "input_command": 2,
            "direct_data": 18,
            "command": 1,
            "accel": 1,
            "decel": 1,
            "velocity": 1,
            "target_position": 2,
        }
        for name, size in sizes.items():
            addr = getattr(regs, name)
            if addr is not None and addr + size > _REGISTER_SPACE:
                raise ValueError(
                    f"{self.profile.path}: registers.{name} 0x{addr:04X} beyond the simulated space"
                )

    # --------------------------------------------------------------- registers
    def status_word(self) -> int:
        """The 32-bit output status word from the arm's state (bits from the profile)."""
        st = self.axis.snapshot()
        sb = self.profile.status_bits
        opcode_style = self.profile.move_style == "command-opcode"
        bits: list[tuple[int | None, bool]] = [
            (sb.in_position, st.in_position),
            (sb.moving, st.moving),
            (sb.alarm, st.alarm_code is not None),
            # AMP: "ready" is the drive's enable state; "busy" is initialising (never here)
            (sb.ready, st.ready and (self.enabled or not opcode_style)),
            (sb.busy, st.moving and not opcode_style),
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
        single = self.profile.single_register_fields
        for (addr, value), name in zip(values, _REFRESHED, strict=True):
            if addr is None:
                continue
            if name in single:  # one 16-bit register on this drive (AMP ST-Q)
                registers[addr - start_address] = value & 0xFFFF
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
        if regs.command is not None and regs.command in written:
            self._opcode(image, start_address, image[regs.command - start_address])
        dd = self.profile.direct_data
        if regs.direct_data is not None and dd is not None:
            trigger_addr = regs.direct_data + 14
            if trigger_addr + 1 in written:
                off = regs.direct_data - start_address
                fields = [_join32(image[off + 2 * k], image[off + 2 * k + 1]) for k in range(9)]
                _, op_type, position, speed, accel, _decel, _current, trigger, _dest = fields
                if trigger == dd.trigger:
                    self._start_move(op_type, position, speed, accel)

    def _opcode(self, image: list[int], start_address: int, opcode: int) -> None:
        """Act on an opcode written to the command register (command-opcode drives)."""
        ops, regs = self.profile.opcodes, self.profile.registers
        if ops is None:
            return
        now = self.axis.clock.now()
        motor = self.axis.motor
        if opcode == ops.enable:
            self.enabled = True
        elif opcode == ops.disable:
            self.enabled = False
            motor.stop(now)
        elif opcode == ops.stop:
            motor.stop(now)
        elif opcode == ops.alarm_reset:
            motor.reset_alarm(now)
        elif opcode == ops.home and self.enabled:
            with contextlib.suppress(MotorFault):  # alarm active: the drive ignores it
                motor.start_home(now)
                self.axis.ensure_tracker()
        elif opcode in (ops.absolute_move, ops.relative_move) and self.enabled:
            assert regs.target_position is not None and regs.velocity is not None
            assert regs.accel is not None
            off = regs.target_position - start_address
            target = _join32(image[off], image[off + 1])
            self._start_move(
                1 if opcode == ops.absolute_move else 2,
                target,
                image[regs.velocity - start_address],
                image[regs.accel - start_address],
            )

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
    serial_port, baudrate
        RTU on a serial device instead (e.g. one end of a pty pair that ``socat`` made;
        the master opens the other end): ``host``/``port`` are then unused.

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
        serial_port: str = "",
        baudrate: int = 9600,
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
        self.serial_port = serial_port
        self.baudrate = baudrate
        if serial_port and transport != "rtu":
            raise ValueError("a serial_port needs transport 'rtu'")
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self._pending: dict[int, list[Fault]] = {unit: [] for unit in self.axes}

    @property
    def url(self) -> str:
        """Where a master connects: ``host:port`` (TCP), ``socket://host:port`` (RTU) or
        the serial device (RTU on a serial line)."""
        if self.serial_port:
            return self.serial_port
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
            if function_code in _UNSUPPORTED_FUNCTIONS and wire.profile.move_style == "direct-data":
                return ExcCodes.ILLEGAL_FUNCTION  # the AZ's function-code list (HM-60262E)
            faults = wire.axis.faults
            now = wire.axis.clock.now()
            if faults.is_down(now):
                fault = Fault.DROP  # still off the line: the reconnected master is dropped again
            else:
                fault = faults.decide()
                if fault is Fault.DROP:
                    faults.drop(now)
                elif fault is Fault.LATE:
                    fault = Fault.NONE  # answered on time (sim.faults: late is serial-only)
            if fault is Fault.DISCONNECT:
                return ExcCodes.GATEWAY_NO_RESPONSE
            if fault is not Fault.NONE:
                self._pending[wire.unit_id].append(fault)
            if set_values is not None and fault not in (Fault.TIMEOUT, Fault.DROP):
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
        if data[unit_at] not in self.axes:
            return self._no_such_unit(data)
        pending = self._pending.get(data[unit_at])
        if not pending:
            return data
        fault = pending.pop(0)
        if fault is Fault.DROP:
            asyncio.get_running_loop().call_soon(self._drop_connections)
            return b""  # the link goes down before the answer
        if fault is Fault.TIMEOUT:
            return b""  # no answer at all
        out = bytearray(data)
        out[5 if self.transport == "tcp" else -1] ^= 0x3C  # MBAP length / CRC high byte
        return bytes(out)

    def _no_such_unit(self, data: bytes) -> bytes:
        """The reply to a request for a unit id no arm answers to.

        RTU: nothing. Only the addressed slave answers a query (MBS section 2.1), so a real
        AZ on the line stays silent and the master times out. TCP: the arms sit behind a
        gateway, which answers exception 0Bh, "gateway target device failed to respond"
        (pymodbus itself would answer 04h, slave device failure).
        """
        if self.transport == "rtu" or len(data) < 9:
            return b""
        out = bytearray(data)
        out[7] |= 0x80
        out[8] = int(ExcCodes.GATEWAY_NO_RESPONSE)
        return bytes(out)

    def _drop_connections(self) -> None:
        """Close every master's connection (the server keeps listening)."""
        server = self._server
        if server is None:
            return
        for conn in list(server.active_connections.values()):
            with contextlib.suppress(Exception):
                conn.close()

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
                port=self.serial_port or f"socket://{self.host}:{self.requested_port}",
                baudrate=self.baudrate,
                trace_packet=self._trace_packet,
            )
        try:
            await server.serve_forever(background=True)
        except (RuntimeError, OSError) as exc:
            if self.serial_port:
                raise OSError(errno.EIO, f"cannot open {self.serial_port}: {exc}") from None
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
