"""Shared fixtures for the optics tests: synthetic Gaussian height maps made with numpy.

A Gaussian random surface is white noise convolved (periodically, by FFT) with a Gaussian
kernel of standard deviation ``corr_px`` pixels, scaled so that the rms of the central
difference slope along x is exactly ``slope_rms``. Central differences of such a field are
jointly Gaussian, and p and q are uncorrelated (the kernel's covariance is even in x and in
y), so the slope density is the product of two Gaussians: the analytic truth the facet
model must reproduce.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from goniolab.optics.heightmap import HeightMap
from goniolab.optics.surface import Surface

GaussianFactory = Callable[..., HeightMap]


def make_gaussian_map(
    n: int = 256,
    slope_rms: float = 0.05,
    *,
    corr_px: float = 1.5,
    seed: int = 1,
    step_um: float = 1.0,
) -> HeightMap:
    """Isotropic Gaussian surface, ``n x n`` pixels, central-difference x-slope rms ``slope_rms``."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(size=(n, n))
    k = np.fft.fftfreq(n)
    kernel_ft = np.exp(-0.5 * (2.0 * np.pi * corr_px) ** 2 * (k[:, None] ** 2 + k[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(noise) * kernel_ft))
    p = (z[:, 2:] - z[:, :-2]) / (2.0 * step_um)
    z *= slope_rms / float(np.sqrt(np.mean(p * p)))
    return HeightMap(z_um=z, dx_um=step_um, dy_um=step_um, source=f"gaussian(s={slope_rms})")


def gaussian_acf_map(n: int, sq_um: float, l_um: float, step_um: float, seed: int) -> HeightMap:
    """Periodic Gaussian surface with ACF Sq^2 exp(-r^2/l^2) (heights scaled to Sq exactly)."""
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(n, step_um)
    filt = np.exp(-0.5 * (math.pi * l_um) ** 2 * (f[:, None] ** 2 + f[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * filt))
    z *= sq_um / z.std()
    return HeightMap(z_um=z, dx_um=step_um, dy_um=step_um, source=f"gauss(Sq={sq_um})")


@pytest.fixture(scope="session")
def gaussian_factory() -> GaussianFactory:
    """The factory itself, for tests that need their own size or roughness."""
    return make_gaussian_map


@pytest.fixture(scope="session")
def gauss_map_1024() -> HeightMap:
    """1024 x 1024 Gaussian surface, per-axis rms slope 0.05 (about 1e6 facets)."""
    return make_gaussian_map(1024, 0.05, seed=7)


@pytest.fixture(scope="session")
def gauss_surface_1024(gauss_map_1024: HeightMap) -> Surface:
    """Facets of :func:`gauss_map_1024` by central differences, levelled."""
    return Surface.from_heightmap(gauss_map_1024, slope_method="central")


@pytest.fixture(scope="session")
def gauss_surface_256() -> Surface:
    """Small Gaussian surface (65k facets, rms slope 0.05) for the cross-checks."""
    return Surface.from_heightmap(make_gaussian_map(256, 0.05, seed=3), slope_method="central")


@pytest.fixture(scope="session")
def flat_surface() -> Surface:
    """A perfectly flat mirror: 1000 facets of zero slope."""
    return Surface(p=np.zeros(1000), q=np.zeros(1000), source="flat")
