"""Colour differences against colour-science (independent code) and Sharma's published pairs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from goniolab.colour.difference import (
    components,
    delta_e_cie1976,
    delta_e_cie1994,
    delta_e_cie2000,
    delta_e_cmc,
)
from goniolab.colour.tolerance import (
    BUILTIN_SETS,
    ToleranceError,
    evaluate,
    load_tolerance_set,
    metamerism_table,
)

# G. Sharma, W. Wu, E. N. Dalal, Color Res. Appl. 30 (2005) 21, table 1: all 34 pairs
SHARMA_1 = [
    (50, 2.6772, -79.7751), (50, 3.1571, -77.2803), (50, 2.8361, -74.0200),
    (50, -1.3802, -84.2814), (50, -1.1848, -84.8006), (50, -0.9009, -85.5211),
    (50, 0, 0), (50, -1, 2), (50, 2.49, -0.001), (50, 2.49, -0.001), (50, 2.49, -0.001),
    (50, 2.49, -0.001), (50, -0.001, 2.49), (50, -0.001, 2.49), (50, -0.001, 2.49),
    (50, 2.5, 0), (50, 2.5, 0), (50, 2.5, 0), (50, 2.5, 0), (50, 2.5, 0), (50, 2.5, 0),
    (50, 2.5, 0), (50, 2.5, 0), (50, 2.5, 0), (60.2574, -34.0099, 36.2677),
    (63.0109, -31.0961, -5.8663), (61.2901, 3.7196, -5.3901), (35.0831, -44.1164, 3.7933),
    (22.7233, 20.0904, -46.694), (36.4612, 47.858, 18.3852), (90.8027, -2.0831, 1.441),
    (90.9257, -0.5406, -0.9208), (6.7747, -0.2908, -2.4247), (2.0776, 0.0795, -1.135),
]  # fmt: skip
SHARMA_2 = [
    (50, 0, -82.7485), (50, 0, -82.7485), (50, 0, -82.7485), (50, 0, -82.7485),
    (50, 0, -82.7485), (50, 0, -82.7485), (50, -1, 2), (50, 0, 0), (50, -2.49, 0.0009),
    (50, -2.49, 0.001), (50, -2.49, 0.0011), (50, -2.49, 0.0012), (50, 0.0009, -2.49),
    (50, 0.001, -2.49), (50, 0.0011, -2.49), (50, 0, -2.5), (73, 25, -18), (61, -5, 29),
    (56, -27, -3), (58, 24, 15), (50, 3.1736, 0.5854), (50, 3.2972, 0), (50, 1.8634, 0.5757),
    (50, 3.2592, 0.335), (60.4626, -34.1751, 39.4387), (62.8187, -29.7946, -4.0864),
    (61.4292, 2.248, -4.962), (35.0232, -40.0716, 1.5901), (23.0331, 14.973, -42.5619),
    (36.2715, 50.5065, 21.2231), (91.1528, -1.6435, 0.0447), (88.6381, -0.8985, -0.7239),
    (5.8714, -0.0985, -2.2286), (0.9033, -0.0636, -0.5514),
]  # fmt: skip
SHARMA_DE00 = [
    2.0425, 2.8615, 3.4412, 1.0, 1.0, 1.0, 2.3669, 2.3669, 7.1792, 7.1792, 7.2195, 7.2195,
    4.8045, 4.8045, 4.7461, 4.3065, 27.1492, 22.8977, 31.903, 19.4535, 1.0, 1.0, 1.0, 1.0,
    1.2644, 1.263, 1.8731, 1.8645, 2.0373, 1.4146, 1.4441, 1.5381, 0.6377, 0.9082,
]  # fmt: skip


def test_ciede2000_reproduces_sharmas_34_pairs() -> None:
    got = delta_e_cie2000(SHARMA_1, SHARMA_2)
    np.testing.assert_allclose(got, SHARMA_DE00, atol=5e-5)
    # symmetric, as CIEDE2000 is
    np.testing.assert_allclose(delta_e_cie2000(SHARMA_2, SHARMA_1), SHARMA_DE00, atol=5e-5)


@pytest.fixture(scope="module")
def pairs() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(11)
    ref = np.column_stack(
        [rng.uniform(5, 95, 400), rng.uniform(-60, 60, 400), rng.uniform(-60, 60, 400)]
    )
    return ref, ref + rng.normal(0.0, 2.0, ref.shape)


def test_every_formula_matches_colour_science(pairs: tuple[np.ndarray, np.ndarray]) -> None:
    import colour

    ref, smp = pairs
    np.testing.assert_allclose(
        delta_e_cie1976(ref, smp), colour.delta_E(ref, smp, "CIE 1976"), rtol=1e-12
    )
    np.testing.assert_allclose(
        delta_e_cie1994(ref, smp), colour.delta_E(ref, smp, "CIE 1994"), rtol=1e-10
    )
    np.testing.assert_allclose(
        delta_e_cie2000(ref, smp), colour.delta_E(ref, smp, "CIE 2000"), rtol=1e-10
    )
    for l_, c_ in ((2.0, 1.0), (1.0, 1.0)):
        np.testing.assert_allclose(
            delta_e_cmc(ref, smp, l_, c_), colour.delta_E(ref, smp, "CMC", l=l_, c=c_), rtol=1e-10
        )


def test_components_add_up_to_de76(pairs: tuple[np.ndarray, np.ndarray]) -> None:
    # CIE 15:2004 eq. 8.9: dE*ab^2 = dL*^2 + dC*^2 + dH*^2, and dH carries the sign of dh
    ref, smp = pairs
    d = components(ref, smp)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), delta_e_cie1976(ref, smp), rtol=1e-10)
    # a pure hue turn, counter-clockwise: dL = dC = 0, dH = +2 C sin(dh/2)
    c, h = 30.0, np.radians(40.0)
    turn = np.radians(10.0)
    a = components(
        [50, c * np.cos(h), c * np.sin(h)], [50, c * np.cos(h + turn), c * np.sin(h + turn)]
    )
    np.testing.assert_allclose(a, [0.0, 0.0, 2 * c * np.sin(turn / 2)], atol=1e-12)


def test_tolerance_verdicts_per_angle_and_overall() -> None:
    tol = BUILTIN_SETS["din6175-2"]
    asp = [15.0, 25.0, 45.0, 75.0, 110.0]
    ref = np.array([[90.0, 0.0, 0.0], [70.0, 0, 0], [40.0, 0, 0], [30.0, 0, 0], [28.0, 0, 0]])
    ok = ref + np.array([0.5, 0.0, 0.0])
    verdicts, overall = evaluate(tol, asp, ref, ok)
    assert overall == {"passed": True, "failed_angles": [], "missing_angles": [],
                       "checked_angles": asp}  # fmt: skip
    bad = ref.copy()
    bad[2, 0] += 1.1  # |dL*| 1.1 > 1.0 at 45 deg
    verdicts, overall = evaluate(tol, asp, ref, bad)
    assert overall["passed"] is False and overall["failed_angles"] == [45.0]
    assert verdicts[2].failed == ("dL",) and verdicts[2].values["dL"] == pytest.approx(1.1)
    # an angle of the set not measured: not a pass
    _, overall = evaluate(tol, asp[:4], ref[:4], ok[:4])
    assert overall["passed"] is False and overall["missing_angles"] == [110.0]


def test_a_toml_set_is_validated_with_file_key_and_reason(tmp_path: Path) -> None:
    text = """name = "oem"\nsource = "OEM norm 1"\nmetric = "CMC"\ncmc_l = 1.0
[angles."15"]\ndE = 2.0\n[angles."45"]\ndE = 1.0\ndL = 0.5\n"""
    tol = load_tolerance_set("oem.toml", text)
    assert tol.metric_label == "CMC(1:1)" and tol.limits[45.0].dL == 0.5
    _, overall = evaluate(
        tol, [15.0, 45.0], [[50, 10, 0], [50, 10, 0]], [[50, 10, 0], [50.6, 10, 0]]
    )
    assert overall["failed_angles"] == [45.0]
    for bad, needle in (
        ('[angles."45"]\ndE = -1\n', "oem.toml: angles.45.dE: must be a positive"),
        ('[angles."x"]\ndE = 1\n', "oem.toml: angles.x: the key must be an aspecular angle"),
        ('[angles."45"]\ndX = 1\n', "oem.toml: angles.45.dX: unknown limit"),
        ('metric = "CIE 2001"\n[angles."45"]\ndE = 1\n', "oem.toml: metric: 'CIE 2001'"),
        ("name = 'x'\n", "oem.toml: angles: needs at least one"),
        ("angles = [", "oem.toml: TOML syntax error"),
    ):
        with pytest.raises(ToleranceError, match=needle):
            load_tolerance_set("oem.toml", bad)


def test_metamerism_table_flags_a_metameric_pair() -> None:
    # two spectra of the same D65 colour built from different primaries differ under A
    wl = np.arange(400.0, 701.0, 10.0)
    smooth = 0.3 + 0.2 * np.exp(-(((wl - 600) / 60) ** 2))
    from goniolab.colour.spectra import ColourSettings, xyz_weights
    from goniolab.colour.tolerance import lab_under

    # add a metameric black (zero D65 tristimulus): a combination in the null space of W

    w = xyz_weights(wl, ColourSettings("D65"))
    _, _, vt = np.linalg.svd(w)
    black = vt[5] / np.abs(vt[5]).max() * 0.1
    spiky = smooth + black
    assert np.all(spiky > 0)
    np.testing.assert_allclose(lab_under(wl, spiky, "D65"), lab_under(wl, smooth, "D65"), atol=1e-9)
    rows = metamerism_table((wl, smooth[None]), (wl, spiky[None]), [45.0])
    by = {r["illuminant"]: r for r in rows}
    assert by["D65"]["dE00"] < 1e-6
    assert max(by["A"]["dE00"], by["FL11"]["dE00"], by["LED-B3"]["dE00"]) > 0.1


def test_an_angle_without_a_pair_is_missing_not_failed() -> None:
    tol = BUILTIN_SETS["de00-1"]
    ref = np.array([[50.0, 0.0, 0.0], [40.0, 0.0, 0.0]])
    smp = np.array([[50.2, 0.0, 0.0], [np.nan, np.nan, np.nan]])
    verdicts, overall = evaluate(tol, [15.0, 45.0], ref, smp)
    assert verdicts[0].passed is True and verdicts[1].passed is None
    assert overall["failed_angles"] == [] and 45.0 in overall["missing_angles"]
    assert overall["passed"] is False  # an angle of the set was not judged
