"""``goniolab predict`` and ``goniolab samples`` through goniolab.cli.main."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.optics.analytic import AnalyticModel
from goniolab.optics.fresnel import fresnel_conductor, fresnel_dielectric


def _run_json(capsys: pytest.CaptureFixture[str], *argv: str) -> Any:
    code = main([*argv, "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    return json.loads(out)


def test_flat_black_glass_reads_100(capsys: pytest.CaptureFixture[str]) -> None:
    rep = _run_json(capsys, "predict", "gloss", "sample:flat", "--n", "1.567")
    assert round(rep["G60"], 1) == 100.0
    assert round(rep["G20"], 1) == 100.0 and round(rep["G85"], 1) == 100.0
    assert rep["haze_index"] == pytest.approx(0.0, abs=1e-6)
    assert rep["e430"]["doi"] == 100.0
    assert rep["d523_angle"] == 20


def test_flat_pu_reads_the_fresnel_ratio(capsys: pytest.CaptureFixture[str]) -> None:
    # docs/PHYSICS.md, "Truths any implementation must hold": n = 1.55 gives 95.4 / 97.3 / 99.8 at 20 / 60 / 85.
    rep = _run_json(capsys, "predict", "gloss", "sample:flat")
    assert [round(rep[k], 1) for k in ("G20", "G60", "G85")] == [95.4, 97.3, 99.8]


def test_stats_of_a_gaussian_sample(capsys: pytest.CaptureFixture[str]) -> None:
    st = _run_json(capsys, "predict", "stats", "sample:gaussian-s0.05")
    # Per-axis rms slope 0.05 -> total rms gradient Sdq = 0.05 sqrt(2).
    assert st["Sdq"] == pytest.approx(0.05 * math.sqrt(2), rel=0.03)
    assert set(st) >= {"Ra_nm", "Sq_nm", "Sdq", "h_r"}
    # Gaussian heights: Ra = sqrt(2/pi) Sq.
    assert st["Ra_nm"] == pytest.approx(math.sqrt(2 / math.pi) * st["Sq_nm"], rel=0.03)


def test_brdf_of_a_gaussian_sample_matches_beckmann(capsys: pytest.CaptureFixture[str]) -> None:
    # docs/PHYSICS.md truth: a Gaussian surface of per-axis rms slope s has the facet BRDF
    # F P22 / (4 ci co cos^4 th), i.e. Beckmann with alpha = s sqrt(2) (masking ~1 here).
    out = _run_json(
        capsys,
        "predict",
        "brdf",
        "sample:gaussian-s0.05",
        "--theta-i",
        "45",
        "--theta-r",
        "39:51:3",
        "--model",
        "facet",
        "--no-masking",
    )
    tr = np.array(out["theta_r_deg"])
    np.testing.assert_allclose(tr, [39.0, 42.0, 45.0, 48.0, 51.0])
    expected = AnalyticModel("beckmann", alpha=0.05 * math.sqrt(2)).luminance_pct(45.0, tr)
    np.testing.assert_allclose(out["luminance_pct"], expected, rtol=0.05)
    # brdf_sr is the aperture average: luminance / 100 / (pi sin^2(3 deg) cos(theta_r)).
    omega = math.pi * math.sin(math.radians(3.0)) ** 2 * np.cos(np.radians(tr))
    np.testing.assert_allclose(
        out["brdf_sr"], np.array(out["luminance_pct"]) / 100 / omega, rtol=1e-3
    )


def test_point_brdf_scales_with_the_complex_fresnel(capsys: pytest.CaptureFixture[str]) -> None:
    # At the in-plane specular direction the facets are level: the local incidence is 45 deg
    # for every contributing facet, so the metal/dielectric ratio is the Fresnel ratio.
    args = (
        "predict",
        "brdf",
        "sample:gaussian-s0.05",
        "--point",
        "--theta-r",
        "45",
        "--model",
        "facet",
    )
    diel = _run_json(capsys, *args)
    metal = _run_json(capsys, *args, "--n", "0.27+3.41j")
    assert "luminance_pct" not in diel
    c = math.cos(math.radians(45.0))
    ratio = float(fresnel_conductor(c, complex(0.27, 3.41))) / float(fresnel_dielectric(c, 1.55))
    assert metal["brdf_sr"][0] / diel["brdf_sr"][0] == pytest.approx(ratio, rel=0.02)


def test_theta_list_forms(capsys: pytest.CaptureFixture[str]) -> None:
    out = _run_json(capsys, "predict", "brdf", "sample:flat", "--point", "--theta-r", "0:10:2.5")
    assert out["theta_r_deg"] == [0.0, 2.5, 5.0, 7.5, 10.0]
    out = _run_json(capsys, "predict", "brdf", "sample:flat", "--point", "--theta-r=-20,5")
    assert out["theta_r_deg"] == [-20.0, 5.0]
    # a negative start is a range, not an option (as for `goniolab scan`), no "=" needed
    out = _run_json(capsys, "predict", "brdf", "sample:flat", "--point", "--theta-r", "-20:20:10")
    assert out["theta_r_deg"] == [-20.0, -10.0, 0.0, 10.0, 20.0]
    out = _run_json(capsys, "predict", "brdf", "sample:flat", "--point", "--theta-r", "0:0.3:0.1")
    assert out["theta_r_deg"] == [0.0, 0.1, 0.2, 0.3]  # 3 x 0.1 lands on 0.3


def test_bad_file_exits_2_with_one_line_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "broken.csv"
    bad.write_text("1,2,3\n4,oops,6\n")
    assert main(["predict", "gloss", str(bad), "--step-um", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "broken.csv" in err and err.startswith("goniolab: error:")
    assert main(["predict", "stats", str(tmp_path / "missing.npy")]) == 2
    assert "missing.npy" in capsys.readouterr().err


def test_unknown_sample_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", "gloss", "sample:wittmann-42"]) == 2
    err = capsys.readouterr().err
    assert "wittmann-42" in err and "wittmann-8" in err


def test_bad_options_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", "brdf", "sample:flat", "--theta-r", "10:0:1"]) == 2
    assert "--theta-r" in capsys.readouterr().err
    assert main(["predict", "brdf", "sample:flat", "--theta-i", "95"]) == 2
    assert "--theta-i" in capsys.readouterr().err
    # an option argparse refuses is one line too, like every other error
    assert main(["predict", "gloss", "sample:flat", "--n", "glass"]) == 2
    err = capsys.readouterr().err
    assert "--n 'glass'" in err and err.startswith("goniolab: error: ") and err.count("\n") == 1


def test_samples_command_lists_the_library(capsys: pytest.CaptureFixture[str]) -> None:
    rows = _run_json(capsys, "samples")
    by_name = {r["name"]: r for r in rows}
    assert len(rows) == 20  # 16 surfaces + 4 painted samples (issue 11)
    assert by_name["wittmann-4"]["seed_g60"] == 26.0 and by_name["wittmann-4"]["seed_ra_nm"] == 250
    assert by_name["flat"]["n"] == 1.55
    assert main(["samples"]) == 0
    assert "wittmann-8" in capsys.readouterr().out


def test_model_and_wavelength_options_and_the_model_in_json(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # the regime rule per geometry: wittmann-1 (Sq ~ 44 nm) is Kirchhoff at 20 and 60 deg,
    # Rayleigh-Rice at 85 deg (g = (4 pi Sq cos 85 / 0.55)^2 ~ 0.008)
    rep = _run_json(capsys, "predict", "gloss", "sample:wittmann-1")
    assert rep["model"]["G20"] == "kirchhoff" and rep["model"]["G85"] == "rayleigh-rice"
    assert rep["wavelength_nm"] == "ISO 2813 C x V"
    facet = _run_json(capsys, "predict", "gloss", "sample:wittmann-1", "--model", "facet")
    # every reading names its model: the gloss geometries and the ASTM E430 readings
    assert facet["model"] == {"G20": "facet", "G60": "facet", "G85": "facet"}
    assert set(facet["e430_model"]) >= {"gloss_20", "haze_b", "gloss_30", "doi"}
    assert set(facet["e430_model"].values()) == {"facet"}
    red = _run_json(
        capsys,
        "predict",
        "gloss",
        "sample:wittmann-1",
        "--model",
        "kirchhoff",
        "--wavelength-nm",
        "700",
    )
    blue = _run_json(
        capsys,
        "predict",
        "gloss",
        "sample:wittmann-1",
        "--model",
        "kirchhoff",
        "--wavelength-nm",
        "420",
    )
    # shorter wavelength, larger Rayleigh factor, weaker specular beam
    assert blue["G20"] < red["G20"]
    assert red["model"]["G20"] == "kirchhoff" and red["wavelength_nm"] == 700.0
    curve = _run_json(
        capsys,
        "predict",
        "brdf",
        "sample:wittmann-1",
        "--theta-i",
        "45",
        "--theta-r",
        "0:70:10",
    )
    assert curve["model"]["auto"] == "kirchhoff"
    # the 512 um map at 1 um resolves +-0.275 in sin around specular: the cones at 0..30 deg
    # reach further, but g = 0.51 < 1 at 45 deg: Kirchhoff answers what the map resolves
    # (issue 20: no hand-over to the facet model, which has no coherent beam) and says so
    assert curve["models"] == ["kirchhoff"] * 8 and "fallback" not in curve
    assert len(curve["warnings"]) == 1
    assert curve["warnings"][0].startswith("theta_r 0, 10, 20, 30 deg: ")
    assert "lambda/(2 step)" in curve["warnings"][0]
    assert main(["predict", "gloss", "sample:flat", "--wavelength-nm", "5"]) == 2
    assert "--wavelength-nm" in capsys.readouterr().err
    assert main(["predict", "gloss", "sample:flat", "--model", "wave"]) == 2
    assert "--model" in capsys.readouterr().err


def test_stats_say_the_regime_per_geometry(capsys: pytest.CaptureFixture[str]) -> None:
    st = _run_json(capsys, "predict", "stats", "sample:wittmann-8")
    assert st["regime"]["20"]["model"] == "facet"
    assert st["regime"]["20"]["g"] > 20


# --------------------------------------------------------------------- issue 20: albedo
@pytest.mark.parametrize("n", ["1.55", "0.27+3.41j"])
def test_albedo_of_a_flat_map_is_its_fresnel_reflectance(
    capsys: pytest.CaptureFixture[str], n: str
) -> None:
    """The flat-mirror limit: all light in the coherent beam, albedo = F(theta_i) (Born &
    Wolf for the conductor), TIS = 0, one model per angle."""
    out = _run_json(
        capsys, "predict", "albedo", "sample:flat", "--n", n, "--theta-i", "0,30,60,85,89"
    )
    assert set(out) >= {"theta_i_deg", "albedo", "tis", "model", "fresnel"}
    assert out["theta_i_deg"] == [0.0, 30.0, 60.0, 85.0, 89.0]
    idx = complex(n.replace("i", "j"))
    for t, a, tis, m in zip(
        out["theta_i_deg"], out["albedo"], out["tis"], out["model"], strict=True
    ):
        c = math.cos(math.radians(t))
        want = (
            float(fresnel_dielectric(c, idx.real))
            if idx.imag == 0
            else float(fresnel_conductor(c, idx))
        )
        assert a == pytest.approx(want, rel=1e-9)
        assert tis == 0.0 and m == "rayleigh-rice"


def test_albedo_of_a_rough_coat_and_its_table(capsys: pytest.CaptureFixture[str]) -> None:
    """A coat: albedo <= Fresnel (+1 %), TIS = albedo - coherent beam > 0, and the text
    table names the model of each row; angles beyond 89 deg are refused."""
    out = _run_json(capsys, "predict", "albedo", "sample:wittmann-1", "--theta-i", "0:80:40")
    assert out["theta_i_deg"] == [0.0, 40.0, 80.0]
    for a, tis, f in zip(out["albedo"], out["tis"], out["fresnel"], strict=True):
        assert 0.0 < tis < a <= 1.01 * f
    assert main(["predict", "albedo", "sample:wittmann-1", "--theta-i", "0,60"]) == 0
    text = capsys.readouterr().out
    assert "TIS" in text and "kirchhoff" in text
    assert main(["predict", "albedo", "sample:flat", "--theta-i", "95"]) == 2
    assert "[0, 89]" in capsys.readouterr().err


def test_a_model_outside_its_validity_hands_over_and_says_so(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Rayleigh-Rice forced on wittmann-1 (g = 0.9 at 20 deg): G20 is computed by Kirchhoff,
    the JSON names it, and stderr carries the same warning (it read 376 GU silently)."""
    code = main(["predict", "gloss", "sample:wittmann-1", "--model", "rayleigh-rice", "--json"])
    captured = capsys.readouterr()
    assert code == 0
    out = json.loads(captured.out)
    assert out["model"]["G20"] == "kirchhoff" and out["model"]["G85"] == "rayleigh-rice"
    assert any(w.startswith("G20: rayleigh-rice is outside its validity") for w in out["warnings"])
    assert "goniolab: warning: G20: rayleigh-rice is outside its validity" in captured.err
    assert 70.0 < out["G20"] < 95.0


def test_netcdf_attrs_name_the_model_of_every_number(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--out``: the stored prediction carries what --json says (``computed_by``,
    ``warnings``), so a file read later still says which model made each number."""
    import xarray as xr

    out = tmp_path / "gloss.nc"
    argv = ["predict", "gloss", "sample:wittmann-1", "--model", "rayleigh-rice"]
    assert main([*argv, "--json", "--out", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        attrs = dict(ds.attrs)
    computed = json.loads(attrs["computed_by"])
    assert computed["G20"] == doc["model"]["G20"] == "kirchhoff"
    assert json.loads(attrs["warnings"]) == doc["warnings"]
    curve = tmp_path / "curve.nc"
    argv = ["predict", "brdf", "sample:wittmann-1", "--theta-r", "0,45"]
    assert main([*argv, "--json", "--out", str(curve)]) == 0
    doc = json.loads(capsys.readouterr().out)
    with xr.open_dataset(curve, engine="h5netcdf") as ds:
        attrs = dict(ds.attrs)
    assert json.loads(attrs["computed_by"]) == doc["models"] == ["kirchhoff", "kirchhoff"]
    assert json.loads(attrs["warnings"]) == doc["warnings"]


def test_batch_rows_name_the_model_of_every_number(capsys: pytest.CaptureFixture[str]) -> None:
    """Several maps (JSON Lines, worker processes): each row carries the same ``model``,
    ``e430_model`` and ``warnings`` as the single-map command."""
    argv = ["predict", "gloss", "sample:flat", "sample:wittmann-1", "--model", "rayleigh-rice"]
    assert main([*argv, "--json", "--jobs", "1"]) == 0
    rows = {r["map"]: r for r in map(json.loads, capsys.readouterr().out.splitlines())}
    assert rows["sample:flat"]["model"] == dict.fromkeys(("G20", "G60", "G85"), "rayleigh-rice")
    assert rows["sample:flat"]["warnings"] == []
    rough = rows["sample:wittmann-1"]
    assert rough["model"]["G20"] == "kirchhoff" and rough["e430_model"]["doi"] == "kirchhoff"
    assert any(w.startswith("G20: rayleigh-rice is outside") for w in rough["warnings"])
