"""One goniometer arm driven by a stepper controller over Modbus TCP or RTU.

:class:`ModbusStepperAxis` implements :class:`drivers.base.Axis` for any controller whose
register map is a ``kind = "modbus-stepper"`` profile (``drivers.profiles``; every
address and opcode with its source in docs/PROTOCOLS.md): the Oriental Motor AZ "direct
data operation" (default) and the Applied Motion command-register style (ST-Q / MDX+). What goes on the wire is fixed by the profile's documented move sequences:

* direct-data (AZ): ``move_to`` writes the 18 registers of the direct-data block in ONE
  function-16 request (data number, operation type 1 = absolute, position [steps], speed,
  acceleration, deceleration, current, trigger = 1, destination = 0; each int32, high word
  first); STOP / ZHOME / ALM-RST are pulsed in the latched input-command word (write the
  bit, then write 0).
* command-opcode (AMP): accel, decel, velocity, target position, then the absolute-move
  opcode into the command register, each a function-16 request; ``connect`` writes the
  enable opcode; stop / home / alarm reset write their opcodes.

Units: ``steps = round(deg * steps_per_deg * gear_ratio)``, with ``steps_per_deg`` the
motor's steps per degree of its own shaft and ``gear_ratio`` the motor turns per arm turn
(1 for a direct drive); :attr:`ModbusStepperAxis.steps_per_deg` is their product, the
steps per degree of the arm;
speed and acceleration registers hold ``round(speed_deg_s * steps_per_deg *
speed_counts_per_step_s)`` and the same for acceleration.

Completion (``wait_in_position``): poll the status word every ``poll_interval_s`` (with the
injectable ``sleep``/``clock``, so a simulated clock can drive it) until IN-POS is set and
MOVE is clear. Then the feedback position must lie within ``stall_tolerance_deg`` of the
commanded target, otherwise :class:`~drivers.base.StallError`. A controller that reports
neither MOVE nor IN-POS on two consecutive polls with the feedback outside the tolerance
has stopped short: also a stall. ALM-A (or the profile's fault bit) -> STOP is sent, the
alarm code is read and :class:`~drivers.base.DeviceFault` raised; no completion by the
deadline -> STOP is sent and :class:`~drivers.base.DeviceTimeout` raised.

Request/response integrity: Modbus TCP matches each reply to its request by the MBAP
transaction id; Modbus RTU has none, and pymodbus takes the first frame that arrives while
a request waits for the answer to it. A reply that comes after its request timed out would
thus answer the *next* request of the same shape (a stale feedback position read after a
move, a position word read as a status word: issue 23, item 2). On RTU the driver
therefore retries itself (pymodbus' own retry is off, its re-send would leave the first
answer on the line) and, after any request that went unanswered or came back garbled,
keeps the line idle for ``late_reply_guard_s`` before the next request: a late frame that
arrives while no request waits is dropped by pymodbus. Every reply is also checked
against its request: the function code, a read's register count, a write's echoed
address and count; a mismatch is a :class:`~drivers.base.ProtocolError` and guards the
line the same way. A reply later than the request's timeout plus the guard cannot be told
from an answer on RTU: the guard (default: the request timeout) is the bound.

Errors: connection refused / port missing -> :class:`~drivers.base.Disconnected` naming
``host:port`` or the serial port; no answer -> :class:`~drivers.base.DeviceTimeout`;
bytes received but no valid frame (bad CRC, corrupted MBAP header) after the retries ->
:class:`~drivers.base.ProtocolError` quoting the bytes;
Modbus exception responses (Modbus Application Protocol V1.1b3, sec. 7):
1-3 (illegal function / address / value: the profile does not fit the device) and 4, 8, 10
(server device failure, memory parity error, gateway path unavailable: nothing a retry
cures) -> :class:`~drivers.base.DeviceFault` carrying the code, never retried;
5 and 6 (acknowledge: still processing; server device busy) and 11 (gateway target failed
to respond) are transient: the request is sent again after a pause, up to ``retries``
times, then :class:`~drivers.base.DeviceTimeout` (which a scan retries). Any
other pymodbus error is wrapped in :class:`~drivers.base.ProtocolError`.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Awaitable, Callable, Sequence
from typing import Any, Literal, NoReturn

import serial
from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.client.mixin import ModbusClientMixin
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerType

from drivers.arm_limits import LAMP_LIMITS_DEG, limits_problem
from drivers.base import (
    AxisStatus,
    DeviceFault,
    DeviceTimeout,
    Disconnected,
    LimitError,
    ProtocolError,
    StallError,
)
from drivers.profiles import StepperProfile, load_stepper_profile
from drivers.serial_io import busy_hint

__all__ = ["ModbusStepperAxis"]

_INT32 = ModbusClientMixin.DATATYPE.INT32
_INT32_MAX = 2**31 - 1
_UINT32 = ModbusClientMixin.DATATYPE.UINT32
#: Received bytes quoted in a "garbled reply" error (the tail of the receive buffer).
_GARBLE_QUOTE_BYTES = 32
_EXCEPTION_NAMES = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "server device failure",
    5: "acknowledge",
    6: "server device busy",
    8: "memory parity error",
    10: "gateway path unavailable",
    11: "gateway target failed to respond",
}


#: Exception codes that say "try again later" (spec sec. 7: 05 ACKNOWLEDGE, 06 SERVER DEVICE
#: BUSY, 0B GATEWAY TARGET DEVICE FAILED TO RESPOND); every other code is final.
_TRANSIENT_EXCEPTIONS = frozenset({5, 6, 11})


class _Busy(Exception):
    """A transient Modbus exception reply (internal: retried by ``_call``)."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def int32_registers(value: int) -> list[int]:
    """Split a signed 32-bit integer into two registers, high word first."""
    return list(ModbusClientMixin.convert_to_registers(value, _INT32, word_order="big"))


def registers_int32(registers: Sequence[int], *, signed: bool = True) -> int:
    """Join two registers (high word first) into a 32-bit integer."""
    value = ModbusClientMixin.convert_from_registers(
        list(registers), _INT32 if signed else _UINT32, word_order="big"
    )
    assert isinstance(value, int)
    return value


class ModbusStepperAxis:
    """A goniometer arm on a Modbus stepper controller (implements ``drivers.base.Axis``).

    Parameters
    ----------
    name
        The arm's configured name (``"lamp"``, ``"detector"``); used in every error.
    profile
        A :class:`~drivers.profiles.StepperProfile` or a profile name / path.
    transport
        ``"tcp"`` (``host``, ``port``) or ``"rtu"`` (``serial_port``, ``baudrate``, ``parity``;
        ``serial_port`` may be ``socket://host:port`` for RTU framing over TCP).
    unit_id
        Modbus device id.
    steps_per_deg
        Motor steps per degree of the motor shaft (e.g. 10000 steps/rev -> 27.78).
    gear_ratio
        Motor turns per arm turn (gearbox reduction; 1 = direct drive). The arm moves
        ``steps_per_deg * gear_ratio`` steps per degree.
    limits_deg
        Soft limits ``(low, high)`` in degrees, checked before any bus traffic.
    speed_deg_s, accel_deg_s2
        Move speed and acceleration (deceleration = acceleration).
    stall_tolerance_deg
        Largest allowed |feedback - target| once the controller reports it stopped.
    timeout_s
        Timeout of one Modbus request.
    poll_interval_s
        Status polling interval while waiting for IN-POS.
    retries
        Request retries after a timeout or a garbled reply (pymodbus' own on TCP, the
        driver's with the late-reply guard on RTU).
    late_reply_guard_s
        RTU: how long the line is kept idle after an unanswered or garbled request before
        the next one (``None``: ``timeout_s``). See the module docstring.
    sleep, clock
        ``await sleep(dt_s)`` and ``clock() -> s`` used for polling and deadlines
        (``asyncio.sleep`` / ``time.monotonic``; pass a sim clock's ``sleep`` / ``now``).
    """

    def __init__(
        self,
        name: str,
        *,
        profile: StepperProfile | str = "oriental-az",
        transport: Literal["tcp", "rtu"] = "tcp",
        host: str = "127.0.0.1",
        port: int = 502,
        serial_port: str = "",
        baudrate: int | None = None,
        parity: str | None = None,
        unit_id: int = 1,
        steps_per_deg: float = 1000.0,
        gear_ratio: float = 1.0,
        limits_deg: tuple[float, float] = LAMP_LIMITS_DEG,
        speed_deg_s: float = 20.0,
        accel_deg_s2: float = 40.0,
        stall_tolerance_deg: float = 0.5,
        timeout_s: float = 1.0,
        poll_interval_s: float = 0.02,
        retries: int = 1,
        late_reply_guard_s: float | None = None,
        sleep: Callable[[float], Awaitable[Any]] = asyncio.sleep,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.name = name
        self.profile = (
            profile if isinstance(profile, StepperProfile) else load_stepper_profile(profile)
        )
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"{name}: transport must be 'tcp' or 'rtu', got {transport!r}")
        if transport == "rtu" and not serial_port:
            raise ValueError(f"{name}: transport 'rtu' needs serial_port")
        if not (steps_per_deg > 0 and math.isfinite(steps_per_deg)):
            raise ValueError(f"{name}: steps_per_deg must be > 0 and finite, got {steps_per_deg}")
        if not (gear_ratio > 0 and math.isfinite(gear_ratio)):
            raise ValueError(f"{name}: gear_ratio must be > 0 and finite, got {gear_ratio}")
        lo, hi = (float(v) for v in limits_deg)
        if problem := limits_problem((lo, hi)):  # drivers.arm_limits, as the config checks
            raise ValueError(f"{name}: limits_deg: {problem}")
        for label, value in (
            ("speed_deg_s", speed_deg_s),
            ("accel_deg_s2", accel_deg_s2),
            ("stall_tolerance_deg", stall_tolerance_deg),
            ("timeout_s", timeout_s),
            ("poll_interval_s", poll_interval_s),
        ):
            if not value > 0:
                raise ValueError(f"{name}: {label} must be > 0, got {value}")
        if not 0 <= unit_id <= 247:
            raise ValueError(f"{name}: unit_id must be 0..247, got {unit_id}")
        self.transport = transport
        self.host = host
        self.port = port
        self.serial_port = serial_port
        self.baudrate = baudrate if baudrate is not None else self.profile.serial.baudrate
        self.parity = parity if parity is not None else self.profile.serial.parity
        self.unit_id = unit_id
        self.gear_ratio = float(gear_ratio)
        self.steps_per_deg = float(steps_per_deg) * self.gear_ratio  # per degree of the arm
        for limit in (lo, hi):
            if not abs(limit * self.steps_per_deg) <= _INT32_MAX:
                raise ValueError(
                    f"{name}: limit {limit:g} deg at {self.steps_per_deg:g} steps/deg is "
                    f"{limit * self.steps_per_deg:.4g} steps, beyond the int32 position register"
                )
        self.limits_deg: tuple[float, float] = (lo, hi)
        self.speed_deg_s = float(speed_deg_s)
        self.accel_deg_s2 = float(accel_deg_s2)
        self.stall_tolerance_deg = float(stall_tolerance_deg)
        self.timeout_s = float(timeout_s)
        self.poll_interval_s = float(poll_interval_s)
        self.retries = retries
        self.late_reply_guard_s = (
            float(timeout_s) if late_reply_guard_s is None else float(late_reply_guard_s)
        )
        if not (math.isfinite(self.late_reply_guard_s) and self.late_reply_guard_s >= 0):
            raise ValueError(f"{name}: late_reply_guard_s must be >= 0, got {late_reply_guard_s}")
        #: RTU: a request went unanswered or its reply was garbled or mismatched; the
        #: line is kept idle for the guard before the next request.
        self._line_suspect = False
        #: RTU: requests that were answered late, garbled or by a reply to another request.
        self.suspect_replies = 0
        self._sleep = sleep
        self._clock = clock
        self.speed_counts = self._counts(
            "speed_deg_s", speed_deg_s, self.profile.speed_counts_per_step_s
        )
        self.accel_counts = self._counts(
            "accel_deg_s2", accel_deg_s2, self.profile.accel_counts_per_step_s2
        )
        self._client: AsyncModbusTcpClient | AsyncModbusSerialClient | None = None
        self._lock = asyncio.Lock()
        self._target_steps: int | None = None
        self._homed = False
        self._received = b""  # bytes received during the current request (trace hook)

    # ------------------------------------------------------------------ helpers
    def _counts(self, label: str, value_per_s: float, counts_per_step: float) -> int:
        exact = value_per_s * self.steps_per_deg * counts_per_step
        counts = round(exact) if math.isfinite(exact) else -1
        limit = 0xFFFF if self.profile.move_style == "command-opcode" else _INT32_MAX
        if not 1 <= counts <= limit:
            raise ValueError(
                f"{self.name}: {label}={value_per_s} gives {counts} register counts with profile "
                f"{self.profile.name!r}; must be 1..{limit}"
            )
        return counts

    @property
    def endpoint(self) -> str:
        """``host:port`` (TCP) or the serial port (RTU), as named in errors."""
        return f"{self.host}:{self.port}" if self.transport == "tcp" else self.serial_port

    def deg_to_steps(self, angle_deg: float) -> int:
        """Steps for an arm angle: ``round(angle_deg * steps_per_deg)``."""
        return round(angle_deg * self.steps_per_deg)

    def steps_to_deg(self, steps: int) -> float:
        """Arm angle for a step count."""
        return steps / self.steps_per_deg

    def check_limits(self, target_deg: float) -> None:
        """Raise :class:`LimitError` unless ``low <= target_deg <= high``."""
        lo, hi = self.limits_deg
        if not lo <= target_deg <= hi:  # also rejects NaN
            raise LimitError(
                f"target {target_deg} deg outside soft limits [{lo}, {hi}] deg", device=self.name
            )

    # ------------------------------------------------------------------ bus
    async def connect(self) -> None:
        """Open the connection; :class:`Disconnected` names the endpoint on failure."""
        if self._client is not None and self._client.connected:
            return
        client: AsyncModbusTcpClient | AsyncModbusSerialClient
        if self.transport == "tcp":
            client = AsyncModbusTcpClient(
                self.host,
                port=self.port,
                timeout=self.timeout_s,
                retries=self.retries,
                reconnect_delay=0,  # a lost link is reported (Disconnected), not hidden
                trace_packet=self._trace_packet,
            )
        else:
            s = self.profile.serial
            client = AsyncModbusSerialClient(
                self.serial_port,
                framer=FramerType.RTU,
                baudrate=self.baudrate,
                bytesize=s.bytesize,
                parity=self.parity,
                stopbits=s.stopbits,
                timeout=self.timeout_s,
                retries=0,  # the driver retries, with the late-reply guard (module docstring)
                reconnect_delay=0,
                trace_packet=self._trace_packet,
            )
        try:
            ok = await client.connect()
        except (
            Exception
        ) as exc:  # pyserial/termios/pymodbus: any failure to open is "port unusable"
            client.close()
            raise Disconnected(
                f"cannot connect to Modbus {self.transport.upper()} {self.endpoint}: "
                f"{busy_hint(exc)}",
                device=self.name,
            ) from exc
        if not ok:
            client.close()
            raise Disconnected(
                f"cannot connect to Modbus {self.transport.upper()} {self.endpoint}"
                f"{self._why_not_open()}",
                device=self.name,
            )
        self._client = client
        if self.profile.move_style == "command-opcode":
            await self._write_opcode("enable")

    def _why_not_open(self) -> str:
        """pymodbus logs why a serial port did not open and returns False: open it once
        ourselves (exclusively, as pymodbus does) to name the reason (missing, busy...)."""
        if self.transport != "rtu":
            return ""
        try:
            serial.serial_for_url(self.serial_port, exclusive=True).close()
        except (serial.SerialException, OSError, ValueError) as exc:
            return f": {busy_hint(exc)}"
        return ""

    async def close(self) -> None:
        """Close the connection (idempotent)."""
        client, self._client = self._client, None
        if client is not None:
            client.close()

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        """pymodbus hook on every packet: remember what arrived during the current request."""
        if not sending and data:
            self._received = bytes(data[-_GARBLE_QUOTE_BYTES:])
        return data

    def _no_valid_answer(self, what: str, exc: Exception) -> DeviceTimeout | ProtocolError:
        """Bytes came back but no frame was accepted: garbled (bad CRC, bad MBAP header,
        wrong length); nothing came back: a timeout."""
        if self._received:
            raw = " ".join(f"{b:02X}" for b in self._received)
            return ProtocolError(
                f"garbled reply from {self.endpoint} to {what}: received [{raw}], "
                f"not a valid Modbus {self.transport.upper()} frame",
                device=self.name,
            )
        return DeviceTimeout(f"no answer from {self.endpoint} to {what}: {exc}", device=self.name)

    def _check(self, rr: Any, what: str) -> Any:
        if rr.isError():
            code = int(getattr(rr, "exception_code", 0))
            text = _EXCEPTION_NAMES.get(code, "unknown exception")
            message = (
                f"Modbus exception {code} ({text}) on {what} at {self.endpoint}, "
                f"unit {self.unit_id}"
            )
            if code in (1, 2, 3):
                raise DeviceFault(
                    f"{message}: the profile {self.profile.name!r} does not fit the device "
                    "(not retried; check the profile's addresses against the manual)",
                    device=self.name,
                    code=code,
                )
            raise DeviceFault(message, device=self.name, code=code)
        return rr

    async def _call(
        self,
        what: str,
        fn: Callable[..., Awaitable[Any]],
        *args: Any,
        expect: Callable[[Any], str] | None = None,
        **kw: Any,
    ) -> Any:
        """One request; ``expect(reply)`` returns "" when the reply answers this request,
        else what is wrong with it. On RTU a timeout, a garbled reply or a reply to another
        request is retried here after the late-reply guard (module docstring)."""
        if self._client is None:
            raise Disconnected(f"not connected to {self.endpoint}", device=self.name)
        if not self._client.connected:
            raise Disconnected(f"connection to {self.endpoint} is closed", device=self.name)
        rtu = self.transport == "rtu"
        attempts = self.retries + 1
        async with self._lock:
            for attempt in range(attempts):
                if rtu and self._line_suspect:
                    # a real-time wait: it is about bytes on the line, not the lab's clock
                    await asyncio.sleep(self.late_reply_guard_s)
                    self._line_suspect = False
                try:
                    rr = await self._request(what, fn, *args, **kw)
                    if rr.isError():
                        code = int(getattr(rr, "exception_code", 0))
                        if code in _TRANSIENT_EXCEPTIONS:
                            raise _Busy(code)
                    wrong = "" if rr.isError() or expect is None else expect(rr)
                    if wrong:
                        raise ProtocolError(
                            f"reply from {self.endpoint} to {what} answers another request: "
                            f"{wrong}",
                            device=self.name,
                        )
                except _Busy as busy:
                    if attempt == attempts - 1:
                        text = _EXCEPTION_NAMES.get(busy.code, "unknown exception")
                        raise DeviceTimeout(
                            f"Modbus exception {busy.code} ({text}) on {what} at "
                            f"{self.endpoint}, unit {self.unit_id}, {attempts} times",
                            device=self.name,
                        ) from None
                    await self._sleep(self.poll_interval_s * 2**attempt)
                    continue
                except (DeviceTimeout, ProtocolError):
                    if not rtu:  # TCP: pymodbus has retried a timeout; ids match replies
                        raise
                    self._line_suspect = True
                    self.suspect_replies += 1
                    if attempt == attempts - 1:
                        raise
                    continue
                return self._check(rr, what)
        raise AssertionError("unreachable")  # pragma: no cover - the loop returns or raises

    async def _request(
        self, what: str, fn: Callable[..., Awaitable[Any]], *args: Any, **kw: Any
    ) -> Any:
        """Send one request through pymodbus; map its errors onto drivers.base errors."""
        assert self._client is not None
        self._received = b""
        try:
            return await fn(*args, device_id=self.unit_id, **kw)
        except ConnectionException as exc:
            raise Disconnected(
                f"connection to {self.endpoint} lost during {what}: {exc}", device=self.name
            ) from exc
        except ModbusIOException as exc:
            if not self._client.connected:
                raise Disconnected(
                    f"connection to {self.endpoint} lost during {what}", device=self.name
                ) from exc
            raise self._no_valid_answer(what, exc) from exc
        except ModbusException as exc:
            raise ProtocolError(
                f"{what} at {self.endpoint} failed: {exc}", device=self.name
            ) from exc
        except TimeoutError as exc:
            raise self._no_valid_answer(what, exc) from exc

    async def _read(self, address: int, count: int, what: str) -> list[int]:
        client = self._client
        if client is None:
            raise Disconnected(f"not connected to {self.endpoint}", device=self.name)

        def expect(rr: Any) -> str:
            got = int(getattr(rr, "function_code", 0))
            n = len(getattr(rr, "registers", []))
            if got != 3 or n != count:
                return f"function {got} with {n} registers, expected function 3 with {count}"
            return ""

        rr = await self._call(
            f"read {what} (0x{address:04X})",
            client.read_holding_registers,
            address,
            count=count,
            expect=expect,
        )
        registers = list(getattr(rr, "registers", []))
        if len(registers) != count:
            raise ProtocolError(
                f"read {what} (0x{address:04X}) returned {len(registers)} registers, "
                f"expected {count}",
                device=self.name,
            )
        return registers

    async def _write(self, address: int, values: Sequence[int], what: str) -> None:
        client = self._client
        if client is None:
            raise Disconnected(f"not connected to {self.endpoint}", device=self.name)

        def expect(rr: Any) -> str:
            got = int(getattr(rr, "function_code", 0))
            echoed = (int(getattr(rr, "address", -1)), int(getattr(rr, "count", -1)))
            if got != 16 or echoed != (address, len(values)):
                return (
                    f"function {got} echoing address 0x{echoed[0]:04X} count {echoed[1]}, "
                    f"expected function 16 echoing 0x{address:04X} count {len(values)}"
                )
            return ""

        await self._call(
            f"write {what} (0x{address:04X})",
            client.write_registers,
            address,
            list(values),
            expect=expect,
        )

    async def _read_int32(self, address: int, what: str, *, signed: bool = True) -> int:
        return registers_int32(await self._read(address, 2, what), signed=signed)

    async def _write_opcode(self, opcode_name: str) -> None:
        opcodes = self.profile.opcodes
        assert opcodes is not None and self.profile.registers.command is not None
        await self._write(
            self.profile.registers.command, [getattr(opcodes, opcode_name)], f"{opcode_name} opcode"
        )

    async def _pulse(self, bit_name: str) -> None:
        bits = self.profile.input_bits
        address = self.profile.registers.input_command
        assert bits is not None and address is not None
        await self._write(
            address, int32_registers(1 << getattr(bits, bit_name)), f"input {bit_name}"
        )
        await self._write(address, [0, 0], "input clear")

    # ------------------------------------------------------------------ state
    def _bit(self, word: int, bit: int | None) -> bool:
        return bit is not None and bool(word >> bit & 1)

    def _alarmed(self, word: int) -> bool:
        sb = self.profile.status_bits
        return self._bit(word, sb.alarm) or self._bit(word, sb.fault)

    async def _read_word_field(self, field: str, address: int, what: str) -> int:
        # a 16-bit field on some drives (profile single_register_fields; docs/PROTOCOLS.md)
        if field in self.profile.single_register_fields:
            return (await self._read(address, 1, what))[0]
        return await self._read_int32(address, what, signed=False)

    async def _status_word(self) -> int:
        address = self.profile.registers.output_status
        return await self._read_word_field("output_status", address, "status")

    async def _alarm_code(self) -> int:
        address = self.profile.registers.alarm_code
        return await self._read_word_field("alarm_code", address, "alarm code")

    async def _raise_alarm(self, context: str) -> NoReturn:
        code = await self._alarm_code()
        raise DeviceFault(
            f"controller alarm {code} (0x{code:X}) {context} at {self.endpoint}",
            device=self.name,
            code=code,
        )

    async def status(self) -> AxisStatus:
        """Read status word, feedback (and command) position and the alarm code if any."""
        word = await self._status_word()
        sb = self.profile.status_bits
        feedback = await self._read_int32(
            self.profile.registers.feedback_position, "feedback position"
        )
        command_deg: float | None = None
        if self.profile.registers.command_position is not None:
            command_deg = self.steps_to_deg(
                await self._read_int32(self.profile.registers.command_position, "command position")
            )
        elif self._target_steps is not None:
            command_deg = self.steps_to_deg(self._target_steps)
        alarm = await self._alarm_code() if self._alarmed(word) else None
        return AxisStatus(
            position_deg=self.steps_to_deg(feedback),
            command_deg=command_deg,
            moving=self._bit(word, sb.moving),
            in_position=self._bit(word, sb.in_position),
            homed=self._homed or self._bit(word, sb.home_end),
            alarm_code=alarm,
            ready=True if sb.ready is None else self._bit(word, sb.ready),
        )

    async def position_deg(self) -> float:
        """Feedback position in degrees."""
        steps = await self._read_int32(
            self.profile.registers.feedback_position, "feedback position"
        )
        return self.steps_to_deg(steps)

    # ------------------------------------------------------------------ motion
    def move_registers(self, target_steps: int) -> list[int]:
        """The 18 direct-data registers of an absolute move to ``target_steps``."""
        dd = self.profile.direct_data
        assert dd is not None
        fields = (
            dd.data_number,
            dd.operation_type,
            target_steps,
            self.speed_counts,
            self.accel_counts,
            self.accel_counts,
            dd.current,
            dd.trigger,
            dd.destination,
        )
        return [r for value in fields for r in int32_registers(value)]

    async def move_to(self, target_deg: float) -> None:
        """Start an absolute move: limit check (no bus traffic), alarm check, then the move."""
        self.check_limits(target_deg)
        target_steps = self.deg_to_steps(target_deg)
        if self._alarmed(await self._status_word()):
            await self._raise_alarm(f"before move to {target_deg} deg")
        regs = self.profile.registers
        if self.profile.move_style == "direct-data":
            assert regs.direct_data is not None
            await self._write(regs.direct_data, self.move_registers(target_steps), "direct data")
        else:
            accel, decel, velocity, target = (
                regs.accel,
                regs.decel,
                regs.velocity,
                regs.target_position,
            )
            # the loader requires all four for move_style "command-opcode"
            assert accel is not None and decel is not None
            assert velocity is not None and target is not None
            await self._write(accel, [self.accel_counts], "accel")
            await self._write(decel, [self.accel_counts], "decel")
            await self._write(velocity, [self.speed_counts], "velocity")
            await self._write(target, int32_registers(target_steps), "target")
            await self._write_opcode("absolute_move")
        self._target_steps = target_steps

    async def _wait(self, timeout_s: float, what: str, target_steps: int | None) -> float:
        sb = self.profile.status_bits
        deadline = self._clock() + timeout_s
        stopped_polls = 0
        while True:
            word = await self._status_word()
            if self._alarmed(word):
                code = await self._alarm_code()
                await self._stop_quietly()
                raise DeviceFault(
                    f"controller alarm {code} (0x{code:X}) during {what} at {self.endpoint}; "
                    "STOP sent",
                    device=self.name,
                    code=code,
                )
            moving = self._bit(word, sb.moving) or self._bit(word, sb.homing)
            in_pos = self._bit(word, sb.in_position)
            if not moving:
                feedback = await self._read_int32(
                    self.profile.registers.feedback_position, "feedback position"
                )
                stopped_polls = stopped_polls + 1 if not in_pos else 0
                if in_pos or stopped_polls >= 2:
                    error_deg = (
                        0.0 if target_steps is None else self.steps_to_deg(feedback - target_steps)
                    )
                    if abs(error_deg) > self.stall_tolerance_deg:
                        raise StallError(
                            f"stopped at {self.steps_to_deg(feedback):.4f} deg, "
                            f"{error_deg:+.4f} deg from the commanded "
                            f"{self.steps_to_deg(target_steps or 0):.4f} deg "
                            f"(tolerance {self.stall_tolerance_deg} deg) during {what}",
                            device=self.name,
                        )
                    if in_pos:
                        return self.steps_to_deg(feedback)
            else:
                stopped_polls = 0
            remaining_s = deadline - self._clock()
            if remaining_s <= 0.0:
                await self._stop_quietly()
                raise DeviceTimeout(
                    f"{what} not finished within {timeout_s} s; STOP sent", device=self.name
                )
            await self._sleep(min(self.poll_interval_s, remaining_s))

    async def wait_in_position(self, timeout_s: float) -> float:
        """Wait for IN-POS and !MOVE; return the feedback position in degrees.

        Raises
        ------
        DeviceFault
            Alarm during the move (STOP sent, ``code`` = controller alarm code).
        StallError
            Stopped farther than ``stall_tolerance_deg`` from the target.
        DeviceTimeout
            Not in position within ``timeout_s`` (STOP sent).
        """
        what = (
            f"move to {self.steps_to_deg(self._target_steps):.4f} deg"
            if self._target_steps is not None
            else "wait for in-position"
        )
        return await self._wait(timeout_s, what, self._target_steps)

    async def home(self, timeout_s: float) -> None:
        """Return to the home (zero) position and wait for it (ZHOME / home opcode)."""
        word = await self._status_word()
        if self._alarmed(word):
            await self._raise_alarm("before homing")
        if self.profile.move_style == "direct-data":
            await self._pulse("zhome")
        else:
            await self._write_opcode("home")
        self._target_steps = 0
        await self._wait(timeout_s, "homing", 0)
        self._homed = True

    async def _stop_quietly(self) -> None:
        """Send STOP while already handling an error: a second failure must not mask it."""
        with contextlib.suppress(DeviceTimeout, Disconnected, ProtocolError, DeviceFault):
            await self.stop()

    async def stop(self) -> None:
        """Stop motion now (STOP pulse / stop opcode)."""
        if self.profile.move_style == "direct-data":
            await self._pulse("stop")
        else:
            await self._write_opcode("stop")

    async def reset_alarm(self) -> None:
        """Clear a latched alarm (ALM-RST pulse / alarm-reset then enable opcodes)."""
        if self.profile.move_style == "direct-data":
            await self._pulse("alarm_reset")
        else:
            await self._write_opcode("alarm_reset")
            await self._write_opcode("enable")
