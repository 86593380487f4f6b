"""The predicted spectrum: interpolation in n against per-wavelength evaluation, the
reflectance-factor scale against a Lambertian sample, and the flop index of the paints."""

from __future__ import annotations

import math

import numpy as np
import pytest

from goniolab.colour.dispersion import Cauchy, Constant
from goniolab.colour.multiangle import (
    E2194_ASPECULAR_DEG,
    aspecular_deg,
    flop_index,
    theta_r_for_aspecular,
)
from goniolab.colour.paint import MetallicFlakes, Paint, PigmentLayer, Spectrum
from goniolab.colour.spectra import spectra_to_xyz, xyz_to_colour
from goniolab.colour.spectral import SpectralPredictor, SurfaceFactory, reflectance_factor_scale
from goniolab.optics.analytic import AnalyticModel
from goniolab.optics.apertures import Cone, integrate_brdf

BECKMANN = SurfaceFactory(lambda n, wl: AnalyticModel("beckmann", alpha=0.1, n=n), name="beckmann")
WL = np.linspace(380.0, 780.0, 21)


def test_interpolation_in_n_matches_per_wavelength_models() -> None:
    paint = Paint(Cauchy(1.48, 0.012))  # strongly dispersive coat: n 1.563 .. 1.500
    tr = np.array([30.0, 45.0, 55.0])
    fast = SpectralPredictor(BECKMANN, paint, wavelengths_nm=WL).surface_fraction(45.0, tr)
    exact = SpectralPredictor(BECKMANN, paint, wavelengths_nm=WL, exact=True).surface_fraction(
        45.0, tr
    )
    assert fast == pytest.approx(exact, rel=1e-4)
    # and it is dispersive: more reflection in the blue
    assert np.all(exact[:, 0] > exact[:, -1])


def test_wavelength_dependent_factory_uses_nodes_and_a_spline() -> None:
    calls: list[float] = []

    def build(n: complex, wl: float) -> AnalyticModel:
        calls.append(wl)
        return AnalyticModel("beckmann", alpha=0.05 + 1e-4 * (wl - 380.0), n=n)

    fac = SurfaceFactory(build, wavelength_dependent=True, name="toy")
    paint = Paint(Constant(1.5))
    fast = SpectralPredictor(fac, paint, wavelengths_nm=WL).surface_fraction(45.0, [50.0])
    assert len(calls) == 11  # nodes 40 nm apart
    exact = SpectralPredictor(fac, paint, wavelengths_nm=WL, exact=True).surface_fraction(
        45.0, [50.0]
    )
    assert fast == pytest.approx(exact, rel=2e-3)


def test_reflectance_factor_of_a_lambertian_sample() -> None:
    r = 0.37
    for tr in (-30.0, 0.0, 25.0, 60.0):
        frac = integrate_brdf(
            lambda wi, wo: np.full(wi.shape[0], r / math.pi), 45.0, tr, Cone(6.0), Cone(6.0)
        )
        assert frac * float(reflectance_factor_scale(tr, 6.0)) == pytest.approx(r, rel=1e-3)


def test_paint_term_through_cones_matches_integrate_brdf() -> None:
    paint = Paint(
        Constant(1.5),
        PigmentLayer(Spectrum.flat(0.3), Spectrum.flat(2.0), 50.0, Spectrum.flat(0.5)),
        metallic=MetallicFlakes(0.3, 10.0),
    )
    sp = SpectralPredictor(None, paint, wavelengths_nm=np.array([550.0]), quadrature_rings=4)
    got = sp.paint_fraction(45.0, [30.0, 50.0])[:, 0]
    ref = [
        integrate_brdf(
            lambda wi, wo: paint.subsurface_brdf(wi, wo, [550.0])[:, 0],
            45.0, t, Cone(6.0), Cone(6.0), n_source=8, n_receptor=8,
        )
        for t in (30.0, 50.0)
    ]  # fmt: skip
    assert got == pytest.approx(ref, rel=5e-3)


def test_aspecular_geometry() -> None:
    assert [theta_r_for_aspecular(a) for a in E2194_ASPECULAR_DEG] == [60, 30, 20, 0, -30, -65]
    assert aspecular_deg(-65.0) == 110.0


def test_flop_index_formula_and_missing_angles() -> None:
    # 2.69 (L15 - L110)^1.11 / L45^0.86 with L15 = 110, L110 = 30, L45 = 60
    assert flop_index({15.0: 110.0, 45.0: 60.0, 110.0: 30.0}) == pytest.approx(
        2.69 * math.exp(1.11 * math.log(80.0)) / math.exp(0.86 * math.log(60.0))
    )
    with pytest.raises(ValueError, match="missing 110"):
        flop_index({15.0: 1.0, 45.0: 1.0})


GLOSSY = SurfaceFactory(lambda n, wl: AnalyticModel("beckmann", alpha=0.03, n=n), name="glossy")


def _fi(paint: Paint) -> float:
    sp = SpectralPredictor(GLOSSY, paint, wavelengths_nm=WL)
    tr = np.array([theta_r_for_aspecular(a) for a in E2194_ASPECULAR_DEG])
    f = sp.spectrum_pct(45.0, tr) / 100.0 * reflectance_factor_scale(tr, 6.0)[:, None]
    lab = xyz_to_colour(spectra_to_xyz(WL, f))[:, 3:6]
    return flop_index(dict(zip(E2194_ASPECULAR_DEG, lab[:, 0], strict=True)))


def test_metallic_flops_and_a_solid_does_not() -> None:
    body = PigmentLayer(Spectrum.flat(0.5), Spectrum.flat(1.0), 20.0, Spectrum.flat(0.3))
    solid = Paint(Constant(1.5), body)
    metallic = Paint(Constant(1.5), body, metallic=MetallicFlakes(0.5, 8.0))
    assert abs(_fi(solid)) < 2.0  # solids ~0-2 (X-Rite)
    assert _fi(metallic) > 8.0  # metallics ~10-17
