"""Plans: angle ranges, reading order, mirror reference, gloss statistics."""

from __future__ import annotations

import math

import pytest

from goniolab.scan.plans import (
    MAX_ANGLES,
    MAX_READINGS,
    MIRROR_INDEX,
    BrdfPlan,
    GlossPlan,
    PlanError,
    angle_range,
    gloss_statistics,
    parse_angles,
)
from goniolab.tui.view_model import ScanSetup


def test_range_is_inclusive_like_the_seed_sweep() -> None:
    # Wittmann et al. sweep the detector 0..70 deg in 1 deg steps: 71 geometries.
    angles = parse_angles("0:70:1")
    assert len(angles) == 71
    assert angles[0] == 0.0 and angles[-1] == 70.0


def test_fractional_step_lands_on_the_grid() -> None:
    assert parse_angles("0:1:0.1") == tuple(k / 10 for k in range(11))
    assert parse_angles("-10:10:2.5") == (-10.0, -7.5, -5.0, -2.5, 0.0, 2.5, 5.0, 7.5, 10.0)


@pytest.mark.parametrize(
    ("start", "stop", "step", "expected"),
    [
        (-20.0, 20.0, 10.0, (-20.0, -10.0, 0.0, 10.0, 20.0)),
        (-20.0, 20.0, 1.0, tuple(float(k) for k in range(-20, 21))),
        (0.0, 0.3, 0.1, (0.0, 0.1, 0.2, 0.3)),  # 0.1 * 3 = 0.30000000000000004 -> 0.3
        (0.0, 1.0, 0.3, (0.0, 0.3, 0.6, 0.9)),  # stop off the grid: not included
        (10.0, 10.0, 1.0, (10.0,)),
        (-1.05, -1.0, 0.01, (-1.05, -1.04, -1.03, -1.02, -1.01, -1.0)),
    ],
)
def test_one_range_expansion_for_the_cli_and_the_tui(
    start: float, stop: float, step: float, expected: tuple[float, ...]
) -> None:
    # the CLI's "start:stop:step" (scan and predict) and the TUI's sweep form expand alike
    assert angle_range(start, stop, step) == expected
    assert parse_angles(f"{start!r}:{stop!r}:{step!r}") == expected
    setup = ScanSetup("sample:flat", 45.0, start, stop, step, repeats=1)
    assert setup.theta_r_values_deg() == list(expected)


def test_a_huge_sweep_in_the_form_is_a_form_error_before_it_is_expanded() -> None:
    from goniolab.errors import UserError

    setup = ScanSetup("sample:flat", 45.0, 0.0, 90.0, 1e-7, repeats=1)
    with pytest.raises(UserError, match=r"scan setup: theta_r: range .* more than the 10000"):
        setup.validate()


def test_lists_keep_their_order() -> None:
    assert parse_angles("30, 10,20") == (30.0, 10.0, 20.0)
    assert parse_angles([5, 6.5]) == (5.0, 6.5)


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ("0:70", "start:stop:step"),
        ("0:70:0", "step must be > 0"),
        ("70:0:1", "stop < start"),
        ("0:x:1", "non-numeric"),
        ("1,b", "non-numeric"),
        ("", "empty"),
        ("0:inf:1", "finite"),
    ],
)
def test_bad_angle_specs_name_the_problem(spec: str, words: str) -> None:
    with pytest.raises(PlanError, match="theta_r") as exc:
        parse_angles(spec)
    assert words in str(exc.value)


def test_points_order_repeats_and_mirror_first() -> None:
    plan = BrdfPlan(45.0, (0.0, 10.0, 20.0), repeats=2, mirror_reference=True)
    pts = plan.points()
    assert len(pts) == 2 * (3 + 1)
    assert [(p.index, p.repeat) for p in pts[:4]] == [
        (MIRROR_INDEX, 0),
        (MIRROR_INDEX, 1),
        (0, 0),
        (0, 1),
    ]
    # the mirror is read at the specular geometry theta_r = theta_i
    assert all(p.theta_r_deg == 45.0 for p in pts[:2])
    assert [p.theta_r_deg for p in pts[2:]] == [0.0, 0.0, 10.0, 10.0, 20.0, 20.0]
    assert len({p.key for p in pts}) == len(pts)


def test_plan_round_trips_through_its_json_form() -> None:
    plan = BrdfPlan(45.0, parse_angles("0:70:1"), repeats=5, dwell_s=0.2, exposure_us=20000,
                    mirror_reference=True, sample="sample:wittmann-3")  # fmt: skip
    assert BrdfPlan.from_dict(plan.to_dict()) == plan


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"repeats": 0}, "repeats"),
        ({"dwell_s": -1.0}, "dwell_s"),
        ({"exposure_us": 100}, "exposure_us"),
        ({"theta_r_deg": (1.0, 1.0)}, "repeated"),
        ({"theta_r_deg": ()}, "no detector angles"),
    ],
)
def test_bad_plans_are_refused(kwargs: dict[str, object], words: str) -> None:
    args: dict[str, object] = {"theta_i_deg": 45.0, "theta_r_deg": (0.0, 1.0)}
    args.update(kwargs)
    with pytest.raises(PlanError, match=words):
        BrdfPlan(**args)  # type: ignore[arg-type]


def test_gloss_statistics_mean_and_sample_std() -> None:
    readings = [
        {20: 80.0, 60: 90.0, 85: None},
        {20: 82.0, 60: 92.0, 85: None},
        {20: 84.0, 60: 94.0, 85: None},
    ]
    st = gloss_statistics(readings)
    assert st.mean_gu == {20: 82.0, 60: 92.0}
    # sample std (ddof=1) of 80, 82, 84 is exactly 2
    assert st.std_gu[20] == pytest.approx(2.0, abs=1e-12)
    assert st.n == {20: 3, 60: 3}
    assert 85 not in st.mean_gu


def test_gloss_single_reading_has_zero_spread() -> None:
    st = gloss_statistics([{60: 42.5}], angles_deg=(60,))
    assert st.mean_gu[60] == 42.5 and st.std_gu[60] == 0.0
    assert math.isfinite(st.std_gu[60])


def test_gloss_plan_rejects_non_iso_angles() -> None:
    with pytest.raises(PlanError, match="20, 60, 85"):
        GlossPlan(count=3, angles_deg=(45,))


def test_oversized_sweeps_are_refused_before_they_are_expanded() -> None:
    # 0:90:0.01 is 9001 angles: allowed; a 1e-7 deg step would be 9e8 angles in memory
    assert len(parse_angles("0:90:0.01")) == 9001
    with pytest.raises(PlanError, match="900000001 angles, more than the 10000"):
        parse_angles("0:90:0.0000001")
    with pytest.raises(PlanError, match=r"10001 angles, more than the 10000"):
        BrdfPlan(45.0, tuple(k * 1e-3 for k in range(MAX_ANGLES + 1)))
    angles = parse_angles("0:99.99:0.01")  # 10000 angles x 11 repeats = 110000 readings
    with pytest.raises(PlanError, match=r"= 110000 readings, more than 100000"):
        BrdfPlan(45.0, angles, repeats=11)
    assert BrdfPlan(45.0, angles, repeats=10).n_geometries == MAX_ANGLES
    assert MAX_READINGS == 100_000


@pytest.mark.parametrize(
    ("theta_i", "theta_r", "arm"), [(90.0, 30.0, "lamp"), (45.0, -95.0, "detector")]
)
def test_a_geometry_at_or_below_the_sample_plane_is_refused_whatever_the_limits(
    theta_i: float, theta_r: float, arm: str
) -> None:
    """At 90 deg from the normal the lamp lights no sample and the detector sees none
    (review of 2026-11-26: a config giving the lamp (-5, 95) deg of travel let the TUI form
    and goniolab scan accept theta_i 90 and 95). The check is geometric, so it holds with a
    goniometer that would reach anything."""
    from goniolab.scan.dryrun import PlanRefused, check_reach
    from goniolab.scan.plans import PlanPoint

    def reaches_all(theta_i_deg: float, theta_r_deg: float) -> None:
        return None

    ok = [PlanPoint(0, 89.9, 30.0, 0), PlanPoint(1, 45.0, -89.9, 0)]
    check_reach(ok, reaches_all, park_deg=None)
    with pytest.raises(
        PlanRefused, match=rf"point 7 \(theta_i={theta_i:g} deg.*{arm}.*sample plane"
    ):
        check_reach([*ok, PlanPoint(7, theta_i, theta_r, 0)], reaches_all, park_deg=None)
