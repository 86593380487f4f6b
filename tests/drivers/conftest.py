"""Fakes for the driver protocol tests: a byte-recording Modbus device and pty pairs.

The fake Modbus device decodes requests itself (MBAP for TCP, RTU frames with a CRC
computed here from the CRC-16/MODBUS definition), so the tests check the driver against
an implementation that shares no code with pymodbus.
"""

from __future__ import annotations

import asyncio
import os
import struct
import tty
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field

import pytest


def crc16_modbus(data: bytes) -> int:
    """CRC-16/MODBUS: reflected poly 0xA001, init 0xFFFF, no final xor (bitwise definition)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def rtu_frame(body: bytes) -> bytes:
    """Append the CRC, low byte first, to an RTU frame body (unit + PDU)."""
    return body + struct.pack("<H", crc16_modbus(body))


@dataclass
class FakeModbusDevice:
    """A register bank answering function 3 and 16, recording every request.

    ``on_write(device, address, values)`` runs after each accepted write (to start a
    simulated move); ``on_read(device, address, count)`` runs before each read (to let a
    move progress). ``exception`` = (function, code) answers every request of that function
    with that Modbus exception.
    """

    regs: dict[int, int] = field(default_factory=dict)
    requests: list[bytes] = field(default_factory=list)  # raw ADUs/frames as received
    pdus: list[bytes] = field(default_factory=list)  # PDUs (function code + data)
    on_write: Callable[[FakeModbusDevice, int, list[int]], None] | None = None
    on_read: Callable[[FakeModbusDevice, int, int], None] | None = None
    exception: tuple[int, int] | None = None
    unit_ids: list[int] = field(default_factory=list)
    mangle: Callable[[bytes], bytes] | None = None  # applied to each whole reply frame

    def set32(self, address: int, value: int) -> None:
        raw = struct.pack(">i" if value < 0 else ">I", value)
        self.regs[address], self.regs[address + 1] = struct.unpack(">HH", raw)

    def get32(self, address: int) -> int:
        hi, lo = self.regs.get(address, 0), self.regs.get(address + 1, 0)
        return int(struct.unpack(">i", struct.pack(">HH", hi, lo))[0])

    def writes(self) -> list[tuple[int, list[int]]]:
        """(address, values) of every function-16 request, in order."""
        out = []
        for pdu in self.pdus:
            if pdu[0] == 16:
                address, count, _n = struct.unpack(">HHB", pdu[1:6])
                out.append((address, list(struct.unpack(f">{count}H", pdu[6 : 6 + 2 * count]))))
        return out

    def answer(self, pdu: bytes) -> bytes:
        self.pdus.append(pdu)
        fc = pdu[0]
        if self.exception is not None and self.exception[0] == fc:
            return bytes([fc | 0x80, self.exception[1]])
        if fc == 3:
            address, count = struct.unpack(">HH", pdu[1:5])
            if self.on_read is not None:
                self.on_read(self, address, count)
            values = [self.regs.get(address + i, 0) for i in range(count)]
            return bytes([3, 2 * count]) + struct.pack(f">{count}H", *values)
        if fc == 16:
            address, count, _n = struct.unpack(">HHB", pdu[1:6])
            values = list(struct.unpack(f">{count}H", pdu[6 : 6 + 2 * count]))
            for i, v in enumerate(values):
                self.regs[address + i] = v
            if self.on_write is not None:
                self.on_write(self, address, values)
            return struct.pack(">BHH", 16, address, count)
        return bytes([fc | 0x80, 1])


class FakeModbusServer:
    """asyncio TCP server on 127.0.0.1:0 speaking Modbus TCP (MBAP) or RTU-over-TCP."""

    def __init__(self, device: FakeModbusDevice, *, rtu: bool = False) -> None:
        self.device = device
        self.rtu = rtu
        self.server: asyncio.Server | None = None
        self.port = 0

    async def start(self) -> None:
        self.server = await asyncio.start_server(self._handle, "127.0.0.1", 0)
        self.port = self.server.sockets[0].getsockname()[1]

    async def stop(self) -> None:
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()

    def _mangle(self, frame: bytes) -> bytes:
        return frame if self.device.mangle is None else self.device.mangle(frame)

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while True:
                if self.rtu:
                    head = await reader.readexactly(2)
                    if head[1] == 16:
                        more = await reader.readexactly(5)
                        rest = await reader.readexactly(more[4] + 2)
                        frame = head + more + rest
                    else:
                        frame = head + await reader.readexactly(6)
                    self.device.requests.append(frame)
                    assert crc16_modbus(frame[:-2]) == struct.unpack("<H", frame[-2:])[0]
                    self.device.unit_ids.append(frame[0])
                    reply = self.device.answer(frame[1:-2])
                    writer.write(self._mangle(rtu_frame(bytes([frame[0]]) + reply)))
                else:
                    header = await reader.readexactly(7)
                    tid, pid, length, unit = struct.unpack(">HHHB", header)
                    pdu = await reader.readexactly(length - 1)
                    self.device.requests.append(header + pdu)
                    self.device.unit_ids.append(unit)
                    reply = self.device.answer(pdu)
                    adu = struct.pack(">HHHB", tid, pid, len(reply) + 1, unit) + reply
                    writer.write(self._mangle(adu))
                await writer.drain()
        except (asyncio.IncompleteReadError, ConnectionResetError):
            pass
        finally:
            writer.close()


@pytest.fixture
async def modbus_server() -> AsyncIterator[Callable[..., object]]:
    """Factory: ``await modbus_server(device, rtu=False)`` -> started FakeModbusServer."""
    servers: list[FakeModbusServer] = []

    async def make(device: FakeModbusDevice, *, rtu: bool = False) -> FakeModbusServer:
        server = FakeModbusServer(device, rtu=rtu)
        await server.start()
        servers.append(server)
        return server

    yield make
    for server in servers:
        await server.stop()


@dataclass
class PtyPair:
    """A pty: ``path`` is what the driver opens, ``fd`` is the fake instrument's end."""

    fd: int
    path: str

    async def read_until(self, terminator: bytes, timeout_s: float = 5.0) -> bytes:
        """Read from the instrument end until ``terminator`` (event-loop friendly)."""
        loop = asyncio.get_running_loop()
        buf = b""
        queue: asyncio.Queue[bytes] = asyncio.Queue()
        loop.add_reader(self.fd, lambda: queue.put_nowait(os.read(self.fd, 4096)))
        try:
            while not buf.endswith(terminator):
                buf += await asyncio.wait_for(queue.get(), timeout_s)
        finally:
            loop.remove_reader(self.fd)
        return buf

    async def read_exactly(self, n: int, timeout_s: float = 5.0) -> bytes:
        """Read exactly ``n`` bytes from the instrument end."""
        loop = asyncio.get_running_loop()
        buf = b""
        queue: asyncio.Queue[bytes] = asyncio.Queue()
        loop.add_reader(self.fd, lambda: queue.put_nowait(os.read(self.fd, n - len(buf))))
        try:
            while len(buf) < n:
                buf += await asyncio.wait_for(queue.get(), timeout_s)
        finally:
            loop.remove_reader(self.fd)
        return buf

    def send(self, data: bytes) -> None:
        os.write(self.fd, data)


@pytest.fixture
def pty_pair() -> Iterator[PtyPair]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    path = os.ttyname(slave)
    try:
        yield PtyPair(master, path)
    finally:
        os.close(master)
        os.close(slave)


@dataclass(frozen=True)
class Fakes:
    """The helpers above, handed to tests through the ``fakes`` fixture."""

    Device: type[FakeModbusDevice] = FakeModbusDevice
    crc16: Callable[[bytes], int] = crc16_modbus
    rtu_frame: Callable[[bytes], bytes] = rtu_frame


@pytest.fixture
def fakes() -> Fakes:
    return Fakes()
