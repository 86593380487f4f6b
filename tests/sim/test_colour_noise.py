"""The twin's colour noise is what its spectro's noise model implies, and no more.

The spectro chain (sim/spectro_chain.py) states its noise: Poisson shot noise and read
noise per detector pixel, ``pixels_per_channel`` pixels averaged into a reported 10 nm
channel, one lamp-flicker factor common to all channels. Propagated to first order through
the ASTM E308 weights and CIE 15:2004's L*a*b* (goniolab/colour/uncertainty.py), that gives
the standard deviations of L*, a*, b* of repeat readings; Monte Carlo draws of the chain,
turned into colour as a scan does, must match them. The Jacobian itself is checked against
central differences of the CIELAB formulas.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from goniolab.colour.spectra import spectra_to_xyz, white_xyz, xyz_to_colour
from goniolab.colour.spectral import reflectance_factor_scale
from goniolab.colour.uncertainty import lab_covariance, lab_jacobian, rms_delta_e_ab
from sim.spectro_chain import SpectroChain
from sim.twin_spectra import SPECTRUM_WAVELENGTHS_NM, body_reflectance

WL = np.asarray(SPECTRUM_WAVELENGTHS_NM)


def _lab(xyz: np.ndarray) -> np.ndarray:
    return np.asarray(xyz_to_colour(xyz)[..., 3:6])


@pytest.mark.parametrize(
    "xyz",
    [(95.0, 100.0, 108.0), (20.0, 18.0, 30.0), (300.0, 280.0, 250.0), (0.5, 0.6, 0.4)],
)
def test_lab_jacobian_is_the_derivative_of_cielab(xyz: tuple[float, float, float]) -> None:
    # (0.5, 0.6, 0.4): below (6/29)^3 of the white, the linear branch of f(t)
    x = np.asarray(xyz, dtype=np.float64)
    j = lab_jacobian(x, white_xyz())
    h = 1e-6 * np.maximum(x, 1.0)
    num = np.empty((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h[k]
        num[:, k] = (_lab(x + e) - _lab(x - e)) / (2 * h[k])
    assert j == pytest.approx(num, rel=1e-6, abs=1e-9)


def _settled_exposure(chain: SpectroChain, frac: np.ndarray) -> int:
    """The auto exposure's target: the strongest channel at half the full well."""
    light = 100.0 * frac * chain.gain()
    return int(0.5 * (chain.full_well_counts - chain.bias_counts) / float(light.max()) * 1e4)


# (what, flux fraction per wavelength, theta_r): a white body at 45/0 read as a Lambertian
# of that reflectance (the fraction a perfect diffuser sends into the 6 deg cone x R), and a
# near-specular reading, 2.7 % of the flux with the coat's faint tilt (the default sample's
# peak at 45/45)
_A = math.radians(3.0)
CASES = [
    ("white 45/0", body_reflectance("white") * math.sin(_A) ** 2 * math.cos(0.0), 0.0),
    ("specular 45/45", 0.027 * (1.0 + 2e-4 * (WL - 580.0)), 45.0),
]


@pytest.mark.parametrize(("what", "frac", "theta_r"), CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize("pixels", [1, 30])
def test_repeat_colour_noise_matches_the_analytic_propagation(
    what: str, frac: np.ndarray, theta_r: float, pixels: int
) -> None:
    chain = dataclasses.replace(SpectroChain(), pixels_per_channel=pixels)
    exposure = _settled_exposure(chain, frac)
    rng = np.random.default_rng(7)
    scale = float(reflectance_factor_scale(theta_r, 6.0))
    n = 3000
    vals = np.array([chain.read(frac, exposure, rng)[0] for _ in range(n)])
    assert chain.read(frac, exposure, rng)[1] < 0.9  # below saturation
    lab = _lab(spectra_to_xyz(WL, vals / 100.0 * scale))
    sd = lab.std(axis=0, ddof=1)
    cov_r = chain.covariance(frac, exposure) * (scale / 100.0) ** 2
    mean_r = chain.mean_reading_pct(frac) / 100.0 * scale  # the specimen plus stray light
    sd_analytic = np.sqrt(np.diag(lab_covariance(WL, mean_r, cov_r)))
    # the sample sd of n Gaussian draws is within 3 x 1/sqrt(2(n-1)) = 3.9 % (n = 3000)
    assert sd == pytest.approx(sd_analytic, rel=0.06)
    # and the covariance itself: the spectral noise per channel
    assert vals.std(axis=0, ddof=1) == pytest.approx(
        np.sqrt(np.diag(chain.covariance(frac, exposure))), rel=0.06
    )


def test_pixel_binning_cuts_the_chromatic_noise_by_root_pixels() -> None:
    # flicker is one factor k on every channel, so on X, Y and Z: f(t) = t^(1/3) scales
    # all three by k^(1/3), and L* + 16, a*, b* with them (sd = value x sigma_k / 3)
    frac, tr = CASES[0][1], CASES[0][2]
    scale = float(reflectance_factor_scale(tr, 6.0))
    sds = {}
    for px in (1, 30):
        chain = dataclasses.replace(SpectroChain(), pixels_per_channel=px, flicker_pct=0.0)
        t = _settled_exposure(chain, frac)
        cov = chain.covariance(frac, t) * (scale / 100.0) ** 2
        sds[px] = np.sqrt(np.diag(lab_covariance(WL, frac * scale, cov)))
    # shot and read noise shrink by sqrt(30), the rounding by 30 (negligible here)
    assert sds[1] / sds[30] == pytest.approx(np.full(3, math.sqrt(30.0)), rel=0.02)
    only_flicker = dataclasses.replace(
        SpectroChain(),
        read_noise_counts=0.0,
        electrons_per_count=1e12,  # no shot noise
        stray_pct=0.0,
        stray_rel=0.0,
        flicker_pct=0.3,
    )
    cov = only_flicker.covariance(frac, 200_000) * (scale / 100.0) ** 2  # rounding / 400
    cov_lab = lab_covariance(WL, frac * scale, cov)
    big_l, a, b = _lab(spectra_to_xyz(WL, frac * scale))
    expected = np.abs([big_l + 16.0, a, b]) * 0.003 / 3.0
    assert np.sqrt(np.diag(cov_lab)) == pytest.approx(expected, rel=1e-3)
    assert rms_delta_e_ab(cov_lab) == pytest.approx(float(np.hypot.reduce(expected)), rel=1e-3)


def test_one_pixel_per_channel_is_the_previous_chain_bit_for_bit() -> None:
    # pixels_per_channel = 1 draws and rounds exactly as the chain did before binning
    chain = dataclasses.replace(SpectroChain(), pixels_per_channel=1)
    frac = CASES[1][1]
    a = chain.read(frac, 8000, np.random.default_rng(3))[0]
    rng = np.random.default_rng(3)
    t_rel = 0.8
    g = chain.gain() * t_rel
    flicker = 1.0 + 0.01 * chain.flicker_pct * float(rng.standard_normal())
    f_pct = 100.0 * frac
    stray = chain.stray_pct + chain.stray_rel * float(np.mean(f_pct))
    signal = np.clip((f_pct + stray) * flicker, 0.0, None) * g
    dark = chain.dark_counts_per_s * 8000 * 1e-6
    counts = rng.poisson((signal + dark) * chain.electrons_per_count) / chain.electrons_per_count
    raw = chain.bias_counts + counts + chain.read_noise_counts * rng.standard_normal(counts.shape)
    raw = np.clip(np.round(raw), 0.0, chain.full_well_counts)
    assert np.array_equal(a, (raw - chain.bias_counts - dark) / g)


def test_pixels_per_channel_must_be_positive() -> None:
    with pytest.raises(ValueError, match="pixels_per_channel"):
        SpectroChain(pixels_per_channel=0)


@pytest.mark.parametrize("theta_r", [55.0, 67.0])
def test_the_chain_adds_no_colour_to_the_truths(theta_r: float) -> None:
    # where the default sample's measured a*/b* swing most (aspecular -10 and -22 deg), the
    # mean of repeat readings is the colour of the truth's own noise-free spectrum plus
    # the stray light (the chain's dark subtraction, gain calibration and exposure add no
    # colour): within 4 standard errors of the analytic propagation
    from goniolab.config import load_lab_config
    from sim.assembly import sample_truth

    cfg = load_lab_config("configs/lab-sim.toml")
    frac = np.asarray(sample_truth(cfg, "sample:wittmann-3").spectral_fraction(45.0, theta_r))
    chain = SpectroChain()
    exposure = min(_settled_exposure(chain, frac), 250_000)
    scale = float(reflectance_factor_scale(theta_r, 6.0))
    rng = np.random.default_rng(11)
    n = 400
    vals = np.array([chain.read(frac, exposure, rng)[0] for _ in range(n)])
    measured = _lab(spectra_to_xyz(WL, vals.mean(axis=0) / 100.0 * scale))
    mean_r = chain.mean_reading_pct(frac) / 100.0 * scale
    truth = _lab(spectra_to_xyz(WL, mean_r))
    cov = chain.covariance(frac, exposure) * (scale / 100.0) ** 2
    se = np.sqrt(np.diag(lab_covariance(WL, mean_r, cov)) / n)
    assert np.all(np.abs(measured - truth) < 4.0 * se)
