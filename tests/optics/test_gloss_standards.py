"""Gloss, haze (ASTM D4039, E430) and DOI readings from reflectance models."""

from __future__ import annotations

import itertools

import pytest

from goniolab.optics.analytic import AnalyticModel
from goniolab.optics.facet import FacetModel
from goniolab.optics.gloss_standards import (
    GlossReport,
    d523_recommended_angle,
    gloss_report,
)
from goniolab.optics.surface import Surface
from goniolab.surfaces.synthetic import make_sample


def _flat(n: float) -> FacetModel:
    return FacetModel(Surface.from_heightmap(make_sample("flat", size=64)), n=n)


def test_flat_black_glass_reads_100_no_haze_full_doi() -> None:
    rep = gloss_report(_flat(1.567))
    for g in (rep.G20, rep.G60, rep.G85):
        assert g == pytest.approx(100.0, abs=1e-6)
    assert rep.haze_index == pytest.approx(0.0, abs=1e-6)
    e = rep.e430
    assert e.gloss_20 == pytest.approx(100.0, abs=1e-6)
    assert e.gloss_30 == pytest.approx(100.0, abs=1e-6)
    assert (e.haze_18_1, e.haze_21_9, e.haze_narrow, e.haze_wide) == (0.0, 0.0, 0.0, 0.0)
    assert e.doi == 100.0
    assert rep.d523_recommended_angle == 20


def test_flat_pu_haze_index_is_the_fresnel_difference() -> None:
    # docs/PHYSICS.md truth: flat n = 1.55 reads 95.4 (20) and 97.3 (60), so HI = 1.9.
    rep = gloss_report(_flat(1.55))
    assert rep.haze_index == pytest.approx(97.3 - 95.4, abs=0.1)
    assert rep.e430.haze_b == 0.0 and rep.e430.doi == 100.0


def test_rougher_beckmann_hazes_more_and_loses_distinctness() -> None:
    # Within the high-gloss range the standards are made for (G20 from ~90 down to ~30).
    reports = [gloss_report(AnalyticModel("beckmann", alpha=a)) for a in (0.005, 0.01, 0.02)]
    for a, b in itertools.pairwise(reports):
        assert b.G20 < a.G20
        assert b.haze_index > a.haze_index
        assert b.e430.haze_b > a.e430.haze_b
        assert b.e430.haze_narrow > a.e430.haze_narrow
        assert b.e430.doi < a.e430.doi
    # A Beckmann lobe is symmetric about specular to first order: the two E430 B sensors agree.
    e = reports[1].e430
    assert e.haze_18_1 == pytest.approx(e.haze_21_9, rel=0.02)
    assert e.haze_b == pytest.approx(0.5 * (e.haze_18_1 + e.haze_21_9), rel=1e-12)


def test_doi_drops_as_the_lobe_reaches_the_03_deg_receptor() -> None:
    # DOI = 100 (Rs - R0.3) / Rs: for a lobe much wider than 0.3 deg, R0.3 ~ Rs -> DOI ~ 0.
    assert abs(gloss_report(AnalyticModel("ggx", alpha=0.2)).e430.doi) < 1.0


@pytest.mark.parametrize(
    ("g60", "angle"),
    [(95.0, 20), (70.1, 20), (70.0, 60), (35.0, 60), (10.0, 60), (9.9, 85), (2.5, 85)],
)
def test_d523_rule(g60: float, angle: int) -> None:
    assert d523_recommended_angle(g60) == angle


def test_report_picks_the_d523_geometry_and_serialises() -> None:
    assert gloss_report(AnalyticModel("beckmann", alpha=0.1)).d523_recommended_angle == 60
    matt = gloss_report(AnalyticModel("beckmann", alpha=0.4))
    assert matt.G60 < 10 and matt.d523_recommended_angle == 85
    d = matt.as_dict()
    assert set(d) == {f.name for f in GlossReport.__dataclass_fields__.values()}
    assert set(d["e430"]) >= {"gloss_20", "haze_18_1", "haze_21_9", "doi"}
