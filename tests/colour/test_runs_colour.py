"""``goniolab runs colour``: dL*/dC*/dH*, dE76/94/00, CMC per angle, tolerance sets with
pass/fail per angle and overall, colours under other illuminants and the metamerism table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from tests.colour._spectral_runs import make_spectral_store


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_spectral_store(tmp_path_factory.mktemp("rc") / "s.sqlite", shift=0.05)


def _colour(capsys: pytest.CaptureFixture[str], store: Path, *args: str) -> dict:
    assert main(["runs", "colour", "1", "--store", str(store), "--json", *args]) == 0
    return json.loads(capsys.readouterr().out)


def test_every_difference_per_angle_matches_colour_science(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import colour

    doc = _colour(capsys, store)
    geoms = {g["aspecular_deg"]: g for g in doc["geometries"]}
    for v in doc["tolerance"]["geometries"]:
        g = geoms[v["aspecular_deg"]]
        m = np.array([g["L"], g["a"], g["b"]])
        p = np.array([g["predicted_L"], g["predicted_a"], g["predicted_b"]])
        assert v["dE76"] == pytest.approx(float(colour.delta_E(m, p, "CIE 1976")), rel=1e-12)
        assert v["dE94"] == pytest.approx(float(colour.delta_E(m, p, "CIE 1994")), rel=1e-10)
        assert v["dE00"] == pytest.approx(float(colour.delta_E(m, p, "CIE 2000")), rel=1e-10)
        assert v["dE_CMC"] == pytest.approx(float(colour.delta_E(m, p, "CMC", l=2, c=1)), rel=1e-10)
        lch_m, lch_p = colour.Lab_to_LCHab(m), colour.Lab_to_LCHab(p)
        assert v["dL"] == pytest.approx(p[0] - m[0])
        assert v["dC"] == pytest.approx(lch_p[1] - lch_m[1])
        assert v["dL"] ** 2 + v["dC"] ** 2 + v["dH"] ** 2 == pytest.approx(v["dE76"] ** 2)
        assert g["dE2000"] == pytest.approx(v["dE00"], rel=1e-10)  # the row's own dE00


def test_text_shows_all_three_formulas_and_the_verdicts(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["runs", "colour", "1", "--store", str(store)]) == 0
    out = capsys.readouterr().out
    for needle in ("dE*ab", "dE94", "dE00", "dL*", "dC*", "dH*", "tolerance din6175-2",
                   "overall: ", "flop index: measured"):  # fmt: skip
        assert needle in out, needle


def test_a_toml_tolerance_set_judges_each_angle(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = _colour(capsys, store)
    de = {v["aspecular_deg"]: v["dE00"] for v in doc["tolerance"]["geometries"]}
    # limits just above the dE00 at 15 and just below it at 45: 15 passes, 45 fails
    toml = tmp_path / "oem.toml"
    toml.write_text(
        f'name = "oem"\nsource = "test"\n[angles."15"]\ndE = {de[15.0] + 0.01}\n'
        f'[angles."45"]\ndE = {de[45.0] - 0.01}\n'
    )
    doc = _colour(capsys, store, "--tolerance", str(toml))
    v = {g["aspecular_deg"]: g for g in doc["tolerance"]["geometries"]}
    assert v[15.0]["passed"] is True and v[45.0]["passed"] is False
    assert v[45.0]["failed"] == ["dE"] and v[25.0]["passed"] is None
    assert doc["tolerance"]["overall"]["passed"] is False
    assert doc["tolerance"]["overall"]["failed_angles"] == [45.0]
    bad = tmp_path / "bad.toml"
    bad.write_text('[angles."45"]\ndE = 0\n')
    assert main(["runs", "colour", "1", "--store", str(store), "--tolerance", str(bad)]) == 2
    assert "bad.toml: angles.45.dE: must be a positive" in capsys.readouterr().err


def test_spectra_reproduce_the_stored_colours_and_feed_the_metamerism_table(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = _colour(capsys, store, "--illuminant", "D65", "--illuminant", "F11", "--metamerism")
    stored = {v["aspecular_deg"]: v["dE00"] for v in doc["tolerance"]["geometries"]}
    # D65 from the exported reflectance factors = the runner's stored L*a*b* (the factor
    # scale, the mirror level and the repeat mean are the same computation)
    d65 = {g["aspecular_deg"]: g["dE00"] for g in doc["illuminants"]["D65"]["geometries"]}
    for a in stored:
        assert d65[a] == pytest.approx(stored[a], abs=2e-3)  # mean of Labs vs Lab of mean
    assert set(doc["illuminants"]) == {"D65", "FL11"}  # the alias resolved
    meta = {(r["illuminant"], r["aspecular_deg"]): r["dE00"] for r in doc["metamerism"]}
    assert {i for i, _ in meta} == {"D65", "A", "FL11", "LED-B3"}
    for a in stored:
        assert meta[("D65", a)] == pytest.approx(d65[a], rel=1e-12)
        assert meta[("FL11", a)] != pytest.approx(meta[("D65", a)], rel=1e-3)
    assert any("400-700 nm" in n for n in doc["spectra_notes"])


def test_no_flop_index_away_from_45_deg(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from goniolab.scan.plans import BrdfPlan
    from goniolab.store import RunStore

    path = tmp_path / "t30.sqlite"
    plan = BrdfPlan(30.0, (15.0, 0.0, -80.0), sample="s")  # 15/30/110 "aspecular" at 30 deg
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config={}, sample="s", model={},
                           version="t")  # fmt: skip
        for k, tr in enumerate(plan.theta_r_deg):
            c = {"X": 1.0, "Y": 2.0, "Z": 3.0, "L": 90.0 - 30 * k, "a": 0.0, "b": 0.0,
                 "C": 0.0, "h_deg": 0.0}  # fmt: skip
            s.add_point(rid, index=k, repeat=0, theta_i_deg=30.0, theta_r_deg=tr,
                        measured_theta_i_deg=30.0, measured_theta_r_deg=tr, luminance_pct=1.0,
                        raw={}, timestamp=1.0, colour=c)  # fmt: skip
    doc = _colour(capsys, path)
    assert doc["flop_index"] is None and "45 deg incidence" in doc["flop_index_note"]
    assert main(["runs", "colour", "1", "--store", str(path)]) == 0
    assert "no flop index at theta_i 30 deg" in capsys.readouterr().out


def test_without_predictions_it_says_so_and_vs_judges_two_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = make_spectral_store(tmp_path / "np.sqlite", with_predictions=False)
    doc = _colour(capsys, path)
    assert "no predicted colours" in doc["tolerance"]["note"]
    assert doc["tolerance"]["overall"]["passed"] is None
    # a run against itself: every difference 0, every angle of the set passes
    doc = _colour(capsys, path, "--vs", "1", "--metamerism")
    assert doc["tolerance"]["overall"]["passed"] is True
    assert max(r["dE00"] for r in doc["metamerism"]) < 1e-9
    assert doc["vs"]["max_dE2000"] == pytest.approx(0.0, abs=1e-9)


def test_the_builtin_din_set_is_labelled_provisional_in_text_and_json(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # its limits are goniolab's starting values, not DIN 6175-2's (not public): every
    # output that judges with it says so; a lab's own set is not provisional unless it says
    doc = _colour(capsys, store)
    assert doc["tolerance"]["name"] == "din6175-2" and doc["tolerance"]["provisional"] is True
    assert doc["tolerance"]["source"].startswith("PROVISIONAL:")
    assert main(["runs", "colour", "1", "--store", str(store)]) == 0
    assert "source: PROVISIONAL: " in capsys.readouterr().out
    toml = tmp_path / "oem.toml"
    toml.write_text('name = "oem"\nsource = "OEM norm 1"\n[angles."45"]\ndE = 1.0\n')
    assert _colour(capsys, store, "--tolerance", str(toml))["tolerance"]["provisional"] is False
    toml.write_text('name = "oem"\nsource = "draft"\nprovisional = true\n[angles."45"]\ndE = 1\n')
    assert _colour(capsys, store, "--tolerance", str(toml))["tolerance"]["provisional"] is True
    toml.write_text('name = "oem"\nprovisional = "yes"\n[angles."45"]\ndE = 1\n')
    assert main(["runs", "colour", "1", "--store", str(store), "--tolerance", str(toml)]) == 2
    assert "provisional: must be true or false" in capsys.readouterr().err
