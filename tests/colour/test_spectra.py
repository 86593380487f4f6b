"""Spectra -> colour: against the CIE tables, colour-science itself and Sharma's dE2000 data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from goniolab.colour.spectra import (
    ColourError,
    ColourSettings,
    check_spectrum,
    colour_module,
    delta_e,
    lab_to_srgb,
    spectrum_to_colour,
    standard_grid_nm,
    xyz_weights,
)


def test_weights_sum_to_the_d65_10deg_white_point() -> None:
    # CIE 15:2004 table T.3: D65, 1964 10 deg observer: X = 94.811, Y = 100, Z = 107.304
    w = xyz_weights(standard_grid_nm(10))
    assert w.sum(axis=1) == pytest.approx([94.811, 100.0, 107.304], abs=0.02)


def test_weights_reproduce_sd_to_xyz() -> None:
    colour = colour_module()
    wl = standard_grid_nm(10)
    r = 0.1 + 0.6 * np.exp(-(((wl - 610.0) / 40.0) ** 2))
    ref = colour.sd_to_XYZ(
        colour.SpectralDistribution(r, wl),
        colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"],
        colour.SDS_ILLUMINANTS["D65"],
        method="ASTM E308",
    )
    assert xyz_weights(wl) @ r == pytest.approx(ref, rel=1e-10)


def test_perfect_diffuser_is_white_under_any_illuminant() -> None:
    wl = standard_grid_nm(5)
    for ill, obs in (("D65", "10"), ("A", "2"), ("C", "CIE 1931 2 Degree Standard Observer")):
        c = spectrum_to_colour(wl, np.ones_like(wl), ColourSettings(ill, obs))
        assert (c.L, c.a, c.b) == pytest.approx((100.0, 0.0, 0.0), abs=0.05)


def test_lch_and_srgb_of_a_red_spectrum() -> None:
    wl = standard_grid_nm(10)
    r = np.where(wl > 600, 0.8, 0.05)
    c = spectrum_to_colour(wl, r)
    assert c.a > 40 and pytest.approx(np.hypot(c.a, c.b)) == c.C
    assert c.h_deg == pytest.approx(np.degrees(np.arctan2(c.b, c.a)) % 360)
    rgb = lab_to_srgb(c.lab)
    assert rgb[0] > 0.6 and rgb[1] < 0.3 and rgb[2] < 0.3


def test_delta_e_2000_sharma_pairs() -> None:
    # G. Sharma, W. Wu, E. N. Dalal, Color Res. Appl. 30 (2005) 21, table 1, pairs 1 and 7
    assert float(delta_e([50.0, 2.6772, -79.7751], [50.0, 0.0, -82.7485])) == pytest.approx(
        2.0425, abs=1e-4
    )
    assert float(delta_e([50.0, 0.0, 0.0], [50.0, -1.0, 2.0])) == pytest.approx(2.3669, abs=1e-4)
    assert float(delta_e([50, 0, 0], [53, 4, 0], "CIE 1976")) == pytest.approx(5.0)


@pytest.mark.parametrize(
    ("wl", "values", "needle"),
    [
        (standard_grid_nm(10), np.ones(40), "40 values for 41 wavelengths"),
        (standard_grid_nm(10), np.r_[np.ones(40), np.nan], "780 nm is nan"),
        (standard_grid_nm(10), np.r_[-0.1, np.ones(40)], "380 nm is negative"),
        (np.linspace(420, 700, 29), np.ones(29), "420-700 nm do not cover 400-700 nm"),
        (np.linspace(350, 750, 41), np.ones(41), "reach outside 360-830 nm"),
        (np.r_[380.0, 390.0, 385.0], np.ones(3), "ascending"),
    ],
)
def test_bad_spectra_name_the_problem(wl: np.ndarray, values: np.ndarray, needle: str) -> None:
    with pytest.raises(ColourError, match=needle):
        check_spectrum(wl, values)


def test_unknown_illuminant_and_observer() -> None:
    with pytest.raises(ColourError, match="unknown illuminant 'D66'"):
        ColourSettings("D66").validated()
    with pytest.raises(ColourError, match="unknown observer '5'"):
        ColourSettings("D65", "5").validated()


def test_the_illuminants_known_without_colour_science_are_in_its_tables() -> None:
    import colour

    from goniolab.colour.spectra import COMMON_ILLUMINANTS

    for observer in ("CIE 1931 2 Degree Standard Observer", "CIE 1964 10 Degree Standard Observer"):
        missing = COMMON_ILLUMINANTS - set(colour.CCS_ILLUMINANTS[observer])
        assert not missing, (observer, missing)
    assert not COMMON_ILLUMINANTS - set(colour.SDS_ILLUMINANTS)


def test_a_config_naming_a_usual_illuminant_loads_without_colour_science(tmp_path: Path) -> None:
    import subprocess
    import sys

    from goniolab.config import configs_dir

    text = (configs_dir() / "lab-sim.toml").read_text()
    assert "[colour]" not in text  # the default D65 is validated too
    path = tmp_path / "lab.toml"
    path.write_text(text + '\n[colour]\nilluminant = "FL11"\n')
    for config, illuminant in ((configs_dir() / "lab-sim.toml", "D65"), (path, "FL11")):
        code = (
            "import sys; from goniolab.config import load_lab_config; "
            f"c = load_lab_config({str(config)!r}); "
            "print(c.colour.illuminant, 'colour' in sys.modules)"
        )
        out = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        )
        assert out.stdout.split() == [illuminant, "False"]


def test_lab_and_lch_match_colour_science() -> None:
    """xyz_to_colour writes CIE 15 eqs. 8.1-8.4 out; colour-science is the independent truth
    (both branches of f(t): dark colours below (6/29)^3 of the white too)."""
    import colour

    from goniolab.colour.spectra import xyz_to_colour

    rng = np.random.default_rng(5)
    xyz = np.concatenate([rng.uniform(0.0, 120.0, (200, 3)), rng.uniform(0.0, 0.5, (50, 3))])
    for settings in (ColourSettings(), ColourSettings("A", "2"), ColourSettings("FL11")):
        s = settings.validated()
        white = colour.CCS_ILLUMINANTS[s.observer][s.illuminant]
        lab = colour.XYZ_to_Lab(xyz / 100.0, white)
        lch = colour.Lab_to_LCHab(lab)
        got = xyz_to_colour(xyz, settings)
        np.testing.assert_allclose(got[:, :3], xyz, rtol=0, atol=0)
        np.testing.assert_allclose(got[:, 3:6], lab, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(got[:, 6], lch[:, 1], rtol=1e-10, atol=1e-10)
        dh = (got[:, 7] - lch[:, 2] + 180.0) % 360.0 - 180.0
        np.testing.assert_allclose(dh[lch[:, 1] > 1e-6], 0.0, atol=1e-8)


def test_a_400_700_grid_is_completed_as_astm_e308_says() -> None:
    """ASTM E308-18 sec. 7.3: a spectrum short of the tables' range is completed by
    repeating its end readings; the colour equals that of the spectrum written out on
    380-780 nm with the ends held, and every face can print how it was done."""
    from goniolab.colour.spectra import range_note

    wl = np.arange(400.0, 701.0, 10.0)
    r = 0.2 + 0.5 * np.exp(-(((wl - 600.0) / 50.0) ** 2))
    full_wl = standard_grid_nm(10)
    full = np.interp(full_wl, wl, r)  # np.interp holds the end values
    for s in (ColourSettings(), ColourSettings("A", "2")):
        a = spectrum_to_colour(wl, r, s)
        b = spectrum_to_colour(full_wl, full, s)
        assert a.lab == pytest.approx(b.lab, abs=1e-9)
    assert "400-700 nm" in range_note(wl) and "E308" in range_note(wl)
    assert range_note(full_wl) == ""
    # a 5 nm grid from 360 to 830 (the CMFs' range) is accepted too
    wl5 = np.arange(360.0, 831.0, 5.0)
    c = spectrum_to_colour(wl5, np.ones_like(wl5))
    assert c.lab == pytest.approx((100.0, 0.0, 0.0), abs=0.05)


@pytest.mark.parametrize(
    ("alias", "key"),
    [("F2", "FL2"), ("F11", "FL11"), ("f11", "FL11"), ("TL84", "FL11"), ("CWF", "FL2"),
     ("LED", "LED-B3"), ("d65", "D65"), ("FL11", "FL11")],
)  # fmt: skip
def test_illuminant_aliases(alias: str, key: str) -> None:
    import colour

    s = ColourSettings(alias).validated()
    assert s.illuminant == key
    np.testing.assert_array_equal(
        s.white_xy, colour.CCS_ILLUMINANTS["CIE 1964 10 Degree Standard Observer"][key]
    )
