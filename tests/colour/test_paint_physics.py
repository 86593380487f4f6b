"""Issue 25's paint-model corrections, each against an analytic truth; the built-in white and
red against the ranges of real paints."""

from __future__ import annotations

import json

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.colour.dispersion import Constant
from goniolab.colour.km import internal_diffuse_reflectance
from goniolab.colour.optics import fresnel_unpolarised
from goniolab.colour.paint import Paint, PaintError, PigmentLayer, Spectrum, paint_from_dict
from goniolab.optics.apertures import direction

WL = np.array([450.0, 550.0, 650.0])


def _body(k: float = 0.05) -> PigmentLayer:
    return PigmentLayer(Spectrum.flat(k), Spectrum.flat(5.0), 1e4, Spectrum.flat(0.5))


def _km_r_inf(k_over_s: float) -> float:
    return 1.0 + k_over_s - np.sqrt(k_over_s**2 + 2.0 * k_over_s)  # Kubelka-Munk R_inf


def test_textbook_saunderson_is_the_k1_k2_formula() -> None:
    """``saunderson = "textbook"``: pi f = (1 - k1)(1 - k2) R / (1 - k2 R) at any geometry
    (Saunderson 1942), with k1 = F(0; n) and k2 = r_i(n) by default or as given."""
    rb = _km_r_inf(0.05 / 5.0)
    wi, wo = direction(45.0, 0.0)[None], direction(0.0, 0.0)[None]
    for k1, k2 in ((None, None), (0.04, 0.6)):
        paint = Paint(Constant(1.5), _body(), saunderson="textbook", k1=k1, k2=k2)
        e1 = fresnel_unpolarised(1.0, 1.5) if k1 is None else k1
        e2 = float(internal_diffuse_reflectance(1.5)) if k2 is None else k2
        expected = (1 - e1) * (1 - e2) * rb / (1 - e2 * rb)
        got = np.pi * paint.subsurface_brdf(wi, wo, WL)[0]
        np.testing.assert_allclose(got, expected, rtol=1e-9)
        got2 = (
            np.pi
            * paint.subsurface_brdf(direction(20.0, 0.0)[None], direction(60.0, 90.0)[None], WL)[0]
        )
        np.testing.assert_allclose(got2, expected, rtol=1e-9)  # Lambertian


def test_directional_over_textbook_is_1_046_at_45_0() -> None:
    """The documented difference: T(45) T(0) / (n^2 (1 - k1)(1 - k2)) = 1.046 for n = 1.5
    (whatever the body, as both share the 1 / (1 - r_i R) inter-reflection)."""
    n = 1.5
    wi, wo = direction(45.0, 0.0)[None], direction(0.0, 0.0)[None]
    d = Paint(Constant(n), _body()).subsurface_brdf(wi, wo, WL)[0]
    t = Paint(Constant(n), _body(), saunderson="textbook").subsurface_brdf(wi, wo, WL)[0]
    ratio = (
        (1 - fresnel_unpolarised(np.cos(np.radians(45.0)), n))
        * (1 - fresnel_unpolarised(1.0, n))
        / (n * n * (1 - fresnel_unpolarised(1.0, n)) * (1 - internal_diffuse_reflectance(n)))
    )
    np.testing.assert_allclose(d / t, ratio, rtol=1e-9)
    assert float(ratio) == pytest.approx(1.046, abs=1e-3)


def test_saunderson_options_from_toml_and_back() -> None:
    from goniolab.colour.paint import paint_to_dict

    p = paint_from_dict({"body": {"K": 0.1, "S": 5}, "saunderson": {"form": "textbook", "k2": 0.6}})
    assert p.saunderson == "textbook" and p.k2 == 0.6 and p.k1 is None
    doc, _ = paint_to_dict(p)
    assert doc["saunderson"] == {"form": "textbook", "k2": 0.6}
    assert paint_from_dict(doc) == p
    with pytest.raises(PaintError, match="saunderson: 'both' is not"):
        paint_from_dict({"saunderson": {"form": "both"}})
    with pytest.raises(PaintError, match=r"saunderson.k2: must be in \[0, 1\)"):
        paint_from_dict({"saunderson": {"form": "textbook", "k2": 1.2}})


def _predict(capsys: pytest.CaptureFixture[str], sample: str) -> dict:
    assert main(["predict", "colour", sample, "--json", "--step-nm", "10"]) == 0
    return json.loads(capsys.readouterr().out)


def test_built_in_white_and_red_read_like_real_paints(capsys: pytest.CaptureFixture[str]) -> None:
    # rutile TiO2 whites in clear: L* 93-96, b* +1..+3 (issue 25); a DPP full-shade red:
    # L* 38-42, C* 55-62, h 30-35 deg (configs/samples.toml), at 45/0 (aspecular 45)
    w = next(g for g in _predict(capsys, "sample:white")["geometries"] if g["aspecular_deg"] == 45)
    assert 93.0 <= w["L"] <= 96.0 and 1.0 <= w["b"] <= 3.0
    r = next(
        g for g in _predict(capsys, "sample:solid-red")["geometries"] if g["aspecular_deg"] == 45
    )
    assert 38.0 <= r["L"] <= 42.0 and 55.0 <= r["C"] <= 62.0 and 30.0 <= r["h_deg"] <= 35.0
