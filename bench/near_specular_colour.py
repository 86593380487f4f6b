"""Is the twin's near-specular colour of ``sample:wittmann-3`` physical, or an artefact?

The twin's noise-free truth (sim/truth.py: scalar Kirchhoff orders of a 0.25 um tile that is
the band-limited interpolation of the 1 um library map, 3 wavelength nodes) shows a*, b*
swinging by +-10..20 over aspecular -25..+25 deg at theta_i 45 (``bench/twin_colour_noise.py
--swing``). This script recomputes the same in-plane readings (6 deg lamp and detector cones,
the lab's) with code that shares nothing with the twin's optics:

* the surface: ``goniolab.surfaces.synthetic.make_sample("wittmann-3", step_um=STEP)``, the
  library's own definition sampled directly at 0.25 um (and 0.125 um with ``--fine``): the
  spherical caps exact to the step, not interpolated from 1 um;
* the optics: the repository's scalar Kirchhoff model
  (:class:`goniolab.optics.kirchhoff.KirchhoffModel`: Taylor-banded FFT of the phase screen,
  Beckmann's obliquity, local Fresnel, Smith masking, cell-exact cone apertures), valid at
  that step (its provenance is printed: ``kirchhoff`` at every geometry), at 16 wavelengths
  400..700 nm (flat beyond, as the twin);
* the colour: D65 / 10 deg / ASTM E308 (goniolab.colour.spectra), reflectance factors on the
  diffuser scale (goniolab.colour.spectral.reflectance_factor_scale), with the twin's black
  body added to every column so that only the surface differs.

Then the same Kirchhoff model on maps built here (spherical caps at Poisson centres, as the
library's generator, plus its film and film defects) with the fillers

* ``mono``: D 5 um, h 0.92 um (the library's wittmann-3: a control for this generator);
* ``D+-30%``: D uniform in [3.5, 6.5] um, h 0.92 um (what ``diameter_um = [min, max]`` in
  configs/samples.toml can already express);
* ``D,h+-30%``: D uniform in [3.5, 6.5] um with h = 0.92 D / 5 (same aspect ratio: particles
  of one kind standing out of the film by the same fraction of their size);

* ``all+-30%``: as ``D,h+-30%``, and the film defects spread the same way (D 2.8..5.2 um);

at the same area fraction (0.32). And a closed-form check that shares no FFT with either:
one spherical cap's scalar Kirchhoff form factor (a Hankel transform), summed incoherently
over a dilute Poisson population (``caps mono``, ``caps D,h+-30%``: no film, no coherent
beam, so read at |aspecular| >= 13 deg only). The physics to expect: identical caps diffract coherently,
so the pattern of one cap (rings in angle with period ~ lambda / D, and the interference of
the flat film with the caps' tops in the coherent beam, phase ~ k q_z h) survives the random
positions and moves with lambda (colour); a spread of sizes and heights averages the rings out.

    PYTHONPATH=$PWD .venv/bin/python bench/near_specular_colour.py [--fine] [--step 5]

Prints one table (a*, b* per aspecular angle for each column) and the ranges over aspecular
-25..+25 deg.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from numpy.typing import NDArray

from goniolab.colour.spectra import spectra_to_xyz, xyz_to_colour
from goniolab.colour.spectral import reflectance_factor_scale
from goniolab.config import load_lab_config
from goniolab.optics.apertures import Cone
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.kirchhoff import KirchhoffModel
from goniolab.surfaces.synthetic import make_sample
from sim.twin_spectra import SPECTRUM_WAVELENGTHS_NM

FloatArray = NDArray[np.float64]

THETA_I_DEG = 45.0
LAMBDAS_NM = tuple(float(x) for x in np.arange(400.0, 701.0, 20.0))
N_COAT = 1.55
#: wittmann-3 (configs/samples.toml): film Ra 28 nm / 80 um; defects 4 um x 0.2 um at 4.5 %;
#: fillers 5 um x 0.92 um at area fraction 0.32
FILM_RA_UM, FILM_CORR_UM = 0.028, 80.0
Caps = tuple[tuple[float, float], float, float, bool]  # D range, area fraction, h, h ~ D
DEFECTS: Caps = ((4.0, 4.0), 0.045, 0.2, False)
DEFECTS_SPREAD: Caps = ((2.8, 5.2), 0.045, 0.2, True)
#: name -> (fillers, film defects)
FILLERS: dict[str, tuple[Caps, Caps]] = {
    "mono": (((5.0, 5.0), 0.32, 0.92, False), DEFECTS),
    "D+-30%": (((3.5, 6.5), 0.32, 0.92, False), DEFECTS),
    "D,h+-30%": (((3.5, 6.5), 0.32, 0.92, True), DEFECTS),
    "all+-30%": (((3.5, 6.5), 0.32, 0.92, True), DEFECTS_SPREAD),
}


def caps(
    rng: np.random.Generator,
    n: int,
    step_um: float,
    d_range_um: tuple[float, float],
    area_fraction: float,
    h_um: float,
    h_scales_with_d: bool,
) -> FloatArray:
    """Spherical caps (base diameter D uniform in ``d_range_um``, height ``h_um`` or
    ``h_um D / 5 um``) at Poisson centres on a periodic n x n tile, overlaps adding (as
    goniolab.surfaces.synthetic builds them, written again here)."""
    d_lo, d_hi = d_range_um
    a2 = (d_lo**2 + d_lo * d_hi + d_hi**2) / 12.0
    count = round(area_fraction * (n * step_um) ** 2 / (math.pi * a2))
    d = rng.uniform(d_lo, d_hi, count)
    h = h_um * d / 5.0 if h_scales_with_d else np.full(count, h_um)
    cx, cy = rng.uniform(0.0, n * step_um, (2, count))
    z = np.zeros((n, n))
    for k in range(count):
        a = 0.5 * d[k]
        r_big = (a * a + h[k] ** 2) / (2.0 * h[k])
        m = math.ceil(a / step_um) + 1
        ix = np.arange(math.floor(cx[k] / step_um) - m, math.floor(cx[k] / step_um) + m + 1)
        iy = np.arange(math.floor(cy[k] / step_um) - m, math.floor(cy[k] / step_um) + m + 1)
        rx = (ix + 0.5) * step_um - cx[k]
        ry = (iy + 0.5) * step_um - cy[k]
        r2 = ry[:, None] ** 2 + rx[None, :] ** 2
        cap = np.where(r2 < a * a, np.sqrt(np.clip(r_big**2 - r2, 0, None)) - (r_big - h[k]), 0.0)
        z[np.ix_(iy % n, ix % n)] += np.clip(cap, 0.0, None)
    return z


def built_map(name: str, n: int, step_um: float, seed: int) -> HeightMap:
    """Film (Gaussian ACF, Ra 28 nm, 80 um) + defects + the named filler population."""
    rng = np.random.default_rng([seed, 7])
    k = 2.0 * np.pi * np.fft.fftfreq(n, d=step_um)
    filt = np.exp(-(k[:, None] ** 2 + k[None, :] ** 2) * FILM_CORR_UM**2 / 8.0)
    film = np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * filt).real
    film *= FILM_RA_UM / np.mean(np.abs(film - film.mean()))
    fillers, defects = FILLERS[name]
    z = film + caps(rng, n, step_um, *defects) + caps(rng, n, step_um, *fillers)
    return HeightMap(z_um=z - z.mean(), dx_um=step_um, dy_um=step_um, source=f"bench:{name}")


def kirchhoff_fraction(hm: HeightMap, tr_deg: FloatArray, cone: Cone) -> tuple[FloatArray, str]:
    """Surface flux fraction ``(n_lambda, n_tr)`` of the Kirchhoff model and the models
    that computed it (must all be ``kirchhoff``)."""
    base = KirchhoffModel(hm, n=N_COAT, wavelength_nm=550.0)
    out = np.empty((len(LAMBDAS_NM), tr_deg.size))
    used: set[str] = set()
    for j, lam in enumerate(LAMBDAS_NM):
        m = base.with_optics(n=N_COAT, wavelength_nm=lam)
        out[j] = np.asarray(m.luminance_pct(THETA_I_DEG, tr_deg, source=cone, detector=cone)) / 100
        used.update(m.provenance(THETA_I_DEG, float(t), cone, cone).model for t in tr_deg[::10])
    return out, ",".join(sorted(used))


def lab_of(
    nodes_nm: tuple[float, ...], surf: FloatArray, body: FloatArray, tr: FloatArray
) -> FloatArray:
    """L*a*b* of surface (at ``nodes_nm``, linear between, flat outside) + body."""
    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    spec = np.stack([np.interp(wl, nodes_nm, surf[:, k]) for k in range(tr.size)]) + body.T
    scale = reflectance_factor_scale(tr, 6.0)[:, None]
    return np.asarray(xyz_to_colour(spectra_to_xyz(wl, spec * scale))[:, 3:6])


def cap_form_factor_sq(
    qpar: FloatArray, qz: FloatArray, a_um: float, h_um: float, nr: int = 600
) -> FloatArray:
    """``|F|^2`` (um^4) of one spherical cap of base radius ``a_um`` and height ``h_um`` on a
    flat mirror, scalar Kirchhoff (the cap's phase screen minus the flat's):
    ``F(q_par, q_z) = 2 pi int_0^a (exp(-i q_z z(r)) - 1) J0(q_par r) r dr`` on the table
    ``qz x qpar`` (1/um), by a midpoint rule in r (Hankel transform of the axisymmetric
    screen; Beckmann & Spizzichino ch. 3)."""
    from scipy.special import j0

    r = (np.arange(nr) + 0.5) * (a_um / nr)
    big_r = (a_um**2 + h_um**2) / (2.0 * h_um)
    z = np.sqrt(big_r**2 - r**2) - (big_r - h_um)
    m1 = (np.exp(-1j * np.outer(qz, z)) - 1.0) * (r * (a_um / nr))[None, :]
    f = 2.0 * np.pi * (m1 @ j0(np.outer(r, qpar)))
    return np.asarray(np.abs(f) ** 2)


def analytic_caps(
    tr_deg: FloatArray, cone: Cone, sizes: list[tuple[float, float]], area_fraction: float
) -> FloatArray:
    """Diffuse surface fraction ``(n_lambda, n_tr)`` of a dilute population of caps at
    independent (Poisson) positions: the fields of different caps add with random phases, so
    the intensity is the number density times the mean ``|F|^2`` (``sizes``: equally likely
    ``(D, h)``), ``dP/(du dv) = rho <|F(k du, k dv, q_z)|^2> / lambda^2`` per unit area in
    direction cosines (Parseval), weighted by the local Fresnel reflectance and Beckmann's
    obliquity factor (as goniolab.optics.kirchhoff) and the lamp/detector cone overlap. No
    coherent beam and no film: read it away from specular (|aspecular| > the 6 deg reach)."""
    from goniolab.optics.apertures import cap_overlap_fraction
    from goniolab.optics.fresnel import fresnel

    ti = math.radians(THETA_I_DEG)
    a_half = math.radians(0.5 * cone.full_angle_deg)
    reach = math.sin(2.0 * a_half)
    mean_a2 = float(np.mean([(0.5 * d) ** 2 for d, _ in sizes]))
    rho = area_fraction / (math.pi * mean_a2)  # caps per um^2
    k_all = 2.0 * np.pi / (np.asarray(LAMBDAS_NM) * 1e-3)
    qpar_tab = np.linspace(0.0, float(k_all.max()) * 1.05 * (reach + 0.6), 1500)
    qz_tab = np.linspace(float(k_all.min()) * 0.9, float(k_all.max()) * 2.0, 500)
    tab = np.mean([cap_form_factor_sq(qpar_tab, qz_tab, 0.5 * d, h) for d, h in sizes], axis=0)
    from scipy.interpolate import RegularGridInterpolator

    ff = RegularGridInterpolator((qz_tab, qpar_tab), tab)
    g1 = np.linspace(-reach, reach, 121)
    du_g, dv_g = np.meshgrid(g1, g1, indexing="ij")
    cell = float(g1[1] - g1[0]) ** 2
    out = np.zeros((len(LAMBDAS_NM), tr_deg.size))
    for j, t in enumerate(tr_deg):
        u_d = math.sin(math.radians(float(t)))
        g_d = math.cos(math.radians(float(t)))
        u, v = u_d + du_g, dv_g
        g2 = 1.0 - u * u - v * v
        ok = g2 > 0.0
        g = np.sqrt(np.where(ok, g2, 1.0))
        chord = np.sqrt((u - u_d) ** 2 + v * v + (g - g_d) ** 2)
        w = cap_overlap_fraction(2.0 * np.arcsin(np.clip(chord / 2.0, 0, 1)), a_half, a_half)
        qsum = math.cos(ti) + g
        s2 = (math.sin(ti) - u) ** 2 + v * v + qsum * qsum
        obliq = s2 * s2 / (4.0 * math.cos(ti) * g * qsum * qsum)
        fr = fresnel(np.clip(0.5 * np.sqrt(s2), 0.0, 1.0), N_COAT)
        qp_dir = np.hypot(u - math.sin(ti), v)  # offset from specular, direction cosines
        for li, k in enumerate(k_all):
            pts = np.stack([np.clip(k * qsum, qz_tab[0], qz_tab[-1]), k * qp_dir], axis=-1)
            p = rho * ff(pts) / (2.0 * math.pi / k) ** 2
            out[li, j] = float(np.sum(np.where(ok, p * fr * obliq * w, 0.0)) * cell)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/lab-sim.toml")
    ap.add_argument("--step", type=float, default=1.0, help="theta_r step (deg)")
    ap.add_argument("--fine", action="store_true", help="also the library map at 0.125 um")
    ap.add_argument("--field-um", type=float, default=256.0)
    args = ap.parse_args()
    from sim.assembly import sample_truth

    cfg = load_lab_config(args.config)
    cone = Cone(cfg.spectro.detector_cone_deg)
    assert math.isclose(cfg.goniometer.source_cone_deg, cfg.spectro.detector_cone_deg)
    tr = np.arange(20.0, 70.0 + 1e-9, args.step)
    truth = sample_truth(cfg, "sample:wittmann-3")
    body = truth._body_fraction(THETA_I_DEG, tr, cone)  # the twin's black body, (41, n_tr)
    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    twin_total = np.array([truth.spectral_fraction(THETA_I_DEG, float(t)) for t in tr])
    labs: dict[str, FloatArray] = {"twin": lab_of(tuple(wl), twin_total.T - body, body, tr)}
    # the twin's own true tile (0.25 um, the 1 um map band-limited + sub-resolution
    # roughness) through the repository's Kirchhoff model: separates the twin's surface from
    # its optics
    t0 = time.perf_counter()
    tile = truth.truth
    hm_tile = HeightMap(
        z_um=tile.z_um.astype(np.float64), dx_um=tile.step_um, dy_um=tile.step_um, source="twin"
    )
    surf, used = kirchhoff_fraction(hm_tile, tr, cone)
    labs["twin tile"] = lab_of(LAMBDAS_NM, surf, body, tr)
    print(f"twin tile: {tile.z_um.shape}, models {used}, {time.perf_counter() - t0:.0f} s")
    steps = [0.25] + ([0.125] if args.fine else [])
    for step in steps:
        t0 = time.perf_counter()
        n = round(args.field_um / step)
        hm = make_sample("wittmann-3", size=n, step_um=step)
        surf, used = kirchhoff_fraction(hm, tr, cone)
        key = f"lib {step:g}um"
        labs[key] = lab_of(LAMBDAS_NM, surf, body, tr)
        print(f"{key}: {n}x{n}, models {used}, {time.perf_counter() - t0:.0f} s")
    for name in FILLERS:
        t0 = time.perf_counter()
        n = round(args.field_um / 0.25)
        surf, used = kirchhoff_fraction(built_map(name, n, 0.25, 1), tr, cone)
        labs[name] = lab_of(LAMBDAS_NM, surf, body, tr)
        print(f"{name}: {n}x{n} at 0.25 um, models {used}, {time.perf_counter() - t0:.0f} s")
    # the closed-form check: one cap's form factor, dilute Poisson caps, no film
    far = np.abs(THETA_I_DEG - tr) >= 13.0
    for name, sizes in (
        ("caps mono", [(5.0, 0.92)]),
        ("caps D,h+-30%", [(d, 0.92 * d / 5.0) for d in np.linspace(3.5, 6.5, 13)]),
    ):
        t0 = time.perf_counter()
        surf = analytic_caps(tr[far], cone, sizes, 0.32)
        lab = np.full((tr.size, 3), np.nan)
        lab[far] = lab_of(LAMBDAS_NM, surf, body[:, far], tr[far])
        labs[name] = lab
        print(f"{name}: analytic, |aspecular| >= 13 deg, {time.perf_counter() - t0:.0f} s")
    cols = list(labs)
    print(
        f"\nsample:wittmann-3 analogues, theta_i {THETA_I_DEG:g}, cones "
        f"{cone.full_angle_deg:g} deg (full angle), black body; a* b* (L*) per column"
    )
    print("| theta_r | aspec | " + " | ".join(cols) + " |")
    print("|---|---|" + "---|" * len(cols))
    for k, t in enumerate(tr):
        cells = " | ".join(
            f"{labs[c][k, 1]:.1f} {labs[c][k, 2]:.1f} ({labs[c][k, 0]:.0f})" for c in cols
        )
        print(f"| {t:g} | {THETA_I_DEG - t:g} | {cells} |")
    print("\nranges over the table (a*, b*):")
    for c in cols:
        lab = labs[c]
        print(
            f"  {c:>14}: a* {np.nanmin(lab[:, 1]):.1f}..{np.nanmax(lab[:, 1]):.1f}, "
            f"b* {np.nanmin(lab[:, 2]):.1f}..{np.nanmax(lab[:, 2]):.1f}, "
            f"max C* {float(np.nanmax(np.hypot(lab[:, 1], lab[:, 2]))):.1f}; "
            f"|aspecular| >= 13: max C* {float(np.nanmax(np.hypot(lab[far, 1], lab[far, 2]))):.1f}"
        )


if __name__ == "__main__":
    main()
