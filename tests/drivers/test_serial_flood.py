"""A 4 MiB line without its terminator does not poison the link (issue 23, Low).

Before, the reader dropped only what its buffer held (64 KiB) and each retry met the rest
of the same flood, so the run failed. Now the link is drained until it goes quiet: the
first read fails once, naming the bytes dropped, and the next request's reply is read.
The device is a real pty (what a USB-serial adapter looks like to the driver).
"""

from __future__ import annotations

import asyncio
import os
import threading

import pytest

from drivers.base import ProtocolError
from drivers.profiles import SerialSettings
from drivers.serial_io import LineTransport

FLOOD = 4 * 1024 * 1024


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view[:65536])
        view = view[n:]


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")
async def test_a_4_mib_flood_fails_one_read_and_the_next_reply_is_read() -> None:
    master, slave = os.openpty()
    link = LineTransport(os.ttyname(slave), SerialSettings(baudrate=115200), device="spectro")
    await link.open()
    try:
        flood = threading.Thread(target=_write_all, args=(master, b"x" * FLOOD), daemon=True)
        flood.start()
        with pytest.raises(ProtocolError, match=r"longer than the buffer") as info:
            await link.read_line("\r", timeout_s=10.0)
        await asyncio.to_thread(flood.join, 10.0)
        assert not flood.is_alive()  # the whole flood was read (and dropped)
        # the retry's reply, sent after the flood
        _write_all(master, b"Y=12.5\r")
        assert await link.read_line("\r", timeout_s=5.0) == "Y=12.5"
        dropped = int(str(info.value).split(": ")[-1].split()[0])
        assert FLOOD - (1 << 17) < dropped <= FLOOD  # said, and about all of it
    finally:
        await link.close()
        os.close(master)
        os.close(slave)
