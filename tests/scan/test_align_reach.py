"""An alignment incidence the arms cannot sweep is refused before any run or motion
(issue 23, Low: it recorded a failed run at the interlock instead).

The truth: lab-sim.toml's arms (lamp 0..85 deg, detector 0..70 deg, min separation 10 deg)
and the alignment's sweeps of +-(5 + 4.5) deg around the specular: the detector reaches
theta_i +- 9.5 only for theta_i in 9.5..60.5, and at theta_r = theta_i - 9.5 the arms are
2 theta_i - 9.5 apart, >= 10 for theta_i >= 9.75.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.config import load_lab_config
from goniolab.scan.align import AlignPlan
from goniolab.scan.align_reach import check_align_reach, reachable_incidence_deg
from goniolab.scan.plans import PlanError

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "lab-sim.toml"


def test_the_reachable_incidences_of_the_sim_lab() -> None:
    g = load_lab_config(CONFIG).goniometer
    assert reachable_incidence_deg(AlignPlan(), g) == (9.75, 60.5)
    check_align_reach(AlignPlan(theta_i_deg=(9.75, 60.5)), g)  # the bounds themselves pass


@pytest.mark.parametrize(
    ("angles", "needle"),
    [
        ((5.0, 40.0), "5: the detector sweep -4.5..14.5 deg leaves the detector arm's 0..70"),
        ((9.7, 40.0), "9.7: at theta_r 0.2 the arms would be 9.9 deg apart"),
        ((20.0, 61.0), "61: the detector sweep 51.5..70.5 deg leaves"),
        ((20.0, 88.0), "88: outside the lamp arm's 0..85 deg"),
    ],
)
def test_unreachable_incidences_are_named(angles: tuple[float, ...], needle: str) -> None:
    g = load_lab_config(CONFIG).goniometer
    with pytest.raises(PlanError) as info:
        check_align_reach(AlignPlan(theta_i_deg=angles), g)
    assert needle in str(info.value) and "incidences 9.75..60.5 deg can be aligned" in str(
        info.value
    )


def test_the_cli_refuses_before_recording_a_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "s.sqlite"
    code = main(["scan", "--config", str(CONFIG), "--plan", "align", "--align-theta-i", "5,40",
                 "--time-scale", "0", "--store", str(store), "--no-write-config"])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert "--align-theta-i 5: the detector sweep" in err and "nothing moved" in err
    assert main(["runs", "list", "--store", str(store), "--json"]) == 0
    assert capsys.readouterr().out.strip() in ("[]", "")  # no run recorded
