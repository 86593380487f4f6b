"""On the realistic twin, the run metrics tell a right prediction from a wrong one."""

from __future__ import annotations

from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.config import configs_dir
from goniolab.model_cache import model_for
from goniolab.optics.apertures import Cone
from goniolab.scan.plans import BrdfPlan
from goniolab.scan.summary import prediction_check, summarize_brdf
from goniolab.store import RunStore


def test_prediction_check_limits() -> None:
    assert not prediction_check(0.8, 1.1, 0.05)["flagged"]
    assert prediction_check(None, None, 0.05)["reasons"] == []
    bad = prediction_check(0.33, 1.0, 0.3)
    assert (
        bad["flagged"] and len(bad["reasons"]) == 2 and "amplitude_ratio 0.33" in bad["reasons"][0]
    )


@pytest.mark.slow
def test_a_wrong_prediction_is_flagged_and_the_right_one_is_not(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "runs.sqlite"
    cfg = str(configs_dir() / "lab-sim.toml")  # the realistic twin, wittmann-3 under it
    code = main(
        [
            "scan",
            "--config",
            cfg,
            "--theta-r",
            "30:60:1",
            "--time-scale",
            "0",
            "--store",
            str(store),
        ]
    )
    assert code == 0
    assert "prediction check: consistent" in capsys.readouterr().out
    with RunStore(store) as s:
        run = s.list_runs()[0]
        plan = BrdfPlan.from_dict(run.plan)
        points = s.points(run.id)
        right = summarize_brdf(plan, points, s.predictions(run.id))
    assert right["prediction_check"]["flagged"] is False
    # the twin does not agree with its prediction to 1e-5 any more: a real model error
    assert 0.05 < abs(right["amplitude_ratio"] - 1) < 0.35

    def predictions(spec: str, n: float) -> dict[int, float]:
        model = model_for(spec, n=n)
        values = model.luminance_pct(45.0, list(plan.theta_r_deg), source=Cone(6), detector=Cone(6))
        return {i: float(v) for i, v in enumerate(values)}

    wrong_n = summarize_brdf(plan, points, predictions("sample:wittmann-3", 2.0))
    assert wrong_n["prediction_check"]["flagged"]
    assert any("amplitude_ratio" in r for r in wrong_n["prediction_check"]["reasons"])
    for other in ("sample:wittmann-1", "sample:wittmann-8"):  # the map of another coating
        wrong_map = summarize_brdf(plan, points, predictions(other, 1.55))
        assert wrong_map["prediction_check"]["flagged"], other
