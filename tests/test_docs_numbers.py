"""Numbers in the README and docs/ that the models make at fixed inputs, read from the
doc's own sentence and recomputed with the real code (docs that cannot go stale): each to
the precision it is printed with.

- README, "Scattering models": G85 of ``sample:gauss-sq177-l5`` by the facet model and by
  physical optics (``goniolab predict gloss sample:gauss-sq177-l5 [--model facet]``);
- README, "Rendering": the lightness a metallic panel and a solid red lose from 25 to 95
  deg aspecular (the 64-pixel render of tests/colour/test_render.py, which bounds them only);
- README, "Fitting a paint": the KM red's a*, b* (``predict colour sample:solid-red``);
- README: the log rotation, store outage, map size limit and separation floor it states
  (against the code's constants);
- README, "--adaptive": its 7-17x is the range of docs/TWIN.md's 36-point rows;
- README, "The physics": the grazing split of the source cone (edge, sub-cones, beam share);
- docs/PHYSICS.md: the Rayleigh-factor example (g, exp(-g), G85) and the coherent share of a
  50 nm coat, from the formula and the models;
- docs/COLOUR.md sec. 6: the built-in white's and red's L*, b*, C*, h at 45/0
  (``goniolab predict colour sample:white``, ``sample:solid-red``; tests/colour/
  test_paint_physics.py holds them inside the real paints' ranges only).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _text(name: str) -> str:
    return " ".join((ROOT / name).read_text(encoding="utf-8").split())


def _said(doc: str, pattern: str) -> re.Match[str]:
    m = re.search(pattern, _text(doc))
    assert m, f"{doc} no longer says {pattern!r}"
    return m


def _near(written: str, value: float, what: str) -> None:
    """``value`` printed to the digits of ``written`` gives ``written`` (one unit of slack)."""
    digits = len(written.split(".")[1]) if "." in written else 0
    assert abs(float(written) - value) <= 10.0**-digits, (
        f"{what}: the doc says {written}, the code {value:.4f}"
    )


def test_readme_g85_of_the_smooth_coat_facet_and_physical_optics() -> None:
    from goniolab.model_cache import model_for

    m = _said(
        "README.md",
        r"on `sample:gauss-sq177-l5` the facet model reads G85 (?P<facet>\d+) GU, physical "
        r"optics (?P<auto>\d+)",
    )
    spec = "sample:gauss-sq177-l5"
    _near(m["facet"], model_for(spec, model="facet", masking=True).gloss((85,))[85], "facet G85")
    _near(m["auto"], model_for(spec, model="auto", masking=True).gloss((85,))[85], "auto G85")


def _colour_45(sample: str, capsys: pytest.CaptureFixture[str]) -> dict[str, Any]:
    from goniolab.cli import main

    assert main(["predict", "colour", sample, "--json"]) == 0
    found: dict[str, Any] = next(
        g for g in json.loads(capsys.readouterr().out)["geometries"] if g["aspecular_deg"] == 45
    )
    return found


@pytest.mark.slow
def test_colour_md_built_in_white_and_red(capsys: pytest.CaptureFixture[str]) -> None:
    w = _said("docs/COLOUR.md", r"White: .*?L\\\* (?P<L>[\d.]+), b\\\* \+(?P<b>[\d.]+) at 45/0")
    r = _said("docs/COLOUR.md", r"Red: L\\\* (?P<L>[\d.]+), C\\\* (?P<C>[\d.]+), h (?P<h>\d+) deg")
    white, red = _colour_45("sample:white", capsys), _colour_45("sample:solid-red", capsys)
    _near(w["L"], white["L"], "white L*")
    _near(w["b"], white["b"], "white b*")
    _near(r["L"], red["L"], "red L*")
    _near(r["C"], red["C"], "red C*")
    _near(r["h"], red["h_deg"], "red h")
    km = _said("README.md", r"vs the KM red's (?P<a>[\d.]+), (?P<b>[\d.]+)\)")
    _near(km["a"], red["a"], "KM red a*")
    _near(km["b"], red["b"], "KM red b*")


@pytest.mark.slow
def test_readme_render_flop_of_a_metallic_and_a_solid(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import numpy as np

    from goniolab.cli import main
    from tests.colour.test_render import _png_factor_lightness

    m = _said(
        "README.md",
        r"a metallic loses ~(?P<metal>\d+) L\\\* \(as a reflectance factor\) from 25 to 95 deg "
        r"aspecular, a solid red (?P<red>[\d.]+)",
    )
    spread = {}
    for name in ("silver-metallic", "solid-red"):
        out = tmp_path / f"{name}.png"
        # what tests/colour/test_render.py draws: 64 px, 20 nm, exposure 1, no sparkle
        assert main(["render", f"sample:{name}", "--out", str(out), "--size", "64",
                     "--step-nm", "20", "--exposure", "1", "--no-sparkle"]) == 0  # fmt: skip
        capsys.readouterr()
        lightness, aspecular = _png_factor_lightness(out, 64)
        away = (aspecular >= 25.0) & (aspecular <= 95.0)
        spread[name] = float(np.ptp(lightness[away]))
    _near(m["metal"], spread["silver-metallic"], "metallic L* lost 25..95 deg")
    _near(m["red"], spread["solid-red"], "solid red L* lost 25..95 deg")


def _g(sq_um: float, theta_deg: float, wavelength_um: float = 0.55) -> float:
    """The Rayleigh factor g = (4 pi Sq cos theta / lambda)^2 (docs/PHYSICS.md)."""
    return (4 * math.pi * sq_um * math.cos(math.radians(theta_deg)) / wavelength_um) ** 2


def test_physics_md_rayleigh_factor_example_and_its_g85() -> None:
    """docs/PHYSICS.md's example map (Sq 177 nm, l 5 um): g at 20/60/85 deg from the map's
    own Sq, the coherent beam's exp(-g), and G85 by the facet and the wave models (said 88
    where the code reads 89.3)."""
    from goniolab.model_cache import model_for

    m = _said(
        "docs/PHYSICS.md",
        r"g = (?P<g20>[\d.]+), (?P<g60>[\d.]+) and (?P<g85>[\d.]+) at 20, 60 and 85 deg; the "
        r"facet model reads G85 (?P<facet>\d+) GU, the wave models (?P<wave>\d+) \(the coherent "
        r"beam alone is `exp\(-(?P<gx>[\d.]+)\)` = (?P<beam>\d+) %",
    )
    spec = "sample:gauss-sq177-l5"
    auto = model_for(spec, model="auto", masking=True)
    sq = auto.stats.sq_um
    for theta in (20, 60, 85):
        _near(m[f"g{theta}"], _g(sq, theta), f"g at {theta} deg")
    _near(m["gx"], _g(sq, 85), "g at 85 deg")
    _near(m["beam"], 100 * math.exp(-_g(sq, 85)), "coherent beam %")
    _near(m["facet"], model_for(spec, model="facet", masking=True).gloss((85,))[85], "facet G85")
    _near(m["wave"], auto.gloss((85,))[85], "wave-model G85")


def test_physics_md_coherent_fraction_of_a_50_nm_coat() -> None:
    """The share of the light in the coherent beam, exp(-g), of Sq 50 nm at 60 deg and 550 nm
    (said 70 %, the formula gives 72 %)."""
    m = _said(
        "docs/PHYSICS.md",
        r"With Sq = (?P<sq>\d+) nm at (?P<t>\d+) deg and (?P<wl>\d+) nm, (?P<pct>\d+) % of the "
        r"reflected light stays in the coherent beam",
    )
    g = _g(float(m["sq"]) / 1000, float(m["t"]), float(m["wl"]) / 1000)
    _near(m["pct"], 100 * math.exp(-g), "coherent share")


def test_readme_grazing_split_of_the_source_cone() -> None:
    """README, "The physics": from which lamp angle the 6 deg source cone is split and into
    how many sub-cones, how many the horizon split has, and the share of the beam a mirror at
    89 deg receives: each from the code that does it."""
    from goniolab.optics.apertures import Cone
    from goniolab.optics.facet_apertures import clipped_source_parts, source_parts

    m = _said(
        "README.md",
        r"\(lamp \+ half cone >= (?P<edge>\d+) deg\) the 6 deg source cone is split into "
        r"(?P<n>\d+) sub-cones: .*? clipped \((?P<horizon>\d+) sub-cones; a mirror at 89 deg "
        r"reads Fresnel x the (?P<share>\d+) % of the beam",
    )
    cone, edge = Cone(6.0), float(m["edge"])
    assert len(source_parts(edge - 3.0 - 0.01, cone)) == 1
    assert len(source_parts(edge - 3.0, cone)) == int(m["n"])
    touching = clipped_source_parts(87.0, cone)  # 87 + 3 = 90: the split, none clipped yet
    assert len(touching) == int(m["horizon"])
    _near(
        m["share"], 100 * sum(share for _, _, share in clipped_source_parts(89.0, cone)), "beam %"
    )


def _readme_constants() -> dict[str, float]:
    import inspect

    from drivers.arm_limits import MIN_SEPARATION_FLOOR_DEG
    from goniolab import logs
    from goniolab.scan.runner import ScanRunner
    from goniolab.surfaces._common import DEFAULT_MAX_MAP_POINTS

    outage = inspect.signature(ScanRunner).parameters["store_outage_s"].default
    return {
        "log MB": logs._MAX_BYTES / 1e6,
        "log files": logs._BACKUPS,
        "store outage min": outage / 60.0,
        "map side": DEFAULT_MAX_MAP_POINTS**0.5,
        "min separation deg": MIN_SEPARATION_FLOOR_DEG,
    }


#: README's sentence around each constant (the store's connect, statement and lock timeouts
#: are not public names of goniolab.store, which tests/test_layers.py holds tests to: not here)
README_SAID = {
    "log MB": r"rotating log file \((?P<x>\d+) MB x \d+\)",
    "log files": r"rotating log file \(\d+ MB x (?P<x>\d+)\)",
    "store outage min": r"or fails in one line after (?P<x>\d+) minutes",
    "map side": r"A map may have at most (?P<x>\d+) x \d+ points",
    "min separation deg": r"`min_separation_deg` below (?P<x>\d+) deg",
}


@pytest.mark.parametrize("name", sorted(README_SAID))
def test_readme_constant_is_the_codes(name: str) -> None:
    assert set(README_SAID) == set(_readme_constants())
    said = float(_said("README.md", README_SAID[name])["x"])
    assert said == pytest.approx(_readme_constants()[name]), f"README says {name} {said}"


def test_readme_adaptive_gain_is_docs_twin_md_table() -> None:
    """README's "7-17x lower rms error" of a 36-point adaptive scan is the range of the
    36-point rows of docs/TWIN.md's table (made by bench/bench_adaptive.py)."""
    m = _said(
        "README.md",
        r"a 36-point scan reconstructs the curve with (?P<lo>\d+)-(?P<hi>\d+)x lower rms",
    )
    twin = (ROOT / "docs" / "TWIN.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| [\w-]+ \| 36 \| ([\d.]+) / ([\d.]+) \|", twin, re.M)
    assert len(rows) >= 3, "docs/TWIN.md: the adaptive table's 36-point rows are gone"
    gains = [float(u) / float(a) for u, a in rows]
    _near(m["lo"], min(gains), "smallest gain")
    _near(m["hi"], max(gains), "largest gain")
