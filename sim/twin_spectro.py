"""The simulated STIL Ruby spectro-colorimeter, and the geometry the sample really sees.

:class:`SimSpectro` implements :class:`drivers.base.Spectrocolorimeter`: it reads its model
(the prediction's own in the ideal twin, the sample's hidden truth :mod:`sim.truth` through
a :class:`~sim.spectro_chain.SpectroChain` in the realistic one) at the geometry the arms
*really* have (:func:`effective_angles`: the sample tilt and the arms' zero offsets of
Wittmann et al. 2021, sec. 5.2-5.3). :class:`MirrorModel` is the reference mirror.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 2.3 (instrument),
   sec. 5.2-5.3 (misalignment).
"""

from __future__ import annotations

import asyncio
import math
import time
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from drivers.base import SpectroReading
from drivers.timing import Clock
from goniolab.optics.apertures import Aperture, Cone, cap_overlap_fraction
from sim.faults import FaultInjector
from sim.spectro_chain import SpectroChain, spectrum_for_luminance, y_weights
from sim.twin_axis import SimAxis
from sim.twin_link import SimLink
from sim.twin_spectra import SPECTRUM_WAVELENGTHS_NM

__all__ = ["LuminanceModel", "MirrorModel", "SimSpectro", "effective_angles"]


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


class SimSpectro(SimLink):
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
        await asyncio.to_thread(y_weights)  # imports colour-science (slow) for the spectra

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
        lum = float(np.dot(y_weights(), values))
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
