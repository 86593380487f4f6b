"""Kubelka-Munk, Saunderson, Airy films: the issue's independent truths."""

from __future__ import annotations

import numpy as np
import pytest

from goniolab.colour.km import (
    internal_diffuse_reflectance,
    km_from_contrast,
    km_r_inf,
    km_reflectance,
    km_reflectance_seed,
    saunderson,
)
from goniolab.colour.optics import airy_film, fresnel_unpolarised

K = np.array([0.02, 0.3, 1.0, 5.0])
S = np.array([2.0, 1.0, 3.0, 0.5])


def test_r_inf_formula_and_thick_layer() -> None:
    q = K / S
    assert km_r_inf(q) == pytest.approx(1 + q - np.sqrt(q * q + 2 * q))
    assert km_reflectance(K, S, 1e4, 0.3) == pytest.approx(km_r_inf(q), rel=1e-9)


def test_zero_thickness_is_the_substrate() -> None:
    assert km_reflectance(K, S, 0.0, np.array([0.1, 0.5, 0.9, 1.0])) == pytest.approx(
        [0.1, 0.5, 0.9, 1.0]
    )


def test_hyperbolic_equals_seed_exponential_form() -> None:
    for x in (0.1, 0.5, 2.0):
        assert km_reflectance(K, S, x, 0.6) == pytest.approx(km_reflectance_seed(K, S, x, 0.6))


def test_energy_and_monotonic_in_substrate() -> None:
    for x in (0.05, 0.5, 5.0):
        r = km_reflectance(K, S, x, 1.0)
        assert np.all(r <= 1.0 + 1e-12) and np.all(r >= 0)
        assert np.all(km_reflectance(K, S, x, 0.2) < km_reflectance(K, S, x, 0.8))


def test_k_s_from_white_and_black_backgrounds_round_trip() -> None:
    x = 0.4
    rw = km_reflectance(K, S, x, 0.9)
    rb = km_reflectance(K, S, x, 0.04)
    k, s = km_from_contrast(rw, rb, x, 0.9, 0.04)
    assert k == pytest.approx(K, rel=1e-8)
    assert s == pytest.approx(S, rel=1e-8)


def test_internal_diffuse_reflectance_n15() -> None:
    # Judd & Wyszecki: r_i ~ 0.596 for n = 1.5 (external diffuse r_e = 0.092)
    assert float(internal_diffuse_reflectance(1.5)) == pytest.approx(0.596, abs=1e-3)


def test_saunderson_white_body_loses_only_the_entry_reflection() -> None:
    ri = float(internal_diffuse_reflectance(1.5))
    assert float(saunderson(1.0, 0.04, ri)) == pytest.approx(0.96)
    assert float(saunderson(0.0, 0.04, ri)) == 0.0


def test_film_lossless_energy_and_bare_interface_limit() -> None:
    wl = np.linspace(380, 780, 41)
    for c in (1.0, 0.7, 0.3):
        r, t = airy_film(c, wl, 1.5, 2.5, 180.0, 1.58)
        assert r + t == pytest.approx(np.ones_like(wl), abs=1e-12)
        r0, _ = airy_film(c, wl, 1.5, 2.5, 0.0, 1.58)
        assert r0 == pytest.approx(fresnel_unpolarised(c, 1.58, 1.5) * np.ones_like(wl))


def test_quarter_wave_film_normal_incidence() -> None:
    # Born & Wolf 1.6.4: at n1 d = lambda/4, R = ((n0 n2 - n1^2)/(n0 n2 + n1^2))^2
    n0, n1, n2 = 1.0, 1.38, 1.52
    d = 550.0 / (4 * n1)
    r, _ = airy_film(1.0, np.array([550.0]), n0, n1, d, n2)
    assert r[0] == pytest.approx(((n0 * n2 - n1**2) / (n0 * n2 + n1**2)) ** 2, rel=1e-10)


@pytest.mark.parametrize("cos_0", [1.0, 0.8])
def test_interference_maxima_of_a_high_index_film(cos_0: float) -> None:
    # TiO2-like film (n 2.5, 300 nm) in a binder (1.5) on both sides: maxima where
    # 2 n_f d cos t_f = (m - 1/2) lambda
    nf, d, nb = 2.5, 300.0, 1.5
    wl = np.linspace(380.0, 780.0, 40001)
    r, _ = airy_film(cos_0, wl, nb, nf, d, nb)
    cos_f = np.sqrt(1 - (1 - cos_0**2) * (nb / nf) ** 2)
    opd = 2 * nf * d * cos_f
    expected = [opd / (m - 0.5) for m in range(1, 10) if 380 < opd / (m - 0.5) < 780]
    peaks = [wl[i] for i in range(1, wl.size - 1) if r[i] > r[i - 1] and r[i] >= r[i + 1]]
    assert peaks == pytest.approx(sorted(expected), abs=0.05)
