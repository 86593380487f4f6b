"""A rendered picture of a painted sample: a curved panel or a sphere under one or two lamps.

Both seeds show their paints as pictures (Durikovic et al. 2007, sec. 7 and figs. 7-9; Mihalik
& Durikovic, fig. 6: a virtual sample under D65). Here every pixel is what a tiny virtual
goniospectrophotometer would read at that point of the shape: the predicted spectral BRDF
for the pixel's lamp and view directions, integrated with the illuminant and observer.

The BRDF (sr^-1, per wavelength) is

- the coat surface's gloss: a Beckmann microfacet lobe (Walter et al. 2007, eqs. 20, 25, 27)
  with ``alpha`` = the map's total rms slope Sdq (the facet model's slope statistics) and the
  coat's n(lambda) in the Fresnel factor; a lamp of angular radius rho broadens the lobe:
  a uniform disc of directions adds rho^2/4 per axis, the half vector half of that angle, so
  the per-axis slope variance alpha^2/2 grows by rho^2/16: ``alpha_eff^2 = alpha^2 + rho^2/8``;
- plus everything beneath: :meth:`goniolab.colour.paint.Paint.subsurface_brdf` (Kubelka-Munk
  body with Saunderson's interface, metallic and pearl flakes).

The BRDF is tabulated once, converted to XYZ (the E308 weights of :func:`xyz_weights`: linear
in the spectrum), over Rusinkiewicz's half/difference angles (theta_h, theta_d, phi_d)
of an isotropic BRDF (S. Rusinkiewicz, "A new change of variables for efficient BRDF
representation", EGWR 1998), with theta_h sampled on a square-root scale (dense near the
gloss peak) as Matusik et al.'s MERL tables are; each pixel then looks its (theta_h,
theta_d, phi_d) up by trilinear interpolation. A pixel's XYZ is
``pi sum_k E_k cos(theta_i,k) f_XYZ``, so that a perfect white diffuser lit along its normal
by a lamp of E = 1 reads Y = 100.

Scenes (orthographic camera along +z, image rows top to bottom):

- ``panel``: a cylindrical panel bent about the horizontal axis, normal
  ``(0, sin b, cos b)`` with b from +35 deg (top row) to -35 deg (bottom row); the key lamp lies
  in the bending plane 45 deg above the view axis, so the centre row is the ASTM E2194 45 deg
  aspecular geometry (theta_i = 45, theta_r = 0) and the rows span about -25 to 115 deg
  aspecular (the specular band at b = 22.5 deg);
- ``sphere``: a sphere filling the frame (background black).

References
----------
.. [1] R. Durikovic, K. Kolchin, S. Ershov, Cent. Eur. J. Phys. 5 (2007) 416, sec. 7.
.. [2] A. Mihalik, R. Durikovic, "Virtual gonio-spectrophotometer", sec. 4, fig. 6.
.. [3] S. Rusinkiewicz, EGWR 1998; W. Matusik et al., "A data-driven reflectance model",
   SIGGRAPH 2003 (theta_h on a square-root scale).
.. [4] B. Walter et al., EGSR 2007, eqs. 20, 25, 27.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from goniolab.colour.optics import fresnel_unpolarised
from goniolab.colour.paint import MetallicFlakes, Paint, PearlFlakes
from goniolab.colour.spectra import ColourSettings, xyz_weights

__all__ = [
    "LAMPS",
    "BrdfTable",
    "Render",
    "Shape",
    "render",
    "tabulate_brdf",
]

FloatArray = NDArray[np.float64]
Shape = Literal["panel", "sphere"]


def _unit(v: tuple[float, float, float]) -> FloatArray:
    a = np.asarray(v, dtype=np.float64)
    out: FloatArray = a / np.linalg.norm(a)
    return out


#: (direction towards the lamp, irradiance) of the key lamp and the fill lamp: the key lies
#: 45 deg above the view axis in the panel's bending plane; the fill, at half the irradiance,
#: low on the left.
LAMPS: tuple[tuple[FloatArray, float], ...] = (
    (_unit((0.0, math.sin(math.radians(45.0)), math.cos(math.radians(45.0)))), 1.0),
    (_unit((-0.55, -0.35, 0.76)), 0.5),
)
#: Half the bending angle of the panel (deg).
PANEL_HALF_ANGLE_DEG = 35.0


@dataclass(frozen=True)
class BrdfTable:
    """XYZ of the BRDF (Y = 100 x the BRDF of a unit reflectance, per sr) on a grid of
    (theta_h on a square-root scale, theta_d, phi_d in [0, pi])."""

    xyz: FloatArray  # (n_h, n_d, n_phi, 3)
    #: The flake lobes alone, one table per flake population (for the sparkle texture).
    flakes_xyz: tuple[FloatArray, ...] = ()
    #: The populations (:class:`goniolab.colour.paint.MetallicFlakes` / ``PearlFlakes``).
    flakes: tuple[MetallicFlakes | PearlFlakes, ...] = ()
    #: Coat index at 550 nm and the lamp's angular radius the table was made for.
    n_coat: float = 1.5
    lamp_radius_deg: float = 3.0

    def lookup(
        self,
        theta_h: FloatArray,
        theta_d: FloatArray,
        phi_d: FloatArray,
        table: FloatArray | None = None,
    ) -> FloatArray:
        """Trilinear interpolation at the given angles (radians), ``(..., 3)``."""
        from scipy.ndimage import map_coordinates  # lazy: scipy is slow to import

        data = self.xyz if table is None else table
        n_h, n_d, n_p, _ = data.shape
        half = 0.5 * math.pi
        u = np.sqrt(np.clip(theta_h / half, 0.0, 1.0)) * (n_h - 1)
        v = np.clip(theta_d / half, 0.0, 1.0) * (n_d - 1)
        w = np.clip(np.mod(phi_d, math.pi) / math.pi, 0.0, 1.0) * (n_p - 1)
        coords = np.stack([u.ravel(), v.ravel(), w.ravel()])
        out = np.empty((u.size, 3))
        for c in range(3):
            out[:, c] = map_coordinates(data[..., c], coords, order=1, mode="nearest")
        result: FloatArray = out.reshape(*np.shape(theta_h), 3)
        return result


def _directions(
    theta_h: FloatArray, theta_d: FloatArray, phi_d: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """wi, wo of Rusinkiewicz angles (phi_h = 0): ``d`` rotated by theta_h about y."""
    sd, cd = np.sin(theta_d), np.cos(theta_d)
    d = np.stack([sd * np.cos(phi_d), sd * np.sin(phi_d), cd], axis=-1)
    ch, sh = np.cos(theta_h), np.sin(theta_h)
    wi = np.stack(
        [ch * d[..., 0] + sh * d[..., 2], d[..., 1], -sh * d[..., 0] + ch * d[..., 2]], axis=-1
    )
    h = np.stack([sh, np.zeros_like(sh), ch], axis=-1)
    wo = 2.0 * np.sum(wi * h, axis=-1, keepdims=True) * h - wi
    return wi, wo


def gloss_brdf(
    wi: FloatArray, wo: FloatArray, n_wl: FloatArray, alpha: float, alpha_lobe: float
) -> FloatArray:
    """Beckmann microfacet BRDF of the coat surface, ``(N, n_wl)`` (Walter eqs. 20, 25, 27):
    ``D(h; alpha_lobe) G1(wi; alpha) G1(wo; alpha) F(wi.h; n) / (4 cos ti cos to)``."""
    from goniolab.optics.analytic import beckmann_d, beckmann_g1

    ci, co = wi[:, 2], wo[:, 2]
    ok = (ci > 0) & (co > 0)
    h = wi + wo
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    d = beckmann_d(h[:, 2], alpha_lobe)
    g = beckmann_g1(np.clip(ci, 1e-9, 1), alpha) * beckmann_g1(np.clip(co, 1e-9, 1), alpha)
    cos_d = np.clip(np.sum(wi * h, axis=-1), 0.0, 1.0)
    f = fresnel_unpolarised(cos_d[:, None], n_wl[None, :])
    geo = np.where(ok, d * g / (4.0 * np.where(ok, ci * co, 1.0)), 0.0)
    out: FloatArray = geo[:, None] * f
    return out


def tabulate_brdf(
    paint: Paint,
    alpha: float,
    *,
    lamp_radius_deg: float = 3.0,
    wavelengths_nm: FloatArray | None = None,
    settings: ColourSettings | None = None,
    n_h: int = 48,
    n_d: int = 24,
    n_phi: int = 12,
) -> BrdfTable:
    """The XYZ table of coat gloss + paint (see the module docstring)."""
    wl = np.linspace(380.0, 780.0, 41) if wavelengths_nm is None else wavelengths_nm
    w = xyz_weights(wl, settings)
    half = 0.5 * math.pi
    th = half * np.linspace(0.0, 1.0, n_h) ** 2
    td = np.linspace(0.0, half, n_d)
    pd = np.linspace(0.0, math.pi, n_phi)
    gh, gd, gp = np.meshgrid(th, td, pd, indexing="ij")
    wi, wo = _directions(gh.ravel(), gd.ravel(), gp.ravel())
    ok = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6)
    rho = math.radians(lamp_radius_deg)
    alpha_lobe = math.sqrt(alpha * alpha + rho * rho / 8.0)
    f = np.zeros((wi.shape[0], wl.size))
    n_coat = paint.coat_n(wl)
    f[ok] = gloss_brdf(wi[ok], wo[ok], n_coat, alpha, alpha_lobe)
    # the paint beneath: :meth:`Paint.subsurface_brdf` written out as its body term plus
    # one lobe per flake population, each lobe also tabulated alone (the sparkle texture)
    wi_ok, wo_ok = wi[ok], wo[ok]
    t_body = paint.body_transmission(wi_ok[:, 2], wl) * paint.body_transmission(wo_ok[:, 2], wl)
    f[ok] += t_body * paint.body_term(wl)[None, :]
    flakes: list[MetallicFlakes | PearlFlakes] = []
    tables: list[FloatArray] = []
    for pop in (paint.metallic, paint.pearl):
        if pop is None:
            continue
        alone = replace(
            paint,
            metallic=pop if pop is paint.metallic else None,
            pearl=pop if pop is paint.pearl else None,
        )
        fl = np.zeros((wi.shape[0], wl.size))
        fl[ok] = alone.flake_brdf(wi_ok, wo_ok, wl)
        f += fl
        tables.append((fl @ w.T).reshape(n_h, n_d, n_phi, 3))
        flakes.append(pop)
    xyz = (f @ w.T).reshape(n_h, n_d, n_phi, 3)
    n550 = float(paint.coat_n(np.array([550.0]))[0])
    return BrdfTable(xyz, tuple(tables), tuple(flakes), n550, float(lamp_radius_deg))


def _rusinkiewicz(
    n: FloatArray, wi: FloatArray, wo: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """theta_h, theta_d, phi_d, cos theta_i, cos theta_o of world directions at normals n."""
    # a tangent frame per normal (the BRDF is isotropic: any frame will do)
    a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(n, a)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    b = np.cross(n, t)

    def local(v: FloatArray) -> FloatArray:
        return np.stack([np.sum(v * t, -1), np.sum(v * b, -1), np.sum(v * n, -1)], axis=-1)

    li, lo = local(wi), local(wo)
    h = li + lo
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    theta_h = np.arccos(np.clip(h[:, 2], -1.0, 1.0))
    phi_h = np.arctan2(h[:, 1], h[:, 0])
    # d = rot_y(-theta_h) rot_z(-phi_h) wi
    cp, sp = np.cos(phi_h), np.sin(phi_h)
    x1 = cp * li[:, 0] + sp * li[:, 1]
    y1 = -sp * li[:, 0] + cp * li[:, 1]
    z1 = li[:, 2]
    ch, sh = np.cos(theta_h), np.sin(theta_h)
    x2 = ch * x1 - sh * z1
    z2 = sh * x1 + ch * z1
    theta_d = np.arccos(np.clip(z2, -1.0, 1.0))
    phi_d = np.arctan2(y1, x2)
    return theta_h, theta_d, phi_d, li[:, 2], lo[:, 2]


@dataclass(frozen=True)
class Render:
    """A rendered image: linear XYZ (Y = 100 for the lit white diffuser, before the
    exposure), display sRGB (the XYZ times the exposure) and, per pixel, the key lamp's
    aspecular angle and cos theta_i (NaN off the shape)."""

    xyz: FloatArray  # (size, size, 3)
    srgb: FloatArray  # (size, size, 3) in [0, 1]
    mask: NDArray[np.bool_]
    aspecular_deg: FloatArray
    cos_i: FloatArray
    #: The exposure applied, whether it was chosen automatically, and the share of the
    #: shape's pixels whose linear sRGB exceeds white at it.
    exposure: float = 1.0
    exposure_auto: bool = False
    clipped_fraction: float = 0.0
    #: Pixels where at least one flake mirrors the lamp (sparkle render only).
    sparkle_pixels: NDArray[np.bool_] | None = None
    pixel_um: float = 0.0


def _geometry(shape: Shape, size: int) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Normals (size, size, 3) and the mask of pixels on the shape."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0  # pixel centres in [-1, 1]
    x, y = np.meshgrid(c, -c)  # y up: row 0 is the top
    if shape == "sphere":
        r2 = x * x + y * y
        mask = r2 < 1.0
        z = np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))
        normals = np.stack([x, y, z], axis=-1)
    elif shape == "panel":
        s = math.sin(math.radians(PANEL_HALF_ANGLE_DEG))
        b = np.arcsin(np.clip(y * s, -1.0, 1.0))
        mask = np.abs(x) < 0.88
        normals = np.stack([np.zeros_like(b), np.sin(b), np.cos(b)], axis=-1)
    else:
        raise ValueError(f"shape must be 'panel' or 'sphere', got {shape!r}")
    return normals, mask


#: Physical width of the rendered panel / sphere (sets the pixel size for the sparkle).
SCENE_WIDTH_MM = 60.0
#: Largest share of the shape's pixels the automatic exposure lets clip to white.
CLIP_FRACTION = 0.01


def _local_frame(normals: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """An orthonormal tangent pair per normal (any: the sparkle count is isotropic)."""
    ref = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(normals, ref)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    t2 = np.cross(normals, t1)
    return t1, t2


def _to_local(v: FloatArray, t1: FloatArray, t2: FloatArray, nm: FloatArray) -> FloatArray:
    out: FloatArray = np.stack(
        [np.sum(v * t1, -1), np.sum(v * t2, -1), np.sum(v * nm, -1)], axis=-1
    )
    return out


def render(
    table: BrdfTable,
    *,
    shape: Shape = "panel",
    size: int = 512,
    lamps: int = 1,
    exposure: float | None = None,
    settings: ColourSettings | None = None,
    sparkle: bool = False,
    seed: int = 0,
) -> Render:
    """Render ``shape`` at ``size`` x ``size`` lit by the first ``lamps`` of :data:`LAMPS`.

    ``exposure``: the factor on the XYZ before display; ``None`` (default) chooses the
    largest that clips at most :data:`CLIP_FRACTION` of the shape's pixels (1 % of them may
    exceed display white; the chosen value and the clipped share are in the result).
    ``sparkle``: each pixel (a ``SCENE_WIDTH_MM / size`` square of paint) draws the number
    of flakes that mirror the lamp from a Poisson law of mean ``mu``
    (:func:`goniolab.colour.sparkle.expected_sparkles`) and shows the flake lobe times
    ``k / mu``: the mean over many pixels is the smooth render, single pixels sparkle.
    """
    if not 1 <= lamps <= len(LAMPS):
        raise ValueError(f"lamps must be 1 or 2, got {lamps}")
    if not (8 <= size <= 8192):
        raise ValueError(f"size must be in [8, 8192] pixels, got {size}")
    if exposure is not None and not (math.isfinite(exposure) and exposure > 0):
        raise ValueError(f"exposure must be > 0, got {exposure}")
    from goniolab.colour.sparkle import expected_sparkles

    normals, mask = _geometry(shape, size)
    nm = normals[mask]
    view = np.broadcast_to(np.array([0.0, 0.0, 1.0]), nm.shape)
    xyz = np.zeros((nm.shape[0], 3))
    asp = np.full(size * size, np.nan)
    cos_key = np.full(size * size, np.nan)
    rng = np.random.default_rng(seed)
    pixel_um = SCENE_WIDTH_MM * 1000.0 / size
    sparkling = np.zeros(nm.shape[0], dtype=bool)
    t1, t2 = _local_frame(nm, view)
    for k, (lamp, irradiance) in enumerate(LAMPS[:lamps]):
        li = np.broadcast_to(lamp, nm.shape)
        th, td, pd, ci, co = _rusinkiewicz(nm, li, view)
        lit = (ci > 0) & (co > 0)
        f = table.lookup(th, td, pd)
        if sparkle and table.flakes_xyz:
            wi_l = _to_local(li, t1, t2, nm)
            wo_l = _to_local(view, t1, t2, nm)
            for flakes, ftab in zip(table.flakes, table.flakes_xyz, strict=True):
                lobe = table.lookup(th, td, pd, ftab)
                mu = expected_sparkles(
                    wi_l,
                    wo_l,
                    flakes,
                    table.n_coat,
                    table.lamp_radius_deg,
                    pixel_um,
                )
                mu = np.where(lit, mu, 0.0)
                count = rng.poisson(mu)
                ratio = np.where(mu > 0, count / np.where(mu > 0, mu, 1.0), 0.0)
                f = f - lobe + lobe * ratio[:, None]
                sparkling |= count > 0
        xyz += np.where(lit[:, None], math.pi * irradiance * ci[:, None] * f, 0.0)
        if k == 0:
            mirror = 2.0 * ci[:, None] * nm - li
            a = np.degrees(np.arccos(np.clip(mirror[:, 2], -1.0, 1.0)))
            # signed: > 0 when the view lies between the mirror direction and the lamp
            side = np.sign(np.sum(np.cross(mirror, view) * np.cross(mirror, li), -1))
            asp[mask.ravel()] = np.where(side >= 0, a, -a)
            cos_key[mask.ravel()] = ci
    linear = _linear_rgb(xyz, settings)  # once: the exposure scales it linearly
    peak = np.max(linear, axis=-1) if linear.size else np.zeros(0)
    if exposure is None:
        q = float(np.quantile(peak, 1.0 - CLIP_FRACTION, method="higher")) if peak.size else 0.0
        # 1 % headroom: 8-bit rounding would otherwise saturate the quantile pixel itself
        exposure = 0.99 / q if q > 0 else 1.0
        auto = True
    else:
        auto = False
    clipped = float(np.mean(peak * exposure > 1.0 + 1e-9)) if peak.size else 0.0
    full = np.zeros((size * size, 3))
    full[mask.ravel()] = xyz
    srgb = np.zeros((size * size, 3))
    srgb[mask.ravel()] = _encode_srgb(linear * exposure)
    spark = np.zeros(size * size, dtype=bool)
    spark[mask.ravel()] = sparkling
    return Render(
        xyz=full.reshape(size, size, 3),
        srgb=srgb.reshape(size, size, 3),
        mask=mask,
        aspecular_deg=asp.reshape(size, size),
        cos_i=cos_key.reshape(size, size),
        exposure=float(exposure),
        exposure_auto=auto,
        clipped_fraction=clipped,
        sparkle_pixels=spark.reshape(size, size),
        pixel_um=pixel_um,
    )


def _linear_rgb(xyz: FloatArray, settings: ColourSettings | None) -> FloatArray:
    """Linear sRGB of XYZ (Y = 100 scale), ``colour.XYZ_to_sRGB`` without the encoding, with
    chromatic adaptation from the illuminant's white point: a pixel clips to white when a
    channel exceeds 1."""
    import warnings

    from goniolab.colour.spectra import colour_module

    if xyz.size == 0:
        return np.zeros((0, 3))
    colour = colour_module()
    s = (settings or ColourSettings()).validated()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rgb = colour.XYZ_to_sRGB(xyz / 100.0, s.white_xy, apply_cctf_encoding=False)
    out: FloatArray = np.nan_to_num(np.asarray(rgb, dtype=np.float64))
    return out


def _encode_srgb(linear: FloatArray) -> FloatArray:
    """Display sRGB in [0, 1] of linear sRGB: IEC 61966-2-1's encoding, clipped."""
    c = np.clip(linear, 0.0, 1.0)
    out: FloatArray = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return out
