"""The prediction use cases (goniolab.app.predictions) called directly, against numbers that
do not come from goniolab: Fresnel's equations for a flat surface, the ISO 2813 definition
of the gloss scale, and the CLI's and the notebook's own output (one use case under both)."""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path

import numpy as np
import pytest

import goniolab.api as gl
from goniolab.app.predictions import (
    API_NAMES,
    CLI_NAMES,
    SurfaceRequest,
    predict_albedo,
    predict_brdf,
    predict_brdf_async,
    predict_gloss,
    surface_stats,
)
from goniolab.cli import main
from goniolab.errors import UserError


def fresnel_unpolarised(theta_deg: float, n: float) -> float:
    """Fresnel's reflectance of unpolarised light on a dielectric of index ``n`` (Born &
    Wolf, Principles of Optics, sec. 1.5.2, eqs. 21a-b), written out here on purpose."""
    ci = math.cos(math.radians(theta_deg))
    st = math.sin(math.radians(theta_deg)) / n
    ct = math.sqrt(1.0 - st * st)
    rs = (ci - n * ct) / (ci + n * ct)
    rp = (n * ci - ct) / (n * ci + ct)
    return 0.5 * (rs * rs + rp * rp)


def test_a_flat_surface_reflects_its_fresnel_reflectance_and_scatters_nothing() -> None:
    pred = predict_albedo(SurfaceRequest("sample:flat", n=complex(1.5)), "0,30,60")
    assert pred.theta_i_deg == [0.0, 30.0, 60.0]
    truth = [fresnel_unpolarised(t, 1.5) for t in (0.0, 30.0, 60.0)]
    assert truth[0] == pytest.approx(0.04, rel=1e-12)  # ((n - 1) / (n + 1))^2
    np.testing.assert_allclose(pred.albedo, truth, rtol=1e-9)
    np.testing.assert_allclose(pred.fresnel, truth, rtol=1e-9)
    assert pred.tis == [0.0, 0.0, 0.0]  # a flat surface scatters no light
    assert len(pred.models) == 3 and all(m in ("rayleigh-rice", "facet") for m in pred.models)


@pytest.mark.parametrize("model", ["facet", "auto"])
def test_a_flat_mirror_puts_its_fresnel_reflectance_into_the_specular_detector(model: str) -> None:
    pred = predict_brdf(
        SurfaceRequest("sample:flat", n=complex(1.5), model=model),
        theta_i_deg=45.0,
        theta_r_deg="35,45,55",
    )
    assert pred.luminance_pct is not None
    # equal cones: all of the source's light reaches the specular detector, none elsewhere
    assert pred.luminance_pct[1] == pytest.approx(100.0 * fresnel_unpolarised(45.0, 1.5), rel=5e-3)
    assert pred.luminance_pct[0] == 0.0 and pred.luminance_pct[2] == 0.0
    assert pred.models == [pred.models[0]] * 3  # the model that computed each angle
    assert pred.source_deg == pred.detector_deg == 6.0  # the Wittmann goniometer's cones
    # a peak one sample wide is not a width: said, not guessed
    assert pred.peak is not None and pred.peak["fwhm_deg"] is None
    assert "not resolved" in pred.peak["fwhm_note"]


def test_flat_black_glass_is_100_gloss_units_at_every_geometry() -> None:
    # ISO 2813 sec. 3: the gloss scale is 100 GU for polished black glass of n = 1.567
    pred = predict_gloss(SurfaceRequest("sample:flat", n=complex(1.567)))
    rep = pred.report
    assert pytest.approx([100.0, 100.0, 100.0], rel=1e-9) == [rep.G20, rep.G60, rep.G85]
    assert set(pred.computed_by) >= {"G20", "G60", "G85", "e430.doi"}
    assert set(pred.model) == {"G20", "G60", "G85", "rule"}  # auto: the rule's choice shown
    assert pred.as_dict()["wavelength_nm"] == "ISO 2813 C x V"


def test_the_cli_prints_the_use_cases_document(capsys: pytest.CaptureFixture[str]) -> None:
    req = SurfaceRequest("sample:wittmann-3", model="facet")
    pred = predict_brdf(req, theta_i_deg=45.0, theta_r_deg="40:50:5")
    assert main(["predict", "brdf", "sample:wittmann-3", "--model", "facet", "--theta-r",
                 "40:50:5", "--json"]) == 0  # fmt: skip
    assert json.loads(capsys.readouterr().out) == json.loads(json.dumps(pred.as_dict()))


def test_the_notebook_and_the_cli_predict_the_same_curve() -> None:
    req = SurfaceRequest("sample:wittmann-3", model="facet")
    pred = predict_brdf(req, theta_i_deg=45.0, theta_r_deg=[40.0, 45.0, 50.0], names=API_NAMES)
    ds = gl.predict_brdf("sample:wittmann-3", theta_r_deg=[40.0, 45.0, 50.0], model="facet")
    np.testing.assert_array_equal(ds["brdf_sr"].values, pred.brdf_sr)
    np.testing.assert_array_equal(ds["luminance_pct"].values, pred.luminance_pct)
    assert json.loads(ds.attrs["computed_by"]) == pred.models == ["facet"] * 3


def test_messages_name_the_input_as_the_face_calls_it() -> None:
    req = SurfaceRequest("sample:flat")
    with pytest.raises(UserError, match=r"^--theta-i 95: must be in \[0, 90\) deg$"):
        predict_brdf(req, theta_i_deg=95, names=CLI_NAMES)
    with pytest.raises(UserError, match=r"^theta_i_deg 95: must be in \[0, 90\) deg$"):
        predict_brdf(req, theta_i_deg=95, names=API_NAMES)
    with pytest.raises(UserError, match=r"^point=True takes no detector_deg/source_deg"):
        predict_brdf(req, point=True, source_deg=3.0, names=API_NAMES)
    with pytest.raises(UserError, match=r"^--wavelength-nm 50: must be in \[100, 20000\] nm$"):
        predict_gloss(SurfaceRequest("sample:flat", wavelength_nm=50.0))
    with pytest.raises(UserError, match=r"^--theta-i '0,95': angles must be in \[0, 89\] deg$"):
        predict_albedo(req, "0,95")


def test_the_async_variant_leaves_the_event_loop_free() -> None:
    ticks = 0

    async def scenario() -> object:
        nonlocal ticks
        task = asyncio.create_task(
            predict_brdf_async(SurfaceRequest("sample:flat", model="facet"), theta_r_deg="45")
        )
        while not task.done():  # the loop keeps running while the model computes
            ticks += 1
            await asyncio.sleep(0)
        return await task

    pred = asyncio.run(scenario())
    assert ticks > 0
    assert isinstance(pred, type(predict_brdf(SurfaceRequest("sample:flat"), theta_r_deg="45")))


def test_stats_of_a_flat_surface_are_zero_and_name_the_regime() -> None:
    st = surface_stats(SurfaceRequest("sample:flat"))
    assert st.doc["Ra_nm"] == 0.0 and st.doc["Sq_nm"] == 0.0 and st.doc["Sdq"] == 0.0
    assert st.doc["h_r"] == 1.0  # every facet in the zero-slope bin (Wittmann sec. 3.1)
    assert set(st.doc["regime"]) == {"20", "60", "85"}


def test_the_cli_and_the_notebook_print_the_same_facet_numbers(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The CLI ran the facet model on its slope cells and the notebook on the per-pixel
    kernels: ``--model facet`` on sample:wittmann-3 at 40:50:5 read 0.277157 against
    0.276315 % (0.3 %). One model for every face: equal numbers."""
    assert main(["predict", "brdf", "sample:wittmann-3", "--model", "facet", "--theta-r",
                 "40:50:5", "--json"]) == 0  # fmt: skip
    cli = json.loads(capsys.readouterr().out)
    via_api = gl.predict_brdf("sample:wittmann-3", theta_r_deg="40:50:5", model="facet")
    np.testing.assert_allclose(via_api["luminance_pct"].values, cli["luminance_pct"], rtol=1e-12)


@pytest.mark.parametrize("model", ["facet", "auto"])
def test_long_facet_work_reports_progress_with_either_model(
    model: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--model facet`` shows the progress the default shows: every walk over a large
    map's slopes (here every map counts as large) reports its rows, the last at the end."""
    from goniolab.optics import surface as surface_mod

    monkeypatch.setattr(surface_mod, "STREAM_MIN_FACETS", 0)
    rng = np.random.default_rng(3)
    path = tmp_path / "rough.npy"
    np.save(path, rng.normal(0.0, 2.0, (96, 96)))
    (tmp_path / "rough.npy.json").write_text('{"dx_um": 10.0, "dy_um": 10.0}\n')
    seen: list[tuple[int, int, str]] = []
    predict_brdf(
        SurfaceRequest(str(path), model=model),
        theta_r_deg="30:60:1",
        progress=lambda done, total, what: seen.append((done, total, what)),
    )
    assert seen, "no progress reported"
    assert all(what.startswith("facet slopes, pass ") for _, _, what in seen)
    assert seen[-1][0] == seen[-1][1] == 95  # rows of facets of a 96^2 map
