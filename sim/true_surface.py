"""The twin's true surface: the sample as it really is, finer than its profilometer map.

The prediction (:class:`goniolab.optics.facet.FacetModel`) sees only the *profilometer map*
of a sample: the STIL MG210 pen of Wittmann et al. (2021, sec. 2.2) samples 1 um steps
with a lateral resolution of about one step and a few nm of height noise. The twin owns a
finer truth that the map only approximates (:func:`build_truth`, settings
:class:`TwinSettings`; its optics are :mod:`sim.truth`):

**The true surface** (:class:`TrueSurface`), a tile finer than the map
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

References
----------
.. [1] B. Wittmann et al., Prog. Org. Coat. 156 (2021) 106247, sec. 2.2.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.heightmap import HeightMap, fill_missing, level_plane
from sim.twin_spectra import body_reflectance

__all__ = ["TRUTH_VERSION", "TrueSurface", "TwinSettings", "build_truth"]

FloatArray = NDArray[np.float64]

#: Version of the truth's physics: part of the disk-cache key (bump it when tables change).
TRUTH_VERSION = 2


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
                TRUTH_VERSION,
                self.seed,
            )
        )


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
    """The built-in samples are generated periodic (goniolab.surfaces.synthetic)."""
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
