"""Every STIL reading is the answer to its own request (issue 23, item 1).

A fake Ruby behind a pty answers MEAS with ``Y=<geometry>``: the geometry the test (the
"arms") stands at when the device *receives* the command. The test walks six geometries
like the runner does (a timed-out reading is retried at the same geometry, up to twice)
and asserts that the reading kept at geometry g says g. Device behaviours, each from a
misbehaving serial instrument:

- ``late``: one MEAS answered after the driver's timeout, the device processing commands
  in order (the retry's command waits behind the slow one);
- ``overtaken``: one MEAS answered late while later commands are answered at once (the
  late reply arrives after replies to later requests);
- ``twice``: one MEAS answered twice.

Before the fence, a reply 0.6 s past the timeout made every later point store the reading
of the previous geometry, and the run ended ``done`` with one retry warning.
"""

from __future__ import annotations

import asyncio
import os
from typing import Any

import pytest

from drivers.base import DeviceTimeout
from drivers.stil import StilSpectro

SPEC = "SPEC 380 5 81 " + ",".join(["10"] * 81)
TIMEOUT_S = 0.25
LATE_S = 0.6  # past the driver's timeout
MEAS_S = 0.05  # the device's own measuring time


class FakeRuby:
    """A STIL Ruby whose MEAS number ``bad`` misbehaves as ``mode`` says."""

    def __init__(self, fd: int, mode: str, bad: int) -> None:
        self.fd = fd
        self.mode = mode
        self.bad = bad
        self.geometry = 0
        self.meas_count = 0
        self.exposure = 10000
        self.log: list[str] = []
        self._tasks: set[asyncio.Task[None]] = set()

    def send(self, text: str) -> None:
        os.write(self.fd, text.encode())

    def measure_reply(self) -> str:
        return f"Y={self.geometry:.4f}\r\n{SPEC}\r\n"

    async def _later(self, delay_s: float, text: str) -> None:
        await asyncio.sleep(delay_s)
        self.send(text)

    async def handle(self, command: str) -> None:
        self.log.append(command)
        if command == "IDN?":
            self.send("STIL RUBY SN 1 (fake)\r\n")
        elif command.startswith("EXP "):
            self.exposure = int(command[4:])
            self.send(f"EXP={self.exposure}\r\n")
        elif command == "MEAS":
            self.meas_count += 1
            reply = self.measure_reply()  # the geometry when the command arrives
            await asyncio.sleep(MEAS_S)
            if self.meas_count != self.bad:
                self.send(reply)
            elif self.mode == "late":  # in order: everything after waits behind it
                await asyncio.sleep(LATE_S)
                self.send(reply)
            elif self.mode == "overtaken":  # later commands are answered first
                task = asyncio.ensure_future(self._later(LATE_S, reply))
                self._tasks.add(task)
            elif self.mode == "twice":
                self.send(reply)
                task = asyncio.ensure_future(self._later(0.5 * MEAS_S, reply))
                self._tasks.add(task)
        else:
            self.send("ERR 1 unknown command\r\n")

    async def serve(self) -> None:
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[bytes] = asyncio.Queue()
        loop.add_reader(self.fd, lambda: queue.put_nowait(os.read(self.fd, 4096)))
        buf = b""
        try:
            while True:
                buf += await queue.get()
                while b"\r" in buf:
                    line, buf = buf.split(b"\r", 1)
                    await self.handle(line.decode())
        finally:
            loop.remove_reader(self.fd)


async def walk(dev: StilSpectro, ruby: FakeRuby, geometries: int) -> list[float]:
    """The runner's loop: move, read, retry a timed-out reading at the same geometry."""
    kept: list[float] = []
    for g in range(1, geometries + 1):
        ruby.geometry = g
        for attempt in range(3):
            try:
                reading = await dev.measure()
            except DeviceTimeout:
                if attempt == 2:
                    raise
                continue
            kept.append(reading.luminance_pct)
            break
    return kept


@pytest.mark.parametrize(("mode", "bad"), [("late", 3), ("overtaken", 3), ("twice", 2)])
async def test_each_reading_belongs_to_its_geometry(pty_pair: Any, mode: str, bad: int) -> None:
    ruby = FakeRuby(pty_pair.fd, mode, bad)
    server = asyncio.ensure_future(ruby.serve())
    dev = StilSpectro(port=pty_pair.path, timeout_s=TIMEOUT_S)
    try:
        await dev.connect()
        kept = await walk(dev, ruby, 6)
        await asyncio.sleep(LATE_S)  # anything still late has arrived by now
        kept += await walk(dev, ruby, 0)
        ruby.geometry = 7
        kept.append((await dev.measure()).luminance_pct)
    finally:
        await dev.close()
        server.cancel()
    assert kept == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
    # what was dropped is counted, not hidden
    assert dev.stale_lines + dev.stale_bytes > 0


async def test_a_clean_device_drops_nothing(pty_pair: Any) -> None:
    ruby = FakeRuby(pty_pair.fd, "none", 0)
    server = asyncio.ensure_future(ruby.serve())
    dev = StilSpectro(port=pty_pair.path, timeout_s=TIMEOUT_S)
    try:
        await dev.connect()
        assert await walk(dev, ruby, 4) == [1.0, 2.0, 3.0, 4.0]
    finally:
        await dev.close()
        server.cancel()
    assert dev.stale_lines == 0 and dev.stale_bytes == 0
    assert ruby.log == ["IDN?", "EXP 10000"] + ["MEAS", "EXP 10000"] * 4


async def test_without_the_fence_a_repeated_answer_shifts_the_readings(pty_pair: Any) -> None:
    # the fence is what catches a repeated answer: the drain alone cannot tell it (this
    # is the failure the issue saw, kept as a check that the fake really misbehaves)
    ruby = FakeRuby(pty_pair.fd, "twice", 2)
    server = asyncio.ensure_future(ruby.serve())
    dev = StilSpectro(port=pty_pair.path, timeout_s=TIMEOUT_S, fence=False)
    try:
        await dev.connect()
        ruby.geometry = 1
        await dev.measure()
        ruby.geometry = 2
        await dev.measure()  # its repeat arrives while the next measurement runs
        ruby.geometry = 3
        shifted = (await dev.measure()).luminance_pct
    finally:
        await dev.close()
        server.cancel()
    assert shifted == 2.0
