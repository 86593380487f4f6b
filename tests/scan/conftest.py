"""Small in-test instruments implementing the drivers.base Protocols, on the sim clock.

The fake goniometer moves along the trapezoidal profile of :mod:`sim.motion` (time passes on
a ``SimClock(0)``: instant, deterministic); the fake spectro-colorimeter reads a Gaussian
specular lobe centred on the mirror direction of the *actual* arm positions, so a tilt or an
arm moved by hand shows in the data exactly as an analytic formula says.
"""

from __future__ import annotations

import asyncio
import math
import threading
from collections.abc import AsyncIterator, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import ArrayLike, NDArray

from drivers.base import (
    AxisStatus,
    GlossReading,
    InterlockError,
    LimitError,
    SpectroReading,
    StallError,
)
from drivers.timing import SimClock, trapezoid_duration_s
from goniolab.store import RunStore

LOBE_AMPLITUDE_PCT = 40.0
LOBE_SIGMA_DEG = 3.0


def lobe_pct(
    theta_i_deg: float, theta_r_deg: ArrayLike, shift_deg: float = 0.0
) -> NDArray[np.float64]:
    """Gaussian lobe around the specular direction theta_r = theta_i + shift_deg."""
    tr = np.asarray(theta_r_deg, dtype=np.float64)
    return LOBE_AMPLITUDE_PCT * np.exp(
        -0.5 * ((tr - theta_i_deg - shift_deg) / LOBE_SIGMA_DEG) ** 2
    )


class FakeAxis:
    def __init__(self, name: str, limits_deg: tuple[float, float], *, homed: bool = False) -> None:
        self.name = name
        self.limits_deg = limits_deg
        self.pos_deg = 0.0
        self.homed = homed

    async def connect(self) -> None:
        pass

    async def close(self) -> None:
        pass

    async def status(self) -> AxisStatus:
        return AxisStatus(position_deg=self.pos_deg, homed=self.homed)

    async def position_deg(self) -> float:
        return self.pos_deg

    async def move_to(self, target_deg: float) -> None:
        self.pos_deg = target_deg

    async def wait_in_position(self, timeout_s: float) -> float:
        return self.pos_deg

    async def home(self, timeout_s: float) -> None:
        self.pos_deg = 0.0
        self.homed = True

    async def stop(self) -> None:
        pass

    async def reset_alarm(self) -> None:
        pass


class FakeGoniometer:
    """Two arms, lamp 0..85 deg and detector -70..70 deg, min separation 10 deg."""

    def __init__(self, clock: SimClock, *, homed: bool = False) -> None:
        self.clock = clock
        self.lamp = FakeAxis("lamp", (0.0, 85.0), homed=homed)
        self.detector = FakeAxis("detector", (-70.0, 70.0), homed=homed)
        self.min_separation_deg = 10.0
        self.speed_deg_s = 20.0
        self.accel_deg_s2 = 40.0
        self.park_deg = (45.0, 45.0)
        self.moves: list[tuple[float, float]] = []
        self.home_calls = 0
        self.park_calls = 0
        self.stop_calls = 0
        self.fail_on_move: int | None = None  # 1-based move number that stalls

    def check_geometry(self, theta_i_deg: float, theta_r_deg: float) -> None:
        for axis, v in ((self.lamp, theta_i_deg), (self.detector, theta_r_deg)):
            lo, hi = axis.limits_deg
            if not lo <= v <= hi:
                raise LimitError(f"{v:g} deg outside the limits [{lo:g}, {hi:g}]", device=axis.name)
        if abs(theta_i_deg + theta_r_deg) < self.min_separation_deg:
            raise InterlockError(
                f"arm separation {abs(theta_i_deg + theta_r_deg):g} deg < "
                f"{self.min_separation_deg:g} deg",
                device="goniometer",
            )

    async def connect(self) -> None:
        pass

    async def close(self) -> None:
        pass

    async def home(self, timeout_s: float) -> None:
        self.home_calls += 1
        await self.lamp.home(timeout_s)
        await self.detector.home(timeout_s)

    async def move_to(
        self, theta_i_deg: float, theta_r_deg: float, timeout_s: float
    ) -> tuple[float, float]:
        self.check_geometry(theta_i_deg, theta_r_deg)
        self.moves.append((theta_i_deg, theta_r_deg))
        if self.fail_on_move is not None and len(self.moves) == self.fail_on_move:
            raise StallError(
                "excessive position deviation (alarm 0x10)", device="detector", code=0x10
            )
        dt = max(
            trapezoid_duration_s(
                theta_i_deg - self.lamp.pos_deg, self.speed_deg_s, self.accel_deg_s2
            ),
            trapezoid_duration_s(
                theta_r_deg - self.detector.pos_deg, self.speed_deg_s, self.accel_deg_s2
            ),
        )
        await self.clock.sleep(dt)
        self.lamp.pos_deg, self.detector.pos_deg = theta_i_deg, theta_r_deg
        return (theta_i_deg, theta_r_deg)

    async def positions_deg(self) -> tuple[float, float]:
        return (self.lamp.pos_deg, self.detector.pos_deg)

    async def park(self, timeout_s: float) -> None:
        self.park_calls += 1
        await self.move_to(*self.park_deg, timeout_s)

    async def stop(self) -> None:
        self.stop_calls += 1


class FakeSpectro:
    """Reads the Gaussian lobe at the real arm positions; a mirror reads ``mirror_pct``."""

    def __init__(self, gonio: FakeGoniometer, clock: SimClock, *, shift_deg: float = 0.0) -> None:
        self.name = "spectro"
        self.gonio = gonio
        self.clock = clock
        self.shift_deg = shift_deg
        self.specimen = "sample"
        self.mirror_pct = 80.0
        self.exposure_us = 0
        self.n_reads = 0
        self.overhead_s = 0.0  # transfer time beyond the exposure

    async def connect(self) -> None:
        pass

    async def close(self) -> None:
        pass

    async def identify(self) -> str:
        return "fake"

    async def set_exposure_us(self, exposure_us: int) -> None:
        self.exposure_us = exposure_us

    async def measure(self) -> SpectroReading:
        await self.clock.sleep(self.exposure_us * 1e-6 + self.overhead_s)
        self.n_reads += 1
        ti, tr = self.gonio.lamp.pos_deg, self.gonio.detector.pos_deg
        if self.specimen == "mirror":
            lum = self.mirror_pct if abs(tr - ti) < 1e-9 else 0.0
        else:
            lum = float(lobe_pct(ti, tr, self.shift_deg))
        # a flat spectrum over 380..780 nm (10 nm): its Y equals the luminance
        return SpectroReading(
            wavelengths_nm=tuple(float(w) for w in range(380, 781, 10)),
            values=(lum,) * 41,
            luminance_pct=lum,
            exposure_us=self.exposure_us,
        )


@dataclass
class FakeModel:
    """ReflectanceModel whose luminance is the unshifted lobe; records the calling threads."""

    threads: list[int] = field(default_factory=list)
    calls: list[tuple[float, tuple[float, ...], Any, Any]] = field(default_factory=list)

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Any = None,
        detector: Any = None,
    ) -> NDArray[np.float64]:
        self.threads.append(threading.get_ident())
        tr = np.atleast_1d(np.asarray(theta_r_deg, dtype=np.float64))
        self.calls.append((theta_i_deg, tuple(tr), source, detector))
        return lobe_pct(theta_i_deg, tr)

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        return math.nan

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: ArrayLike) -> NDArray[np.float64]:
        return np.full(np.shape(theta_r_deg), np.nan)

    def reflected_fraction(
        self, theta_i_deg: float, theta_r_deg: float, source: Any, receptor: Any
    ) -> float:
        return math.nan

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        return {20: 80.0, 60: 90.0, 85: 95.0}


class FakeGlossmeter:
    """Yields scripted readings; an entry that is an exception is raised instead."""

    def __init__(self, script: list[GlossReading | Exception]) -> None:
        self.name = "glossmeter"
        self.script = list(script)
        self.connects = 0
        self.closes = 0
        self.wait_when_empty = False

    async def connect(self) -> None:
        self.connects += 1

    async def close(self) -> None:
        self.closes += 1

    async def measure(self, angles_deg: Sequence[int] = (20, 60, 85)) -> GlossReading:
        await asyncio.sleep(0)  # a real meter waits for its reply: let other tasks run
        if not self.script:
            raise AssertionError("glossmeter script exhausted")
        item = self.script.pop(0)
        if isinstance(item, Exception):
            raise item
        return item

    async def readings(self) -> AsyncIterator[GlossReading]:
        while self.script:
            yield await self.measure()
        if self.wait_when_empty:  # nobody presses the meter's button again
            await asyncio.Event().wait()


@dataclass
class FakeLab:
    clock: SimClock
    goniometer: FakeGoniometer
    spectro: FakeSpectro
    model: FakeModel


@pytest.fixture
def fake_lab() -> FakeLab:
    clock = SimClock(0)
    gonio = FakeGoniometer(clock)
    return FakeLab(
        clock=clock, goniometer=gonio, spectro=FakeSpectro(gonio, clock), model=FakeModel()
    )


@pytest.fixture
def store(tmp_path: Path) -> Iterator[RunStore]:
    s = RunStore(tmp_path / "runs.sqlite")
    yield s
    s.close()
