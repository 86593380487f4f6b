"""The simulated lab in-process: arms, spectro-colorimeter and glossmeter.

Each class implements the matching :mod:`drivers.base` Protocol, so the scan runner, the
CLI and the contract tests use them exactly like the real drivers. The simulated
goniometer is the project's own ``drivers.goniometer.TwoArmGoniometer(SimAxis, SimAxis)``
(built by :mod:`goniolab.lab`, since :mod:`sim` imports only ``drivers.base``,
``drivers.profiles`` and ``goniolab.optics``): one interlock for real and simulated arms. Readings come from
the physics: a :class:`goniolab.optics.models.ReflectanceModel` (normally the
``FacetModel`` of the sample's height map) evaluated at the geometry the arms *really*
have -- including the sample tilt and the arms' zero offsets that Wittmann et al. (2021,
sec. 5.2-5.3) name as the cause of the scatter on glossy samples -- through the
configured source and detector cones. Model evaluation is CPU work and runs in a thread
(:func:`asyncio.to_thread`) so the event loop never stalls.

Two twins (config ``[sim.twin] mode``, :mod:`goniolab.lab`):

* **ideal**: the spectro and glossmeter read the prediction's own model, with a relative
  noise ``noise_pct``; nothing else (tests of the plumbing compare exactly).
* **realistic**: they read the sample's hidden truth (:mod:`sim.truth`) through a
  :class:`SpectroChain` (lamp spectrum x detector response, dark current and shot noise
  growing with the exposure, read noise, a 16-bit full scale that saturates, a stray-light
  floor, lamp flicker) and a glossmeter with :class:`GlossDrift` (calibration drift and
  warm-up temperature); the arms have backlash (:class:`SimAxis`), and zero offsets and a
  sample tilt drawn per session (:func:`goniolab.lab.build_sim_instruments`).

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 2.3 (instrument),
   sec. 5.2-5.3 (misalignment).
.. [2] ISO 2813:2014 / ASTM D523: specular gloss at 20/60/85 deg.
.. [3] Zehntner ZGM1120 Technical Manual rev. 3.0 (2021), pp. 16-28: 0.1 GU resolution,
   -2 = overflow.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.base import (
    GLOSS_ANGLES_DEG,
    AxisStatus,
    DeviceFault,
    DeviceTimeout,
    Disconnected,
    GlossReading,
    LimitError,
    SpectroReading,
    StallError,
)
from drivers.timing import Clock
from goniolab.optics.apertures import Aperture, Cone, cap_overlap_fraction
from goniolab.optics.models import ReflectanceModel
from sim.faults import Fault, FaultInjector
from sim.motion import MotorFault, SimMotor
from sim.truth import SPECTRUM_WAVELENGTHS_NM, luminance_weights

__all__ = [
    "GLOSS_OVERFLOW_GU",
    "SPECTRUM_WAVELENGTHS_NM",
    "GlossDrift",
    "LuminanceModel",
    "MirrorModel",
    "SimAxis",
    "SimGlossmeter",
    "SimSpectro",
    "SpectroChain",
    "detector_response",
    "effective_angles",
    "lamp_spectrum",
    "spectrum_for_luminance",
]

#: Readings above this are reported as overflow (ZGM1120 range 0..2000 GU).
GLOSS_OVERFLOW_GU = 2000.0

#: Slope of the simulated spectral shape per nm around 580 nm (a faint warm tint).
_SPECTRUM_TILT_PER_NM = 1.5e-4


class LuminanceModel(Protocol):
    """What the simulated spectro needs of a model: the goniometer reading."""

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = ...,
        detector: Aperture = ...,
    ) -> NDArray[np.float64]:
        """100 x fraction of the source flux reaching the detector aperture."""
        ...


class MirrorModel:
    """The goniometer's reference mirror: 100 % at the specular geometry.

    An ideal mirror images the source cone (half angle a_s) into an equal cone around
    the specular direction; the reading is 100 x the fraction of that image the detector
    cone (half angle a_d) collects -- the overlap of two spherical caps whose centres are
    ``|theta_r - theta_i|`` apart (:func:`goniolab.optics.facet.cap_overlap_fraction`).
    Readings are relative to this mirror (Wittmann et al. 2021, sec. 2.3).
    """

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: ArrayLike,
        *,
        source: Aperture = Cone(6.0),  # noqa: B008 -- frozen dataclass, safe default
        detector: Aperture = Cone(6.0),  # noqa: B008
    ) -> NDArray[np.float64]:
        """Mirror reading in % for circular source and detector cones.

        Raises
        ------
        TypeError
            For rectangular apertures (the glossmeter has its own black-glass standard).
        """
        if not (isinstance(source, Cone) and isinstance(detector, Cone)):
            raise TypeError("the goniometer mirror reference is defined for Cone apertures")
        gamma = np.radians(np.abs(np.asarray(theta_r_deg, dtype=np.float64) - theta_i_deg))
        frac = cap_overlap_fraction(
            gamma, math.radians(source.half_angle_deg), math.radians(detector.half_angle_deg)
        )
        return np.asarray(100.0 * frac, dtype=np.float64)


def effective_angles(
    lamp_deg: float,
    detector_deg: float,
    *,
    sample_tilt_deg: float = 0.0,
    lamp_zero_offset_deg: float = 0.0,
    detector_zero_offset_deg: float = 0.0,
) -> tuple[float, float]:
    """Incidence and signed reflection angle the sample really sees.

    The arms stand at ``lamp_deg`` (lamp at -theta_i, lamp side) and ``detector_deg``
    (signed theta_r, > 0 specular side) in their own frames. An arm's zero offset shifts
    its true angle: ``lamp_true = lamp_deg + lamp_zero_offset_deg``,
    ``det_true = detector_deg + detector_zero_offset_deg``. A sample tilted by tau in the
    plane of incidence, towards the specular side, turns its normal to +tau, so the
    angles measured from that normal are (Wittmann et al. 2021, sec. 5.2-5.3)::

        theta_i_eff = lamp_true + tau
        theta_r_eff = det_true - tau

    and the specular peak moves to ``theta_r = theta_i + 2 tau`` in arm coordinates.

    Returns
    -------
    tuple of float
        ``(theta_i_eff_deg, theta_r_eff_deg)``.
    """
    ti = lamp_deg + lamp_zero_offset_deg + sample_tilt_deg
    tr = detector_deg + detector_zero_offset_deg - sample_tilt_deg
    return ti, tr


def _y_weights() -> NDArray[np.float64]:
    """Normalised luminance weights ybar(l) S_D65(l) (CIE 1964 10 deg observer, D65, as
    docs/PHYSICS.md, "Colour and the paint layer" prescribes), see
    :func:`sim.truth.luminance_weights`."""
    return luminance_weights()


def spectrum_for_luminance(luminance_pct: float) -> tuple[float, ...]:
    """A plausible near-neutral reflectance spectrum whose Y equals ``luminance_pct``.

    The shape is a clear coating over a neutral substrate with a faint warm tint,
    ``s(l) = 1 + k (l - 580 nm)`` with ``k = 1.5e-4 /nm`` (about +/-3 % over the visible),
    scaled so that ``Y = sum(R ybar S_D65) / sum(ybar S_D65)`` (CIE 15:2004 eq. 7.1 with
    the 10 deg observer and D65) equals ``luminance_pct`` exactly.

    Parameters
    ----------
    luminance_pct
        Target relative luminance Y in % of the mirror reference.

    Returns
    -------
    tuple of float
        Reflectance in % at :data:`SPECTRUM_WAVELENGTHS_NM`.
    """
    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    shape = 1.0 + _SPECTRUM_TILT_PER_NM * (wl - 580.0)
    y_shape = float(np.dot(_y_weights(), shape))
    return tuple(float(v) for v in luminance_pct * shape / y_shape)


def _planck(wl_nm: NDArray[np.float64], temp_k: float) -> NDArray[np.float64]:
    """Planck spectral radiance (arbitrary units) at ``wl_nm``."""
    c2 = 1.4388e7  # hc/k in nm K
    return np.asarray(wl_nm**-5.0 / np.expm1(c2 / (wl_nm * temp_k)))


def lamp_spectrum(kind: str) -> NDArray[np.float64]:
    """Relative spectral power of the goniometer's lamp on :data:`SPECTRUM_WAVELENGTHS_NM`
    (max 1): a 3000 K halogen-tungsten lamp (Wittmann et al. 2021, sec. 2.3: 200 W
    halogen; Planck's law) or a phosphor-converted white LED (blue 450 nm die plus a broad
    yellow phosphor band)."""
    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    if kind == "halogen":
        s = _planck(wl, 3000.0)
    elif kind == "led":
        s = np.exp(-0.5 * ((wl - 450.0) / 10.0) ** 2) + 0.75 * np.exp(
            -0.5 * ((wl - 565.0) / 55.0) ** 2
        )
    else:
        raise ValueError(f"lamp must be 'halogen' or 'led', got {kind!r}")
    return np.asarray(s / s.max())


def detector_response() -> NDArray[np.float64]:
    """Relative spectral response of the spectro's silicon array on
    :data:`SPECTRUM_WAVELENGTHS_NM` (max 1): a front-illuminated CCD, weak in the blue
    (about 25 % at 400 nm), peaking near 650 nm."""
    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    r = 0.15 + 0.85 * np.exp(-0.5 * ((wl - 650.0) / 170.0) ** 2)
    return np.asarray(r / r.max())


@dataclass(frozen=True)
class SpectroChain:
    """The spectro's light path and detector, from reflected flux to reported values.

    For a specimen reflecting the fraction ``f(l)`` of the lamp's flux into the detector,
    channel ``l`` collects ``(100 f(l) + stray_pct + stray_rel <100 f>) x g(l) x t / 10 ms``
    counts (``<.>`` the mean over channels: stray light proportional to the flux), where
    ``g(l) = full_well x lamp(l) resp(l) / full_scale_pct`` (a reading of
    ``full_scale_pct`` % fills the strongest channel at 10 ms), plus dark current
    ``dark_counts_per_s x t``; shot noise is Poisson on the electrons
    (``electrons_per_count``), plus Gaussian read noise; the lamp flickers by
    ``flicker_pct`` (1 sigma, common to all channels). The raw counts (with a bias) clip
    at the 16-bit full well. The instrument subtracts its dark reference (bias + mean dark
    at that exposure) and divides by its calibration ``g(l) t / 10 ms``: the reported
    values are in % of a perfect mirror, exact on average below saturation, noisy at low
    counts, low once a channel saturates.
    """

    lamp: str = "halogen"
    full_scale_pct: float = 5.0
    full_well_counts: float = 65535.0
    bias_counts: float = 500.0
    electrons_per_count: float = 2.0
    read_noise_counts: float = 5.0
    dark_counts_per_s: float = 300.0
    stray_pct: float = 0.002
    flicker_pct: float = 0.3
    #: spectral stray light: each channel also sees this fraction of the mean light entering
    #: the spectrometer (a grating's scatter, ASTM E387 "stray radiant power ratio"), so a
    #: bright specimen lifts its own dark channels (a red's blue end) in proportion
    stray_rel: float = 1e-3
    #: share of the detector's response that goes to s-polarised light (0.5: insensitive).
    #: A grating spectrometer favours one polarisation by a few %; it matters where the
    #: specimen polarises, e.g. the black glass at 60 deg (R_s 18 %, R_p 0.4 %)
    s_weight: float = 0.5

    def __post_init__(self) -> None:
        lamp_spectrum(self.lamp)  # validate

    def gain(self) -> NDArray[np.float64]:
        """Counts per % of mirror at 10 ms, per channel."""
        resp = lamp_spectrum(self.lamp) * detector_response()
        resp = resp / resp.max()
        return np.asarray((self.full_well_counts - self.bias_counts) * resp / self.full_scale_pct)

    def read(
        self, fraction: NDArray[np.float64], exposure_us: int, rng: np.random.Generator
    ) -> tuple[NDArray[np.float64], float]:
        """One exposure: (values in % of a perfect mirror, peak fraction of full scale)."""
        t_rel = exposure_us / 10_000.0
        g = self.gain() * t_rel
        flicker = 1.0 + 0.01 * self.flicker_pct * float(rng.standard_normal())
        f_pct = 100.0 * np.asarray(fraction)
        stray = self.stray_pct + self.stray_rel * float(np.mean(f_pct))
        signal = np.clip((f_pct + stray) * flicker, 0.0, None) * g
        dark = self.dark_counts_per_s * exposure_us * 1e-6
        electrons = (signal + dark) * self.electrons_per_count
        counts = rng.poisson(electrons) / self.electrons_per_count
        raw = self.bias_counts + counts + self.read_noise_counts * rng.standard_normal(counts.shape)
        raw = np.clip(np.round(raw), 0.0, self.full_well_counts)
        peak = float(raw.max() / self.full_well_counts)
        values = (raw - self.bias_counts - dark) / g
        return np.asarray(values), peak


@dataclass(frozen=True)
class GlossDrift:
    """The glossmeter's calibration drift and temperature (ZGM1120-like).

    The instrument's temperature warms from ``ambient_c`` by ``warmup_c`` with time
    constant ``warmup_tau_s`` after power-on; its gain drifts by ``drift_pct_per_h`` per
    hour since the last calibration and by ``temp_coeff_pct_per_c`` per degree from the
    calibration temperature; each value gets ``noise_gu`` (1 sigma) before rounding to
    0.1 GU. ``calibrate`` (on the black standard) resets the time and temperature terms.
    """

    drift_pct_per_h: float = 0.5
    temp_coeff_pct_per_c: float = 0.05
    ambient_c: float = 23.0
    warmup_c: float = 4.0
    warmup_tau_s: float = 900.0
    noise_gu: float = 0.1

    def temperature_c(self, t_s: float) -> float:
        """Instrument temperature ``t_s`` seconds after power-on."""
        return self.ambient_c + self.warmup_c * (1.0 - math.exp(-max(t_s, 0.0) / self.warmup_tau_s))

    def gain(self, t_s: float, calibrated_at_s: float) -> float:
        """Reading / truth at time ``t_s`` for a calibration at ``calibrated_at_s``."""
        hours = max(t_s - calibrated_at_s, 0.0) / 3600.0
        dt_c = self.temperature_c(t_s) - self.temperature_c(calibrated_at_s)
        return 1.0 + 0.01 * (self.drift_pct_per_h * hours + self.temp_coeff_pct_per_c * dt_c)


class _SimLink:
    """The connection state and fault injection every simulated instrument shares.

    Operations on a closed link raise :class:`drivers.base.Disconnected`; each operation
    then passes the fault injector (timeouts, garbled replies, disconnects). A recoverable
    drop (:attr:`sim.faults.Fault.DROP`) closes the link; :meth:`connect` succeeds again
    once the device is back (``recover_after_s`` of lab clock later).
    """

    name: str
    faults: FaultInjector
    clock: Clock
    _connected: bool = False

    async def connect(self) -> None:
        """Open the (simulated) link.

        Raises
        ------
        drivers.base.Disconnected
            The device dropped off the line and is not back yet.
        """
        now = self.clock.now()
        if self.faults.is_down(now):
            raise Disconnected(
                f"no answer: the device dropped off the line and is back in "
                f"{self.faults.down_until_s - now:.3g} s",
                device=self.name,
            )
        self._connected = True

    async def close(self) -> None:
        """Close the link."""
        self._connected = False

    def _op(self, operation: str) -> None:
        if not self._connected:
            raise Disconnected(f"not connected ({operation})", device=self.name)
        fault = self.faults.decide()
        if fault is Fault.DROP:
            self._connected = False
            self.faults.drop(self.clock.now())
            raise Disconnected(
                f"simulated link drop during {operation}: reconnect after "
                f"{self.faults.spec.recover_after_s:g} s",
                device=self.name,
            )
        if fault is Fault.DISCONNECT:
            raise Disconnected(
                f"simulated disconnect after {self.faults.spec.disconnect_after} operations "
                f"({operation})",
                device=self.name,
            )
        error = self.faults.error_for(fault, operation)
        if error is not None:
            raise error


class SimAxis(_SimLink):
    """A simulated goniometer arm (implements :class:`drivers.base.Axis`).

    Parameters
    ----------
    name
        Arm name (``"lamp"``, ``"detector"``), used in every error.
    motor
        The motion model; its soft limits are this axis' ``limits_deg``.
    clock
        The lab clock (:class:`sim.clock.SimClock` or :class:`sim.clock.RealClock`).
    stall_tolerance_deg
        Largest allowed |command - feedback| once a move has ended; more is a stall.
    faults
        Fault injector for this arm (timeouts, disconnects); ``None`` = no faults.
    backlash_deg
        Play in the gears between the motor (whose encoder the controller reports) and the
        arm: after a move in the + direction the arm stands ``backlash_deg / 2`` behind
        the motor, after a move in the - direction as far ahead (``SimMotor.last_direction``,
        also for moves commanded over the wire). Invisible to the feedback; only the
        optics see it.
    """

    def __init__(
        self,
        name: str,
        motor: SimMotor,
        clock: Clock,
        *,
        stall_tolerance_deg: float = 0.5,
        faults: FaultInjector | None = None,
        backlash_deg: float = 0.0,
    ) -> None:
        self.name = name
        self.motor = motor
        self.clock = clock
        self.limits_deg: tuple[float, float] = motor.soft_limits_deg
        self.stall_tolerance_deg = stall_tolerance_deg
        self.faults = faults or FaultInjector(name)
        self.backlash_deg = float(backlash_deg)
        self._connected = False
        self._tracker: asyncio.Task[None] | None = None

    # -------------------------------------------------------------- connection
    async def close(self) -> None:
        """Close the link; a running move continues (as on a real controller)."""
        await super().close()
        if self._tracker is not None and not self._tracker.done():
            self._tracker.cancel()
        self._tracker = None

    # -------------------------------------------------------------- time keeping
    def ensure_tracker(self) -> None:
        """Keep virtual time flowing until the current move ends (needed at scale 0
        when nobody waits in-process, e.g. a wire server polled over the network)."""
        if self._tracker is None or self._tracker.done():
            self._tracker = asyncio.get_running_loop().create_task(
                self._track(), name=f"SimAxis-{self.name}-tracker"
            )

    async def _track(self) -> None:
        while True:
            now = self.clock.now()
            nxt = self.motor.next_event_s(now)
            if nxt is None:
                return
            await self.clock.sleep(max(nxt - now, 1e-9))

    # -------------------------------------------------------------- Axis protocol
    async def status(self) -> AxisStatus:
        """Controller state at the current clock time."""
        self._op("status")
        return self.snapshot()

    def snapshot(self) -> AxisStatus:
        """Status without counting an operation (used by the wire servers)."""
        now = self.clock.now()
        m = self.motor
        alarm = m.alarm_code(now)
        moving = m.is_moving(now)
        pos = m.position_deg(now)
        cmd = m.command_deg(now)
        return AxisStatus(
            position_deg=pos,
            command_deg=cmd,
            moving=moving,
            in_position=(not moving)
            and alarm is None
            and abs(cmd - pos) <= self.stall_tolerance_deg,
            homed=m.homed,
            alarm_code=alarm,
            ready=alarm is None and not moving,
        )

    async def position_deg(self) -> float:
        """Feedback position in degrees."""
        self._op("position")
        return self.motor.position_deg(self.clock.now())

    def actual_deg(self) -> float:
        """Where the arm truly is, in degrees from its mechanical zero (physics input),
        backlash included."""
        motor = self.motor.physical_deg(self.clock.now()) - self.motor.home_switch_deg
        return motor - 0.5 * self.backlash_deg * self.motor.last_direction

    async def move_to(self, target_deg: float) -> None:
        """Start an absolute move; returns once accepted.

        Raises
        ------
        LimitError
            ``target_deg`` outside ``limits_deg`` (checked before anything moves).
        DeviceFault
            An alarm is active.
        """
        self._op("move_to")
        lo, hi = self.limits_deg
        if not lo <= target_deg <= hi:
            raise LimitError(
                f"target {target_deg:g} deg outside limits [{lo:g}, {hi:g}] deg", device=self.name
            )
        try:
            self.motor.start_move(target_deg, self.clock.now())
        except MotorFault as exc:
            raise DeviceFault(str(exc), device=self.name, code=exc.code) from exc
        self.ensure_tracker()

    async def wait_in_position(self, timeout_s: float) -> float:
        """Wait (on the lab clock) until the move ends; return the feedback position.

        Raises
        ------
        DeviceFault
            An alarm occurred (e.g. mid-move or at a limit switch).
        StallError
            The move ended with feedback and command more than ``stall_tolerance_deg``
            apart.
        DeviceTimeout
            Still moving after ``timeout_s`` (clock seconds).
        """
        self._op("wait_in_position")
        deadline = self.clock.now() + timeout_s
        while True:
            now = self.clock.now()
            m = self.motor
            alarm = m.alarm_code(now)
            if alarm is not None:
                raise DeviceFault(
                    f"alarm 0x{alarm:02X} at {m.position_deg(now):.3f} deg",
                    device=self.name,
                    code=alarm,
                )
            nxt = m.next_event_s(now)
            if nxt is None:
                pos, cmd = m.position_deg(now), m.command_deg(now)
                if abs(cmd - pos) > self.stall_tolerance_deg:
                    raise StallError(
                        f"stalled at {pos:.3f} deg, commanded {cmd:.3f} deg "
                        f"(tolerance {self.stall_tolerance_deg:g} deg)",
                        device=self.name,
                    )
                return pos
            remaining = deadline - now
            if remaining <= 0.0:
                raise DeviceTimeout(
                    f"not in position after {timeout_s:g} s (at {m.position_deg(now):.3f} deg, "
                    f"target {m.target_deg():.3f} deg)",
                    device=self.name,
                )
            await self.clock.sleep(max(min(nxt - now, remaining), 1e-9))

    async def home(self, timeout_s: float) -> None:
        """Return to the home switch and zero the encoder there.

        Raises
        ------
        DeviceFault, DeviceTimeout
            As :meth:`wait_in_position`.
        """
        self._op("home")
        try:
            self.motor.start_home(self.clock.now())
        except MotorFault as exc:
            raise DeviceFault(str(exc), device=self.name, code=exc.code) from exc
        self.ensure_tracker()
        await self.wait_in_position(timeout_s)

    async def stop(self) -> None:
        """Quick stop where the arm is."""
        self._op("stop")
        self.motor.stop(self.clock.now())

    async def reset_alarm(self) -> None:
        """Clear the active alarm."""
        self._op("reset_alarm")
        self.motor.reset_alarm(self.clock.now())


class SimSpectro(_SimLink):
    """A simulated STIL Ruby spectro-colorimeter (implements ``Spectrocolorimeter``).

    Parameters
    ----------
    model
        The sample's reflectance model (anything with ``luminance_pct``; swap it for a
        :class:`MirrorModel` to simulate the reference mirror).
    lamp, detector
        The simulated arms; their *actual* positions define the geometry.
    clock
        Lab clock (the exposure takes ``exposure_us`` of its time).
    source_cone_deg, detector_cone_deg
        Full angles of the lamp divergence and the detector opening (Wittmann 2.3: 6, 6).
    noise_pct
        Relative noise (1 sigma, % of the reading).
    rng
        Seeded generator for the noise.
    sample_tilt_deg, lamp_zero_offset_deg, detector_zero_offset_deg
        Misalignments, see :func:`effective_angles`.
    faults
        Fault injector (timeouts, garbled replies, disconnects).
    name
        Device name in errors.
    chain
        The realistic twin's light path and detector (:class:`SpectroChain`); the model
        must then offer ``spectral_fraction`` (:class:`sim.truth.TruthOptics`,
        :class:`sim.truth.FlatSpecimen`). ``None``: the ideal twin (``luminance_pct`` of
        the model with ``noise_pct``).
    """

    #: Ruby exposure range in microseconds (PROTOCOLS.md).
    EXPOSURE_RANGE_US: tuple[int, int] = (500, 250_000)

    def __init__(
        self,
        model: LuminanceModel,
        lamp: SimAxis,
        detector: SimAxis,
        clock: Clock,
        *,
        source_cone_deg: float = 6.0,
        detector_cone_deg: float = 6.0,
        noise_pct: float = 0.0,
        rng: np.random.Generator | None = None,
        sample_tilt_deg: float = 0.0,
        lamp_zero_offset_deg: float = 0.0,
        detector_zero_offset_deg: float = 0.0,
        exposure_us: int = 10_000,
        faults: FaultInjector | None = None,
        name: str = "spectro",
        chain: SpectroChain | None = None,
    ) -> None:
        self.name = name
        self.chain = chain
        self.model = model
        self.lamp = lamp
        self.detector = detector
        self.clock = clock
        self.source = Cone(source_cone_deg)
        self.detector_aperture = Cone(detector_cone_deg)
        self.noise_pct = noise_pct
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self.sample_tilt_deg = sample_tilt_deg
        self.lamp_zero_offset_deg = lamp_zero_offset_deg
        self.detector_zero_offset_deg = detector_zero_offset_deg
        self.exposure_us = exposure_us
        self.faults = faults or FaultInjector(name)
        self._connected = False

    async def identify(self) -> str:
        """Identification string."""
        self._op("identify")
        return "STIL RUBY (goniolab simulator)"

    async def set_exposure_us(self, exposure_us: int) -> None:
        """Set the integration time.

        Raises
        ------
        ValueError
            Outside the Ruby's 500..250000 us.
        """
        self._op("set_exposure_us")
        lo, hi = self.EXPOSURE_RANGE_US
        if not lo <= exposure_us <= hi:
            raise ValueError(f"{self.name}: exposure {exposure_us} us outside [{lo}, {hi}] us")
        self.exposure_us = int(exposure_us)

    def geometry_deg(self) -> tuple[float, float]:
        """The effective (theta_i, theta_r) the sample sees now, see :func:`effective_angles`."""
        return effective_angles(
            self.lamp.actual_deg(),
            self.detector.actual_deg(),
            sample_tilt_deg=self.sample_tilt_deg,
            lamp_zero_offset_deg=self.lamp_zero_offset_deg,
            detector_zero_offset_deg=self.detector_zero_offset_deg,
        )

    def predict_luminance_pct(self, theta_i_deg: float, theta_r_deg: float) -> float:
        """Noise-free reading at an effective geometry (blocking: call from a thread)."""
        value = self.model.luminance_pct(
            theta_i_deg,
            np.asarray([theta_r_deg], dtype=np.float64),
            source=self.source,
            detector=self.detector_aperture,
        )
        return float(np.asarray(value).reshape(-1)[0])

    async def warm_up(self) -> None:
        """Evaluate the model once (in a thread) so the first reading answers promptly.

        The first evaluation of a facet model loads its compiled kernels and builds its
        aperture tables, and the first spectrum imports colour-science; together they can
        take longer than a driver's reply timeout (2 s in the
        shipped configs). The wire servers call this before they accept connections. The
        geometry is the specular one at 45 deg, valid for every model; the noise
        generator is not touched, so seeded readings stay the same.
        """
        await asyncio.to_thread(self._spectral, 45.0, 45.0)
        await asyncio.to_thread(_y_weights)  # imports colour-science (slow) for the spectra

    async def read_luminance_pct(self) -> float:
        """One noisy luminance value at the arms' current actual geometry."""
        return (await self._expose()).luminance_pct

    async def reading(self) -> SpectroReading:
        """One reading (spectrum, luminance, signal level) at the arms' current actual
        geometry, without passing the fault injector (the wire device has its own)."""
        return await self._expose()

    def _spectral(self, theta_i_deg: float, theta_r_deg: float) -> NDArray[np.float64]:
        """Flux fraction per wavelength at an effective geometry (blocking); through a
        polarisation-sensitive detector (``chain.s_weight``) where the specimen gives its s
        and p parts (``spectral_fraction_sp``: the flat references)."""
        by_sp = getattr(self.model, "spectral_fraction_sp", None)
        if self.chain is not None and self.chain.s_weight != 0.5 and by_sp is not None:
            f_s, f_p = by_sp(
                theta_i_deg, theta_r_deg, source=self.source, detector=self.detector_aperture
            )
            w = self.chain.s_weight
            return np.asarray(w * np.asarray(f_s) + (1.0 - w) * np.asarray(f_p))
        spectral = getattr(self.model, "spectral_fraction", None)
        if spectral is not None:
            return np.asarray(
                spectral(
                    theta_i_deg, theta_r_deg, source=self.source, detector=self.detector_aperture
                ),
                dtype=np.float64,
            )
        lum = self.predict_luminance_pct(theta_i_deg, theta_r_deg)
        return np.asarray(spectrum_for_luminance(lum), dtype=np.float64) / 100.0

    async def _expose(self) -> SpectroReading:
        """Expose at the current geometry (sampled at the start of the exposure)."""
        ti, tr = self.geometry_deg()
        exposure = self.exposure_us
        await self.clock.sleep(exposure * 1e-6)
        if self.chain is None:
            clean = await asyncio.to_thread(self.predict_luminance_pct, ti, tr)
            if self.noise_pct:
                clean *= 1.0 + 0.01 * self.noise_pct * float(self._rng.standard_normal())
            lum = max(clean, 0.0)
            return SpectroReading(
                wavelengths_nm=SPECTRUM_WAVELENGTHS_NM,
                values=spectrum_for_luminance(lum),
                luminance_pct=lum,
                exposure_us=exposure,
                timestamp=time.time(),
            )
        fraction = await asyncio.to_thread(self._spectral, ti, tr)
        values, peak = self.chain.read(fraction, exposure, self._rng)
        lum = float(np.dot(_y_weights(), values))
        return SpectroReading(
            wavelengths_nm=SPECTRUM_WAVELENGTHS_NM,
            values=tuple(float(v) for v in values),
            luminance_pct=lum,
            exposure_us=exposure,
            timestamp=time.time(),
            peak_fraction=peak,
        )

    async def measure(self) -> SpectroReading:
        """Expose and return luminance plus a spectrum consistent with it.

        The geometry is sampled at the start of the exposure.
        """
        self._op("measure")
        return await self._expose()


class SimGlossmeter(_SimLink):
    """A simulated ISO 2813 glossmeter (implements ``Glossmeter``), ZGM1120-like.

    Parameters
    ----------
    model
        The sample's reflectance model (``model.gloss`` gives the GU values).
    clock
        Lab clock (measurement time and auto-send interval).
    noise_pct
        Relative noise (1 sigma, % of the reading) before rounding to 0.1 GU.
    rng
        Seeded generator.
    measure_time_s
        Duration of one measurement.
    autosend_interval_s
        Interval of pushed readings in :meth:`readings` (an operator pressing the
        button); 0 disables the stream.
    temperature_c
        Reported instrument temperature (ideal twin; with ``drift`` it follows
        :meth:`GlossDrift.temperature_c`).
    faults
        Fault injector.
    name
        Device name in errors.
    drift
        The realistic twin's calibration drift and warm-up (:class:`GlossDrift`); with it,
        ``noise_pct`` is replaced by ``drift.noise_gu``. ``None``: the ideal twin.
    """

    def __init__(
        self,
        model: ReflectanceModel,
        clock: Clock,
        *,
        noise_pct: float = 0.0,
        rng: np.random.Generator | None = None,
        measure_time_s: float = 0.5,
        autosend_interval_s: float = 5.0,
        temperature_c: float = 23.0,
        faults: FaultInjector | None = None,
        name: str = "glossmeter",
        drift: GlossDrift | None = None,
    ) -> None:
        self.name = name
        self.drift = drift
        self._powered_at_s = clock.now()
        self._calibrated_at_s = self._powered_at_s
        self._gloss_cache: dict[int, float] = {}
        self.model = model
        self.clock = clock
        self.noise_pct = noise_pct
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self.measure_time_s = measure_time_s
        self.autosend_interval_s = autosend_interval_s
        self.temperature_c = temperature_c
        self.faults = faults or FaultInjector(name)
        self._connected = False

    @property
    def model(self) -> ReflectanceModel:
        """The sample under the meter; setting it (another sample) forgets the cached gloss."""
        return self._model

    @model.setter
    def model(self, model: ReflectanceModel) -> None:
        self._model = model
        self._gloss_cache.clear()

    async def predicted_gu(self, angles_deg: Sequence[int]) -> dict[int, float]:
        """Noise-free model gloss per geometry (cached until the sample changes)."""
        missing = [a for a in angles_deg if a not in self._gloss_cache]
        if missing:
            values = await asyncio.to_thread(self.model.gloss, tuple(missing))
            self._gloss_cache.update({int(k): float(v) for k, v in values.items()})
        return {a: self._gloss_cache[a] for a in angles_deg}

    async def warm_up(self) -> None:
        """Compute (and cache) the model gloss at 20/60/85 deg before the first request."""
        await self.predicted_gu(GLOSS_ANGLES_DEG)

    async def read_values_gu(
        self, angles_deg: Sequence[int]
    ) -> tuple[dict[int, float | None], tuple[int, ...]]:
        """Noisy values rounded to 0.1 GU, and the geometries that overflowed."""
        for a in angles_deg:
            if a not in GLOSS_ANGLES_DEG:
                raise ValueError(f"{self.name}: geometry {a} deg not one of {GLOSS_ANGLES_DEG}")
        await self.clock.sleep(self.measure_time_s)
        clean = await self.predicted_gu(angles_deg)
        values: dict[int, float | None] = {a: None for a in GLOSS_ANGLES_DEG}
        overflow: list[int] = []
        gain = 1.0
        if self.drift is not None:
            now = self.clock.now() - self._powered_at_s
            gain = self.drift.gain(now, self._calibrated_at_s - self._powered_at_s)
        for a in angles_deg:
            v = clean[a] * gain
            if self.drift is not None:
                v += self.drift.noise_gu * float(self._rng.standard_normal())
            elif self.noise_pct:
                v *= 1.0 + 0.01 * self.noise_pct * float(self._rng.standard_normal())
            if v > GLOSS_OVERFLOW_GU:
                overflow.append(a)
                values[a] = None
            else:
                values[a] = round(max(v, 0.0), 1)
        return values, tuple(overflow)

    async def measure(self, angles_deg: Sequence[int] = GLOSS_ANGLES_DEG) -> GlossReading:
        """One measurement at the requested geometries (others are ``None``)."""
        self._op("measure")
        values, overflow = await self.read_values_gu(angles_deg)
        return GlossReading(
            values_gu=values,
            overflow_deg=overflow,
            temperature_c=self.current_temperature_c(),
            timestamp=time.time(),
            raw="",
        )

    def current_temperature_c(self) -> float:
        """The instrument's temperature now (warming up after power-on with ``drift``)."""
        if self.drift is None:
            return self.temperature_c
        return round(self.drift.temperature_c(self.clock.now() - self._powered_at_s), 1)

    def calibrate_ppm(self) -> int:
        """Calibrate on the black standard: the drift starts again from here. Returns the
        deviation found (gain - 1, in ppm), as the ZGM1120's Calibrate (opcode 72) does."""
        now = self.clock.now()
        ppm = 0
        if self.drift is not None:
            gain = self.drift.gain(
                now - self._powered_at_s, self._calibrated_at_s - self._powered_at_s
            )
            ppm = round((gain - 1.0) * 1e6)
        self._calibrated_at_s = now
        return ppm

    def readings(self) -> AsyncIterator[GlossReading]:
        """Readings pushed every ``autosend_interval_s`` clock seconds (auto-send)."""
        return self._stream()

    async def _stream(self) -> AsyncIterator[GlossReading]:
        if self.autosend_interval_s <= 0:
            return
        while True:
            await self.clock.sleep(self.autosend_interval_s)
            yield await self.measure()
