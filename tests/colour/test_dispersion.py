"""Dispersion formulas against glass-catalogue values."""

from __future__ import annotations

import numpy as np
import pytest

from goniolab.colour.dispersion import (
    ALUMINIUM,
    Cauchy,
    DispersionError,
    Sellmeier,
    dispersion_from_dict,
    parse_nk_table,
)

BK7 = Sellmeier((1.03961212, 0.231792344, 1.01046945), (0.00600069867, 0.0200179144, 103.560653))


def test_sellmeier_bk7_catalogue_indices() -> None:
    # SCHOTT N-BK7 data sheet: n_F (486.13) 1.52238, n_d (587.56) 1.51680, n_C (656.27) 1.51432
    n = BK7.index([486.13, 587.56, 656.27]).real
    assert n == pytest.approx([1.52238, 1.51680, 1.51432], abs=2e-5)


def test_cauchy_two_term_matches_bk7_within_1e3() -> None:
    c = Cauchy(1.5046, 0.00420)
    wl = np.linspace(400, 700, 7)
    assert np.max(np.abs(c.index(wl).real - BK7.index(wl).real)) < 1e-3


def test_table_interpolates_and_checks_coverage() -> None:
    t = parse_nk_table("# coat\nwavelength n k\n400 1.60 0\n800, 1.50, 0.01\n", source="coat.csv")
    assert t.index([600.0])[0] == pytest.approx(1.55 + 0.005j)
    with pytest.raises(DispersionError, match=r"coat\.csv: covers 400-800 nm"):
        t.check_covers([380.0, 780.0])
    with pytest.raises(DispersionError, match="line 3: not numbers"):
        parse_nk_table("400 1.5\n500 1.5\n600 x\n", source="bad")


def test_config_forms_and_errors() -> None:
    assert dispersion_from_dict(1.5).index([500.0])[0] == 1.5
    d = dispersion_from_dict({"kind": "cauchy", "A": 1.5, "B": 0.005})
    assert d.index([500.0])[0].real == pytest.approx(1.5 + 0.005 / 0.25)
    with pytest.raises(DispersionError, match=r"coat: cauchy needs the key 'A'"):
        dispersion_from_dict({"kind": "cauchy"}, where="coat")
    with pytest.raises(DispersionError, match="unknown kind 'abbe'"):
        dispersion_from_dict({"kind": "abbe"})


def test_aluminium_is_a_good_mirror() -> None:
    # normal-incidence reflectance of Al is about 0.9 across the visible
    n = ALUMINIUM.index(np.array([400.0, 550.0, 700.0]))
    r = np.abs((n - 1) / (n + 1)) ** 2
    assert np.all((r > 0.86) & (r < 0.94))
