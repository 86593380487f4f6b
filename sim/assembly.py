"""The simulated lab assembled from a lab config: the twin builds itself here.

:func:`build_sim_instruments` makes the simulated arms, spectro and glossmeter of a config
(``[sim]``, ``[sim.faults]``, ``[sim.twin]``, seeded); :func:`build_sim_server` puts them on
the endpoints the config's drivers use (:mod:`sim.wire`); :class:`SimLab` holds one
simulated lab while it runs and swaps the specimen under its instruments (the sample's
truth, the reference mirror, the black-glass standard). :mod:`goniolab.lab_wiring` only chooses
between this and the real drivers; ``goniolab sim serve`` serves it.

The twin serves on the wire the protocols it registers here in the protocol tables of
:mod:`drivers.protocols` (:meth:`~drivers.protocols.ProtocolTable.register_simulator`):
Modbus steppers, the STIL spectro and the ZGM1120 glossmeter. A config asking the wire twin
for another protocol is refused, naming the key.

The config is read by its fields only (``LabConfig`` is imported for the type checker):
the twin knows physics and bytes, not the application (tests/test_layers.py). Errors name
the config file and key (:class:`goniolab.errors.ConfigError`).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.base import ProfileError
from drivers.protocols import GLOSSMETERS, SPECTROS, STEPPERS, ProtocolTable
from drivers.timing import SimClock
from goniolab.errors import ConfigError, UserError
from goniolab.optics.models import ReflectanceModel
from sim.faults import FaultInjector, FaultSpec
from sim.instruments import (
    GlossDrift,
    SimAxis,
    SimGlossmeter,
    SimSpectro,
    SpectroChain,
)
from sim.motion import SimMotor
from sim.truth import FlatSpecimen, TruthOptics, TwinSettings, table_code_key, truth_for
from sim.twin_cache import (
    FOREIGN_MAX_AGE_S,
    MAX_CACHE_BYTES,
    CacheEntry,
    CacheInfo,
    clear,
    scan,
)
from sim.twin_cache import prune as prune_cache
from sim.wire import ModbusAxisServer, SimLabServer, StilPtyDevice, WireAxis, ZgmPtyDevice

if TYPE_CHECKING:  # the type only: sim never imports the application (tests/test_layers.py)
    from drivers.profiles import StepperProfile, StilProfile, ZgmProfile
    from goniolab.config import AxisConfig, GlossmeterConfig, LabConfig, SpectroConfig

__all__ = [
    "TWIN_CACHE_FOREIGN_MAX_AGE_S",
    "TWIN_CACHE_MAX_BYTES",
    "SimInstruments",
    "SimLab",
    "build_sim_instruments",
    "build_sim_server",
    "draw_session",
    "sample_truth",
    "socket_url",
    "twin_cache",
    "twin_cache_dir",
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


def twin_cache_dir() -> Path:
    """Where the twin keeps its response tables (:mod:`sim.twin_cache`): ``twin`` in the
    user cache directory (``platformdirs.user_cache_dir("goniolab")``: on Linux
    ``$XDG_CACHE_HOME/goniolab/twin``, by default ``~/.cache/goniolab/twin``)."""
    import platformdirs

    return Path(platformdirs.user_cache_dir("goniolab")) / "twin"


#: What the twin prunes its cache to after each write: at most this many bytes, and no file
#: of another code version unused for longer than this many seconds (:mod:`sim.twin_cache`).
TWIN_CACHE_MAX_BYTES = MAX_CACHE_BYTES
TWIN_CACHE_FOREIGN_MAX_AGE_S = FOREIGN_MAX_AGE_S


def twin_cache(
    *,
    clear_all: bool = False,
    prune: bool = False,
    max_bytes: int = MAX_CACHE_BYTES,
    foreign_max_age_s: float = FOREIGN_MAX_AGE_S,
) -> tuple[CacheInfo, list[CacheEntry], str]:
    """The twin's disk cache (``goniolab sim cache``): emptied with ``clear_all``, pruned
    with ``prune`` (:func:`sim.twin_cache.prune`, with ``max_bytes`` and
    ``foreign_max_age_s``), then as it is; with the files removed and the running table
    code's key (:func:`sim.truth.table_code_key`)."""
    d, code = twin_cache_dir(), table_code_key()
    removed: list[CacheEntry] = []
    if clear_all:
        removed = clear(d)
    elif prune:
        removed = prune_cache(
            d, code_key=code, max_bytes=max_bytes, foreign_max_age_s=foreign_max_age_s
        )
    return scan(d), removed, code


def twin_settings(cfg: LabConfig) -> TwinSettings:
    """The truth's settings from ``[sim.twin]`` (disk cache: :func:`twin_cache_dir`)."""
    t = cfg.sim.twin
    cache_dir = None
    if t.cache:
        cache_dir = str(twin_cache_dir())
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
        from goniolab.surfaces.synthetic import sample_info

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

    spec = spec or cfg.sample_map()
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
            s_weight=t.s_weight,
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


def socket_url(url: str) -> tuple[str, int] | None:
    """``(host, port)`` of a pyserial ``socket://host:port`` URL, else ``None``."""
    if not url.startswith("socket://"):
        return None
    host, sep, port = url[len("socket://") :].rpartition(":")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        return None
    return host, int(port)


# --------------------------------------------------------------------------- on the wire
def _modbus_unit(sim_axis: SimAxis, profile: StepperProfile, ax: AxisConfig) -> WireAxis:
    """One arm as a unit of a simulated Modbus controller (:mod:`sim.wire.modbus`)."""
    return WireAxis(sim_axis, profile, ax.steps_per_deg * ax.gear_ratio, ax.unit_id)


def _stil_pty(spectro: SimSpectro, profile: StilProfile, sc: SpectroConfig) -> StilPtyDevice:
    """The spectro behind a pty speaking its ``stil-spectro`` profile."""
    return StilPtyDevice(spectro, profile, sc.port)


def _zgm_pty(gloss: SimGlossmeter, profile: ZgmProfile, gc: GlossmeterConfig) -> ZgmPtyDevice:
    """The glossmeter behind a pty speaking the ZGM1120 protocol."""
    return ZgmPtyDevice(gloss, profile, gc.port, serial_number=gc.serial_number)


STEPPERS.register_simulator("modbus", _modbus_unit)
SPECTROS.register_simulator("stil", _stil_pty)
GLOSSMETERS.register_simulator("zgm1120", _zgm_pty)


def _served(
    src: str, key: str, table: ProtocolTable, protocol: str, instrument: Any, section: Any
) -> Any:
    """The wire device of ``instrument`` for ``protocol`` (config section ``key``).

    Raises
    ------
    ConfigError
        The twin does not serve the protocol, or its profile cannot be loaded or served.
    """
    simulator = table.simulator(protocol)
    if simulator is None:
        served = ", ".join(f'"{n}"' for n in table.simulated())
        raise ConfigError(
            src, f"{key}.protocol", f"the simulated lab serves the {served} protocol only"
        )
    try:
        return simulator(instrument, table[protocol].load_profile(section.profile), section)
    except (ProfileError, ValueError) as exc:
        raise ConfigError(src, f"{key}.profile", str(exc)) from None


def build_sim_server(cfg: LabConfig, sims: SimInstruments) -> SimLabServer:
    """The simulated lab on the endpoints the config's drivers will use.

    Arms on ``transport = "tcp"`` are served by a Modbus TCP server on ``host:port``; arms
    on ``transport = "rtu"`` by a Modbus RTU server framed over TCP, which needs
    ``serial_port = "socket://host:port"``. Arms sharing an endpoint share one server
    (one unit id each). Port 0 lets the kernel pick a free port (see ``goniolab.lab_wiring.Lab``).
    Each device is served by the simulator its protocol registered
    (:mod:`drivers.protocols`).

    Raises
    ------
    ConfigError
        An RTU arm whose ``serial_port`` is not ``socket://host:port``, a protocol the
        twin does not serve, or a profile that cannot be loaded or served.
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
            where = socket_url(ax.serial_port)
            if where is None:
                raise ConfigError(
                    src,
                    f"goniometer.{name}.serial_port",
                    f"the simulated lab serves Modbus RTU over a TCP socket only: use "
                    f'serial_port = "socket://127.0.0.1:PORT" (got {ax.serial_port!r})',
                )
            key = ("rtu", *where)
        wire = _served(src, f"goniometer.{name}", STEPPERS, ax.protocol, sim_axis, ax)
        servers.setdefault(key, []).append(wire)
    modbus = [
        ModbusAxisServer(w, host=h, port=p, transport="tcp" if t == "tcp" else "rtu")
        for (t, h, p), w in servers.items()
    ]
    gm = cfg.glossmeter
    gloss = _served(src, "glossmeter", GLOSSMETERS, gm.protocol, sims.glossmeter, gm)
    sc = cfg.spectro
    spectro = _served(src, "spectro", SPECTROS, sc.protocol, sims.spectro, sc)
    return SimLabServer(modbus, spectro, gloss)


# --------------------------------------------------------------------------- the running twin
class SimLab:
    """One simulated lab while it runs: its instruments and the specimen under them.

    Parameters
    ----------
    config
        The lab config.
    model
        The prediction's model of ``[sample]`` (what the ideal twin measures).
    clock
        The lab's sim clock.
    truth
        The hidden truth of ``[sample]`` (realistic twin; built with :func:`sample_truth`
        when not given).
    """

    def __init__(
        self,
        config: LabConfig,
        model: ReflectanceModel,
        clock: SimClock,
        truth: TruthOptics | None = None,
    ) -> None:
        self.config = config
        self.model = model
        self.instruments = build_sim_instruments(config, model, clock, truth)
        self._truths: dict[str, TruthOptics] = {}
        if self.instruments.truth is not None:
            self._truths[config.sample.map] = self.instruments.truth
        self._sample_under: ReflectanceModel | None = None

    def server(self) -> SimLabServer:
        """The instruments on the config's endpoints (not started; :func:`build_sim_server`)."""
        return build_sim_server(self.config, self.instruments)

    async def prepare_sample(self, spec: str) -> None:
        """Realistic twin: build the truth of sample ``spec`` (worker thread, cached), so
        that :meth:`put_sample` can put it under the instruments at once. No-op for the
        ideal twin."""
        if self.instruments.truth is None or not spec or spec in self._truths:
            return
        self._truths[spec] = await asyncio.to_thread(sample_truth, self.config, spec)

    def put_sample(self, model: ReflectanceModel, spec: str = "") -> None:
        """The spectro and the glossmeter measure the sample ``spec`` (predicted by
        ``model``) from now on, as if it had been put under the instruments
        (``place_specimen("sample")`` puts it back after a reference). The realistic twin
        measures that sample's truth (built by :meth:`prepare_sample`, or here, blocking,
        if it was not), the ideal one reads ``model``."""
        self._sample_under = model
        specimen: Any = model
        if self.instruments.truth is not None:
            spec = spec or self.config.sample.map
            truth = self._truths.get(spec)
            if truth is None:
                truth = self._truths[spec] = sample_truth(self.config, spec)
            if self.instruments.truth is not truth:
                self.instruments.truth.save_cache()
            self.instruments.truth = truth
            specimen = truth
        if self.instruments.spectro.model is not specimen:
            self.instruments.spectro.model = specimen
        if self.instruments.glossmeter.model is not specimen:
            self.instruments.glossmeter.model = specimen  # forgets the gloss cached for the old one

    async def place_specimen(self, which: str) -> None:
        """Put the reference mirror (``"mirror"``), the ISO 2813 black-glass
        standard (``"standard"``, n = 1.567, flat) or the sample under the instruments.
        The references lie on the reference seat (no tilt); the sample has this session's
        tilt. Both twins read a protected-aluminium mirror (88-92 %, as certified in
        ``configs/standards.toml``) or the black glass; the ideal twin the sample model, the
        realistic one the sample's truth.
        ``goniolab.lab_wiring.Lab`` hands it on as ``lab.place_specimen``."""
        realistic = self.instruments.truth is not None
        # references sit on the reference seat (no tilt); the sample has this session's
        self.instruments.spectro.sample_tilt_deg = (
            self.instruments.session["sample_tilt_deg"] if which == "sample" else 0.0
        )
        if which == "mirror":
            # both twins: the certified protected-Al mirror of configs/standards.toml (88-92 %)
            self.instruments.spectro.model = FlatSpecimen()
        elif which == "standard":
            self.instruments.spectro.model = FlatSpecimen(n=1.567, name="black glass")
        elif which == "sample":
            sample: Any = (
                self.instruments.truth if realistic else (self._sample_under or self.model)
            )
            self.instruments.spectro.model = sample
        else:
            raise ValueError(f"specimen must be 'mirror', 'standard' or 'sample', got {which!r}")

    def save_truth_cache(self) -> None:
        """Keep what the realistic twin computed for its sample (blocking)."""
        if self.instruments.truth is not None:
            self.instruments.truth.save_cache()
