"""Fresnel reflectance against the seed's eq. 9, closed forms and tabulated values."""

from __future__ import annotations

import numpy as np
import pytest

from goniolab.optics.fresnel import (
    fresnel,
    fresnel_conductor,
    fresnel_dielectric,
    fresnel_dielectric_sp,
)


def _eq9(iota: np.ndarray, n: float) -> np.ndarray:
    """Wittmann et al. (2021) eq. 9 verbatim, angle form (undefined at iota = 0)."""
    tau = np.arcsin(np.sin(iota) / n)
    return 0.5 * (
        np.tan(tau - iota) ** 2 / np.tan(tau + iota) ** 2
        + np.sin(tau - iota) ** 2 / np.sin(tau + iota) ** 2
    )


@pytest.mark.parametrize("n", [1.33, 1.55, 1.567, 2.4])
def test_cos_form_equals_seed_eq9(n: float) -> None:
    iota = np.radians(np.linspace(0.5, 89.5, 179))
    np.testing.assert_allclose(fresnel_dielectric(np.cos(iota), n), _eq9(iota, n), rtol=1e-12)


@pytest.mark.parametrize("n", [1.0001, 1.5, 1.567, 3.0])
def test_normal_incidence_limit_and_grazing(n: float) -> None:
    r0 = fresnel_dielectric(1.0, n)
    assert np.isfinite(r0)
    assert r0 == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-14)
    # eq. 9 approaches the same limit from iota > 0
    assert float(_eq9(np.array([1e-4]), n)[0]) == pytest.approx(float(r0), rel=1e-6)
    assert fresnel_dielectric(0.0, n) == pytest.approx(1.0, abs=1e-15)


def test_iso2813_black_glass_values() -> None:
    # docs/PHYSICS.md, "Fresnel reflectance": n = 1.567 black glass, 0.04908 (20), 0.10006 (60), 0.61915 (85)
    cos_t = np.cos(np.radians([20.0, 60.0, 85.0]))
    np.testing.assert_allclose(
        fresnel_dielectric(cos_t, 1.567), [0.04908, 0.10006, 0.61915], atol=5e-6
    )


@pytest.mark.parametrize("n", [1.5, 1.567, 2.0])
def test_brewster_angle_p_polarisation(n: float) -> None:
    theta_b = np.arctan(n)
    r_s, r_p = fresnel_dielectric_sp(np.cos(theta_b), n)
    assert float(r_p) == pytest.approx(0.0, abs=1e-15)
    assert float(fresnel_dielectric(np.cos(theta_b), n)) == pytest.approx(0.5 * float(r_s))
    # and R_p is not zero on either side of it
    for d in (-0.05, 0.05):
        assert float(fresnel_dielectric_sp(np.cos(theta_b + d), n)[1]) > 1e-5


def test_total_internal_reflection_below_unit_index() -> None:
    # from the dense side (n < 1) beyond the critical angle everything is reflected
    n = 1 / 1.5
    crit = np.arcsin(n)
    assert fresnel_dielectric(np.cos(crit + 0.01), n) == pytest.approx(1.0)
    assert fresnel_dielectric(np.cos(crit - 0.1), n) < 1.0


def test_copper_normal_incidence_closed_form() -> None:
    n, k = 0.27, 3.41
    expected = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)  # = 0.91844...
    assert float(fresnel_conductor(1.0, complex(n, k))) == pytest.approx(expected, rel=1e-13)
    assert expected == pytest.approx(0.9184, abs=1e-4)


@pytest.mark.parametrize("eta", [complex(0.27, 3.41), complex(1.5, 0.2), complex(2.9, 3.0)])
def test_conductor_equals_born_wolf_closed_form(eta: complex) -> None:
    """Closed form for absorbing media (Born & Wolf 14.2; Hecht): a^2, b^2 parametrisation."""
    n, k = eta.real, eta.imag
    th = np.radians(np.linspace(0.0, 89.0, 90))
    s, c = np.sin(th), np.cos(th)
    u = n * n - k * k - s * s
    root = np.sqrt(u * u + 4 * n * n * k * k)
    a = np.sqrt(0.5 * (root + u))
    b = np.sqrt(0.5 * (root - u))
    r_s = ((a - c) ** 2 + b**2) / ((a + c) ** 2 + b**2)
    r_p = r_s * ((a - s * np.tan(th)) ** 2 + b**2) / ((a + s * np.tan(th)) ** 2 + b**2)
    np.testing.assert_allclose(fresnel_conductor(c, eta), 0.5 * (r_s + r_p), rtol=1e-10)


def test_conductor_reduces_to_dielectric_for_zero_k() -> None:
    c = np.cos(np.radians(np.linspace(0, 90, 181)))
    np.testing.assert_allclose(
        fresnel_conductor(c, 1.55 + 0j), fresnel_dielectric(c, 1.55), rtol=1e-12
    )
    np.testing.assert_allclose(fresnel(c, 1.55 + 0j), fresnel_dielectric(c, 1.55), rtol=0)
    np.testing.assert_allclose(fresnel(c, 0.27 + 3.41j), fresnel_conductor(c, 0.27 + 3.41j), rtol=0)


def test_vectorised_shape_preserved() -> None:
    c = np.full((3, 4), 0.5)
    assert fresnel_dielectric(c, 1.5).shape == (3, 4)
    assert fresnel_conductor(c, 1.5 + 1j).shape == (3, 4)


def test_bad_input_is_rejected_clearly() -> None:
    with pytest.raises(ValueError, match="refractive index"):
        fresnel_dielectric(0.5, -1.0)
    with pytest.raises(ValueError, match="k >= 0"):
        fresnel_conductor(0.5, 1.5 - 1j)
    with pytest.raises(ValueError, match="NaN"):
        fresnel_dielectric(np.array([0.5, np.nan]), 1.5)
