"""The realistic twin's colour noise: repeat readings against the chain's own noise model.

At named geometries (theta_i = 45 deg), the twin's noise-free flux fraction
(``SimSpectro._spectral`` of the sample's truth, sim/truth.py) is read ``--repeats`` times
through the spectro chain (sim/spectro_chain.py) at the exposure the auto exposure settles
on (the strongest channel at half the full well, goniolab/scan/exposure.py's target), and
turned into colour as a scan does (reflectance factors on the diffuser scale, D65 / 10 deg /
ASTM E308). Printed per geometry: the noise-free colour, the sample standard deviations of
L*, a*, b* and the mean CIEDE2000 of a repeat from the mean colour (the ``rep dE00`` column
of ``goniolab runs colour``), against the first-order propagation of the chain's covariance
(:meth:`sim.spectro_chain.SpectroChain.covariance`,
:func:`goniolab.colour.uncertainty.lab_covariance`).

``--swing`` prints instead the noise-free colour of the default sample over theta_r
20..70 deg, from the truth's Kirchhoff tables at its 3 wavelength nodes (450/550/650 nm,
linear between, flat outside) and at 13 (400..700 nm every 25 nm): where the a*, b* of a
scan come from when no noise is added.

    .venv/bin/python bench/twin_colour_noise.py [--pixels 1] [--repeats 400] [--swing]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from goniolab.colour.spectra import delta_e, spectra_to_xyz, xyz_to_colour
from goniolab.colour.spectral import reflectance_factor_scale
from goniolab.colour.uncertainty import lab_covariance
from goniolab.config import load_lab_config
from goniolab.optics.apertures import Cone
from sim.assembly import sample_truth
from sim.spectro_chain import SpectroChain
from sim.twin_spectra import SPECTRUM_WAVELENGTHS_NM

#: (sample, theta_r): aspecular 45 (the 45/0 of a white tile), 15, 5 and 0, and the
#: default sample's worst swing (aspecular -22)
GEOMETRIES: tuple[tuple[str, float], ...] = (
    ("sample:white", 0.0),
    ("sample:white", 30.0),
    ("sample:white", 45.0),
    ("sample:wittmann-3", 0.0),
    ("sample:wittmann-3", 40.0),
    ("sample:wittmann-3", 45.0),
    ("sample:wittmann-3", 55.0),
    ("sample:wittmann-3", 67.0),
    ("sample:silver-metallic", 30.0),
)


def fraction_at(cfg_path: str, sample: str, theta_r_deg: float) -> np.ndarray:
    """The twin's noise-free flux fraction per wavelength at 45 / theta_r (6 deg cones)."""
    cfg = load_lab_config(cfg_path)
    truth = sample_truth(cfg, sample)
    return np.asarray(
        truth.spectral_fraction(45.0, theta_r_deg, source=Cone(6.0), detector=Cone(6.0))
    )


def settled_exposure_us(chain: SpectroChain, fraction: np.ndarray) -> int:
    """The exposure at which the strongest channel holds half the full well (the auto
    exposure's target), within the Ruby's 500..250000 us."""
    light = 100.0 * fraction * chain.gain()  # counts per pixel at 10 ms
    t = 0.5 * (chain.full_well_counts - chain.bias_counts) / float(light.max()) * 10_000
    return int(min(max(t, 500), 250_000))


def swing(cfg_path: str) -> None:
    """Noise-free L*a*b* of the default sample's truth over theta_r, 3 against 13 nodes."""
    from goniolab.surfaces.resolve import resolve_map
    from sim.assembly import twin_settings
    from sim.truth import truth_for

    cfg = load_lab_config(cfg_path)
    spec = cfg.sample_map()
    hm = resolve_map(spec, step_um=cfg.sample.step_um)
    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    trs = np.arange(20.0, 71.0, 1.0)
    scale = reflectance_factor_scale(trs, 6.0)[:, None]
    labs = []
    for nodes in ((450.0, 550.0, 650.0), tuple(float(x) for x in np.arange(400, 701, 25))):
        settings = dataclasses.replace(twin_settings(cfg), wavelengths_nm=nodes)
        truth = truth_for(hm, n=cfg.sample.n, body="black", settings=settings, name=spec)
        frac = np.array([truth.spectral_fraction(45.0, float(t)) for t in trs])
        labs.append(xyz_to_colour(spectra_to_xyz(wl, frac * scale))[:, 3:6])
        truth.save_cache()
    print(f"{spec}, body black, theta_i 45, noise-free truth: L* a* b* at 3 | 13 nodes")
    print("| theta_r | aspec | 3 nodes | 13 nodes |")
    print("|---|---|---|---|")
    for k, t in enumerate(trs):
        a, b = labs[0][k], labs[1][k]
        print(
            f"| {t:g} | {45 - t:g} | {a[0]:.1f} {a[1]:.1f} {a[2]:.1f} "
            f"| {b[0]:.1f} {b[1]:.1f} {b[2]:.1f} |"
        )
    for name, lab in zip(("3", "13"), labs, strict=True):
        print(
            f"{name} nodes: a* {lab[:, 1].min():.1f}..{lab[:, 1].max():.1f}, "
            f"b* {lab[:, 2].min():.1f}..{lab[:, 2].max():.1f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/lab-sim.toml")
    ap.add_argument(
        "--pixels", type=int, default=None, help="pixels per channel (default: chain's)"
    )
    ap.add_argument("--repeats", type=int, default=400)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--swing", action="store_true", help="noise-free colour over theta_r")
    args = ap.parse_args()
    if args.swing:
        swing(args.config)
        return
    chain = SpectroChain()
    if args.pixels is not None:
        chain = dataclasses.replace(chain, pixels_per_channel=args.pixels)
    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    rng = np.random.default_rng(args.seed)
    print(
        f"pixels_per_channel {chain.pixels_per_channel}, flicker {chain.flicker_pct} %, "
        f"{args.repeats} repeats"
    )
    print(
        "| sample | theta_r | aspec | L* a* b* (noise-free) | exposure us "
        "| sd L* a* b* measured | sd L* a* b* analytic | rep dE00 |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for sample, tr in GEOMETRIES:
        frac = fraction_at(args.config, sample, tr)
        scale = float(reflectance_factor_scale(tr, 6.0))
        t_us = settled_exposure_us(chain, frac)
        vals = np.array([chain.read(frac, t_us, rng)[0] for _ in range(args.repeats)])
        lab = xyz_to_colour(spectra_to_xyz(wl, vals / 100.0 * scale))[:, 3:6]
        mean_spec = vals.mean(axis=0) / 100.0 * scale
        lab_mean = xyz_to_colour(spectra_to_xyz(wl, mean_spec))[3:6]
        clean = xyz_to_colour(spectra_to_xyz(wl, frac * scale))[3:6]
        cov = chain.covariance(frac, t_us) * (scale / 100.0) ** 2
        mean_r = chain.mean_reading_pct(frac) / 100.0 * scale  # with the stray light
        sd_an = np.sqrt(np.diag(lab_covariance(wl, mean_r, cov)))
        sd = lab.std(axis=0, ddof=1)
        de = delta_e(lab, np.broadcast_to(lab_mean, lab.shape), "CIE 2000")
        print(
            f"| {sample.removeprefix('sample:')} | {tr:g} | {45.0 - tr:g} "
            f"| {clean[0]:.1f} {clean[1]:.2f} {clean[2]:.2f} | {t_us} "
            f"| {sd[0]:.3f} {sd[1]:.3f} {sd[2]:.3f} | {sd_an[0]:.3f} {sd_an[1]:.3f} "
            f"{sd_an[2]:.3f} | {float(np.mean(de)):.3f} |"
        )


if __name__ == "__main__":
    main()
