"""``goniolab predict`` on heights too large for double precision: one clear error naming the
cause, exit 2, never ``Infinity``/``NaN`` in ``--json`` (not valid JSON) or a silent 0 GU
computed from overflowed slopes (issue 10, defect 7)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main


@pytest.fixture
def huge_map(tmp_path: Path) -> Path:
    z = np.random.default_rng(0).normal(size=(20, 20)) * 1e300
    p = tmp_path / "huge.csv"
    np.savetxt(p, z, delimiter=",", header="dx_um = 1.0", comments="# ")
    return p


@pytest.mark.parametrize(
    "command",
    [
        ["stats"],
        ["gloss"],
        ["brdf", "--theta-r", "40:50:5"],
        ["brdf", "--theta-r", "45", "--point"],
    ],
    ids=["stats", "gloss", "brdf", "brdf-point"],
)
def test_heights_that_overflow_are_one_clear_error(
    huge_map: Path, capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    code = main(["predict", command[0], str(huge_map), *command[1:], "--json"])
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""  # no half-written JSON
    assert err.count("\n") == 1 and err.startswith("goniolab: error: ")
    assert "huge.csv" in err and ("not finite" in err or "overflow" in err)
    assert "1e+300" in err or "e+30" in err  # names how large the heights/slopes are


def test_a_plain_map_still_gives_valid_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    z = np.random.default_rng(0).normal(size=(32, 32)) * 0.05
    p = tmp_path / "ok.csv"
    np.savetxt(p, z, delimiter=",", header="dx_um = 1.0", comments="# ")
    assert main(["predict", "stats", str(p), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(c))
    assert np.isfinite(doc["Sq_nm"]) and doc["Sq_nm"] > 0


@pytest.mark.parametrize(
    "command",
    [["gloss"], ["brdf", "--theta-i", "80", "--theta-r", "75:85:5"], ["albedo"]],
    ids=["gloss", "brdf", "albedo"],
)
def test_a_models_non_finite_guard_is_one_clear_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    """The Kirchhoff energy check raises NonFiniteEnergySums (a FloatingPointError) rather
    than scale by a non-finite factor (never a silent 1); every ``predict`` command turns
    it into the overflow error, exit 2, no traceback and no half-written JSON."""
    from goniolab.optics.energy_budget import NonFiniteEnergySums
    from goniolab.optics.kirchhoff import KirchhoffModel

    def broken(self: object, theta_i_deg: float, lams_um: object) -> list[float]:
        raise NonFiniteEnergySums(f"kirchhoff energy check at {theta_i_deg:g} deg: D_1 = [nan]")

    monkeypatch.setattr(KirchhoffModel, "_energy_scales_at", broken)
    surface = "sample:gauss-sq177-l5"
    code = main(["predict", command[0], surface, "--model", "kirchhoff", *command[1:], "--json"])
    out, err = capsys.readouterr()
    assert code == 2, err
    assert out == ""
    assert "kirchhoff energy check at" in err and "D_1 = [nan]" in err
    assert "overflowed double precision" in err and "Traceback" not in err


def test_another_floating_point_error_is_not_called_an_overflow(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Only the energy check's guard is the overflow error: a FloatingPointError of
    another cause (``numpy.seterr(all="raise")`` in a notebook) passes unchanged."""
    from goniolab.app.predictions import SurfaceRequest, predict_gloss
    from goniolab.optics.kirchhoff import KirchhoffModel

    def other(self: object, theta_i_deg: float, lams_um: object) -> list[float]:
        raise FloatingPointError("underflow encountered in multiply")

    monkeypatch.setattr(KirchhoffModel, "_energy_scales_at", other)
    with pytest.raises(FloatingPointError, match=r"^underflow encountered in multiply$"):
        predict_gloss(SurfaceRequest("sample:gauss-sq177-l5", model="kirchhoff"))
