"""The digital twin's hidden truth: what a simulated sample really is, and what it reflects.

The prediction (:class:`goniolab.optics.facet.FacetModel`) sees only the *profilometer map*
of a sample: the STIL MG210 pen of Wittmann et al. (2021, sec. 2.2) samples 1 um steps
with a lateral resolution of about one step and a few nm of height noise. The twin owns a
finer truth that the map only approximates, and computes the instruments' readings from it
with physics the predictor does not share:

* **The true surface** (:class:`TrueSurface`), a tile finer than the map
  (``step_um = 0.25`` by default, 4 points per map step):

  - the map's band (spatial frequencies up to the map's Nyquist, ``1/(2 dx)``) is the
    band-limited (FFT) interpolation of the map *minus* one realisation of the
    profilometer's height noise: the noise is in the map, not on the sample;
  - plus sub-resolution roughness: a Gaussian-correlated random field
    (``subres_rq_nm``, ``subres_corr_um``) whose spectrum lies entirely *above* the
    map's Nyquist, so no 1 um profilometer can see it;
  - plus the long-wave waviness of the 5 mm lamp spot, larger than any map: an rms slope
    ``waviness_slope_rms`` of the spot-scale surface (Gaussian), which blurs the specular
    peak by ``q_z`` times that slope in direction cosines. (The sample's mean tilt is an
    alignment error of the session, :mod:`sim.instruments`.)

  By construction :meth:`TrueSurface.profilometer_map` (ideal low-pass to the map's band,
  resampling on the map's grid, plus the same seeded noise realisation) returns the map
  the predictor uses, to rounding: the prediction's input is exactly "the true surface as
  measured".

* **Scalar Kirchhoff (tangent-plane) scattering** on the true tile, not the facet model
  (docs/PHYSICS.md, "Where the facet model stops: physical optics"; Beckmann & Spizzichino 1963; the NIST seed's
  "Kirchhoff" method). For a band of ``q_z = cos ti + cos ts`` the field scattered into the
  direction-cosine offset ``(du, dv)`` from the specular direction is the FFT of the phase
  screen ``exp(i k q_z z(x, y))``; on the periodic tile it is a grating, whose order
  ``(m, n)`` carries the fraction ``P = |U|^2 / N^2`` of the power (Parseval: they sum to
  one). Each order is weighted by the Fresnel reflectance at the local incidence
  ``cos(iota) = |wi + wo| / 2`` and by the obliquity factor

  .. math:: Q = \\frac{|w_i + w_o|^4}{4 \\cos\\theta_i \\cos\\theta_s q_z^2}
              = F_{geom}^2 \\frac{\\cos\\theta_i}{\\cos\\theta_s},

  Beckmann's geometric factor ``F_geom = (1 + cos ti cos ts - sin ti sin ts cos ps) /
  (cos ti (cos ti + cos ts))`` squared, times the change from solid angle to direction
  cosines. ``Q = 1`` at the specular direction, so a flat surface is the Fresnel mirror,
  a slightly rough one loses ``exp(-(k q_z Sq)^2)`` to diffuse scatter (Debye-Waller), and
  in the geometrical-optics limit the stationary phase picks the facet of slope
  ``du / q_z`` that mirrors wi into wo, with the facet BRDF
  ``F P22 / (4 cos ti cos ts cos^4 theta_h)`` (PHYSICS.md): the limits the tests check.
  It includes diffraction by features near the wavelength, the smooth-surface limit and
  the grazing-incidence behaviour the seed's sec. 5.4 (eq. 14) finds the facet model
  missing; shadowing and masking by the coat's roughness are applied to each reading as
  Smith's ``G1(ti) G1(tr)`` for the tile's rms slope in the plane (:func:`smith_shadowing`:
  felt at grazing angles on rough coats); no multiple reflections (on a dielectric these
  are small, seed sec. 5.4).

  ``q_z`` varies over a sweep; the FFT is done for bands of ``q_z`` whose phase error
  ``k dq Sq`` stays below ``band_phase_rad`` (at least ``min_band_dq``, at most 0.25
  apart); a reading rescales the two bands around its own ``q_z`` to it (exact in the
  geometrical-optics and the smooth limits) and interpolates linearly between them. Each band is
  evaluated at three wavelengths (450, 550, 650 nm by default) and interpolated over the
  spectrum.

* **The instrument integration** in direction-cosine space (Harvey-Shack shift
  invariance): the source cone is an ellipse of semi-axes ``a_s cos ti`` x ``a_s`` around
  the specular order (uniform), convolved with the waviness Gaussian; the detector cone an
  ellipse ``a_d cos tr`` x ``a_d`` around its own direction cosine. The ISO 2813 rectangles
  are rectangles. A reading is the convolved order power summed over the detector, by
  row-wise cumulative sums (partial cells interpolated).

* **The body**: light entering the clear coat (1 - F(ti)), reflected diffusely by the body
  (spectral reflectance ``R_b(lambda)``), leaving with 1 - F(tr) after internal
  reflections (Saunderson: ``(1 - r_i) R_b / (1 - r_i R_b)``, ``r_i = 0.6`` for n = 1.5,
  docs/PHYSICS.md, "Colour and the paint layer"), Lambertian: ``R_d cos(tr) Omega_d / pi`` of the
  flux reaches a detector of solid angle ``Omega_d``.

Cost and caching: a table is one FFT of the tile per (q_z band, wavelength), shared by
every incidence angle (the band is rescaled to each reading's own q_z). Tables are kept in
memory and in a disk cache (``cache_dir``), keyed by the truth's content and the
settings; docs/TWIN.md gives measured build times.

References
----------
.. [1] B. Wittmann et al., Prog. Org. Coat. 156 (2021) 106247, secs. 2.2, 2.3, 5.2-5.4.
.. [2] P. Beckmann, A. Spizzichino, "The Scattering of Electromagnetic Waves from Rough
   Surfaces" (1963), ch. 3 (Kirchhoff, geometric factor F).
.. [3] J. E. Harvey et al., "Diffracted radiance: a fundamental quantity in nonparaxial
   scalar diffraction theory", Appl. Opt. 38 (1999) 6469 (direction-cosine space).
.. [4] J. L. Saunderson, J. Opt. Soc. Am. 32 (1942) 727.
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.apertures import (
    ISO2813_BLACK_GLASS_N,
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Aperture,
    Cone,
    Rect,
)
from goniolab.optics.fresnel import fresnel
from goniolab.optics.heightmap import HeightMap, fill_missing, level_plane

__all__ = [
    "BODY_SPECTRA",
    "SPECTRUM_WAVELENGTHS_NM",
    "FlatSpecimen",
    "TrueSurface",
    "TruthOptics",
    "TwinSettings",
    "body_reflectance",
    "build_truth",
    "luminance_weights",
    "truth_for",
]

FloatArray = NDArray[np.float64]

#: Wavelength grid of the simulated spectra: 380..780 nm in 10 nm steps.
SPECTRUM_WAVELENGTHS_NM: tuple[float, ...] = tuple(float(w) for w in range(380, 781, 10))

#: Internal diffuse reflectance of a clear coat of n ~ 1.5 (Saunderson's r_i, PHYSICS.md).
_R_INTERNAL = 0.6

#: Version of the truth's physics: part of the disk-cache key (bump it when tables change).
_TRUTH_VERSION = 2

#: Widest q_z band: readings interpolate linearly between neighbouring bands, which is only
#: accurate while they are close (the Debye-Waller factor is not linear in q_z).
_MAX_BAND_DQ = 0.25

#: Named body reflectances (fractions), smooth analytic curves over 380..780 nm: the
#: black-inked PVC under the seed's coatings, a TiO2 white, a neutral grey and two colours.
BODY_SPECTRA: tuple[str, ...] = ("black", "white", "grey", "red", "blue")


def _sigmoid(x: FloatArray) -> FloatArray:
    return np.asarray(1.0 / (1.0 + np.exp(-x)))


def body_reflectance(
    name: str, wavelengths_nm: Sequence[float] = SPECTRUM_WAVELENGTHS_NM
) -> FloatArray:
    """Diffuse reflectance (fraction) of a named body at ``wavelengths_nm``.

    Raises
    ------
    ValueError
        Unknown name (the message lists :data:`BODY_SPECTRA`).
    """
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    if name == "black":  # carbon-black ink: ~3 %, slightly rising to the red
        r = 0.028 + 0.006 * (wl - 380.0) / 400.0
    elif name == "white":  # TiO2 white: absorbs below ~410 nm
        r = 0.88 * _sigmoid((wl - 410.0) / 8.0) + 0.05
    elif name == "grey":
        r = np.full_like(wl, 0.30)
    elif name == "red":
        r = 0.05 + 0.65 * _sigmoid((wl - 600.0) / 15.0)
    elif name == "blue":
        r = 0.05 + 0.45 * np.exp(-(((wl - 460.0) / 45.0) ** 2))
    else:
        raise ValueError(f"unknown body {name!r}; known: {', '.join(BODY_SPECTRA)}")
    return np.asarray(r, dtype=np.float64)


@functools.lru_cache(maxsize=4)
def luminance_weights(
    observer: str = "CIE 1964 10 Degree Standard Observer", illuminant: str = "D65"
) -> FloatArray:
    """Normalised weights ``ybar(l) S(l)`` on :data:`SPECTRUM_WAVELENGTHS_NM`.

    ``Y = sum(w R)`` for a reflectance R (CIE 15:2004 eq. 7.1). The spectro uses the 10 deg
    observer and D65 (PHYSICS.md), the glossmeter the 2 deg V(lambda) and illuminant C
    (ISO 2813). colour-science is imported here, lazily (it is slow to import).
    """
    from goniolab.lazy_imports import import_colour

    colour = import_colour()

    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    cmfs = colour.MSDS_CMFS[observer]
    ybar = np.interp(wl, cmfs.wavelengths, cmfs.values[:, 1])
    sd = colour.SDS_ILLUMINANTS[illuminant]
    s = np.interp(wl, sd.wavelengths, sd.values)
    w = ybar * s
    return np.asarray(w / w.sum(), dtype=np.float64)


class _SpectralFraction(Protocol):
    def spectral_fraction(
        self, theta_i_deg: float, theta_r_deg: float, *, source: Aperture, detector: Aperture
    ) -> FloatArray: ...


def _luminance_pct(
    optics: _SpectralFraction,
    theta_i_deg: float,
    theta_r_deg: object,
    source: Aperture,
    detector: Aperture,
) -> FloatArray:
    """100 x the luminance-weighted (:func:`luminance_weights`) spectral fraction reaching the
    detector, per signed ``theta_r_deg``: the noise-free reading of either specimen."""
    tr = np.asarray(theta_r_deg, dtype=np.float64)
    w = luminance_weights()
    out = [
        100.0
        * float(
            np.dot(
                w, optics.spectral_fraction(theta_i_deg, float(t), source=source, detector=detector)
            )
        )
        for t in tr.flat
    ]
    return np.asarray(out, dtype=np.float64).reshape(tr.shape)


@dataclass(frozen=True)
class TwinSettings:
    """How the twin builds its truth (config ``[sim.twin]``; defaults in the docstrings).

    Attributes
    ----------
    step_um
        Step of the true tile (finer than the map: 0.25 um).
    max_tile
        Largest tile side in points (the map is cropped to its centre beyond).
    subres_rq_nm, subres_corr_um
        Rms height and correlation length of the roughness below the profilometer's
        resolution.
    profilometer_noise_nm
        Rms height noise of the profilometer (in the map, not on the sample).
    waviness_slope_rms
        Rms slope (rad) of the spot-scale waviness under the 5 mm lamp spot.
    wavelengths_nm
        Wavelengths at which the Kirchhoff tables are computed.
    band_phase_rad, min_band_dq
        Width of a q_z band: phase error ``k dq Sq`` at most ``band_phase_rad``, and
        ``dq`` at least ``min_band_dq``.
    seed
        Seed of the random parts (profilometer noise, sub-resolution roughness).
    cache_dir
        Disk cache of the response tables (``None``: memory only).
    """

    step_um: float = 0.25
    max_tile: int = 2048
    subres_rq_nm: float = 4.0
    subres_corr_um: float = 0.3
    profilometer_noise_nm: float = 2.0
    waviness_slope_rms: float = 3e-4
    wavelengths_nm: tuple[float, ...] = (450.0, 550.0, 650.0)
    band_phase_rad: float = 1.0
    min_band_dq: float = 0.06
    seed: int = 1
    cache_dir: str | None = None

    def key(self) -> str:
        """What the tables depend on (not the cache location)."""
        return repr(
            (
                self.step_um,
                self.max_tile,
                self.subres_rq_nm,
                self.subres_corr_um,
                self.profilometer_noise_nm,
                self.waviness_slope_rms,
                self.wavelengths_nm,
                self.band_phase_rad,
                self.min_band_dq,
                _TRUTH_VERSION,
                self.seed,
            )
        )


# --------------------------------------------------------------------------------------
# The true surface
# --------------------------------------------------------------------------------------


def _resample_axis(x: FloatArray, num: int, axis: int) -> FloatArray:
    """Band-limited (Fourier) resampling of a periodic real array along ``axis`` to ``num``.

    Zero-padding the spectrum interpolates (the original samples are reproduced);
    truncating it low-passes to the new Nyquist. The Nyquist bin of an even length is
    halved going up and folded (doubled real part) going down, so that down(up(x)) == x.
    """
    n = x.shape[axis]
    if num == n:
        return x
    spec = np.fft.rfft(x, axis=axis)
    shape = list(spec.shape)
    shape[axis] = num // 2 + 1
    out = np.zeros(shape, dtype=spec.dtype)
    keep = min(n, num) // 2 + 1
    sl: list[slice | int] = [slice(None)] * x.ndim
    sl[axis] = slice(0, keep)
    out[tuple(sl)] = spec[tuple(sl)]
    nyq: list[slice | int] = [slice(None)] * x.ndim
    if num > n and n % 2 == 0:
        nyq[axis] = n // 2
        out[tuple(nyq)] *= 0.5
    elif num < n and num % 2 == 0:
        nyq[axis] = num // 2
        out[tuple(nyq)] = 2.0 * out[tuple(nyq)].real
    return np.asarray(np.fft.irfft(out, n=num, axis=axis) * (num / n))


def _resample2(z: FloatArray, shape: tuple[int, int]) -> FloatArray:
    """Band-limited resampling of a periodic 2-D array to ``shape`` (both axes)."""
    out = np.asarray(z, dtype=np.float64)
    out = _resample_axis(out, shape[0], 0)
    return _resample_axis(out, shape[1], 1)


def _highpass_field(
    rng: np.random.Generator, shape: tuple[int, int], step_um: float, corr_um: float, f_cut: float
) -> FloatArray:
    """Unit-rms random field with Gaussian ACF ``exp(-r^2/L^2)`` and no spectrum inside
    ``|fx|, |fy| <= f_cut`` (cycles/um): invisible to a profilometer of Nyquist ``f_cut``."""
    ny, nx = shape
    noise = rng.standard_normal(shape)
    fy = np.fft.fftfreq(ny, d=step_um)
    fx = np.fft.rfftfreq(nx, d=step_um)
    k2 = (2 * np.pi) ** 2 * (fy[:, None] ** 2 + fx[None, :] ** 2)
    filt = np.exp(-k2 * corr_um**2 / 8.0)
    inside = (np.abs(fy)[:, None] <= f_cut) & (np.abs(fx)[None, :] <= f_cut)
    filt[inside] = 0.0
    field = np.fft.irfft2(np.fft.rfft2(noise) * filt, s=shape)
    sd = float(field.std())
    return np.asarray(field / sd if sd > 0 else field)


def _is_periodic(hm: HeightMap) -> bool:
    """The built-in samples are generated periodic (goniolab.surfaces.samples)."""
    return hm.meta.get("generator") == "goniolab.surfaces.samples"


@dataclass
class TrueSurface:
    """A sample as it really is (see the module docstring).

    Attributes
    ----------
    name
        Where it came from (``sample:NAME`` or a file).
    z_um
        The true tile (float32, micrometres, zero mean), step ``step_um`` both ways.
    step_um
        Its step.
    periodic
        The tile is periodic (library samples); otherwise the Kirchhoff field is windowed.
    n
        Refractive index of the clear coat / surface.
    body
        Body reflectance name (:data:`BODY_SPECTRA`).
    map_shape, map_step_um
        Grid of the profilometer map it reproduces.
    noise_um
        The profilometer's noise realisation on that grid (in the map, not the sample).
    settings
        The twin settings it was built with.
    """

    name: str
    z_um: NDArray[np.float32]
    step_um: float
    periodic: bool
    n: complex
    body: str
    map_shape: tuple[int, int]
    map_step_um: float
    noise_um: FloatArray
    settings: TwinSettings
    content_key: str = ""

    @functools.cached_property
    def sq_um(self) -> float:
        """Rms height of the tile."""
        return float(np.sqrt(np.mean(np.square(self.z_um, dtype=np.float64))))

    @functools.cached_property
    def slope_rms_x(self) -> float:
        """Rms slope of the tile along x (the plane of incidence), by central differences."""
        z = self.z_um.astype(np.float64)
        dz = (np.roll(z, -1, axis=1) - np.roll(z, 1, axis=1)) / (2.0 * self.step_um)
        return float(np.sqrt(np.mean(np.square(dz))))

    def profilometer_map(self) -> HeightMap:
        """What the profilometer measures: the tile low-passed to the map's band,
        resampled on the map's grid, plus the profilometer's noise (seeded)."""
        z = _resample2(self.z_um.astype(np.float64), self.map_shape) + self.noise_um
        return HeightMap(
            z_um=z - z.mean(),
            dx_um=self.map_step_um,
            dy_um=self.map_step_um,
            source=f"profilometer({self.name})",
        )


def build_truth(
    hm: HeightMap,
    *,
    n: complex | float = 1.55,
    body: str = "black",
    settings: TwinSettings | None = None,
    name: str | None = None,
) -> TrueSurface:
    """Build the true surface behind a profilometer map (blocking: seconds for 512 x 512).

    Parameters
    ----------
    hm
        The map the prediction uses (levelled and gap-filled here).
    n
        Refractive index.
    body
        Body reflectance name.
    settings
        Twin settings (default :class:`TwinSettings`).
    name
        Label (default ``hm.source``).
    """
    s = settings or TwinSettings()
    body_reflectance(body)  # validate the name early
    periodic = _is_periodic(hm)
    work = hm if periodic else level_plane(fill_missing(hm))
    if not math.isclose(work.dx_um, work.dy_um, rel_tol=1e-6):
        raise ValueError(
            f"{hm.source}: the twin needs a square grid (dx = dy), got {work.dx_um}, {work.dy_um}"
        )
    factor = max(1, round(work.dx_um / s.step_um))
    z = np.asarray(work.z_um, dtype=np.float64)
    side = max(2, s.max_tile // factor)
    if z.shape[0] > side or z.shape[1] > side:  # crop to the centre (no longer periodic)
        oy, ox = max(0, (z.shape[0] - side) // 2), max(0, (z.shape[1] - side) // 2)
        z = z[oy : oy + side, ox : ox + side]
        periodic = False
    z = z - z.mean()
    key = [int(b) for b in (name or hm.source).encode()]
    rng = np.random.default_rng([s.seed, 12, *key])
    noise = rng.standard_normal(z.shape) * (s.profilometer_noise_nm * 1e-3)
    noise -= noise.mean()
    fine_shape = (z.shape[0] * factor, z.shape[1] * factor)
    step = work.dx_um / factor
    zt = _resample2(z - noise, fine_shape)
    if s.subres_rq_nm > 0 and factor > 1:
        f_cut = 0.5 / work.dx_um
        zt += (s.subres_rq_nm * 1e-3) * _highpass_field(
            rng, fine_shape, step, s.subres_corr_um, f_cut
        )
    zt -= zt.mean()
    digest = hashlib.sha1(np.ascontiguousarray(z).tobytes()).hexdigest()[:16]
    return TrueSurface(
        name=name or hm.source,
        z_um=zt.astype(np.float32),
        step_um=step,
        periodic=periodic,
        n=complex(n),
        body=body,
        map_shape=z.shape,
        map_step_um=float(work.dx_um),
        noise_um=noise,
        settings=s,
        content_key=f"{digest}-{complex(n)}-{body}-{factor}-{periodic}",
    )


# --------------------------------------------------------------------------------------
# Optics of the truth
# --------------------------------------------------------------------------------------


@dataclass
class _Table:
    """Order powers of one (wavelength, q_z band) phase screen: the fraction ``|U|^2/N^2``
    of the power each diffraction order carries, at offsets ``(du, dv)`` from the specular
    direction (direction cosines; u along the specular side of the plane of incidence),
    rows ``|dv| <= reach``, blurred by the spot-scale waviness."""

    du: FloatArray  # (ncol,) ascending, uniform
    dv: FloatArray  # (nrow,) ascending, uniform
    p: NDArray[np.float32]  # (nrow, ncol)
    qz: float  # the band's q_z

    def reading(
        self,
        theta_i_deg: float,
        u_d: float,
        q_exact: float,
        n: complex,
        source: Aperture,
        detector: Aperture,
    ) -> float:
        """Flux fraction reaching ``detector`` centred on the in-plane direction cosine
        ``u_d`` for incidence ``theta_i_deg``.

        The band's orders are first rescaled by ``c = q_exact / qz`` about the specular
        direction: in the geometrical-optics regime the pattern of a phase screen scales
        with q_z (an order at du comes from slopes du/q_z), and the coherent specular
        order stays where it is, so the rescaling makes the band exact at the reading's
        own q_z in both limits. Each order is weighted by the Fresnel reflectance at its
        local incidence and by the obliquity factor Q, and spreads the source's image
        around its own direction (a cap of the source's size: cap overlap with the
        detector; rectangles for ISO 2813).
        """
        ti = math.radians(theta_i_deg)
        sin_ti, cos_ti = math.sin(ti), math.cos(ti)
        if isinstance(source, Cone) and isinstance(detector, Cone):
            a_s = math.radians(source.half_angle_deg)
            a_d = math.radians(detector.half_angle_deg)
            reach = math.sin(min(a_s + a_d, math.pi / 2))
        elif isinstance(source, Rect) and isinstance(detector, Rect):
            reach = math.radians(0.5 * (source.in_plane_deg + detector.in_plane_deg))
        else:
            raise TypeError("source and detector must both be Cones or both Rects")
        c = q_exact / self.qz
        h = float(self.du[1] - self.du[0])
        lo = max(0, math.floor(((u_d - sin_ti - reach) / c - self.du[0]) / h) - 1)
        hi = min(self.du.size, math.ceil(((u_d - sin_ti + reach) / c - self.du[0]) / h) + 2)
        if hi <= lo:
            return 0.0
        u = sin_ti + c * self.du[None, lo:hi]
        v = c * self.dv[:, None]
        p = self.p[:, lo:hi].astype(np.float64)
        g2 = 1.0 - u * u - v * v
        ok = g2 > 0.0
        g = np.sqrt(np.where(ok, g2, 1.0))
        q = cos_ti + g
        s2 = (sin_ti - u) ** 2 + v * v + q * q  # |wi + wo|^2
        obliq = s2 * s2 / (4.0 * cos_ti * g * q * q)
        fr_lut = _fresnel_lut(n)
        pos_f = np.clip(0.5 * np.sqrt(s2), 0.0, 1.0) * (fr_lut.size - 2)
        i_f = pos_f.astype(np.int64)
        fr = fr_lut[i_f] + (pos_f - i_f) * (fr_lut[i_f + 1] - fr_lut[i_f])
        g_d = math.sqrt(max(0.0, 1.0 - u_d * u_d))
        if isinstance(source, Cone) and isinstance(detector, Cone):
            chord2 = (u - u_d) ** 2 + v * v + (g - g_d) ** 2
            x_max, lut = _cone_lut(source.half_angle_deg, detector.half_angle_deg)
            pos = np.minimum(chord2 * ((lut.size - 2) / x_max), lut.size - 2)
            i0 = pos.astype(np.int64)
            w = lut[i0] + (pos - i0) * (lut[i0 + 1] - lut[i0])
        else:
            assert isinstance(source, Rect) and isinstance(detector, Rect)
            t_o = np.arcsin(np.clip(u / np.sqrt(np.clip(1.0 - v * v, 1e-12, None)), -1.0, 1.0))
            b_o = np.arcsin(np.clip(v, -1.0, 1.0))
            t_d = math.asin(max(-1.0, min(1.0, u_d)))
            w = _overlap_1d(
                t_o - t_d, math.radians(source.in_plane_deg), math.radians(detector.in_plane_deg)
            ) * _overlap_1d(b_o, math.radians(source.perp_deg), math.radians(detector.perp_deg))
        return float(np.sum(np.where(ok, p * fr * obliq * w, 0.0)))


def smith_shadowing(theta_deg: float | FloatArray, slope_rms: float) -> FloatArray:
    """Smith's shadowing (masking) function G1 of a Gaussian surface of rms slope
    ``slope_rms`` in the plane, seen at ``theta_deg`` from the normal (B. G. Smith, IEEE
    Trans. Antennas Propag. 15 (1967) 668; Walter et al., EGSR 2007, eq. 27)::

        nu = cot(theta) / (sqrt(2) sigma),   Lambda = (exp(-nu^2) / (nu sqrt(pi)) - erfc(nu)) / 2
        G1 = 1 / (1 + Lambda)

    1 at normal incidence and for a smooth coat, falling at grazing angles for a rough one.
    """
    from scipy.special import erfc

    t = np.radians(np.abs(np.asarray(theta_deg, dtype=np.float64)))
    if slope_rms <= 0.0:
        return np.ones_like(t)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = 1.0 / np.tan(np.clip(t, 1e-9, math.pi / 2 - 1e-9)) / (math.sqrt(2.0) * slope_rms)
        lam = 0.5 * (np.exp(-(nu**2)) / (nu * math.sqrt(math.pi)) - erfc(nu))
    return np.asarray(1.0 / (1.0 + np.maximum(lam, 0.0)))


def _overlap_1d(d: FloatArray, a: float, b: float) -> FloatArray:
    """Fraction of an interval of width ``a`` centred at ``d`` inside one of width ``b``
    centred at 0."""
    if a <= 0.0:
        return np.asarray(np.where(np.abs(d) <= 0.5 * b, 1.0, 0.0))
    ov = np.minimum(d + 0.5 * a, 0.5 * b) - np.maximum(d - 0.5 * a, -0.5 * b)
    return np.asarray(np.clip(ov, 0.0, None) / a)


@functools.lru_cache(maxsize=16)
def _fresnel_lut(n: complex) -> FloatArray:
    """Fresnel reflectance on a uniform grid of 16384 intervals of cos(iota) in [0, 1]
    (plus a repeated last value), for linear interpolation."""
    c = np.linspace(0.0, 1.0, 16385)
    f = fresnel(c, n)
    return np.append(f, f[-1])


@functools.lru_cache(maxsize=16)
def _cone_lut(src_half_deg: float, det_half_deg: float) -> tuple[float, FloatArray]:
    """Cap overlap (:func:`goniolab.optics.facet.cap_overlap_fraction`) against the squared
    chord ``|wo - d|^2 = 4 sin^2(gamma/2)`` between an image centre and the detector axis,
    on a uniform grid ``[0, x_max]`` of 8192 intervals with a trailing 0 beyond."""
    from goniolab.optics.apertures import cap_overlap_fraction

    a_s, a_d = math.radians(src_half_deg), math.radians(det_half_deg)
    g_max = min(a_s + a_d, math.pi / 2)
    x_max = (2.0 * math.sin(0.5 * g_max)) ** 2 * 1.0001
    x = np.linspace(0.0, x_max, 8193)
    gamma = 2.0 * np.arcsin(np.clip(np.sqrt(x) / 2.0, 0.0, 1.0))
    return x_max, np.append(cap_overlap_fraction(gamma, a_s, a_d), 0.0)


def _gauss_blur(p: FloatArray, sigma_v: float, sigma_u: float) -> FloatArray:
    """Separable Gaussian blur (sigmas in cells); the rows/cols beyond the edges are zero."""
    out = p
    for axis, sig in ((0, sigma_v), (1, sigma_u)):
        if sig < 0.05:
            continue
        r = math.ceil(4.0 * sig)
        k = np.exp(-0.5 * (np.arange(-r, r + 1) / sig) ** 2)
        k /= k.sum()
        acc = np.zeros_like(out)
        n = out.shape[axis]
        for j, kj in zip(range(-r, r + 1), k, strict=True):
            src = [slice(None)] * 2
            dst = [slice(None)] * 2
            src[axis] = slice(max(0, -j), n - max(0, j))
            dst[axis] = slice(max(0, j), n - max(0, -j))
            acc[tuple(dst)] += kj * out[tuple(src)]
        out = acc
    return out


class TruthOptics:
    """What the instruments see of a :class:`TrueSurface` (see the module docstring).

    Implements ``luminance_pct`` (the :class:`sim.instruments.LuminanceModel` protocol) and
    ``gloss``, plus the spectral reading :meth:`spectral_fraction` the realistic spectro
    uses. Thread-safe (tables are built under a lock).
    """

    def __init__(self, truth: TrueSurface) -> None:
        self.truth = truth
        self.settings = truth.settings
        self._tables: dict[tuple[object, ...], _Table] = {}
        self._lock = threading.Lock()
        self._disk_loaded: set[str] = set()
        self._dirty = False
        self.build_seconds = 0.0
        self.ffts = 0
        self._body = body_reflectance(truth.body)

    # ------------------------------------------------------------------ bands
    def _band_dq(self, lam_um: float) -> float:
        k = 2 * math.pi / lam_um
        sq = max(self.truth.sq_um, 1e-6)
        dq = self.settings.band_phase_rad / (k * sq)
        return min(max(dq, self.settings.min_band_dq), _MAX_BAND_DQ)

    def _bands_for(self, q: float, lam_um: float) -> tuple[tuple[float, float], float]:
        """The two band centres around ``q`` and the linear weight of the upper one."""
        dq = self._band_dq(lam_um)
        j = math.floor(q / dq)
        lo = j * dq
        w = (q - lo) / dq
        return (round(lo, 9), round(lo + dq, 9)), w

    # ------------------------------------------------------------------ tables
    def _pattern(
        self, lam_um: float, qz: float, reach_v: float
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Order powers ``|U|^2/N^2`` of the rows ``|dv| <= reach_v``, with their du and dv
        offsets (ascending)."""
        import scipy.fft

        t = self.truth
        k = 2.0 * math.pi / lam_um
        phase = t.z_um * np.float32(k * qz)
        field = np.empty(phase.shape, dtype=np.complex64)
        np.cos(phase, out=field.real)
        np.sin(phase, out=field.imag)
        del phase
        norm = float(field.size)
        if not t.periodic:
            ny, nx = t.z_um.shape
            wy = np.hanning(ny).astype(np.float32)
            wx = np.hanning(nx).astype(np.float32)
            field *= wy[:, None]
            field *= wx[None, :]
            norm = float(np.sum(wy.astype(np.float64) ** 2) * np.sum(wx.astype(np.float64) ** 2))
        spec = scipy.fft.fft2(field, workers=-1, overwrite_x=True)
        self.ffts += 1
        ny, nx = spec.shape
        fv = np.fft.fftfreq(ny, d=t.step_um) * lam_um
        order = np.argsort(fv, kind="stable")
        rows = order[np.abs(fv[order]) <= reach_v]
        sub = spec[rows]
        power = (sub.real.astype(np.float64) ** 2 + sub.imag.astype(np.float64) ** 2) / (
            norm * spec.size
        )
        power = np.fft.fftshift(power, axes=1)
        du = np.fft.fftshift(np.fft.fftfreq(nx, d=t.step_um)) * lam_um
        return power, du, fv[rows]

    def _build(self, lam_um: float, qz: float, reach_v: float) -> _Table:
        """One table: the order powers of the phase screen at ``qz``, blurred by the
        spot-scale waviness (``qz`` x its rms slope, in direction cosines)."""
        blur = qz * self.settings.waviness_slope_rms
        h_v = lam_um / (self.truth.z_um.shape[0] * self.truth.step_um)
        # rows for the reach, with room for the rescaling by q_exact / qz (<= 1.3)
        p, du, dv = self._pattern(lam_um, qz, 1.3 * reach_v + 4.0 * blur + 2.0 * h_v)
        h_u = float(du[1] - du[0])
        p = _gauss_blur(p, blur / h_v, blur / h_u)
        return _Table(du=du, dv=dv, p=p.astype(np.float32), qz=qz)

    def _table(self, lam_nm: float, qz: float, reach_v: float) -> _Table:
        key = (lam_nm, qz, round(reach_v, 6))
        tab = self._tables.get(key)
        if tab is not None:
            return tab
        with self._lock:
            tab = self._tables.get(key)
            if tab is None:
                self._load_disk()
                tab = self._tables.get(key)
            if tab is None:
                import time

                t0 = time.perf_counter()
                tab = self._build(lam_nm * 1e-3, qz, reach_v)
                self.build_seconds += time.perf_counter() - t0
                self._tables[key] = tab
                self._dirty = True
        return tab

    # ------------------------------------------------------------------ disk cache
    def _cache_file(self) -> Path | None:
        d = self.settings.cache_dir
        if not d:
            return None
        h = hashlib.sha1((self.truth.content_key + self.settings.key()).encode()).hexdigest()[:20]
        return Path(d) / f"twin-{h}.npz"

    def _load_disk(self) -> None:
        path = self._cache_file()
        if path is None or str(path) in self._disk_loaded:
            return
        self._disk_loaded.add(str(path))
        if not path.exists():
            return
        try:
            with np.load(path, allow_pickle=False) as data:
                for i, k in enumerate(data["keys"]):
                    key = tuple(float(x) for x in str(k).split("|"))
                    if len(key) != 3:
                        continue
                    self._tables.setdefault(
                        key, _Table(data[f"u_{i}"], data[f"v_{i}"], data[f"p_{i}"], key[1])
                    )
        except (OSError, ValueError, KeyError):
            return  # a damaged cache is rebuilt

    def save_cache(self) -> None:
        """Write the tables built so far to the disk cache (atomic; no-op without one)."""
        path = self._cache_file()
        if path is None or not self._dirty:
            return
        with self._lock:
            items = list(self._tables.items())
            self._dirty = False
        arrays: dict[str, NDArray[np.generic]] = {
            "keys": np.array(["|".join(repr(float(x)) for x in k) for k, _ in items])  # type: ignore[arg-type]
        }
        for i, (_, tab) in enumerate(items):
            arrays[f"u_{i}"] = tab.du
            arrays[f"v_{i}"] = tab.dv
            arrays[f"p_{i}"] = tab.p
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
            np.savez(tmp, **arrays)  # type: ignore[arg-type]
            os.replace(tmp, path)
        except OSError:
            pass  # the cache is an optimisation

    # ------------------------------------------------------------------ readings
    @staticmethod
    def _reach_v(source: Aperture, detector: Aperture) -> float:
        """Out-of-plane direction cosines an aperture pair can collect from."""
        if isinstance(source, Cone) and isinstance(detector, Cone):
            return math.sin(math.radians(source.half_angle_deg + detector.half_angle_deg))
        if isinstance(source, Rect) and isinstance(detector, Rect):
            return math.sin(math.radians(0.5 * (source.perp_deg + detector.perp_deg)))
        raise TypeError("source and detector must both be Cones or both Rects")

    def _surface_at(
        self, ti_deg: float, tr_deg: FloatArray, source: Aperture, detector: Aperture
    ) -> FloatArray:
        """Surface-reflected flux fraction, shape (n_wavelength_nodes, n_tr).

        Two bands around the reading's own ``q_z = cos ti + cos tr``, each rescaled to it
        (:meth:`_Table.reading`), interpolated linearly in q_z.
        """
        reach = round(self._reach_v(source, detector), 6)
        cos_ti = math.cos(math.radians(ti_deg))
        out = np.zeros((len(self.settings.wavelengths_nm), tr_deg.size))
        for li, lam in enumerate(self.settings.wavelengths_nm):
            for j, tr in enumerate(tr_deg.flat):
                u_d = math.sin(math.radians(float(tr)))
                q = cos_ti + math.cos(math.radians(float(tr)))
                (q_lo, q_hi), w = self._bands_for(q, lam * 1e-3)
                if q_lo <= 0.0:
                    w = 1.0
                acc = 0.0
                for qb, wb in ((q_lo, 1.0 - w), (q_hi, w)):
                    if wb <= 1e-12 or qb <= 0.0:
                        continue
                    tab = self._table(lam, qb, reach)
                    acc += wb * tab.reading(ti_deg, u_d, q, self.truth.n, source, detector)
                out[li, j] = acc
        return out

    def _body_fraction(self, ti_deg: float, tr_deg: FloatArray, detector: Aperture) -> FloatArray:
        """Diffuse body flux fraction per spectrum wavelength, shape (41, n_tr)."""
        n = self.truth.n
        fi = float(fresnel(math.cos(math.radians(ti_deg)), n))
        cos_tr = np.cos(np.radians(tr_deg))
        ft = fresnel(cos_tr, n)
        rb = self._body[:, None]
        saunderson = (1.0 - _R_INTERNAL) * rb / (1.0 - _R_INTERNAL * rb)
        r_ext = _hemispherical_fresnel(n)
        if isinstance(detector, Cone):
            omega = 2 * math.pi * (1 - math.cos(math.radians(detector.half_angle_deg)))
        else:
            omega = math.radians(detector.in_plane_deg) * math.radians(detector.perp_deg)
        ang = (1.0 - ft) / (1.0 - r_ext) * cos_tr * omega / math.pi
        return np.asarray((1.0 - fi) * saunderson * ang[None, :])

    def spectral_fraction(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        *,
        source: Aperture = Cone(6.0),  # noqa: B008 -- frozen dataclass
        detector: Aperture = Cone(6.0),  # noqa: B008
    ) -> FloatArray:
        """Fraction of the incident flux reaching the detector, per wavelength of
        :data:`SPECTRUM_WAVELENGTHS_NM` (surface + body), blocking."""
        tr = np.asarray([theta_r_deg], dtype=np.float64)
        surf = self._surface_at(theta_i_deg, tr, source, detector)[:, 0]
        # shadowing and masking by the coat's own roughness (the Kirchhoff tables have
        # none): Smith's G1 for the lamp and for the detector, felt at grazing angles on
        # rough coats (issue 21: the twin must have what real samples have)
        sigma = self.truth.slope_rms_x
        surf = surf * float(
            smith_shadowing(theta_i_deg, sigma) * smith_shadowing(theta_r_deg, sigma)
        )
        wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
        spec = np.interp(wl, np.asarray(self.settings.wavelengths_nm), surf)
        body = self._body_fraction(theta_i_deg, tr, detector)[:, 0]
        return np.asarray(spec + body)

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: object,
        *,
        source: Aperture = Cone(6.0),  # noqa: B008
        detector: Aperture = Cone(6.0),  # noqa: B008
    ) -> FloatArray:
        """Noise-free luminance reading (10 deg observer, D65) in % of a perfect mirror."""
        return _luminance_pct(self, theta_i_deg, theta_r_deg, source, detector)

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        """ISO 2813 gloss of the truth: flux through the standard's rectangles over that of
        the polished black glass (n = 1.567), weighted with V(lambda) and illuminant C."""
        w = luminance_weights("CIE 1931 2 Degree Standard Observer", "C")
        out: dict[int, float] = {}
        for a in angles_deg:
            key = int(a)
            if key not in ISO2813_RECEPTOR:
                raise ValueError(
                    f"no ISO 2813 geometry at {a} deg; known: {sorted(ISO2813_RECEPTOR)}"
                )
            frac = self.spectral_fraction(
                key, key, source=ISO2813_SOURCE, detector=ISO2813_RECEPTOR[key]
            )
            ref = float(fresnel(math.cos(math.radians(key)), ISO2813_BLACK_GLASS_N))
            out[key] = 100.0 * float(np.dot(w, frac)) / ref
        return out


@functools.lru_cache(maxsize=8)
def _hemispherical_fresnel(n: complex) -> float:
    """Cosine-weighted hemispherical average of the external Fresnel reflectance."""
    t = np.linspace(0.0, math.pi / 2, 2001)
    f = fresnel(np.cos(t), n)
    w = 2.0 * np.sin(t) * np.cos(t)
    return float(np.trapezoid(f * w, t))


@dataclass
class FlatSpecimen:
    """A flat reference specimen under the goniometer: the reference mirror (protected
    aluminium, ``n = None``: reflectance 0.88-0.92 over the visible) or the ISO 2813 black
    glass (``n = 1.567``). Its reading is ``R(ti) x`` the cap overlap of the source image
    and the detector (:func:`goniolab.optics.facet.cap_overlap_fraction`)."""

    n: float | None = None
    name: str = "mirror"
    _cache: dict[str, FloatArray] = field(default_factory=dict)

    def reflectance(self, theta_i_deg: float) -> FloatArray:
        """Spectral reflectance (fraction) at incidence ``theta_i_deg``."""
        wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
        if self.n is None:  # protected Al: ~0.88 in the blue, 0.92 in the red
            return np.asarray(0.88 + 0.04 * (wl - 380.0) / 400.0)
        return np.full(wl.shape, float(fresnel(math.cos(math.radians(theta_i_deg)), self.n)))

    def spectral_fraction(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        *,
        source: Aperture = Cone(6.0),  # noqa: B008
        detector: Aperture = Cone(6.0),  # noqa: B008
    ) -> FloatArray:
        """Flux fraction per wavelength reaching a Cone detector."""
        from goniolab.optics.apertures import cap_overlap_fraction

        if not (isinstance(source, Cone) and isinstance(detector, Cone)):
            raise TypeError("flat specimens are read through Cone apertures")
        gamma = math.radians(abs(theta_r_deg - theta_i_deg))
        frac = float(
            cap_overlap_fraction(
                np.asarray([gamma]),
                math.radians(source.half_angle_deg),
                math.radians(detector.half_angle_deg),
            )[0]
        )
        return np.asarray(self.reflectance(theta_i_deg) * frac)

    def luminance_pct(
        self,
        theta_i_deg: float,
        theta_r_deg: object,
        *,
        source: Aperture = Cone(6.0),  # noqa: B008
        detector: Aperture = Cone(6.0),  # noqa: B008
    ) -> FloatArray:
        """Noise-free luminance in % of a perfect mirror."""
        return _luminance_pct(self, theta_i_deg, theta_r_deg, source, detector)

    def spectral_fraction_sp(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        *,
        source: Aperture = Cone(6.0),  # noqa: B008
        detector: Aperture = Cone(6.0),  # noqa: B008
    ) -> tuple[FloatArray, FloatArray]:
        """The reading of fully s- and of fully p-polarised light (their mean is
        :meth:`spectral_fraction`): the glass's
        Fresnel ``R_s``, ``R_p`` (Born & Wolf sec. 1.5.2); the mirror's table is taken
        as unpolarising (both parts equal)."""
        total = self.spectral_fraction(theta_i_deg, theta_r_deg, source=source, detector=detector)
        if self.n is None:
            return total, total
        from goniolab.optics.fresnel import fresnel_dielectric_sp

        r_s, r_p = fresnel_dielectric_sp(math.cos(math.radians(theta_i_deg)), self.n)
        r = 0.5 * (float(r_s) + float(r_p))
        return total * float(r_s) / r, total * float(r_p) / r


_TRUTHS: dict[tuple[object, ...], TruthOptics] = {}
_TRUTHS_LOCK = threading.Lock()


def truth_for(
    hm: HeightMap, *, n: complex | float, body: str, settings: TwinSettings, name: str
) -> TruthOptics:
    """The (cached per process) :class:`TruthOptics` of a map, built on first use."""
    key = (name, hm.z_um.shape, float(hm.dx_um), complex(n), body, settings.key())
    with _TRUTHS_LOCK:
        optics = _TRUTHS.get(key)
    if optics is None:
        optics = TruthOptics(build_truth(hm, n=n, body=body, settings=settings, name=name))
        with _TRUTHS_LOCK:
            optics = _TRUTHS.setdefault(key, optics)
    return optics
