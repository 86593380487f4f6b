"""The digital twin's hidden truth: what a simulated sample really is, and what it reflects.

The prediction (:class:`goniolab.optics.facet.FacetModel`) sees only the *profilometer map*
of a sample: the STIL MG210 pen of Wittmann et al. (2021, sec. 2.2) samples 1 um steps
with a lateral resolution of about one step and a few nm of height noise. The twin owns a
finer truth that the map only approximates, and computes the instruments' readings from it
with physics the predictor does not share:

* **The true surface** (:class:`~sim.true_surface.TrueSurface`, :mod:`sim.true_surface`), a
  tile finer than the map: the map's band minus the profilometer's noise, plus
  sub-resolution roughness and the spot-scale waviness; its profilometer map is the map the
  predictor uses, to rounding.

* **Scalar Kirchhoff (tangent-plane) scattering** on the true tile, not the facet model,
  integrated over the instrument's apertures in direction-cosine space
  (:mod:`sim.kirchhoff_orders`: :class:`~sim.kirchhoff_orders.OrderTable`, Smith's shadowing). This
  module chooses the q_z bands, builds and caches the tables and adds the body.

* **The body**: light entering the clear coat (1 - F(ti)), reflected diffusely by the body
  (spectral reflectance ``R_b(lambda)``), leaving with 1 - F(tr) after internal
  reflections (Saunderson: ``(1 - r_i) R_b / (1 - r_i R_b)``, ``r_i = 0.6`` for n = 1.5,
  docs/PHYSICS.md, "Colour and the paint layer"), Lambertian: ``R_d cos(tr) Omega_d / pi`` of the
  flux reaches a detector of solid angle ``Omega_d``.

Cost and caching: a table is one FFT of the tile per (q_z band, wavelength), shared by
every incidence angle (the band is rescaled to each reading's own q_z). Tables are kept in
memory and in a disk cache (``cache_dir``), keyed by the truth's content, the settings and
the code that builds them (:func:`table_code_key`), written atomically and pruned
(:mod:`sim.twin_cache`); docs/TWIN.md gives measured build times.

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
from goniolab.optics.heightmap import HeightMap
from sim.kirchhoff_orders import OrderTable, gauss_blur, smith_shadowing
from sim.true_surface import TrueSurface, TwinSettings, build_truth
from sim.twin_flakes import twin_paint
from sim.twin_spectra import (
    BODY_SPECTRA,
    SPECTRUM_WAVELENGTHS_NM,
    body_reflectance,
    luminance_weights,
)

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
    "smith_shadowing",
    "table_code_key",
    "truth_for",
]

FloatArray = NDArray[np.float64]

#: Internal diffuse reflectance of a clear coat of n ~ 1.5 (Saunderson's r_i, PHYSICS.md).
_R_INTERNAL = 0.6

#: Widest q_z band: readings interpolate linearly between neighbouring bands, which is only
#: accurate while they are close (the Debye-Waller factor is not linear in q_z).
_MAX_BAND_DQ = 0.25


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


#: The orders of a flat mirror: all the power in the specular order (the band at q_z = 0).
_MIRROR_ORDERS = OrderTable(
    du=np.array([-1e-3, 0.0, 1e-3]),
    dv=np.array([0.0]),
    p=np.array([[0.0, 1.0, 0.0]], dtype=np.float32),
    qz=1.0,
)


@functools.lru_cache(maxsize=1)
def table_code_key() -> str:
    """What, besides the truth's content and settings, decides a cached table's numbers: the
    source of the modules that build the true tile and its tables (this one,
    :mod:`sim.true_surface`, :mod:`sim.kirchhoff_orders`, the twin's spectra and flakes, the
    optics' heightmap levelling, Fresnel and apertures) and the numpy and scipy versions.

    Part of the disk cache's key. Without it, tables written by another version of the twin
    (another branch, an older checkout: the cache directory is per user, not per checkout)
    were read back as this one's; they differ by up to ~1e-4 relative, and the spectro's
    Poisson noise, whose sampler draws a variable number of uniforms, turns such a change
    into a different noise stream for every later reading: at an instant clock, RMSE 0.250
    or 0.247 % for the same seed (the closing note's "known defect")."""
    import importlib

    import scipy

    # with the optics and twin modules these import (the review of 2026-11-26 found the
    # levelling, Fresnel, apertures, body spectra and flakes missing from the key); by
    # import_module: goniolab.optics exports a function named fresnel
    names = (
        "sim.true_surface",
        "sim.kirchhoff_orders",
        "sim.twin_spectra",
        "sim.twin_flakes",
        "goniolab.optics.heightmap",
        "goniolab.optics.fresnel",
        "goniolab.optics.apertures",
    )
    modules = [__file__, *(str(importlib.import_module(n).__file__) for n in names)]
    h = hashlib.sha1(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    for mod in modules:
        h.update(Path(str(mod)).read_bytes())
    return h.hexdigest()[:16]


class TruthOptics:
    """What the instruments see of a :class:`TrueSurface` (see the module docstring).

    Implements ``luminance_pct`` (the :class:`sim.instruments.LuminanceModel` protocol) and
    ``gloss``, plus the spectral reading :meth:`spectral_fraction` the realistic spectro
    uses. Thread-safe (tables are built under a lock).
    """

    def __init__(self, truth: TrueSurface) -> None:
        self.truth = truth
        self.settings = truth.settings
        self._tables: dict[tuple[object, ...], OrderTable] = {}
        self._lock = threading.Lock()
        self._disk_loaded: set[str] = set()
        self._dirty = False
        self.build_seconds = 0.0
        self.ffts = 0
        self._body = body_reflectance(truth.body)
        self._paint = twin_paint(truth.body)  # a painted truth's flakes (sim/twin_flakes.py)

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

    def _build(self, lam_um: float, qz: float, reach_v: float) -> OrderTable:
        """One table: the order powers of the phase screen at ``qz``, blurred by the
        spot-scale waviness (``qz`` x its rms slope, in direction cosines)."""
        blur = qz * self.settings.waviness_slope_rms
        h_v = lam_um / (self.truth.z_um.shape[0] * self.truth.step_um)
        # rows for the reach, with room for the rescaling by q_exact / qz (<= 1.3)
        p, du, dv = self._pattern(lam_um, qz, 1.3 * reach_v + 4.0 * blur + 2.0 * h_v)
        h_u = float(du[1] - du[0])
        p = gauss_blur(p, blur / h_v, blur / h_u)
        return OrderTable(du=du, dv=dv, p=p.astype(np.float32), qz=qz)

    def _table(self, lam_nm: float, qz: float, reach_v: float) -> OrderTable:
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
        from sim.twin_cache import cache_file

        key = self.truth.content_key + self.settings.key() + table_code_key()
        return cache_file(d, table_code_key(), hashlib.sha1(key.encode()).hexdigest()[:20])

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
                        key, OrderTable(data[f"u_{i}"], data[f"v_{i}"], data[f"p_{i}"], key[1])
                    )
        except (OSError, ValueError, KeyError):
            return  # a damaged cache is rebuilt
        from sim.twin_cache import mark_used

        mark_used(path)  # the least recently used files are pruned first

    def save_cache(self) -> None:
        """Write the tables built so far to the disk cache (atomic; no-op without one),
        then prune the cache (:func:`sim.twin_cache.prune`: other code versions' files
        unused for a day, then the least recently used down to its size cap)."""
        path = self._cache_file()
        if path is None or not self._dirty:
            return
        from sim.twin_cache import prune, write_atomic

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

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as f:  # a file object: np.savez adds no ".npz" to it
                np.savez(f, **arrays)  # type: ignore[arg-type]

        try:
            write_atomic(path, write)
            prune(path.parent, code_key=table_code_key(), keep=path)
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
        (:meth:`OrderTable.reading`), interpolated linearly in q_z; below the first band,
        the flat mirror and the first band, weighted for the tile's coherent share.
        """
        reach = round(self._reach_v(source, detector), 6)
        cos_ti = math.cos(math.radians(ti_deg))
        out = np.zeros((len(self.settings.wavelengths_nm), tr_deg.size))
        for li, lam in enumerate(self.settings.wavelengths_nm):
            for j, tr in enumerate(tr_deg.flat):
                u_d = math.sin(math.radians(float(tr)))
                q = cos_ti + math.cos(math.radians(float(tr)))
                (q_lo, q_hi), w = self._bands_for(q, lam * 1e-3)
                acc = 0.0
                if q_lo <= 0.0:
                    # below the first band (grazing: G85's q_z = 0.174): the band at q_z = 0
                    # is the flat mirror (all power coherent); mixed with the first band so
                    # that the coherent share is the tile's own at this q_z (the first band
                    # alone carried its own, 0.45 against 0.72 for wittmann-3 at 85 deg)
                    c_q, c_hi = (
                        float(self.coherent_share(np.array([lam]), q)[0]),
                        float(self.coherent_share(np.array([lam]), q_hi)[0]),
                    )
                    w = 1.0 if c_hi >= 1.0 - 1e-9 else min(1.0, max(0.0, (1 - c_q) / (1 - c_hi)))
                    if w < 1.0:
                        acc += (1.0 - w) * _MIRROR_ORDERS.reading(
                            ti_deg, u_d, q, self.truth.n, source, detector
                        )
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

    def shadowing(self, theta_i_deg: float, theta_r_deg: float) -> tuple[float, FloatArray]:
        """Shadowing and masking by the coat's own roughness, which the Kirchhoff tables
        lack (issue 21: the twin must have what real samples have), on the light the
        roughness scatters only: ``(G, C)``.

        ``G = G1(theta_i) G1(theta_r)``, Smith's function of the tile's rms slope
        (:func:`smith_shadowing`), multiplies the diffuse part of a reading;
        ``C = |<exp(i k q_z z)>|^2`` per wavelength node is the coherent share of the
        reflection, the characteristic function of the tile's heights at
        ``q_z = cos theta_i + cos theta_r`` (Beckmann & Spizzichino ch. 5; ``exp(-g)`` for
        Gaussian heights): the coherent beam, ``C`` times what a flat mirror of the coat
        reads there, is not shadowed (:meth:`spectral_fraction`). Shadowing is geometric
        optics: a bump casts a shadow only where it is optically rough at that geometry.
        The coherent beam of a coat optically smooth at grazing incidence (wittmann-3 at
        85 deg, ``g = 0.38``) passes its filler bumps, whose shadows, 0.3 um tall and 3 um
        long at 5 deg elevation, are washed out by diffraction (Fresnel number
        ``h^2 / (lambda L)`` ~ 0.05); a coat rough at that geometry (``C`` -> 0) gets
        Smith's factor whole. The earlier factor on all of the reflection cut the twin's
        G85 of wittmann-3 from 60.0 to 26.7 GU, below the unmasked facet prediction
        (36.3 GU), where Wittmann et al. (2021, fig. 9b, sec. 5.4) measure the silica
        samples' G85 above it."""
        sigma = self.truth.slope_rms_x
        g2 = float(smith_shadowing(theta_i_deg, sigma) * smith_shadowing(theta_r_deg, sigma))
        nodes = np.asarray(self.settings.wavelengths_nm, dtype=np.float64)
        if g2 >= 1.0:
            return 1.0, np.ones_like(nodes)
        q = math.cos(math.radians(theta_i_deg)) + math.cos(math.radians(abs(theta_r_deg)))
        return g2, self.coherent_share(nodes, q)

    def coherent_share(self, wavelengths_nm: FloatArray, qz: float) -> FloatArray:
        """``|<exp(i k q_z z)>|^2`` over the tile per wavelength, from its height histogram
        (8192 bins: the phase within a bin varies by under 0.05 rad for the tiles here)."""
        counts, centres = self._height_histogram
        k = 2.0 * math.pi / (np.asarray(wavelengths_nm, dtype=np.float64) * 1e-3)
        phase = np.outer(k * qz, centres)
        p = counts / counts.sum()
        mean = (np.cos(phase) @ p) + 1j * (np.sin(phase) @ p)
        return np.asarray(np.abs(mean) ** 2)

    @functools.cached_property
    def _height_histogram(self) -> tuple[FloatArray, FloatArray]:
        z = np.asarray(self.truth.z_um, dtype=np.float64).ravel()
        counts, edges = np.histogram(z, bins=8192)
        return counts.astype(np.float64), 0.5 * (edges[:-1] + edges[1:])

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
        g2, coherent = self.shadowing(theta_i_deg, theta_r_deg)
        if g2 < 1.0:
            # the coherent beam's part of the reading: the tile's coherent share of what a
            # flat mirror of the coat reads here (the source image in the detector)
            q = math.cos(math.radians(theta_i_deg)) + math.cos(math.radians(theta_r_deg))
            mirror = _MIRROR_ORDERS.reading(
                theta_i_deg, math.sin(math.radians(theta_r_deg)), q, self.truth.n, source, detector
            )
            beam = np.minimum(coherent * mirror, surf)
            surf = beam + g2 * (surf - beam)
        wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
        spec = np.interp(wl, np.asarray(self.settings.wavelengths_nm), surf)
        body = self._body_fraction(theta_i_deg, tr, detector)[:, 0]
        if self._paint is not None:
            body = body + self._paint.flake_fraction(
                theta_i_deg,
                theta_r_deg,
                source=source,
                detector=detector,
                n=float(np.real(self.truth.n)),
            )
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
