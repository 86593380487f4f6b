"""The simulated spectro's light path: lamp, detector response, noise, and a spectrum's shape.

:class:`SpectroChain` (the realistic twin) turns the flux fraction a specimen reflects into
the values a STIL Ruby reports (lamp x silicon response, dark current and shot noise, read
noise, a 16-bit full scale that saturates, stray light, lamp flicker);
:func:`spectrum_for_luminance` gives the ideal twin's near-neutral spectrum of a luminance;
:func:`y_weights` the luminance weights both use.

References
----------
.. [1] B. Wittmann et al., "BRDF and gloss computation of polyurethane coatings from
   roughness measurements", Prog. Org. Coat. 156 (2021) 106247, sec. 2.3 (instrument).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.twin_spectra import SPECTRUM_WAVELENGTHS_NM, luminance_weights

__all__ = [
    "SpectroChain",
    "detector_response",
    "lamp_spectrum",
    "spectrum_for_luminance",
    "y_weights",
]

#: Slope of the simulated spectral shape per nm around 580 nm (a faint warm tint).
_SPECTRUM_TILT_PER_NM = 1.5e-4


def y_weights() -> NDArray[np.float64]:
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
    y_shape = float(np.dot(y_weights(), shape))
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
    ``flicker_pct`` (1 sigma, common to all channels). The counts are per detector pixel;
    a reported 10 nm channel is the mean of ``pixels_per_channel`` pixels, so its shot and
    read noise are those of one pixel over ``sqrt(pixels_per_channel)``. The raw counts
    (with a bias) clip at the 16-bit full well. The instrument subtracts its dark reference
    (bias + mean dark at that exposure) and divides by its calibration ``g(l) t / 10 ms``:
    the reported values are in % of a perfect mirror, exact on average below saturation,
    noisy at low counts, low once a channel saturates. :meth:`covariance` is the
    covariance of the reported values that this model implies (below saturation).
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
    #: It matters where the specimen polarises, e.g. the black glass at 60 deg (R_s 18 %,
    #: R_p 0.4 %). Default 0.51, a polarisation dependence ``(S_s - S_p) / (S_s + S_p)`` of
    #: 2 %: a grating's efficiency differs between s and p by tens of % (C. Palmer,
    #: *Diffraction Grating Handbook*, 8th ed., ch. 9 "efficiency characteristics"); a
    #: multimode fibre in front of it (the Ruby's input) scrambles most of that, leaving a
    #: residual of a few % (J. Kostkowski, *Reliable Spectroradiometry*, 1997, ch. 7,
    #: polarisation errors). A typical value, unconfirmed for the STIL Ruby: its manual
    #: gives none.
    s_weight: float = 0.51
    #: detector pixels averaged into one reported 10 nm channel. A grating spectrometer's
    #: linear CCD has 2048 pixels (Sony ILX511, Ocean Optics USB2000+ data sheet
    #: 270-00000-000-05-201303) spread over the visible and near infrared: 0.16 nm per
    #: pixel over 370-700 nm for the USB2000 of the University of Toronto's AST325 lab guide,
    #: about 0.3 nm over a 350-1000 nm grating, so a 10 nm channel (the ASTM E308 band) sums
    #: 30-60 pixels. 30 is the conservative end. With 1 (one pixel per channel, the twin
    #: before), each channel carried one pixel's shot noise independently of its neighbours:
    #: 0.4-1.5 % at half full scale, a repeat dE00 of 0.3 on a white at 45/0 and 0.5-1.1
    #: near specular, ten times a multi-angle instrument's repeatability.
    pixels_per_channel: int = 30

    def __post_init__(self) -> None:
        lamp_spectrum(self.lamp)  # validate
        if self.pixels_per_channel < 1:
            raise ValueError(f"pixels_per_channel must be >= 1, got {self.pixels_per_channel}")

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
        signal = np.clip(self.mean_reading_pct(fraction) * flicker, 0.0, None) * g
        dark = self.dark_counts_per_s * exposure_us * 1e-6
        px = self.pixels_per_channel
        # electrons of the channel's px pixels together; counts and read noise per pixel
        electrons = (signal + dark) * self.electrons_per_count * px
        counts = rng.poisson(electrons) / (self.electrons_per_count * px)
        read = self.read_noise_counts / np.sqrt(px) * rng.standard_normal(counts.shape)
        raw = np.round((self.bias_counts + counts + read) * px) / px  # the summed counts
        raw = np.clip(raw, 0.0, self.full_well_counts)
        peak = float(raw.max() / self.full_well_counts)
        values = (raw - self.bias_counts - dark) / g
        return np.asarray(values), peak

    def mean_reading_pct(self, fraction: NDArray[np.float64]) -> NDArray[np.float64]:
        """Light entering per channel in % of a mirror, the specimen's plus stray light: the
        mean of the reported values below saturation (the point :meth:`covariance` is about)."""
        f_pct = 100.0 * np.asarray(fraction, dtype=np.float64)
        return np.asarray(f_pct + self.stray_pct + self.stray_rel * float(np.mean(f_pct)))

    def covariance(self, fraction: NDArray[np.float64], exposure_us: int) -> NDArray[np.float64]:
        """Covariance (%^2) of the reported values of :meth:`read` at ``fraction``, to
        first order, below saturation.

        Per channel ``l``, with ``c_l = (100 f_l + stray) g_l t/10 ms`` the mean signal in
        counts per pixel, ``d`` the dark counts, ``e`` the electrons per count and ``P`` the
        pixels per channel: Poisson shot noise ``(c_l + d) / (e P)``, read noise
        ``sigma_r^2 / P`` and the rounding of the channel's summed counts, ``1 / (12 P^2)``, all
        independent between channels, divided by ``(g_l t/10 ms)^2``; plus the lamp's
        flicker, one factor on every channel: ``(flicker_pct/100)^2 m m^T`` with
        ``m_l = 100 f_l + stray`` (the reported value's mean).
        """
        t_rel = exposure_us / 10_000.0
        g = self.gain() * t_rel
        m = self.mean_reading_pct(fraction)
        dark = self.dark_counts_per_s * exposure_us * 1e-6
        px = self.pixels_per_channel
        var_counts = (
            (m * g + dark) / (self.electrons_per_count * px)
            + self.read_noise_counts**2 / px
            + 1.0 / (12.0 * px**2)
        )
        flick = (0.01 * self.flicker_pct) ** 2
        return np.asarray(np.diag(var_counts / g**2) + flick * np.outer(m, m))
