"""The wave models' shortcuts that must not change a reading (issue 26, whole process).

Each shortcut is held to the plain formula it replaces, evaluated here over every cell:
equal to the last bit, since ``goniolab predict ... --json`` must print the same bytes
(``bench/bench_lean.py --same-as BASE`` checks the whole commands).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from goniolab.optics.cell_apertures import CellBox
from goniolab.optics.fresnel import fresnel
from goniolab.optics.rayleigh_rice import RayleighRiceModel, rr_q_factor
from tests.optics.conftest import make_gaussian_map


def _rr_factor_whole_window(m: RayleighRiceModel, theta_i_deg: float, lam: float) -> float:
    """``min(1, R (1 - exp(-g)) / (exp(-g) D))`` with D summed over every cell of the
    Nyquist window (the evanescent ones as 0), as the docstring of
    :meth:`RayleighRiceModel._energy_scales_at` states it."""
    t = m._shared.tiled
    ci = math.cos(math.radians(theta_i_deg))
    nx0, nx1, ny0, ny1 = m._nyquist()
    box = CellBox(nx0, nx1, ny0, ny1)
    pv = m.psd.psd_um4[np.ix_(box.iy % t.ny_t, box.ix % t.nx_t)]
    cx, cy = m._cell_size(lam)
    x = box.ix.astype(np.float64)[None, :] * cx - math.sin(math.radians(theta_i_deg))
    y = box.iy.astype(np.float64)[:, None] * cy
    z2 = 1.0 - x * x - y * y
    ok = z2 > 1e-12
    z = np.sqrt(np.where(ok, z2, 0.0))
    st = np.sqrt(x * x + y * y)
    ts_deg = np.degrees(np.arctan2(st, z))
    phi_deg = np.where(st > 0, np.degrees(np.arctan2(-y, -x)), 0.0)
    q = rr_q_factor(theta_i_deg, ts_deg, phi_deg, m.n)
    d = float(np.sum(np.where(ok, 16.0 * math.pi**2 * ci * z * q * pv, 0.0)))
    d *= 1.0 / (t.nx_t * t.dx_um * t.ny_t * t.dy_um) / lam**2
    dw = math.exp(-m._g_at(theta_i_deg, lam))
    room = float(fresnel(ci, m.n)) * (1.0 - dw)
    return min(1.0, room / (dw * d)) if d > 0.0 else 1.0


@pytest.mark.parametrize("theta_i_deg", [70.0, 85.0, 89.0])
@pytest.mark.parametrize(("slope", "step_um"), [(0.02, 0.5), (0.3, 1.0)])
def test_rr_energy_factor_from_the_real_cells_is_the_whole_window_sum(
    theta_i_deg: float, slope: float, step_um: float
) -> None:
    # a smooth map (the factor 1) and a steep one (the factor binds at grazing incidence)
    hm = make_gaussian_map(128, slope, corr_px=2.0, seed=3, step_um=step_um)
    m = RayleighRiceModel(hm, n=1.55)
    lams = [0.4, 0.55, 0.7]
    got = m._energy_scales_at(theta_i_deg, lams)
    want = [_rr_factor_whole_window(m, theta_i_deg, lam) for lam in lams]
    assert got == want  # bit for bit
    if slope > 0.1 and theta_i_deg >= 89.0:
        assert min(got) < 1.0  # the case where the sum decides a reading


@pytest.mark.parametrize("corr_px", [0.4, 0.8, 1.2, 2.0, 4.0])
@pytest.mark.parametrize("length_um", [0.3, 0.55, 1.0, 2.5])
def test_the_correlation_bound_never_contradicts_the_length(
    corr_px: float, length_um: float
) -> None:
    """The regime rule's ``corr_length_um < lambda`` read through the real-space bound
    (:meth:`MapStats.corr_length_below`) is the comparison with the transforms' length:
    the bound decides only when the length is surely not below."""
    from goniolab.optics.shared_map import SharedMap

    hm = make_gaussian_map(256, 0.02, corr_px=corr_px, seed=5, step_um=0.5)
    shared = SharedMap(hm, 1024, 0.25)
    quick = shared.stats.corr_length_below(length_um)
    decided = shared._corr_at_least(length_um)
    exact = shared._corr_length_um()  # the transforms' value, computed apart
    assert quick == (exact < length_um)
    if decided:
        assert exact >= length_um


def test_the_rule_reads_a_smooth_maps_length_only_when_the_bound_cannot_decide() -> None:
    from goniolab.optics.model_choice import choose_model
    from goniolab.optics.shared_map import SharedMap

    # correlation length 2.0 um > 0.55 um, g 0.15-1: decided by the bound, never computed
    hm = make_gaussian_map(256, 0.03, corr_px=2.0, seed=5, step_um=0.5)
    shared = SharedMap(hm, 1024, 0.25)
    ch = choose_model(shared.stats, 45.0, 550.0)
    assert 0.15 < ch.g <= 1.0 and ch.model == "kirchhoff"
    assert callable(shared.stats._corr)
    # 0.44 um < 0.55 um: the bound cannot decide; the rule computes it, picks Rayleigh-Rice
    fine = make_gaussian_map(256, 0.05, corr_px=0.4, seed=5, step_um=0.5)
    fshared = SharedMap(fine, 1024, 0.25)
    ch = choose_model(fshared.stats, 45.0, 550.0)
    assert ch.model == "rayleigh-rice" and "correlation length 0.44 um" in ch.reason
    assert not callable(fshared.stats._corr)


def test_a_curve_asks_the_correlation_bound_once() -> None:
    """The rule asks at every angle of a curve; the bound (a tile's dot products) is
    formed once per length."""
    from goniolab.optics.shared_map import SharedMap

    hm = make_gaussian_map(256, 0.03, corr_px=2.0, seed=5, step_um=0.5)
    shared = SharedMap(hm, 1024, 0.25)
    calls: list[float] = []
    plain = shared._acf_above_level

    def counted(length_um: float) -> bool:
        calls.append(length_um)
        return plain(length_um)

    shared._acf_above_level = counted  # type: ignore[method-assign]
    for _ in range(71):
        assert not shared.stats.corr_length_below(0.55)
    assert calls == [0.55]


@pytest.mark.parametrize(("theta_i_deg", "receptor"), [(85.0, (4.0, 6.0)), (60.0, (4.4, 11.7))])
def test_rr_cells_from_the_real_cells_are_the_formula_over_the_box(
    theta_i_deg: float, receptor: tuple[float, float]
) -> None:
    """Rayleigh-Rice's cell powers (formed on the real cells only) equal the module
    docstring's ``exp(-g) 16 pi^2 cos ti cos ts Q PSD df^2 / lambda^2`` over every cell of
    the box (0 where evanescent), bit for bit."""
    from goniolab.optics.apertures import ISO2813_SOURCE, Rect

    hm = make_gaussian_map(128, 0.02, corr_px=2.0, seed=3, step_um=0.5)
    m = RayleighRiceModel(hm, n=1.55)
    lam = 0.55
    rec = Rect(*receptor)
    ra, rb = m._reach(ISO2813_SOURCE, rec)
    tr = math.radians(theta_i_deg)
    os, _ = m._oversampling(lam, rec, np.array([theta_i_deg]))
    box, _ = m._box_for(theta_i_deg, lam, tr - ra, tr + ra, rb, os)
    (got,), _ = m._cell_powers(theta_i_deg, [lam], [box], os)
    x, y, z, ok = m._geometry(theta_i_deg, lam, box, os)
    if theta_i_deg > 80.0:
        assert not ok.all()  # some cells are evanescent (the case the shortcut skips)
    st = np.sqrt(x * x + y * y)
    ts_deg = np.degrees(np.arctan2(st, np.where(ok, z, 0.0)))
    phi_deg = np.where(st > 0, np.degrees(np.arctan2(-y, -x)), 0.0)
    q = rr_q_factor(theta_i_deg, ts_deg, phi_deg, m.n)
    pv = m._psd_cells(box, os)
    t = m._shared.tiled
    df2 = 1.0 / (os[0] * t.nx_t * t.dx_um * os[1] * t.ny_t * t.dy_um)
    ci = math.cos(tr)
    p = 16.0 * math.pi**2 * ci * np.where(ok, z, 0.0) * q * pv * df2 / lam**2
    scale = m._energy_scales(theta_i_deg, [lam])[0]
    want = np.where(ok, scale * math.exp(-m._g_at(theta_i_deg, lam)) * p, 0.0)
    assert np.array_equal(got, want)
