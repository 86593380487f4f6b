"""Aperture quadrature and the source x receptor BRDF integral (Mihalik eqs. 15-17)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from numpy.typing import NDArray

from goniolab.optics.apertures import (
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Cone,
    Rect,
    aperture_contains,
    direction,
    inplane_centre,
    integrate_brdf,
    projected_solid_angle_sr,
    sample_aperture,
    solid_angle_sr,
)

F64 = NDArray[np.float64]


@pytest.mark.parametrize(
    "aperture", [Cone(6.0), Cone(0.5), Rect(4.4, 11.7), Rect(0.75, 2.5), Rect(40.0, 20.0)]
)
@pytest.mark.parametrize(("theta", "phi"), [(0.0, 0.0), (60.0, 180.0), (20.0, 37.0)])
def test_patches_are_unit_inside_and_sum_to_the_exact_solid_angle(
    aperture: Cone | Rect, theta: float, phi: float
) -> None:
    dirs, w = sample_aperture(aperture, theta, phi, n=12)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
    assert np.all(aperture_contains(aperture, theta, phi, dirs))
    # Exact: cap 2 pi (1 - cos h); rectangle int cos b da db = A * 2 sin(B/2).
    if isinstance(aperture, Cone):
        exact = 2 * np.pi * (1 - np.cos(np.radians(aperture.full_angle_deg / 2)))
    else:
        exact = np.radians(aperture.in_plane_deg) * 2 * np.sin(np.radians(aperture.perp_deg / 2))
    assert w.sum() == pytest.approx(exact, rel=1e-12)
    assert solid_angle_sr(aperture) == pytest.approx(exact, rel=1e-12)
    # The weighted mean direction points at the centre (symmetric quadrature).
    mean = (dirs * w[:, None]).sum(axis=0)
    np.testing.assert_allclose(mean / np.linalg.norm(mean), direction(theta, phi), atol=1e-12)


def test_rect_axes_in_plane_and_perpendicular() -> None:
    # A Rect 10 x 0 deg centred at theta=30, phi=0 spans theta 25..35 in the x-z plane.
    dirs, _ = sample_aperture(Rect(10.0, 0.0), 30.0, 0.0, n=5)
    np.testing.assert_allclose(dirs[:, 1], 0.0, atol=1e-15)
    thetas = np.degrees(np.arccos(dirs[:, 2]))
    np.testing.assert_allclose(np.sort(thetas), [26.0, 28.0, 30.0, 32.0, 34.0], atol=1e-12)
    # A Rect 0 x 10 deg tilts out of the plane: y component sin(beta), beta in +-4 deg.
    dirs, _ = sample_aperture(Rect(0.0, 10.0), 30.0, 0.0, n=5)
    np.testing.assert_allclose(
        np.sort(np.degrees(np.arcsin(dirs[:, 1]))), [-4, -2, 0, 2, 4], atol=1e-12
    )


def test_inplane_centre_sign_convention() -> None:
    assert inplane_centre(45.0) == (45.0, 180.0)
    assert inplane_centre(-30.0) == (30.0, 0.0)


def _lambert(rho: float) -> Callable[[F64, F64], F64]:
    def f(wi: F64, wo: F64) -> F64:
        return np.full(wi.shape[0], rho / np.pi)

    return f


@pytest.mark.parametrize("theta_r", [0.0, 25.0, 60.0, -40.0])
def test_lambertian_cone_gives_rho_times_projected_solid_angle_over_pi(theta_r: float) -> None:
    # Projected solid angle of a cap of half angle h centred at theta_c (fully above the
    # horizon): Omega * cos(theta_c) * (1 + cos h) / 2 = pi sin^2 h cos theta_c.
    rho, h = 0.8, np.radians(3.0)
    got = integrate_brdf(_lambert(rho), 45.0, theta_r, Cone(6.0), Cone(6.0), n_receptor=24)
    exact = rho * np.pi * np.sin(h) ** 2 * np.cos(np.radians(abs(theta_r))) / np.pi
    assert got == pytest.approx(exact, rel=2e-4)


@pytest.mark.parametrize("angle", [20, 60, 85])
def test_lambertian_rect_matches_closed_form(angle: int) -> None:
    # int cos b cos(theta + a) cos b da db = 2 cos(theta) sin(A) (B + sin B cos B),
    # with half widths A (in plane) and B (perpendicular).
    rec = ISO2813_RECEPTOR[angle]
    a, b, t = np.radians(rec.in_plane_deg / 2), np.radians(rec.perp_deg / 2), np.radians(angle)
    exact = 0.5 * 2 * np.cos(t) * np.sin(a) * (b + np.sin(b) * np.cos(b)) / np.pi
    got = integrate_brdf(_lambert(0.5), angle, angle, ISO2813_SOURCE, rec)
    assert got == pytest.approx(exact, rel=1e-4)


def _narrow_lobe(sigma_deg: float) -> Callable[[F64, F64], F64]:
    """Normalised Gaussian lobe around the mirror direction: int f cos(to) dOmega_o = 1."""
    s = np.radians(sigma_deg)

    def f(wi: F64, wo: F64) -> F64:
        mirror = wi * np.array([-1.0, -1.0, 1.0])
        delta = np.arccos(np.clip(np.sum(mirror * wo, axis=1), -1.0, 1.0))
        return np.exp(-0.5 * (delta / s) ** 2) / (2 * np.pi * s**2) / wo[:, 2]

    return f


def test_narrow_lobe_is_fully_captured_and_missed_off_specular() -> None:
    lobe = _narrow_lobe(0.3)
    point = integrate_brdf(lobe, 30.0, 30.0, Cone(0.0), Cone(6.0), n_receptor=64)
    assert point == pytest.approx(1.0, abs=2e-3)
    gloss60 = integrate_brdf(lobe, 60.0, 60.0, ISO2813_SOURCE, ISO2813_RECEPTOR[60], n_receptor=40)
    assert gloss60 == pytest.approx(1.0, abs=2e-3)
    assert integrate_brdf(lobe, 30.0, 40.0, Cone(0.0), Cone(6.0), n_receptor=32) < 1e-12


def test_point_source_and_receptor_give_brdf_cosine() -> None:
    got = integrate_brdf(_lambert(0.3), 20.0, 50.0, Cone(0.0), Cone(0.0))
    assert got == pytest.approx(0.3 / np.pi * np.cos(np.radians(50.0)), rel=1e-12)


def test_bad_subdivision_count_is_rejected() -> None:
    with pytest.raises(ValueError, match="subdivisions"):
        sample_aperture(Cone(6.0), 0.0, 0.0, n=0)


@pytest.mark.parametrize("theta_r_deg", [0.0, 30.0, -45.0, 85.0, 86.9, 88.0])
def test_projected_solid_angle_of_the_detector_cone(theta_r_deg: float) -> None:
    """``pi sin^2(a) cos(theta_r)`` for a cap above the horizon (the closed form of the
    integral of w over a cap), the quadrature of its part above the horizon beyond."""
    t, p = inplane_centre(theta_r_deg)
    dirs, w = sample_aperture(Cone(6.0), t, p, n=64)
    want = float(np.sum(np.clip(dirs[:, 2], 0.0, None) * w))
    assert projected_solid_angle_sr(Cone(6.0), theta_r_deg) == pytest.approx(want, rel=1e-4)
