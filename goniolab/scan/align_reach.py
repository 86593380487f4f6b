"""Whether an alignment plan's sweeps fit the goniometer, checked before anything moves.

An alignment at incidence ``theta_i`` sweeps the detector over the nominal specular
``theta_i +- coarse_span`` and then ``+- fine_span`` around the peak it found, so the
detector must reach ``theta_i +- (coarse_span + fine_span)``, the lamp ``theta_i``, and at
the sweep's near end the arms must stay ``min_separation_deg`` apart (``theta_i + theta_r
>= min_separation``, the interlock's convention: :mod:`drivers.goniometer`). An incidence
outside that used to start an ``align`` run that failed at the interlock (issue 23, Low);
now it is refused up front with the incidences that can be measured.
"""

from __future__ import annotations

from goniolab.config import GoniometerConfig
from goniolab.scan.align import AlignPlan
from goniolab.scan.plans import PlanError

__all__ = ["check_align_reach", "reachable_incidence_deg"]


def reachable_incidence_deg(plan: AlignPlan, g: GoniometerConfig) -> tuple[float, float]:
    """The incidence angles (lo, hi) whose sweeps fit; lo > hi when none does."""
    reach = plan.coarse_span_deg + plan.fine_span_deg
    lamp_lo, lamp_hi = g.lamp.limits_deg
    det_lo, det_hi = g.detector.limits_deg
    lo = max(lamp_lo, det_lo + reach, (g.min_separation_deg + reach) / 2.0)
    hi = min(lamp_hi, det_hi - reach)
    return lo, hi


def check_align_reach(plan: AlignPlan, g: GoniometerConfig) -> None:
    """Raise :class:`PlanError` naming each incidence the arms cannot sweep and why."""
    reach = plan.coarse_span_deg + plan.fine_span_deg
    lamp_lo, lamp_hi = g.lamp.limits_deg
    det_lo, det_hi = g.detector.limits_deg
    problems: list[str] = []
    for ti in plan.theta_i_deg:
        near, far = ti - reach, ti + reach
        if not lamp_lo <= ti <= lamp_hi:
            problems.append(f"{ti:g}: outside the lamp arm's {lamp_lo:g}..{lamp_hi:g} deg")
        elif near < det_lo or far > det_hi:
            problems.append(
                f"{ti:g}: the detector sweep {near:g}..{far:g} deg leaves the detector arm's "
                f"{det_lo:g}..{det_hi:g} deg"
            )
        elif ti + near < g.min_separation_deg:
            problems.append(
                f"{ti:g}: at theta_r {near:g} the arms would be {ti + near:g} deg apart, "
                f"less than min_separation_deg {g.min_separation_deg:g}"
            )
    if problems:
        lo, hi = reachable_incidence_deg(plan, g)
        where = (
            f"incidences {lo:g}..{hi:g} deg can be aligned"
            if lo <= hi
            else "no incidence can be aligned with these limits"
        )
        raise PlanError(
            f"align: --align-theta-i {'; '.join(problems)} (sweeps of +-{reach:g} deg around "
            f"the specular; {where}; nothing moved)"
        )
