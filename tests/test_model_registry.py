"""The registry of scattering models (goniolab/model_registry.py) is the one list of model
names: a model registered in a test appears in the CLI's ``--model`` choices and help, is
accepted by ``[sample] model`` and is built by :func:`goniolab.model_cache.model_for`; the names
the ``auto`` rule picks and the ``kind`` of every built-in model are registered."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, get_args

import numpy as np
import pytest

from goniolab import model_registry
from goniolab.cli import build_parser
from goniolab.config import load_lab_config
from goniolab.errors import UserError
from goniolab.model_cache import model_for
from goniolab.model_registry import ModelOptions, ScatteringModel
from goniolab.optics.apertures import ISO2813_BLACK_GLASS_N, ISO2813_RECEPTOR, solid_angle_sr
from goniolab.optics.fresnel import fresnel_dielectric
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.models import ReflectanceModel


class Lambertian:
    """A toy model with no height map: a white Lambertian reflector, ``f = 1/pi`` sr^-1."""

    kind = "toy-lambert"

    def __init__(self, albedo: float) -> None:
        self.albedo = albedo

    def brdf_point(self, theta_i_deg: float, theta_r_deg: float, phi_r_deg: float = 180.0) -> float:
        return self.albedo / math.pi

    def brdf_inplane(self, theta_i_deg: float, theta_r_deg: Any) -> Any:
        return np.full(np.shape(theta_r_deg), self.albedo / math.pi)

    def reflected_fraction(
        self, theta_i_deg: float, theta_r_deg: float, source: Any, receptor: Any
    ) -> float:
        # f cos(theta_r) over a small receptor: (albedo / pi) x its solid angle x cos
        return (
            self.albedo / math.pi * solid_angle_sr(receptor) * math.cos(math.radians(theta_r_deg))
        )

    def luminance_pct(
        self, theta_i_deg: float, theta_r_deg: Any, *, source: Any = None, detector: Any = None
    ) -> Any:
        tr = np.asarray(theta_r_deg, dtype=np.float64)
        return 100.0 * self.albedo / math.pi * solid_angle_sr(detector) * np.cos(np.radians(tr))

    def gloss(self, angles_deg: Sequence[int] = (20, 60, 85)) -> dict[int, float]:
        # ISO 2813: the sample's flux into the receptor over the black glass standard's
        out = {}
        for t in angles_deg:
            rec = ISO2813_RECEPTOR[int(t)]
            std = float(fresnel_dielectric(math.cos(math.radians(t)), ISO2813_BLACK_GLASS_N))
            out[int(t)] = 100.0 * self.reflected_fraction(t, t, None, rec) / std
        return out


def build_lambertian(hm: HeightMap | None, options: ModelOptions) -> ReflectanceModel:
    assert hm is None  # needs_heightmap=False: the spec is not read
    return Lambertian(albedo=1.0 if options.masking else 0.5)


@pytest.fixture
def toy() -> Iterator[ScatteringModel]:
    entry = model_registry.register(
        ScatteringModel(
            "toy-lambert",
            build_lambertian,
            "a white Lambertian reflector (test toy)",
            "no surface at all",
            needs_heightmap=False,
        )
    )
    try:
        yield entry
    finally:
        model_registry.unregister("toy-lambert")


def _model_action(argv_prefix: list[str]) -> Any:
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    p = sub[argv_prefix[0]]
    if len(argv_prefix) > 1:
        p = p._subparsers._group_actions[0].choices[argv_prefix[1]]  # type: ignore[union-attr]
    return next(a for a in p._actions if "--model" in a.option_strings)


def test_builtin_names_are_registered_once_in_order() -> None:
    assert model_registry.model_names() == ("auto", "facet", "kirchhoff", "rayleigh-rice")
    assert model_registry.model_names()[0] == model_registry.DEFAULT_MODEL


def test_every_name_the_auto_rule_picks_is_registered() -> None:
    from goniolab.optics.model_choice import ModelName

    assert set(get_args(ModelName)) <= set(model_registry.model_names())


def test_every_builtin_model_reports_its_registered_name() -> None:
    hm = HeightMap(np.random.default_rng(1).normal(0.0, 0.05, (64, 64)), 0.5, 0.5, "noise")
    for name in model_registry.model_names():
        model = model_for(hm, model=name, backend="numpy")
        assert getattr(model, "kind", "facet") == name


def test_a_registered_model_is_a_cli_choice_with_its_help(toy: ScatteringModel) -> None:
    for where in (["predict", "gloss"], ["predict", "brdf"], ["scan"], ["fit", "colour"]):
        action = _model_action(where)
        assert "toy-lambert" in action.choices, where
    assert "a white Lambertian reflector (test toy)" in _model_action(["predict", "stats"]).help
    args = build_parser().parse_args(["predict", "gloss", "sample:flat", "--model", "toy-lambert"])
    assert args.model == "toy-lambert"


def test_an_unregistered_model_is_refused_by_the_cli() -> None:
    with pytest.raises(UserError, match="invalid choice: 'toy-lambert'"):
        build_parser().parse_args(["predict", "gloss", "sample:flat", "--model", "toy-lambert"])


def test_a_registered_model_passes_config_validation(toy: ScatteringModel, tmp_path: Path) -> None:
    path = tmp_path / "lab.toml"
    path.write_text('[sample]\nmodel = "toy-lambert"\n')
    assert load_lab_config(path).sample.model == "toy-lambert"


def test_an_unregistered_model_fails_config_validation(tmp_path: Path) -> None:
    path = tmp_path / "lab.toml"
    path.write_text('[sample]\nmodel = "toy-lambert"\n')
    with pytest.raises(UserError) as err:
        load_lab_config(path)
    assert f"{path}: sample.model: Input should be 'auto', 'facet', 'kirchhoff' or " in str(
        err.value
    )


def test_model_for_builds_a_registered_model_without_a_map(toy: ScatteringModel) -> None:
    # no such file: a model that needs no height map does not read the spec
    model = model_for("no-such-map.npy", model="toy-lambert", masking=False)
    assert isinstance(model, Lambertian) and model.albedo == 0.5
    assert model.brdf_point(30.0, 30.0) == pytest.approx(0.5 / math.pi)


def test_unknown_model_is_a_user_error_naming_the_registered_ones() -> None:
    with pytest.raises(UserError, match=r"unknown model 'wave'; use one of auto, facet, kirchhoff"):
        model_for("sample:flat", model="wave")


def test_names_are_unique_and_lower_case(toy: ScatteringModel) -> None:
    with pytest.raises(ValueError, match="already registered"):
        model_registry.register(toy)
    with pytest.raises(ValueError, match="lower case"):
        model_registry.register(ScatteringModel("Toy", build_lambertian, "", ""))


def test_the_notebook_api_gets_an_in_memory_map_model_the_one_way(toy: ScatteringModel) -> None:
    from goniolab import api

    # a map in memory goes through model_for like a file: the registry's models ...
    flat = HeightMap(np.zeros((8, 8)), 1.0, 1.0, "memory")
    ds = api.predict_gloss(flat, model="toy-lambert")
    # ISO 2813: 100 x the flux into the 60 deg receptor over the black glass standard's
    omega = solid_angle_sr(ISO2813_RECEPTOR[60])
    black = float(fresnel_dielectric(math.cos(math.radians(60)), ISO2813_BLACK_GLASS_N))
    expected = 100.0 * (1.0 / math.pi) * omega * 0.5 / black
    assert float(ds["gloss_gu"].sel(geometry_deg=60)) == pytest.approx(expected, rel=1e-12)
    # ... and the same refusal of heights that overflow when squared (1e200 um)
    huge = HeightMap(np.full((8, 8), 1e200), 1.0, 1.0, "huge")
    with pytest.raises(UserError, match=r"huge: heights up to 1e\+200 um overflow"):
        api.predict_gloss(huge, model="facet")
