"""The twin's truth (sim/truth.py) against independent truths: the profilometer identity,
the Fresnel mirror, ISO 2813 flat-surface gloss (PHYSICS.md), the Debye-Waller loss of a
slightly rough surface, and the facet model in the geometrical-optics limit."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from goniolab.optics.apertures import Cone
from goniolab.optics.facet import FacetModel, cap_overlap_fraction
from goniolab.optics.fresnel import fresnel
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.surface import Surface
from goniolab.surfaces.synthetic import make_sample
from sim.truth import FlatSpecimen, TruthOptics, TwinSettings, body_reflectance, build_truth

#: No sub-resolution roughness, profilometer noise or waviness: the tile is the map.
BARE = TwinSettings(subres_rq_nm=0.0, profilometer_noise_nm=0.0, waviness_slope_rms=0.0)


def periodic_map(z: np.ndarray, step_um: float = 1.0) -> HeightMap:
    return HeightMap(
        z_um=z,
        dx_um=step_um,
        dy_um=step_um,
        source="test",
        meta={"generator": "goniolab.surfaces.samples"},
    )


def test_the_profilometer_map_of_the_truth_is_the_map_the_prediction_uses() -> None:
    hm = make_sample("wittmann-3", size=64)
    settings = TwinSettings(subres_rq_nm=5.0, profilometer_noise_nm=2.0)
    truth = build_truth(hm, settings=settings, name="w3")
    assert truth.z_um.shape == (256, 256) and truth.step_um == pytest.approx(0.25)
    measured = truth.profilometer_map()
    assert np.max(np.abs(measured.z_um - (hm.z_um - hm.z_um.mean()))) < 1e-5  # float32 tile
    # what the profilometer cannot see: the sub-resolution roughness (all of it above the
    # map's Nyquist) and its own noise, which is in the map but not on the sample
    spec = np.fft.fft2(truth.z_um.astype(np.float64))
    f = np.fft.fftfreq(256, d=0.25)
    high = (np.abs(f)[:, None] > 0.5) | (np.abs(f)[None, :] > 0.5)
    rq_high = math.sqrt(float(np.sum(np.abs(spec[high]) ** 2)) / spec.size**2)
    assert rq_high == pytest.approx(5e-3, rel=1e-6)
    assert float(truth.noise_um.std()) == pytest.approx(2e-3, rel=0.05)


def test_a_flat_truth_reads_the_fresnel_mirror_through_the_cones() -> None:
    optics = TruthOptics(build_truth(periodic_map(np.zeros((64, 64))), n=1.55, settings=BARE))
    optics._body = np.zeros_like(optics._body)  # surface reflection only
    th = np.array([41.0, 43.0, 45.0, 47.0, 49.0])
    ref = (
        100.0
        * float(fresnel(math.cos(math.radians(45.0)), 1.55))
        * cap_overlap_fraction(np.radians(np.abs(th - 45.0)), math.radians(3), math.radians(3))
    )
    np.testing.assert_allclose(optics.luminance_pct(45.0, th), ref, rtol=3e-3)


def test_a_flat_truth_has_the_iso2813_gloss_of_physics_md() -> None:
    # docs/PHYSICS.md, "Truths any implementation must hold": a flat n = 1.55 surface reads 95.4 / 97.3 / 99.8 GU
    optics = TruthOptics(build_truth(periodic_map(np.zeros((64, 64))), n=1.55, settings=BARE))
    optics._body = np.zeros_like(optics._body)
    gloss = optics.gloss()
    assert gloss[20] == pytest.approx(95.4, abs=0.06)
    assert gloss[60] == pytest.approx(97.3, abs=0.06)
    assert gloss[85] == pytest.approx(99.8, abs=0.06)


def test_a_slightly_rough_surface_loses_the_debye_waller_factor() -> None:
    # Gaussian heights, Sq = 20 nm, correlation 2 um: the coherent specular reflectance is
    # F exp(-(k q_z Sq)^2) (PHYSICS.md); its diffuse part spreads over ~lambda/2um, far
    # outside a 1 deg cone
    rng = np.random.default_rng(3)
    from goniolab.surfaces.synthetic import _gaussian_field

    z = _gaussian_field(rng, (512, 512), 0.25, 2.0) * 0.02
    settings = TwinSettings(
        subres_rq_nm=0.0,
        profilometer_noise_nm=0.0,
        waviness_slope_rms=0.0,
        wavelengths_nm=(550.0,),
    )
    optics = TruthOptics(build_truth(periodic_map(z, 0.25), n=1.55, settings=settings))
    sq = optics.truth.sq_um
    for ti in (20.0, 45.0, 70.0):
        got = optics._surface_at(ti, np.array([ti]), Cone(1.0), Cone(1.0))[0, 0]
        g = (2 * math.pi / 0.55 * 2 * math.cos(math.radians(ti)) * sq) ** 2
        want = float(fresnel(math.cos(math.radians(ti)), 1.55)) * math.exp(-g)
        assert got == pytest.approx(want, rel=3e-3), ti


@pytest.mark.slow
def test_kirchhoff_meets_the_facet_model_in_the_geometrical_optics_limit() -> None:
    # rms slope 0.05 over 10 um correlation: heights of ~0.35 um, k q Sq ~ 5 rad (GO regime)
    hm = make_sample("gaussian-s0.05", size=256)
    settings = TwinSettings(
        subres_rq_nm=0.0,
        profilometer_noise_nm=0.0,
        waviness_slope_rms=0.0,
        wavelengths_nm=(550.0,),
    )
    truth = build_truth(hm, n=1.55, settings=settings)
    optics = TruthOptics(truth)
    fine = HeightMap(z_um=truth.z_um.astype(np.float64), dx_um=0.25, dy_um=0.25, source="tile")
    facet = FacetModel(Surface.from_heightmap(fine, slope_method="central"), n=1.55)
    th = np.array([35.0, 40.0, 45.0, 50.0, 55.0, 60.0])
    k = 100.0 * np.array(
        [optics._surface_at(45.0, np.array([t]), Cone(6.0), Cone(6.0))[0, 0] for t in th]
    )
    f = facet.luminance_pct(45.0, th)
    ratio = k / f
    assert np.all(np.abs(ratio[1:4] - 1.0) < 0.03), ratio  # 40..50 deg
    assert np.all(np.abs(ratio - 1.0) < 0.07), ratio  # the flanks: speckle of a 256 um tile


def test_tables_survive_the_disk_cache(tmp_path: Path) -> None:
    hm = make_sample("wittmann-1", size=64)
    settings = TwinSettings(cache_dir=str(tmp_path))
    first = TruthOptics(build_truth(hm, settings=settings, name="w1"))
    a = first.luminance_pct(45.0, [40.0, 45.0, 52.0])
    assert first.ffts > 0
    first.save_cache()
    assert len(list(tmp_path.glob("twin-*.npz"))) == 1
    again = TruthOptics(build_truth(hm, settings=settings, name="w1"))
    np.testing.assert_allclose(again.luminance_pct(45.0, [40.0, 45.0, 52.0]), a, rtol=1e-6)
    assert again.ffts == 0


def test_reference_specimens_and_bodies() -> None:
    glass = FlatSpecimen(n=1.567)
    r60 = float(fresnel(0.5, 1.567))
    assert glass.luminance_pct(60.0, [60.0])[0] == pytest.approx(100.0 * r60, rel=1e-3)
    assert FlatSpecimen().luminance_pct(45.0, [45.0])[0] == pytest.approx(89.3, abs=1.0)
    assert body_reflectance("white")[-1] > 0.85 > 0.05 > body_reflectance("black")[0]
    with pytest.raises(ValueError, match="known: black"):
        body_reflectance("purple")
