"""Build a lab -- simulated or real instruments -- from a lab config.

``async with Lab.from_config("configs/lab-sim.toml") as lab:`` gives

* ``lab.goniometer`` (:class:`drivers.goniometer.TwoArmGoniometer`), ``lab.spectro``,
  ``lab.glossmeter``: objects implementing the :mod:`drivers.base` Protocols;
* ``lab.model``: the reflectance model of ``[sample]`` (``goniolab.models.model_for``,
  built in a worker thread), ``lab.source`` / ``lab.detector`` (the lamp and detector
  cones), ``lab.clock`` (the sim clock, or a real one), ``lab.config``.

Modes (``[lab] mode``):

* ``"sim"``: in-process simulated instruments (:mod:`sim.instruments`). With
  ``[sim.twin] mode = "realistic"`` (the default) they measure the sample's hidden truth
  (:mod:`sim.truth`, built in a worker thread from the same map the prediction uses) with
  realistic instruments; with ``"ideal"`` they read the prediction's own model.
* ``"drivers"``: the real drivers of :mod:`drivers` to the configured endpoints; with
  ``start_sim_servers = true`` the simulated lab is first served on those endpoints
  (:class:`sim.wire.SimLabServer`: Modbus TCP, or RTU over ``socket://``, + ptys), so
  the drivers run end to end against it. Port 0 there (``port = 0``, ``serial_port =
  "socket://127.0.0.1:0"``) binds a free port and hands it to the drivers.

Closing the lab closes the instruments, then stops the simulated servers. The
direction of imports is lab -> sim / drivers, never the other way round.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.base import Axis, DeviceError, Glossmeter, ProfileError, Spectrocolorimeter
from drivers.goniometer import TwoArmGoniometer
from drivers.profiles import load_stepper_profile, load_stil_profile, load_zgm_profile
from drivers.timing import Clock, RealClock, SimClock
from goniolab.config import AxisConfig, ConfigError, LabConfig, load_lab_config
from goniolab.errors import UserError
from goniolab.optics.apertures import Cone
from goniolab.optics.models import ReflectanceModel
from sim.faults import FaultInjector, FaultSpec
from sim.instruments import (
    GlossDrift,
    MirrorModel,
    SimAxis,
    SimGlossmeter,
    SimSpectro,
    SpectroChain,
)
from sim.motion import SimMotor
from sim.truth import FlatSpecimen, TruthOptics, TwinSettings, truth_for
from sim.wire import ModbusAxisServer, SimLabServer, StilPtyDevice, WireAxis, ZgmPtyDevice

if TYPE_CHECKING:
    from drivers.modbus_stepper import ModbusStepperAxis

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


@dataclass
class SimInstruments:
    """The simulated instruments of one lab (shared by the in-process and wire modes).

    ``session`` holds the misalignments of this session (see :func:`draw_session`) and
    ``truth`` the sample's hidden truth (realistic twin; ``None`` for the ideal one).
    """

    lamp: SimAxis
    detector: SimAxis
    spectro: SimSpectro
    glossmeter: SimGlossmeter
    clock: SimClock
    session: dict[str, float]
    truth: TruthOptics | None = None


def twin_settings(cfg: LabConfig) -> TwinSettings:
    """The truth's settings from ``[sim.twin]`` (disk cache under the user cache dir)."""
    t = cfg.sim.twin
    cache_dir = None
    if t.cache:
        import platformdirs

        cache_dir = str(Path(platformdirs.user_cache_dir("goniolab")) / "twin")
    return TwinSettings(
        step_um=t.step_um,
        subres_rq_nm=t.subres_rq_nm,
        subres_corr_um=t.subres_corr_um,
        profilometer_noise_nm=t.profilometer_noise_nm,
        waviness_slope_rms=t.waviness_slope_rms,
        seed=cfg.sim.seed,
        cache_dir=cache_dir,
    )


def _sample_body(spec: str, default: str) -> str:
    """A library sample's ``body`` key (configs/samples.toml), else ``default``."""
    if spec.startswith("sample:"):
        from goniolab.surfaces.samples import sample_info

        body = sample_info(spec.removeprefix("sample:")).params.get("body", default)
        return str(body)
    return default


def sample_truth(cfg: LabConfig, spec: str | None = None) -> TruthOptics:
    """The hidden truth behind ``spec`` (default ``[sample] map``) for the realistic twin
    (blocking: a few seconds the first time, then cached per process).

    Raises
    ------
    ConfigError
        The map cannot be resolved or loaded, or has a body the twin does not know.
    """
    from goniolab.surfaces.resolve import resolve_map

    spec = spec or _map_spec(cfg)
    src = cfg.source or "<config>"
    try:
        hm = resolve_map(spec, step_um=cfg.sample.step_um)
        body = _sample_body(spec, cfg.sim.twin.body)
        return truth_for(hm, n=cfg.sample.n, body=body, settings=twin_settings(cfg), name=spec)
    except (UserError, ValueError, OSError) as exc:
        raise ConfigError(src, "sample.map", f"the twin cannot build the truth: {exc}") from None


def draw_session(cfg: LabConfig) -> dict[str, float]:
    """This session's misalignments: ``[sim]`` values plus, for the realistic twin, a
    uniform draw in +/- the ``[sim.twin]`` ranges (seeded by ``[sim] seed``)."""
    s = cfg.sim
    out = {
        "sample_tilt_deg": s.sample_tilt_deg,
        "lamp_zero_offset_deg": s.lamp_zero_offset_deg,
        "detector_zero_offset_deg": s.detector_zero_offset_deg,
        "backlash_deg": 0.0,
    }
    if s.twin.mode == "realistic":
        rng = np.random.default_rng([s.seed, 7])
        t = s.twin
        out["lamp_zero_offset_deg"] += float(rng.uniform(-1, 1)) * t.lamp_zero_range_deg
        out["detector_zero_offset_deg"] += float(rng.uniform(-1, 1)) * t.detector_zero_range_deg
        out["sample_tilt_deg"] += float(rng.uniform(-1, 1)) * t.sample_tilt_range_deg
        out["backlash_deg"] = t.backlash_deg
    return out


def _map_spec(cfg: LabConfig) -> str:
    """``[sample] map``, with a relative file path taken relative to the config file."""
    spec = cfg.sample.map
    if spec.startswith("sample:") or not cfg.source:
        return spec
    p = Path(spec).expanduser()
    if not p.is_absolute():
        candidate = Path(cfg.source).resolve().parent / p
        if candidate.exists():
            return str(candidate)
    return spec


def sample_model(cfg: LabConfig) -> ReflectanceModel:
    """The reflectance model of ``[sample]`` (blocking; call it in a thread).

    Raises
    ------
    ConfigError
        The map cannot be resolved or loaded (names the config key ``sample.map``).
    """
    from goniolab.models import model_for

    try:
        model: ReflectanceModel = model_for(
            _map_spec(cfg),
            n=cfg.sample.n,
            step_um=cfg.sample.step_um,
            model=cfg.sample.model,
            wavelength_nm=cfg.sample.wavelength_nm,
        )
    except (UserError, ValueError, OSError) as exc:
        raise ConfigError(cfg.source or "<config>", "sample.map", str(exc)) from None
    return model


def _fault_spec(cfg: LabConfig, device: str) -> FaultSpec:
    f = cfg.sim.faults
    if device not in f.devices:
        return FaultSpec()
    return FaultSpec(
        timeout_rate=f.timeout_rate,
        garble_rate=f.garble_rate,
        disconnect_after=f.disconnect_after,
        disconnect_rate=f.disconnect_rate,
        recover_after_s=f.recover_after_s,
    )


def _sim_axis(
    name: str,
    ax: AxisConfig,
    start_deg: float,
    clock: SimClock,
    faults: FaultInjector,
    backlash_deg: float = 0.0,
) -> SimAxis:
    motor = SimMotor(
        name,
        speed_deg_s=ax.speed_deg_s,
        accel_deg_s2=ax.accel_deg_s2,
        soft_limits_deg=ax.limits_deg,
        start_deg=start_deg,
        homed=True,  # a powered lab: the arms stand at park, coordinates set
    )
    return SimAxis(
        name,
        motor,
        clock,
        stall_tolerance_deg=ax.stall_tolerance_deg,
        faults=faults,
        backlash_deg=backlash_deg,
    )


def build_sim_instruments(
    cfg: LabConfig,
    model: ReflectanceModel,
    clock: SimClock,
    truth: TruthOptics | None = None,
) -> SimInstruments:
    """Simulated arms, spectro and glossmeter as configured (``[sim]``, seeded).

    The arms power up at the park geometry; ``[sim.faults]`` sets the injected faults.
    With ``[sim.twin] mode = "realistic"`` the instruments measure ``truth`` (built with
    :func:`sample_truth` when not given) through realistic instruments; with ``"ideal"``
    they read ``model``.
    """
    seeds = np.random.SeedSequence(cfg.sim.seed).spawn(6)
    rngs = [np.random.default_rng(s) for s in seeds]
    g = cfg.goniometer
    t = cfg.sim.twin
    realistic = t.mode == "realistic"
    if realistic and truth is None:
        truth = sample_truth(cfg)
    session = draw_session(cfg)
    lamp = _sim_axis(
        "lamp",
        g.lamp,
        g.park.theta_i_deg,
        clock,
        FaultInjector("lamp", _fault_spec(cfg, "lamp"), rngs[0]),
        session["backlash_deg"],
    )
    detector = _sim_axis(
        "detector",
        g.detector,
        g.park.theta_r_deg,
        clock,
        FaultInjector("detector", _fault_spec(cfg, "detector"), rngs[1]),
        session["backlash_deg"],
    )
    f = cfg.sim.faults
    for axis, stall, alarm in (
        (lamp, f.lamp_stall_at_deg, f.lamp_alarm_at_deg),
        (detector, f.detector_stall_at_deg, f.detector_alarm_at_deg),
    ):
        axis.motor.inject_stall(stall)
        if alarm is not None:
            axis.motor.inject_alarm(alarm, f.alarm_code)
    chain = (
        SpectroChain(
            lamp=t.lamp,
            full_scale_pct=t.full_scale_pct,
            dark_counts_per_s=t.dark_counts_per_s,
            read_noise_counts=t.read_noise_counts,
            stray_pct=t.stray_pct,
            flicker_pct=t.flicker_pct,
        )
        if realistic
        else None
    )
    specimen: Any = truth if realistic else model
    spectro = SimSpectro(
        specimen,
        lamp,
        detector,
        clock,
        source_cone_deg=g.source_cone_deg,
        detector_cone_deg=cfg.spectro.detector_cone_deg,
        noise_pct=cfg.sim.noise_pct,
        rng=rngs[2],
        sample_tilt_deg=session["sample_tilt_deg"],
        lamp_zero_offset_deg=session["lamp_zero_offset_deg"],
        detector_zero_offset_deg=session["detector_zero_offset_deg"],
        exposure_us=cfg.spectro.exposure_us,
        faults=FaultInjector("spectro", _fault_spec(cfg, "spectro"), rngs[3]),
        chain=chain,
    )
    drift = (
        GlossDrift(
            drift_pct_per_h=t.gloss_drift_pct_per_h,
            temp_coeff_pct_per_c=t.gloss_temp_coeff_pct_per_c,
            warmup_c=t.gloss_warmup_c,
            noise_gu=t.gloss_noise_gu,
        )
        if realistic
        else None
    )
    glossmeter = SimGlossmeter(
        specimen,
        clock,
        noise_pct=cfg.sim.noise_pct,
        rng=rngs[4],
        autosend_interval_s=cfg.sim.gloss_autosend_s,
        faults=FaultInjector("glossmeter", _fault_spec(cfg, "glossmeter"), rngs[5]),
        drift=drift,
    )
    return SimInstruments(
        lamp, detector, spectro, glossmeter, clock, session, truth if realistic else None
    )


def _socket_url(url: str) -> tuple[str, int] | None:
    """``(host, port)`` of a pyserial ``socket://host:port`` URL, else ``None``."""
    if not url.startswith("socket://"):
        return None
    host, sep, port = url[len("socket://") :].rpartition(":")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        return None
    return host, int(port)


def build_sim_server(cfg: LabConfig, sims: SimInstruments) -> SimLabServer:
    """The simulated lab on the endpoints the config's drivers will use.

    Arms on ``transport = "tcp"`` are served by a Modbus TCP server on ``host:port``; arms
    on ``transport = "rtu"`` by a Modbus RTU server framed over TCP, which needs
    ``serial_port = "socket://host:port"``. Arms sharing an endpoint share one server
    (one unit id each). Port 0 lets the kernel pick a free port (see :class:`Lab`).

    Raises
    ------
    ConfigError
        An RTU arm whose ``serial_port`` is not ``socket://host:port``, or a profile
        that cannot be loaded or served.
    """
    src = cfg.source or "<config>"
    servers: dict[tuple[str, str, int], list[WireAxis]] = {}
    for name, ax, sim_axis in (
        ("lamp", cfg.goniometer.lamp, sims.lamp),
        ("detector", cfg.goniometer.detector, sims.detector),
    ):
        if ax.transport == "tcp":
            key = ("tcp", ax.host, ax.port)
        else:
            where = _socket_url(ax.serial_port)
            if where is None:
                raise ConfigError(
                    src,
                    f"goniometer.{name}.serial_port",
                    f"the simulated lab serves Modbus RTU over a TCP socket only: use "
                    f'serial_port = "socket://127.0.0.1:PORT" (got {ax.serial_port!r})',
                )
            key = ("rtu", *where)
        try:
            wire = WireAxis(
                sim_axis,
                load_stepper_profile(ax.profile),
                ax.steps_per_deg * ax.gear_ratio,  # steps per degree of the arm
                ax.unit_id,
            )
        except (ProfileError, ValueError) as exc:
            raise ConfigError(src, f"goniometer.{name}.profile", str(exc)) from None
        servers.setdefault(key, []).append(wire)
    modbus = [
        ModbusAxisServer(w, host=h, port=p, transport="tcp" if t == "tcp" else "rtu")
        for (t, h, p), w in servers.items()
    ]
    if cfg.glossmeter.protocol != "zgm1120":
        raise ConfigError(
            src, "glossmeter.protocol", 'the simulated lab serves the "zgm1120" protocol only'
        )
    spectro = StilPtyDevice(sims.spectro, load_stil_profile(cfg.spectro.profile), cfg.spectro.port)
    gloss = ZgmPtyDevice(
        sims.glossmeter,
        load_zgm_profile(cfg.glossmeter.profile),
        cfg.glossmeter.port,
        serial_number=cfg.glossmeter.serial_number,
    )
    return SimLabServer(modbus, spectro, gloss)


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
        self._sample_under: ReflectanceModel | None = None
        self._truths: dict[str, TruthOptics] = {}
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
        truth = None
        if (
            cfg.lab.mode == "sim" or cfg.lab.start_sim_servers
        ) and cfg.sim.twin.mode == "realistic":
            truth = await asyncio.to_thread(sample_truth, cfg)  # the twin's hidden truth
            self._truths[cfg.sample.map] = truth
        if cfg.lab.mode == "sim":
            self._wire_sims(self._build_sims(self._model, truth))
        else:
            if cfg.lab.start_sim_servers:
                await self._serve_sims(self._build_sims(self._model, truth))
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
    def _build_sims(
        self, model: ReflectanceModel, truth: TruthOptics | None = None
    ) -> SimInstruments:
        """The simulated instruments on a sim clock (the lab's clock), reading ``model``
        (ideal twin) or ``truth`` (realistic twin)."""
        sim_clock = SimClock(self.time_scale)
        self.clock = sim_clock
        self.sims = build_sim_instruments(self.config, model, sim_clock, truth)
        self.place_specimen = self._place_specimen
        return self.sims

    def _wire_sims(self, sims: SimInstruments) -> None:
        """``mode = "sim"``: the lab's instruments are the simulated ones, in process."""
        self._goniometer = self._two_arms(sims.lamp, sims.detector)
        self._spectro = sims.spectro
        self._glossmeter = sims.glossmeter

    async def _serve_sims(self, sims: SimInstruments) -> None:
        """``start_sim_servers``: serve the simulated instruments on the config's
        endpoints (Modbus, ptys), for the real drivers to reach."""
        server = build_sim_server(self.config, sims)
        try:
            await server.start()
        except OSError as exc:
            raise UserError(f"cannot start the simulated lab: {exc}", exit_code=1) from None
        self.server = server

    async def prepare_sample(self, spec: str) -> None:
        """Realistic twin: build the truth of sample ``spec`` (worker thread, cached), so
        that :meth:`put_sample` can put it under the instruments at once. No-op for the
        ideal twin and a real lab."""
        if self.sims is None or self.sims.truth is None or not spec or spec in self._truths:
            return
        self._truths[spec] = await asyncio.to_thread(sample_truth, self.config, spec)

    def put_sample(self, model: ReflectanceModel, spec: str = "") -> None:
        """Simulated lab: the spectro and the glossmeter measure the sample ``spec``
        (predicted by ``model``) from now on, as if it had been put under the instruments
        (``place_specimen("sample")`` puts it back after a reference). The realistic twin
        measures that sample's truth (built by :meth:`prepare_sample`, or here, blocking,
        if it was not), the ideal one reads ``model``. A real lab measures whatever lies
        there."""
        if self.sims is None:
            return
        self._sample_under = model
        specimen: Any = model
        if self.sims.truth is not None:
            spec = spec or self.config.sample.map
            truth = self._truths.get(spec)
            if truth is None:
                truth = self._truths[spec] = sample_truth(self.config, spec)
            if self.sims.truth is not truth:
                self.sims.truth.save_cache()
            self.sims.truth = truth
            specimen = truth
        if self.sims.spectro.model is not specimen:
            self.sims.spectro.model = specimen
        if self.sims.glossmeter.model is not specimen:
            self.sims.glossmeter.model = specimen  # forgets the gloss cached for the old one

    async def _place_specimen(self, which: str) -> None:
        """Simulated lab: put the reference mirror (``"mirror"``), the ISO 2813 black-glass
        standard (``"standard"``, n = 1.567, flat) or the sample under the instruments.
        The references lie on the reference seat (no tilt); the sample has this session's
        tilt. The ideal twin reads :class:`sim.instruments.MirrorModel` or the sample model; the
        realistic one a protected-aluminium mirror, the black glass or the sample's truth.
        Set as ``lab.place_specimen`` only when the lab is simulated."""
        if self.sims is None:
            raise RuntimeError("place_specimen needs the simulated lab")
        realistic = self.sims.truth is not None
        # references sit on the reference seat (no tilt); the sample has this session's
        self.sims.spectro.sample_tilt_deg = (
            self.sims.session["sample_tilt_deg"] if which == "sample" else 0.0
        )
        if which == "mirror":
            self.sims.spectro.model = FlatSpecimen() if realistic else MirrorModel()
        elif which == "standard":
            self.sims.spectro.model = FlatSpecimen(n=1.567, name="black glass")
        elif which == "sample":
            sample: Any = self.sims.truth if realistic else (self._sample_under or self.model)
            self.sims.spectro.model = sample
        else:
            raise ValueError(f"specimen must be 'mirror', 'standard' or 'sample', got {which!r}")

    # ------------------------------------------------------------------ real drivers
    def _wire_drivers(self) -> None:
        """``mode = "drivers"``: the drivers of :mod:`drivers` to the configured endpoints
        (or to the simulated lab this lab serves there)."""
        from drivers.glossmeter import open_glossmeter
        from drivers.stil import StilSpectro

        cfg = self.config
        g = cfg.goniometer
        self._goniometer = self._two_arms(
            self._axis_driver("lamp", g.lamp), self._axis_driver("detector", g.detector)
        )
        self._spectro = StilSpectro(
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

    def _axis_driver(self, name: str, ax: AxisConfig) -> ModbusStepperAxis:
        """The Modbus stepper driver of one arm."""
        from drivers.modbus_stepper import ModbusStepperAxis

        port, serial_port = self._served_at(ax)
        return ModbusStepperAxis(
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
                    *(_socket_url(ax.serial_port) or ()),
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
        if self.sims is not None and self.sims.truth is not None:
            await asyncio.to_thread(self.sims.truth.save_cache)
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
