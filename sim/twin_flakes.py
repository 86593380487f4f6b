"""The twin's own truth of a painted sample: effect flakes in a pigmented binder under the coat.

A real metallic paint is a clear coat over a binder carrying aluminium flakes: small mirrors
lying nearly parallel to the panel, their normals spread around the panel normal by the
spraying and the film's shrinkage. Near the specular direction they return a strong lobe
(the *flop* of a metallic: bright at 15 deg aspecular, dark at 110), and the pigmented
binder returns a diffuse body. The prediction models that with
:mod:`goniolab.colour.paint` (Durikovic et al. 2007). The twin does **not** call it: it is
the lab's independent hidden truth, with its own description of the same physics, its own
material tables and a batch that differs from the paint's nominal recipe as a real panel
does (a few % in the flake orientation, coverage and binder), so that a scan differs from
the prediction as a real lab's would.

The truth of a painted sample (:class:`TwinPaint`, named in :data:`TWIN_PAINTS`; a library
sample points at it with its ``body`` key in ``configs/samples.toml``):

* **Flakes**: a population of flat mirrors covering the area fraction ``coverage`` of the
  panel (projected on it). Their normals ``m`` are a *Gaussian* population of tilt angles:
  the two tilt components (about x and y) are independent normals of sd ``sigma =
  tilt_rms_deg / sqrt(2)``, i.e. per solid angle
  ``p(m) = exp(-t^2 / (2 sigma^2)) t / (2 pi sigma^2 sin t) / Z`` (t the tilt, Z the share
  above the horizon). (The prediction uses a Beckmann distribution in ``tan t``.)
* **Reflection by a flake** inside the coat (index n): light arrives along ``wi'`` (Snell
  refraction of the lamp direction), a flake of normal m intercepts the flux in proportion
  to its area times ``wi'.m``, and mirrors it into ``wo' = 2 (wi'.m) m - wi'``. With the
  Jacobian ``dOmega_o = 4 (wi'.m) dOmega_m`` of the mirror map (Torrance & Sparrow 1967) the
  inside radiance factor is

      f'(wi', wo') = A rho(wi'.h) p(h) / (4 cos t_h cos t_i' cos t_o'),  h = (wi' + wo') / |.|

  whose hemispherical integral ``int f' cos t_o' dOmega_o'`` is exactly ``A rho`` for a
  flat ``rho`` (no flakes below the horizon, no total internal reflection): the lobe
  creates no light (tests/sim/test_twin_flakes.py).
* **Through the clear coat**: the lamp's light enters with ``1 - F(t_i)`` and leaves with
  ``1 - F(t_o)`` (Fresnel of the coat, Born & Wolf sec. 1.5.2); radiance over n^2 is
  conserved across the interface (the solid-angle compression of Snell's law, Nicodemus
  1963), so outside ``f = (1 - F(t_i)) (1 - F(t_o)) f' / n^2``. Directions refracted beyond
  the critical angle never leave (they are not in any outside aperture).
* **The flake's reflectance** ``rho``: Fresnel of aluminium against the binder with the
  complex index of Palik's handbook (Shiles et al. 1980) times the flakes' surface quality
  (milled flakes carry an oxide and a lubricant film: a few % below bulk aluminium).
* **The binder above the flakes** (``depth_um``) takes the specular light out of the beam
  on the way down and up: ``exp(-mu X' (1/cos t_i' + 1/cos t_o'))`` with the collimated
  extinction ``mu = K/2 + S`` (Kubelka 1948: diffuse light crosses a layer along twice its
  thickness on average, K = 2 alpha; every scattered photon leaves the mirror beam). What
  it scatters back is diffuse and joins the body.
* **The body**: the pigmented binder between the flakes as a Kubelka-Munk layer of its own
  K, S tables over the primer (the hyperbolic solution, Kubelka 1948 eq. 14 in Judd &
  Wyszecki's notation), plus the backscatter of the binder above the flakes:
  ``R_d = (1 - A) R_binder + A R_above``. The truth passes R_d through the same Saunderson
  interface as every twin body (:mod:`sim.truth`).

Left out (a real paint has them; they are small for the silver): flake-flake and
flake-body inter-reflections, light the coat's surface returns to the flakes, the flakes'
edges and the coat's dispersion (the coat index is the sample's ``n``).

References
----------
.. [1] R. Durikovic, K. Kolchin, S. Ershov, "Prediction of optical properties of paints",
   Cent. Eur. J. Phys. 5 (2007) 416, secs. 5.1-5.3 (flakes as small mirrors in the binder).
.. [2] K. E. Torrance, E. M. Sparrow, JOSA 57 (1967) 1105 (the facet Jacobian 1 / (4 wi.h)).
.. [3] E. Shiles, T. Sasaki, M. Inokuti, D. Y. Smith, Phys. Rev. B 22 (1980) 1612;
   E. D. Palik (ed.), Handbook of Optical Constants of Solids (1985): aluminium n, k.
.. [4] P. Kubelka, JOSA 38 (1948) 448; D. B. Judd, G. Wyszecki, Color in Business, Science
   and Industry, 3rd ed. (1975), ch. 8 (hyperbolic KM solution).
.. [5] F. E. Nicodemus, "Radiance", Am. J. Phys. 31 (1963) 368 (L / n^2 across an interface).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from goniolab.optics.apertures import Aperture, Cone, Rect
from sim.twin_spectra import SPECTRUM_WAVELENGTHS_NM

__all__ = [
    "MICA_INDEX",
    "TWIN_PAINTS",
    "TwinPaint",
    "aluminium_index",
    "direction",
    "rutile_index",
    "twin_paint",
]

FloatArray = NDArray[np.float64]

_WL = np.asarray(SPECTRUM_WAVELENGTHS_NM, dtype=np.float64)

#: Aluminium n, k (Palik's handbook, Shiles et al. 1980), the twin's own table, 100 nm nodes.
_AL_NM = (400.0, 500.0, 600.0, 700.0, 800.0)
_AL_N = (0.49, 0.77, 1.20, 1.83, 2.80)
_AL_K = (4.86, 6.08, 7.26, 8.31, 8.45)


def aluminium_index(wavelengths_nm: FloatArray = _WL) -> NDArray[np.complex128]:
    """Complex index ``n + ik`` of aluminium, linear between Palik's nodes (ends held)."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    return np.asarray(np.interp(wl, _AL_NM, _AL_N) + 1j * np.interp(wl, _AL_NM, _AL_K))


def _fresnel(cos_i: FloatArray, n1: float, n2: complex | NDArray[np.complex128]) -> FloatArray:
    """Unpolarised Fresnel reflectance from medium ``n1`` (real) onto ``n2`` (complex allowed)
    at incidence cosine ``cos_i`` (Born & Wolf sec. 1.5.2 and 14.2)."""
    c = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    n2c = np.asarray(n2, dtype=np.complex128)
    sin2 = 1.0 - c * c
    cos_t = np.sqrt(1.0 - (n1 / n2c) ** 2 * sin2 + 0j)
    rs = (n1 * c - n2c * cos_t) / (n1 * c + n2c * cos_t)
    rp = (n2c * c - n1 * cos_t) / (n2c * c + n1 * cos_t)
    return np.asarray(0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2), dtype=np.float64)


def rutile_index(wavelengths_nm: FloatArray = _WL) -> FloatArray:
    """Ordinary index of rutile TiO2, DeVore's Sellmeier fit
    ``n^2 = 5.913 + 0.2441 / (lambda^2 - 0.0803)`` (lambda in um; JOSA 41 (1951) 416)."""
    lam2 = (np.asarray(wavelengths_nm, dtype=np.float64) * 1e-3) ** 2
    return np.asarray(np.sqrt(5.913 + 0.2441 / (lam2 - 0.0803)))


#: Muscovite mica, the platelets' core (beta index 1.58-1.61: Deer, Howie & Zussman, Rock-
#: Forming Minerals vol. 3).
MICA_INDEX = 1.59


def _film_reflectance(
    cos_0: FloatArray, n0: float, n1: FloatArray, d_nm: float, n2: float
) -> FloatArray:
    """Unpolarised reflectance of a lossless film (index ``n1`` per wavelength, thickness
    ``d_nm``) between ``n0`` and ``n2``, light arriving at cosine ``cos_0`` in ``n0``:
    Airy's sum ``r = (r01 + r12 e^{2i beta}) / (1 + r01 r12 e^{2i beta})``,
    ``beta = 2 pi n1 d cos t1 / lambda`` (Born & Wolf sec. 7.6.1), ``(..., 41)``."""
    c0 = np.clip(np.asarray(cos_0, dtype=np.float64), 0.0, 1.0)
    s2 = 1.0 - c0 * c0
    c1 = np.sqrt(1.0 - (n0 / n1) ** 2 * s2 + 0j)
    c2 = np.sqrt(1.0 - (n0 / n2) ** 2 * s2 + 0j)
    beta = 2.0 * np.pi * n1 * d_nm * c1 / _WL
    ph = np.exp(2j * beta)
    out = np.zeros(np.broadcast(c0, n1).shape)
    for r01, r12 in (
        ((n0 * c0 - n1 * c1) / (n0 * c0 + n1 * c1), (n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2)),
        ((n1 * c0 - n0 * c1) / (n1 * c0 + n0 * c1), (n2 * c1 - n1 * c2) / (n2 * c1 + n1 * c2)),
    ):
        out = out + 0.5 * np.abs((r01 + r12 * ph) / (1.0 + r01 * r12 * ph)) ** 2
    return np.asarray(out)


def _platelet(cos_0: FloatArray, n_binder: float, film_nm: float) -> FloatArray:
    """Reflectance of a pearl platelet in the binder: the TiO2 film on the near face, the
    mica (too thick for coherence) and the film on the far face, summed incoherently
    ``R = R1 + (1 - R1)^2 R2 / (1 - R1 R2)`` (lossless films: T = 1 - R), ``(..., 41)``."""
    n1 = rutile_index()
    r1 = _film_reflectance(cos_0, n_binder, n1, film_nm, MICA_INDEX)
    c_m = np.sqrt(
        np.clip(1.0 - (1.0 - np.clip(cos_0, 0, 1) ** 2) * (n_binder / MICA_INDEX) ** 2, 0, 1)
    )
    r2 = _film_reflectance(c_m, MICA_INDEX, n1, film_nm, n_binder)
    return np.asarray(r1 + (1.0 - r1) ** 2 * r2 / (1.0 - r1 * r2))


def _km_reflectance(k: FloatArray, s: FloatArray, x_um: float, r_g: FloatArray) -> FloatArray:
    """Kubelka-Munk reflectance of a layer of thickness ``x_um`` over a substrate ``r_g``:
    ``(1 - r_g (a - b coth bSX)) / (a - r_g + b coth bSX)``, ``a = 1 + K/S``,
    ``b = sqrt(a^2 - 1)`` (Judd & Wyszecki ch. 8)."""
    a = 1.0 + k / s
    b = np.sqrt(a * a - 1.0)
    if x_um <= 0.0:
        return np.asarray(r_g * np.ones_like(a))
    coth = 1.0 / np.tanh(np.maximum(b * s * x_um, 1e-12))
    return np.asarray((1.0 - r_g * (a - b * coth)) / (a - r_g + b * coth))


def direction(theta_deg: FloatArray, beta_deg: FloatArray) -> FloatArray:
    """Unit vectors ``(..., 3)`` at signed in-plane angle ``theta`` from the normal (x > 0 on
    the specular side) and out-of-plane angle ``beta``: ``(sin t cos b, sin b, cos t cos b)``."""
    t = np.radians(np.asarray(theta_deg, dtype=np.float64))
    b = np.radians(np.asarray(beta_deg, dtype=np.float64))
    return np.stack([np.sin(t) * np.cos(b), np.sin(b), np.cos(t) * np.cos(b)], axis=-1)


def _aperture_points(
    aperture: Aperture, theta_deg: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Quadrature of an aperture centred on the in-plane angle ``theta_deg``: in-plane and
    out-of-plane angles (deg) and solid-angle weights (sr, ``cos b dt db``)."""
    if isinstance(aperture, Cone):
        a = aperture.half_angle_deg
        if a <= 0.0:
            return np.array([theta_deg]), np.array([0.0]), np.array([1.0])
        # Gauss-Legendre in r^2 (equal area rings) x 12 azimuths: exact for smooth integrands
        # to the order the lobe needs across a 3 deg aperture
        x, w = np.polynomial.legendre.leggauss(4)
        r = a * np.sqrt(0.5 * (x + 1.0))
        wr = 0.5 * w * 0.5  # d(r^2)/2 over [0, a^2] mapped from [-1, 1], per unit area
        phi = (np.arange(12) + 0.5) * (2.0 * math.pi / 12)
        rr, pp = np.meshgrid(r, phi, indexing="ij")
        ww = np.broadcast_to(wr[:, None], rr.shape) * (2.0 * math.pi / 12) * a * a
        dt = (rr * np.cos(pp)).ravel()
        db = (rr * np.sin(pp)).ravel()
        wts = ww.ravel() * np.radians(1.0) ** 2 * np.cos(np.radians(db))
    elif isinstance(aperture, Rect):
        nt, nb = 7, 9
        ht, hb = 0.5 * aperture.in_plane_deg, 0.5 * aperture.perp_deg
        gt = (np.arange(nt) + 0.5) / nt * 2.0 * ht - ht
        gb = (np.arange(nb) + 0.5) / nb * 2.0 * hb - hb
        tt, bb = np.meshgrid(gt, gb, indexing="ij")
        dt, db = tt.ravel(), bb.ravel()
        cell = math.radians(2.0 * ht / nt) * math.radians(2.0 * hb / nb)
        wts = np.full(dt.shape, cell) * np.cos(np.radians(db))
    else:  # pragma: no cover - Aperture is Cone | Rect
        raise TypeError(f"unknown aperture {aperture!r}")
    return theta_deg + dt, db, np.asarray(wts, dtype=np.float64)


@dataclass(frozen=True, slots=True)
class TwinPaint:
    """One painted sample's truth (see the module docstring).

    Parameters
    ----------
    name
        The name a sample's ``body`` key gives.
    coverage
        Area fraction of the panel covered by flakes (projected), 0..1.
    tilt_rms_deg
        rms tilt of the flake normals from the panel normal (2-D Gaussian population).
    depth_um
        Pigmented binder above the flakes.
    k_per_um, s_per_um
        The binder's Kubelka-Munk K and S per um at :data:`SPECTRUM_WAVELENGTHS_NM` nodes
        ``k_nm`` (linear between, ends held).
    binder_um
        Binder thickness between the flakes, over the primer of reflectance ``primer``.
    flake_quality
        The flakes' reflectance relative to bulk aluminium.
    """

    name: str
    coverage: float
    tilt_rms_deg: float
    depth_um: float
    k_nm: tuple[float, ...]
    k_per_um: tuple[float, ...]
    s_per_um: tuple[float, ...]
    binder_um: float
    primer: float
    flake_quality: float = 0.97
    #: ``"aluminium"`` (metal mirrors) or ``"pearl"`` (rutile TiO2 film on a mica platelet)
    flake: str = "aluminium"
    #: the pearl's TiO2 film thickness (nm)
    film_nm: float = 0.0

    def __post_init__(self) -> None:
        if self.flake not in ("aluminium", "pearl"):
            raise ValueError(f"twin paint {self.name}: flake must be 'aluminium' or 'pearl'")
        if self.flake == "pearl" and not self.film_nm > 0.0:
            raise ValueError(f"twin paint {self.name}: a pearl needs film_nm > 0")
        if not 0.0 <= self.coverage <= 1.0:
            raise ValueError(f"twin paint {self.name}: coverage must be in [0, 1]")
        if not 0.05 <= self.tilt_rms_deg <= 45.0:
            raise ValueError(f"twin paint {self.name}: tilt_rms_deg must be in [0.05, 45]")
        if not (len(self.k_nm) == len(self.k_per_um) == len(self.s_per_um) >= 1):
            raise ValueError(f"twin paint {self.name}: one K and one S per node")

    # ------------------------------------------------------------------ materials
    def ks(self) -> tuple[FloatArray, FloatArray]:
        """The binder's K and S per um on the spectrum grid."""
        k = np.interp(_WL, self.k_nm, self.k_per_um)
        s = np.interp(_WL, self.k_nm, self.s_per_um)
        return np.asarray(k), np.asarray(s)

    def extinction_per_um(self) -> FloatArray:
        """Collimated extinction of the binder, ``K/2 + S`` per um (module docstring)."""
        k, s = self.ks()
        return np.asarray(0.5 * k + s)

    def diffuse_reflectance(self) -> FloatArray:
        """``R_d = (1 - A) R_binder + A R_above`` under the coat (fraction, 41 values)."""
        k, s = self.ks()
        r_binder = _km_reflectance(k, s, self.binder_um, np.full(_WL.shape, self.primer))
        r_above = _km_reflectance(k, s, self.depth_um, np.zeros(_WL.shape))
        return np.asarray((1.0 - self.coverage) * r_binder + self.coverage * r_above)

    def flake_reflectance(self, cos_local: FloatArray, n_binder: float) -> FloatArray:
        """``rho``: the flake's reflectance against the binder, ``(..., 41)``."""
        c = np.asarray(cos_local, dtype=np.float64)[..., None]
        if self.flake == "pearl":
            return _platelet(c, n_binder, self.film_nm)
        return np.asarray(self.flake_quality * _fresnel(c, n_binder, aluminium_index()))

    def tilt_pdf(self, cos_tilt: FloatArray) -> FloatArray:
        """Density of flake normals per solid angle at tilt ``acos(cos_tilt)`` (sr^-1),
        normalised over the upper hemisphere."""
        sigma = math.radians(self.tilt_rms_deg) / math.sqrt(2.0)
        t = np.arccos(np.clip(np.asarray(cos_tilt, dtype=np.float64), -1.0, 1.0))
        z = 1.0 - math.exp(-((0.5 * math.pi) ** 2) / (2.0 * sigma * sigma))
        ratio = np.where(t > 1e-9, t / np.maximum(np.sin(t), 1e-300), 1.0)
        out = np.exp(-(t * t) / (2.0 * sigma * sigma)) * ratio / (2.0 * math.pi * sigma**2 * z)
        return np.asarray(np.where(t <= 0.5 * math.pi, out, 0.0))

    # ------------------------------------------------------------------ the lobe
    def inside_brdf(self, wi_in: FloatArray, wo_in: FloatArray, n: float) -> FloatArray:
        """The flakes' radiance factor inside the coat (sr^-1), ``(..., 41)``, for upward
        unit vectors ``wi_in``, ``wo_in`` (towards where the light comes from and goes)."""
        wi = np.asarray(wi_in, dtype=np.float64)
        wo = np.asarray(wo_in, dtype=np.float64)
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        cos_h = h[..., 2]
        cos_d = np.clip(np.sum(wi * h, axis=-1), 0.0, 1.0)
        ci = np.maximum(wi[..., 2], 1e-9)
        co = np.maximum(wo[..., 2], 1e-9)
        geom = self.coverage * self.tilt_pdf(cos_h) / (4.0 * np.maximum(cos_h, 1e-9) * ci * co)
        rho = self.flake_reflectance(cos_d, n)
        mu = self.extinction_per_um()
        path = self.depth_um * (1.0 / ci + 1.0 / co)
        atten = np.exp(-path[..., None] * mu)
        return np.asarray(geom[..., None] * rho * atten)

    def outside_brdf(self, wi: FloatArray, wo: FloatArray, n: float) -> FloatArray:
        """The flakes' BRDF seen outside the coat (sr^-1), ``(..., 41)``:
        ``(1 - F(t_i)) (1 - F(t_o)) f'(wi', wo') / n^2`` with Snell's refracted directions."""
        wi_a = np.asarray(wi, dtype=np.float64)
        wo_a = np.asarray(wo, dtype=np.float64)
        t_i = 1.0 - _fresnel(wi_a[..., 2], 1.0, complex(n))
        t_o = 1.0 - _fresnel(wo_a[..., 2], 1.0, complex(n))
        f_in = self.inside_brdf(_refract(wi_a, n), _refract(wo_a, n), n)
        return np.asarray((t_i * t_o)[..., None] * f_in / (n * n))

    def flake_fraction(
        self,
        theta_i_deg: float,
        theta_r_deg: float,
        *,
        source: Aperture,
        detector: Aperture,
        n: float,
    ) -> FloatArray:
        """Fraction of the lamp's flux the flakes send into the detector, per wavelength of
        :data:`SPECTRUM_WAVELENGTHS_NM`: the lamp's directions averaged over the source
        aperture (equal flux per solid angle), ``int f cos t_o dOmega_o`` over the detector's."""
        ts, bs, ws = _aperture_points(source, -float(theta_i_deg))
        td, bd, wd = _aperture_points(detector, float(theta_r_deg))
        wi = direction(ts, bs)[:, None, :]
        wo = direction(td, bd)[None, :, :]
        f = self.outside_brdf(np.broadcast_to(wi, (ts.size, td.size, 3)), wo, n)
        cos_o = np.clip(wo[..., 2], 0.0, None)
        w = (ws / ws.sum())[:, None] * wd[None, :] * cos_o
        return np.asarray(np.einsum("sd,sdl->l", w, f))


def _refract(w: FloatArray, n: float) -> FloatArray:
    """Upward direction inside the coat of an outside direction (Snell): ``(x/n, y/n, z')``."""
    xy = w[..., :2] / n
    z = np.sqrt(np.clip(1.0 - np.sum(xy * xy, axis=-1, keepdims=True), 0.0, 1.0))
    return np.concatenate([xy, z], axis=-1)


#: The twin's painted samples. ``silver-metallic``: the batch behind the library's
#: sample:silver-metallic (recipe: coverage 0.55, rms tilt 7 deg, 0.5 um of binder over the
#: flakes, K 0.3, S 0.25 per um): this batch's flakes lie a little more ordered (6.9 deg
#: rms, Gaussian in the tilt angle) and a little denser, its carbon-black binder is slightly
#: more absorbing and scattering in the blue.
TWIN_PAINTS: dict[str, TwinPaint] = {
    "silver-metallic": TwinPaint(
        name="silver-metallic",
        coverage=0.56,
        tilt_rms_deg=6.9,
        depth_um=0.5,
        k_nm=(380.0, 580.0, 780.0),
        k_per_um=(0.33, 0.31, 0.29),
        s_per_um=(0.26, 0.25, 0.24),
        binder_um=20.0,
        primer=0.3,
    ),
    #: behind sample:pearl (recipe: TiO2-on-mica, 140 nm film of n 2.55 at 550 nm, coverage
    #: 0.5, rms tilt 8 deg, a dark binder K 2.0, S 0.5): this batch's film is rutile
    #: (DeVore's index, 2.65 at 550 nm) 135 nm thick -- the same optical thickness at 550
    #: nm, more dispersion in the blue -- and its platelets lie a little more ordered.
    "pearl": TwinPaint(
        name="pearl",
        coverage=0.5,
        tilt_rms_deg=7.9,
        depth_um=0.0,
        k_nm=(380.0, 580.0, 780.0),
        k_per_um=(2.1, 2.0, 1.9),
        s_per_um=(0.5, 0.5, 0.5),
        binder_um=20.0,
        primer=0.05,
        flake="pearl",
        film_nm=135.0,
    ),
}


def twin_paint(name: str) -> TwinPaint | None:
    """The twin paint of that name, or ``None`` (a plain body of :mod:`sim.twin_spectra`)."""
    return TWIN_PAINTS.get(name)
