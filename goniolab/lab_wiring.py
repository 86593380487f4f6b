"""Build a lab -- simulated or real instruments -- from a lab config.

``async with Lab.from_config("configs/lab-sim.toml") as lab:`` gives

* ``lab.goniometer`` (:class:`drivers.goniometer.TwoArmGoniometer`), ``lab.spectro``,
  ``lab.glossmeter``: objects implementing the :mod:`drivers.base` Protocols;
* ``lab.model``: the reflectance model of ``[sample]`` (``goniolab.model_cache.model_for``,
  built in a worker thread), ``lab.source`` / ``lab.detector`` (the lamp and detector
  cones), ``lab.clock`` (the sim clock, or a real one), ``lab.config``.

Modes (``[lab] mode``):

* ``"sim"``: in-process simulated instruments, assembled by :mod:`sim.assembly`. With
  ``[sim.twin] mode = "realistic"`` (the default) they measure the sample's hidden truth
  (:mod:`sim.truth`, built in a worker thread from the same map the prediction uses) with
  realistic instruments; with ``"ideal"`` they read the prediction's own model.
* ``"drivers"``: the real drivers of :mod:`drivers` to the configured endpoints; with
  ``start_sim_servers = true`` the simulated lab is first served on those endpoints
  (:class:`sim.wire.SimLabServer`: Modbus TCP, or RTU over ``socket://``, + ptys), so
  the drivers run end to end against it. Port 0 there (``port = 0``, ``serial_port =
  "socket://127.0.0.1:0"``) binds a free port and hands it to the drivers.

The drivers are those of each device's protocol (:mod:`drivers.protocols`: the config's
``protocol`` keys). Closing the lab closes the instruments, then stops the simulated
servers. This module only chooses: the twin assembles itself (:mod:`sim.assembly`, whose
names it re-exports), and the direction of imports is lab -> sim / drivers, never the
other way round.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Callable, Iterable
from pathlib import Path
from types import TracebackType
from typing import Any

from drivers.base import Axis, DeviceError, Glossmeter, Spectrocolorimeter
from drivers.goniometer import TwoArmGoniometer
from drivers.protocols import SPECTROS, STEPPERS
from drivers.timing import Clock, RealClock, SimClock
from goniolab.config import AxisConfig, ConfigError, LabConfig, load_lab_config
from goniolab.errors import UserError
from goniolab.optics.apertures import Cone
from goniolab.optics.models import ReflectanceModel
from sim.assembly import (
    SimInstruments,
    SimLab,
    build_sim_instruments,
    build_sim_server,
    draw_session,
    sample_truth,
    socket_url,
    twin_settings,
)
from sim.wire import SimLabServer

__all__ = [
    "INSTRUMENTS",
    "Lab",
    "SimInstruments",
    "build_sim_instruments",
    "build_sim_server",
    "draw_session",
    "sample_model",
    "sample_truth",
    "twin_settings",
]


def sample_model(cfg: LabConfig) -> ReflectanceModel:
    """The reflectance model of ``[sample]`` (blocking; call it in a thread).

    Raises
    ------
    ConfigError
        The map cannot be resolved or loaded (names the config key ``sample.map``).
    """
    from goniolab.model_cache import model_for

    try:
        model: ReflectanceModel = model_for(
            cfg.sample_map(),
            n=cfg.sample.n,
            step_um=cfg.sample.step_um,
            model=cfg.sample.model,
            wavelength_nm=cfg.sample.wavelength_nm,
        )
    except (UserError, ValueError, OSError) as exc:
        raise ConfigError(cfg.source or "<config>", "sample.map", str(exc)) from None
    return model


#: The lab's instruments, in the order they are connected.
INSTRUMENTS: tuple[str, ...] = ("goniometer", "spectro", "glossmeter")


class Lab:
    """Instruments, model and clock of one lab; use ``async with Lab.from_config(...)``.

    Parameters
    ----------
    config
        A validated :class:`~goniolab.config.LabConfig`.
    time_scale
        Overrides ``[lab] time_scale`` of the sim clock (0 = instant).
    model
        Use this reflectance model instead of building the one of ``[sample]``
        (tests, or a caller that already has it).
    instruments
        Which instruments to connect (default: all three). A glossmeter session opens
        only ``("glossmeter",)`` so it works while the goniometer is off or unreachable.
    """

    def __init__(
        self,
        config: LabConfig,
        *,
        time_scale: float | None = None,
        model: ReflectanceModel | None = None,
        instruments: Iterable[str] = INSTRUMENTS,
    ) -> None:
        if time_scale is not None and not time_scale >= 0:
            raise UserError(f"--time-scale must be >= 0, got {time_scale}")
        self.instruments = frozenset(instruments)
        unknown = self.instruments - set(INSTRUMENTS)
        if unknown or not self.instruments:
            raise ValueError(
                f"instruments must be a non-empty subset of {INSTRUMENTS}, got {sorted(unknown)}"
            )
        self.config = config
        self.time_scale = config.lab.time_scale if time_scale is None else float(time_scale)
        self.source = Cone(config.goniometer.source_cone_deg)
        self.detector = Cone(config.spectro.detector_cone_deg)
        self._model = model
        self.clock: Clock = RealClock()
        self.sims: SimInstruments | None = None
        self.server: SimLabServer | None = None
        self._goniometer: TwoArmGoniometer | None = None
        self._spectro: Spectrocolorimeter | None = None
        self._glossmeter: Glossmeter | None = None
        self._closers: list[Callable[[], Any]] = []
        self._sim: SimLab | None = None
        self.place_specimen: Callable[[str], Awaitable[None]] | None = None

    @classmethod
    def from_config(
        cls,
        path_or_config: str | Path | LabConfig,
        *,
        time_scale: float | None = None,
        model: ReflectanceModel | None = None,
        instruments: Iterable[str] = INSTRUMENTS,
    ) -> Lab:
        """A lab from a config file (loaded and validated) or an already loaded config."""
        cfg = (
            path_or_config
            if isinstance(path_or_config, LabConfig)
            else load_lab_config(path_or_config)
        )
        return cls(cfg, time_scale=time_scale, model=model, instruments=instruments)

    # ------------------------------------------------------------------ accessors
    def _need(self, what: str, value: Any) -> Any:
        if what in INSTRUMENTS and what not in self.instruments:
            raise RuntimeError(f"this lab was opened without the {what}")
        if value is None:
            raise RuntimeError(f"lab not open: use 'async with Lab.from_config(...)' ({what})")
        return value

    @property
    def goniometer(self) -> TwoArmGoniometer:
        """The two-arm goniometer."""
        g: TwoArmGoniometer = self._need("goniometer", self._goniometer)
        return g

    @property
    def spectro(self) -> Spectrocolorimeter:
        """The spectro-colorimeter."""
        s: Spectrocolorimeter = self._need("spectro", self._spectro)
        return s

    @property
    def glossmeter(self) -> Glossmeter:
        """The glossmeter."""
        m: Glossmeter = self._need("glossmeter", self._glossmeter)
        return m

    @property
    def model(self) -> ReflectanceModel:
        """The reflectance model of ``[sample]``."""
        m: ReflectanceModel = self._need("model", self._model)
        return m

    @property
    def mode(self) -> str:
        """``"sim"`` or ``"drivers"``."""
        return self.config.lab.mode

    # ------------------------------------------------------------------ lifecycle
    async def open(self) -> None:
        """Build the model (in a thread), the instruments and connect them.

        Raises
        ------
        ConfigError, UserError
            Bad sample map, profile or endpoint in the config.
        drivers.base.DeviceError
            An instrument cannot be reached (names the device and endpoint).
        """
        try:
            await self._open()
        except BaseException:
            await self.close()
            raise

    async def _open(self) -> None:
        cfg = self.config
        if self._model is None:
            self._model = await asyncio.to_thread(sample_model, cfg)
        if cfg.lab.mode == "sim" or cfg.lab.start_sim_servers:
            truth = None
            if cfg.sim.twin.mode == "realistic":  # the twin's hidden truth
                truth = await asyncio.to_thread(sample_truth, cfg)
            self.clock = SimClock(self.time_scale)
            self._sim = SimLab(cfg, self._model, self.clock, truth)
            self.sims = self._sim.instruments
            self.place_specimen = self._place_specimen
        if cfg.lab.mode == "sim":
            assert self.sims is not None
            self._goniometer = self._two_arms(self.sims.lamp, self.sims.detector)
            self._spectro = self.sims.spectro
            self._glossmeter = self.sims.glossmeter
        else:
            if self._sim is not None:
                await self._serve(self._sim)
            self._wire_drivers()
        await self._connect()

    def _two_arms(self, lamp: Axis, detector: Axis) -> TwoArmGoniometer:
        """The goniometer of two arm axes, with the config's interlock and park."""
        g = self.config.goniometer
        return TwoArmGoniometer(
            lamp,
            detector,
            min_separation_deg=g.min_separation_deg,
            park_deg=(g.park.theta_i_deg, g.park.theta_r_deg),
            corrections_deg=self.config.alignment.corrections_deg(),
        )

    # ------------------------------------------------------------------ simulated lab
    # ------------------------------------------------------------------ simulated lab
    async def _serve(self, sim: SimLab) -> None:
        """``start_sim_servers``: serve the simulated instruments on the config's
        endpoints (Modbus, ptys), for the real drivers to reach."""
        server = sim.server()
        try:
            await server.start()
        except OSError as exc:
            raise UserError(f"cannot start the simulated lab: {exc}", exit_code=1) from None
        self.server = server

    async def prepare_sample(self, spec: str) -> None:
        """Realistic twin: build the truth of sample ``spec`` (worker thread, cached), so
        that :meth:`put_sample` can put it under the instruments at once. No-op for the
        ideal twin and a real lab."""
        if self._sim is not None:
            await self._sim.prepare_sample(spec)

    async def _place_specimen(self, which: str) -> None:
        """Simulated lab: put ``"mirror"``, ``"standard"`` or ``"sample"`` under the
        instruments (:meth:`sim.assembly.SimLab.place_specimen`); handed out as
        ``lab.place_specimen`` only when the lab is simulated."""
        if self._sim is None:
            raise RuntimeError("place_specimen needs the simulated lab")
        await self._sim.place_specimen(which)

    def put_sample(self, model: ReflectanceModel, spec: str = "") -> None:
        """Simulated lab: the instruments measure the sample ``spec`` (predicted by
        ``model``) from now on (:meth:`sim.assembly.SimLab.put_sample`). A real lab
        measures whatever lies there."""
        if self._sim is not None:
            self._sim.put_sample(model, spec)

    def _wire_drivers(self) -> None:
        """``mode = "drivers"``: the drivers of :mod:`drivers` to the configured endpoints
        (or to the simulated lab this lab serves there)."""
        from drivers.glossmeter import open_glossmeter

        cfg = self.config
        g = cfg.goniometer
        self._goniometer = self._two_arms(
            self._axis_driver("lamp", g.lamp), self._axis_driver("detector", g.detector)
        )
        spectro_driver = SPECTROS[cfg.spectro.protocol].driver_class()
        self._spectro = spectro_driver(
            "spectro",
            port=cfg.spectro.port,
            profile=cfg.spectro.profile,
            baudrate=cfg.spectro.baudrate,
            exposure_us=cfg.spectro.exposure_us,
            timeout_s=cfg.spectro.timeout_s,
        )
        gm = cfg.glossmeter
        self._glossmeter = open_glossmeter(
            gm.port,
            protocol=gm.protocol,
            profile=gm.profile,
            serial_number=gm.serial_number,
            baudrate=gm.baudrate,
            timeout_s=gm.timeout_s,
        )

    def _axis_driver(self, name: str, ax: AxisConfig) -> Axis:
        """The stepper driver of one arm (its protocol's driver class)."""
        port, serial_port = self._served_at(ax)
        driver: Axis = STEPPERS[ax.protocol].driver_class()(
            name,
            profile=ax.profile,
            transport=ax.transport,
            host=ax.host,
            port=port,
            serial_port=serial_port,
            baudrate=ax.baudrate,
            parity=ax.parity,
            unit_id=ax.unit_id,
            steps_per_deg=ax.steps_per_deg,
            gear_ratio=ax.gear_ratio,
            limits_deg=ax.limits_deg,
            speed_deg_s=ax.speed_deg_s,
            accel_deg_s2=ax.accel_deg_s2,
            stall_tolerance_deg=ax.stall_tolerance_deg,
            timeout_s=ax.timeout_s,
        )
        return driver

    def _served_at(self, ax: AxisConfig) -> tuple[int, str]:
        """``(port, serial_port)`` to reach an arm: the configured ones or, when this lab
        serves the simulated controllers and the config says port 0 (``port = 0`` or
        ``serial_port = "socket://host:0"``), the port the kernel gave the server."""
        if self.server is not None:
            for srv in self.server.modbus:
                served = (srv.transport, srv.host, srv.requested_port)
                if ax.transport == "tcp" and served == ("tcp", ax.host, ax.port):
                    return srv.port, ax.serial_port
                if ax.transport == "rtu" and served == (
                    "rtu",
                    *(socket_url(ax.serial_port) or ()),
                ):
                    return ax.port, srv.url
        return ax.port, ax.serial_port

    # ------------------------------------------------------------------ connect / close
    async def _connect(self) -> None:
        parts = {
            "goniometer": self._goniometer,
            "spectro": self._spectro,
            "glossmeter": self._glossmeter,
        }
        for name in INSTRUMENTS:
            if name not in self.instruments:
                continue
            part = parts[name]
            assert part is not None
            await part.connect()
            self._closers.append(part.close)

    async def close(self) -> None:
        """Close the instruments (each even if another fails), then stop the sim servers."""
        while self._closers:
            closer = self._closers.pop()
            with contextlib.suppress(DeviceError, OSError):
                await closer()
        if self._sim is not None:
            await asyncio.to_thread(self._sim.save_truth_cache)
        if self.server is not None:
            await self.server.stop()
            self.server = None

    async def __aenter__(self) -> Lab:
        await self.open()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()
