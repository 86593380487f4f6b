"""The facet model against analytic truths (docs/PHYSICS.md, "Truths any implementation must hold")."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np
import pytest
from numpy.typing import NDArray

from goniolab.optics import _kernels as K
from goniolab.optics import _kernels_numpy as KN
from goniolab.optics.apertures import (
    ISO2813_RECEPTOR,
    ISO2813_SOURCE,
    Cone,
    Rect,
    aperture_contains,
    integrate_brdf,
    sample_aperture,
)
from goniolab.optics.facet import FacetModel, cap_overlap_fraction, cap_overlap_moments
from goniolab.optics.fresnel import fresnel, fresnel_dielectric
from goniolab.optics.heightmap import HeightMap
from goniolab.optics.metrics import peak_metrics
from goniolab.optics.models import ReflectanceModel
from goniolab.optics.surface import Surface, slope_histogram

FloatArray = np.ndarray


def _wi(theta_i_deg: float) -> FloatArray:
    t = math.radians(theta_i_deg)
    return np.array([math.sin(t), 0.0, math.cos(t)])


def _gaussian_facet_brdf(
    sx: float, sy: float, n: complex = 1.55
) -> Callable[[FloatArray, FloatArray], FloatArray]:
    """Analytic facet BRDF F P22 / (4 cos ti cos to cos^4 th) with Gaussian P22 (SCATMECH Facet)."""

    def brdf(wi: FloatArray, wo: FloatArray) -> FloatArray:
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        ph, qh = -h[..., 0] / h[..., 2], -h[..., 1] / h[..., 2]
        p22 = np.exp(-0.5 * (ph / sx) ** 2 - 0.5 * (qh / sy) ** 2) / (2 * np.pi * sx * sy)
        f = (
            fresnel(np.sum(wi * h, axis=-1), n)
            * p22
            / (4 * wi[..., 2] * wo[..., 2] * h[..., 2] ** 4)
        )
        return np.where((wi[..., 2] > 0) & (wo[..., 2] > 0), f, 0.0)

    return brdf


def _sigma(surface: Surface) -> tuple[float, float]:
    return float(np.sqrt(np.mean(surface.p**2))), float(np.sqrt(np.mean(surface.q**2)))


# --------------------------------------------------------------------------- flat surfaces
@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_flat_gloss_truths(flat_surface: Surface, backend: str) -> None:
    # docs/PHYSICS.md: flat n = 1.567 reads 100.0 at every geometry; n = 1.55: 95.4 / 97.3 / 99.8
    g = FacetModel(flat_surface, n=1.567, backend=backend).gloss()  # type: ignore[arg-type]
    for t in (20, 60, 85):
        assert g[t] == pytest.approx(100.0, abs=1e-9)
    g = FacetModel(flat_surface, n=1.55, backend=backend).gloss()  # type: ignore[arg-type]
    assert [round(g[t], 1) for t in (20, 60, 85)] == [95.4, 97.3, 99.8]


@pytest.mark.parametrize("theta_i_deg", [20.0, 45.0, 70.0])
@pytest.mark.parametrize(("src", "det"), [(6.0, 6.0), (2.0, 6.0), (0.0, 6.0)])
def test_flat_mirror_luminance_is_fresnel(
    flat_surface: Surface, theta_i_deg: float, src: float, det: float
) -> None:
    """A mirror with detector >= source reads 100 F(n, ti) at tr = ti, 0 beyond the cones."""
    m = FacetModel(flat_surface, n=1.5)
    ref = 100 * float(fresnel_dielectric(math.cos(math.radians(theta_i_deg)), 1.5))
    far = theta_i_deg + 0.5 * (src + det) + 0.2
    for tr in ([theta_i_deg, far], [theta_i_deg, far, theta_i_deg - 1.0]):  # exact, grid
        lum = m.luminance_pct(theta_i_deg, tr, source=Cone(src), detector=Cone(det))
        assert lum[0] == pytest.approx(ref, rel=1e-9)
        assert lum[1] == 0.0
    exact = 100 * m.reflected_fraction(theta_i_deg, theta_i_deg, Cone(src), Cone(det))
    assert exact == pytest.approx(ref, rel=1e-12)


def test_flat_mirror_small_detector_reads_the_solid_angle_ratio(flat_surface: Surface) -> None:
    m = FacetModel(flat_surface, n=1.5)
    f45 = float(fresnel_dielectric(math.cos(math.radians(45.0)), 1.5))
    ratio = (1 - math.cos(math.radians(1.0))) / (1 - math.cos(math.radians(3.0)))
    lum = m.luminance_pct(45.0, [45.0], source=Cone(6.0), detector=Cone(2.0))
    assert lum[0] == pytest.approx(100 * f45 * ratio, rel=1e-9)


def _flat_mirror_reading(theta_i_deg: float, theta_r_deg: float, n: float, a_deg: float) -> float:
    """Exact flat-mirror goniometer reading, equal source and detector cones (half angle a).

    The mirror sends source direction s to (-s_x, -s_y, s_z), so s reaches the detector
    iff it lies within a of the detector's mirror image d' = (sin tr, 0, cos tr). In polar
    coordinates (r, phi) about wi, phi from the direction towards d', that is
    ``|phi| <= phi0(r)``, ``cos phi0 = (cos a - cos r cos g)/(sin r sin g)``, g = |tr - ti|.
    The reading averages F(s_z) over that part of the source cap: Gauss-Legendre in r (split
    at the kinks of phi0) and in phi over [-phi0, phi0].
    """
    ti, a = math.radians(theta_i_deg), math.radians(a_deg)
    g = abs(math.radians(theta_r_deg - theta_i_deg))
    e_z = -math.sin(ti) if theta_r_deg >= theta_i_deg else math.sin(ti)  # tangent towards d'
    x, w = np.polynomial.legendre.leggauss(64)
    total = 0.0
    cuts = sorted({0.0, min(abs(g - a), a), min(g + a, a), a})
    for lo, hi in itertools.pairwise(cuts):
        r = lo + (hi - lo) * 0.5 * (x + 1)
        wr = (hi - lo) * 0.5 * w
        with np.errstate(divide="ignore", invalid="ignore"):
            c = (math.cos(a) - np.cos(r) * math.cos(g)) / (np.sin(r) * math.sin(g))
        phi0 = np.arccos(np.clip(np.where(np.isfinite(c), c, -1.0), -1.0, 1.0))
        phi = phi0[:, None] * x[None, :]
        s_z = np.cos(r)[:, None] * math.cos(ti) + np.sin(r)[:, None] * np.cos(phi) * e_z
        f = fresnel_dielectric(s_z, n)
        total += float(np.sum(wr * np.sin(r) * phi0 * (f @ w)))
    return total / (2 * math.pi * (1 - math.cos(a)))


@pytest.mark.parametrize(("theta_i_deg", "tol"), [(45.0, 4e-3), (70.0, 1.2e-2)])
def test_flat_mirror_scan_follows_the_cap_overlap(
    flat_surface: Surface, theta_i_deg: float, tol: float
) -> None:
    """Scanning the detector across a mirror: the exact reading (2-D quadrature,
    :func:`_flat_mirror_reading`) is F averaged over the part of the source cone whose image
    falls in the detector, not F(ti) O(gamma): that zeroth-order form is off by 1 % of the
    peak at 45 deg and 4 % at 70 deg in the flanks. The model carries the first-order term
    (F's gradient times the lens's first moment); what remains is second order, the mean of
    F over the cone against its centre value (measured 0.3 % of the peak at 45 deg, 0.9 %
    at 70 deg). Grid (many angles) and exact per-facet path (two angles) alike.
    """
    ti = theta_i_deg
    m = FacetModel(flat_surface, n=1.5)
    tr = np.linspace(ti - 7.0, ti + 7.0, 57)
    lum = m.luminance_pct(ti, tr)
    exact = np.array([100 * _flat_mirror_reading(ti, t, 1.5, 3.0) for t in tr])
    np.testing.assert_allclose(lum, exact, atol=tol * lum.max())
    two = m.luminance_pct(ti, tr[[20, 40]])
    np.testing.assert_allclose(two, exact[[20, 40]], atol=tol * lum.max())
    f_ti = 100 * float(fresnel_dielectric(math.cos(math.radians(ti)), 1.5))
    zeroth = f_ti * cap_overlap_fraction(np.radians(np.abs(tr - ti)), *np.radians([3.0, 3.0]))
    assert np.abs(lum - exact).max() < 0.5 * np.abs(zeroth - exact).max()


def test_flat_albedo_is_fresnel(flat_surface: Surface) -> None:
    m = FacetModel(flat_surface, n=1.5)
    for ti in (0.0, 30.0, 80.0):
        h = m.brdf_hemisphere(ti, bin_deg=1.0)
        assert h.albedo == pytest.approx(float(fresnel_dielectric(math.cos(math.radians(ti)), 1.5)))


# --------------------------------------------------------------------------- cap overlap
@pytest.mark.parametrize(
    ("a_s_deg", "a_d_deg", "gamma_deg"),
    [
        (3.0, 3.0, 0.0),
        (3.0, 3.0, 2.0),
        (3.0, 3.0, 5.5),
        (2.0, 5.0, 4.0),
        (5.0, 2.0, 4.0),
        (20.0, 30.0, 35.0),
    ],
)
def test_cap_overlap_against_monte_carlo(a_s_deg: float, a_d_deg: float, gamma_deg: float) -> None:
    rng = np.random.default_rng(11)
    a_s, a_d, g = np.radians([a_s_deg, a_d_deg, gamma_deg])
    k = 400_000
    ct = 1 - rng.random(k) * (1 - math.cos(a_s))  # uniform in solid angle over the source cap
    st = np.sqrt(1 - ct * ct)
    ph = rng.random(k) * 2 * np.pi
    pts = np.stack([st * np.cos(ph), st * np.sin(ph), ct], axis=-1)
    d = np.array([math.sin(g), 0.0, math.cos(g)])
    mc = float(np.mean(pts @ d >= math.cos(a_d)))
    sd = math.sqrt(max(mc * (1 - mc), 1e-12) / k)
    got = float(cap_overlap_fraction(np.array([g]), a_s, a_d)[0])
    assert abs(got - mc) < 5 * sd + 1e-9


def test_cap_overlap_small_caps_match_the_planar_lens() -> None:
    # equal circles at a distance equal to their radius: lens / circle = (2 pi/3 - sqrt3/2)/pi
    lens = (2 * math.pi / 3 - math.sqrt(3) / 2) / math.pi
    for a in (1e-5, 9.9e-4, 1.01e-3, math.radians(3.0)):
        got = float(cap_overlap_fraction(np.array([a]), a, a)[0])
        assert got == pytest.approx(lens, rel=2e-3 if a > 0.01 else 1e-5)
    assert float(cap_overlap_fraction(np.array([0.01]), 0.0, 0.02)[0]) == 1.0
    assert float(cap_overlap_fraction(np.array([0.0]), 0.02, 0.0)[0]) == 0.0


@pytest.mark.parametrize(("a_s_deg", "a_d_deg"), [(3.0, 3.0), (1.0, 3.0), (3.0, 1.0), (20.0, 35.0)])
def test_cap_overlap_moments_against_monte_carlo(a_s_deg: float, a_d_deg: float) -> None:
    """O equals the closed-form lens (quadrature to 1e-6); M1 = mean over the source cap of sin(r) cos(phi) x
    indicator, by Monte Carlo with 4e5 uniform points (standard error < 0.3 % of a_s)."""
    a_s, a_d = math.radians(a_s_deg), math.radians(a_d_deg)
    gam = np.radians(np.array([0.0, 0.3, 1.0, 2.5, 3.9, 5.5]) * max(a_s_deg, a_d_deg) / 3.0)
    o, m1 = cap_overlap_moments(gam, a_s, a_d)
    np.testing.assert_allclose(o, cap_overlap_fraction(gam, a_s, a_d), atol=1e-6)
    rng = np.random.default_rng(11)
    cos_r = 1.0 - rng.random(400_000) * (1.0 - math.cos(a_s))  # uniform on the cap
    sin_r = np.sqrt(1.0 - cos_r**2)
    phi = rng.uniform(-math.pi, math.pi, cos_r.size)
    for g, got in zip(gam, m1, strict=True):
        # angular distance to the detector centre at (g, phi = 0)
        cos_d = cos_r * math.cos(g) + sin_r * math.sin(g) * np.cos(phi)
        inside = cos_d >= math.cos(a_d)
        mc = float(np.mean(sin_r * np.cos(phi) * inside))
        assert got == pytest.approx(mc, abs=3e-3 * a_s)
        if g == 0.0 or g >= a_s + a_d:
            assert got == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("n", [1.5, 0.27 + 3.41j, 2.4 + 0.3j])
def test_fresnel_derivative_equals_finite_differences(n: complex) -> None:
    c = np.linspace(0.02, 0.98, 49)
    nc = complex(n)
    f, df = K.fresnel_d_numpy(c, nc.real, nc.imag)
    np.testing.assert_allclose(f, fresnel(c, n), rtol=1e-12)
    h = 1e-6
    fd = (fresnel(c + h, n) - fresnel(c - h, n)) / (2 * h)
    np.testing.assert_allclose(df, fd, rtol=1e-5, atol=1e-8)
    for ck, fk, dk in zip(c, f, df, strict=True):
        f1, d1 = K._fresnel_d_scalar(float(ck), nc.real, nc.imag)
        assert f1 == pytest.approx(fk, rel=1e-12) and d1 == pytest.approx(dk, rel=1e-9, abs=1e-14)


# --------------------------------------------------------------------------- numba == numpy
def test_numba_kernels_equal_numpy_twins(gauss_surface_256: Surface) -> None:
    mx, my, mz = gauss_surface_256.normals
    wi = _wi(50.0)
    for n_re, n_im, seed in ((1.55, 0.0, False), (0.27, 3.41, False), (1.55, 0.0, True)):
        args = (mx, my, mz, wi, n_re, n_im, seed)
        tables = K.hemisphere_bin_tables(math.radians(1.0), 90, 360)
        h1, t1 = K.hemisphere_numba(*args, *tables)
        h2, t2 = K.hemisphere_numpy(*args, *tables)
        np.testing.assert_allclose(h1, h2, rtol=1e-10, atol=1e-12)
        assert t1 == pytest.approx(t2, rel=1e-12)
        for grad in (False, True):
            grid = (-0.3, math.radians(0.05), 1500, -0.1, math.radians(0.05), 121, grad)
            g1, gg1, s1 = K.deposit_numba(*args, *grid)
            g2, gg2, s2 = K.deposit_numpy(*args, *grid)
            np.testing.assert_allclose(g1, g2, rtol=1e-10, atol=1e-12 * g1.max())
            np.testing.assert_allclose(gg1, gg2, rtol=1e-10, atol=1e-12 * np.abs(gg1).max())
            assert s1 == pytest.approx(s2, rel=1e-12) and s1 == pytest.approx(g1.sum(), rel=1e-9)
            assert 0 < s1 <= t1 * (1 + 1e-12)
            assert np.any(gg1 != 0.0) == grad
        d = np.array([-math.sin(0.9), 0.0, math.cos(0.9)])
        gam = np.linspace(0, 0.1, 4097)
        table = cap_overlap_fraction(gam, 0.05, 0.05)
        m1 = cap_overlap_moments(gam, 0.05, 0.05)[1]
        c1 = K.cone_response_numba(*args, d, table, 0.0, 0.1, 1.0, m1)
        c2 = K.cone_response_numpy(*args, d, table, 0.0, 0.1, 1.0, m1)
        assert c1 == pytest.approx(c2, rel=1e-10) and c1 > 0
        r1 = K.rect_response_numba(*args, 0.9, 0.013, 0.077, 0.044, 0.2)
        r2 = K.rect_response_numpy(*args, 0.9, 0.013, 0.077, 0.044, 0.2)
        assert r1 == pytest.approx(r2, rel=1e-10) and r1 > 0


def test_hemisphere_bins_equal_acos_atan2_bins() -> None:
    """The trig-free bin search puts random directions in the bins of theta = acos(z) and
    phi = atan2(y, x) mod 360 (exact arithmetic; directions within 1e-9 rad of an edge skipped)."""
    rng = np.random.default_rng(8)
    v = rng.normal(size=(200_000, 3))
    v[:, 2] = np.abs(v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    h = math.radians(0.5)
    cos_e, _, dia_e, _ = K.hemisphere_bin_tables(h, 180, 720)
    th = np.arccos(v[:, 2]) / h
    ph = (np.arctan2(v[:, 1], v[:, 0]) % (2 * np.pi)) / h
    ok = (np.abs(th - np.round(th)) > 1e-7) & (np.abs(ph - np.round(ph)) > 1e-7)
    it = KN._theta_bins(v[ok, 2], cos_e)
    ip = KN._phi_bins(K.diamond_numpy(v[ok, 0], v[ok, 1]), dia_e)
    np.testing.assert_array_equal(it, np.floor(th[ok]).astype(int))
    np.testing.assert_array_equal(ip, np.floor(ph[ok]).astype(int))


@pytest.mark.parametrize("kw", [{}, {"n": 0.27 + 3.41j}, {"weighting": "seed"}, {"masking": True}])
def test_backends_agree_on_every_response(
    gauss_surface_256: Surface, kw: dict[str, object]
) -> None:
    a = FacetModel(gauss_surface_256, backend="numba", **kw)  # type: ignore[arg-type]
    b = FacetModel(gauss_surface_256, backend="numpy", **kw)  # type: ignore[arg-type]
    np.testing.assert_allclose(
        a.brdf_hemisphere(40.0).f_sr, b.brdf_hemisphere(40.0).f_sr, rtol=1e-9, atol=1e-12
    )
    tr = np.arange(20.0, 61.0, 2.5)
    np.testing.assert_allclose(
        a.luminance_pct(40.0, tr), b.luminance_pct(40.0, tr), rtol=1e-9, atol=1e-12
    )
    ga, gb = a.gloss(), b.gloss()
    for t in ga:
        assert ga[t] == pytest.approx(gb[t], rel=1e-10)


def test_numba_threads_split_large_surfaces(gauss_surface_1024: Surface) -> None:
    """Chunked (threaded) kernels cover every facet once and sum to the numpy result."""
    a = FacetModel(gauss_surface_1024)
    chunks = a._chunks()
    np.testing.assert_array_equal(np.concatenate([c[0] for c in chunks]), a._mx)
    b = FacetModel(gauss_surface_1024, backend="numpy")
    assert len(b._chunks()) == 1
    assert a.reflected_fraction(60, 60, ISO2813_SOURCE, ISO2813_RECEPTOR[60]) == pytest.approx(
        b.reflected_fraction(60, 60, ISO2813_SOURCE, ISO2813_RECEPTOR[60]), rel=1e-10
    )
    ha, hb = a.brdf_hemisphere(60.0), b.brdf_hemisphere(60.0)
    np.testing.assert_allclose(ha.f_sr, hb.f_sr, rtol=1e-9, atol=1e-12)


# --------------------------------------------------------------------------- Gaussian truth
@pytest.mark.parametrize("weighting", ["radiometric", "seed"])
def test_hemisphere_reproduces_the_analytic_gaussian_facet_brdf(
    gauss_surface_1024: Surface, weighting: str
) -> None:
    """Histogram BRDF vs F P22 / (4 cos ti cos to cos^4 th) with Gaussian P22 (measured sigmas).

    Tolerance: bins whose expected facet count exceeds 400 have a Poisson relative noise
    below 5 %, inflated somewhat by the spatial correlation of neighbouring slopes
    (kernel 1.5 px); over those bins the mean ratio must be 1 within 1 % (it averages
    hundreds of bins), the rms within 6 % and no bin off by more than 25 %. The albedo (sum
    over all bins) must match the analytic integral within 0.5 %. The seed's Fresnel-only
    weight w = F changes the analytic form by cos ti cos th_h / (wi.h).
    """
    sx, sy = _sigma(gauss_surface_1024)
    radiometric = _gaussian_facet_brdf(sx, sy)

    def ana(wi: FloatArray, wo: FloatArray) -> FloatArray:
        f = radiometric(wi, wo)
        if weighting == "seed":
            h = wi + wo
            h = h / np.linalg.norm(h, axis=-1, keepdims=True)
            f = f * wi[..., 2] * h[..., 2] / np.sum(wi * h, axis=-1)
        return f

    m = FacetModel(gauss_surface_1024, weighting=weighting)  # type: ignore[arg-type]
    for ti in (20.0, 45.0, 70.0):
        h = m.brdf_hemisphere(ti, bin_deg=1.0)
        th = np.radians(h.theta_edges_deg)
        thc = 0.5 * (th[1:] + th[:-1])[:, None]
        phc = np.radians(0.5 * (h.phi_edges_deg[1:] + h.phi_edges_deg[:-1]))[None, :]
        wo = np.stack(
            np.broadcast_arrays(np.sin(thc) * np.cos(phc), np.sin(thc) * np.sin(phc), np.cos(thc)),
            axis=-1,
        )
        fa = ana(_wi(ti), wo)
        proj = 0.5 * np.diff(np.sin(th) ** 2)[:, None] * math.radians(1.0)
        f_i = float(fresnel_dielectric(math.cos(math.radians(ti)), 1.55))
        expected_count = fa * proj * gauss_surface_1024.n_facets / f_i
        sel = expected_count > 400
        assert sel.sum() > 200
        r = h.f_sr[sel] / fa[sel] - 1
        assert abs(r.mean()) < 0.01
        assert r.std() < 0.06
        assert np.abs(r).max() < 0.25
        assert h.albedo == pytest.approx(float(np.sum(fa * proj)), rel=5e-3)


def test_brdf_inplane_reproduces_the_analytic_gaussian_facet_brdf(
    gauss_surface_1024: Surface,
) -> None:
    """brdf_inplane (histogram P22, bin 0.01) vs the Gaussian facet BRDF within 2 sigma_slope.

    With N = 1e6 facets and P22 ~ 60 near the peak, a 0.01 bin holds ~6000 facets (1.3 %
    Poisson, a few % with the slopes' spatial correlation); within |p_h| < 2 sigma the
    counts stay above ~800. P22 is interpolated bilinearly between bin centres, so the
    binning bias is second order (< 1 %). Tolerance: every point within 8 %, mean |error|
    below 3 % (measured: 3.6 % and 1 %).
    """
    sx, sy = _sigma(gauss_surface_1024)
    m = FacetModel(gauss_surface_1024, slope_bin=0.01)
    for ti in (30.0, 60.0):
        dt = np.linspace(-11.0, 11.0, 45)  # p_h = tan(dt/2): |p_h| < 0.097 ~ 2 sigma
        tr = ti + dt
        wo = np.stack([-np.sin(np.radians(tr)), 0 * tr, np.cos(np.radians(tr))], axis=-1)
        fa = _gaussian_facet_brdf(sx, sy)(_wi(ti), wo)
        r = m.brdf_inplane(ti, tr) / fa - 1
        assert np.abs(r).max() < 0.08
        assert np.abs(r).mean() < 0.03
        assert m.brdf_point(ti, tr[20]) == pytest.approx(float(m.brdf_inplane(ti, tr[20:21])[0]))


@pytest.mark.parametrize("weighting", ["radiometric", "seed"])
def test_point_brdf_of_a_rough_surface_far_from_the_normal(
    gaussian_factory: Callable[..., HeightMap], weighting: str
) -> None:
    """brdf() (the P22 lookup) vs the analytic Gaussian facet BRDF where cos^4 theta_h matters.

    Per-axis rms slope 0.3, half vectors 18-30 deg from the normal in every azimuth: there
    the 1/cos^4 theta_h of the analytic form (and the cos theta_h of the seed weighting)
    differ from their neighbours by ~9 %, far above the histogram noise averaged over 400
    directions (bin 0.05, ~1000 facets per bin near the peak: mean of the ratio within
    3 %, measured 0.4-1.0 % on three seeds; rms within 8 %, measured 3.7 %).
    """
    surf = Surface.from_heightmap(gaussian_factory(512, 0.3, seed=5), slope_method="central")
    sx, sy = _sigma(surf)
    rng = np.random.default_rng(2)
    th = np.radians(rng.uniform(18.0, 30.0, 400))
    ph = rng.uniform(0.0, 2.0 * np.pi, 400)
    h = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)
    wi = _wi(10.0)
    wo = 2.0 * (h @ wi)[:, None] * h - wi
    fa = _gaussian_facet_brdf(sx, sy)(wi, wo)
    if weighting == "seed":
        fa = fa * wi[2] * h[:, 2] / (h @ wi)
    m = FacetModel(surf, slope_bin=0.05, weighting=weighting)  # type: ignore[arg-type]
    r = m.brdf(wi, wo) / fa - 1.0
    assert abs(r.mean()) < 0.03
    assert r.std() < 0.08


def test_luminance_matches_integrate_brdf_of_the_analytic_gaussian(
    gauss_surface_1024: Surface,
) -> None:
    """The cone-overlap reading vs Mihalik's double quadrature (integrate_brdf) of the analytic
    Gaussian facet BRDF: the aperture averages many histogram bins, so 3 % suffices."""
    sx, sy = _sigma(gauss_surface_1024)
    ana = _gaussian_facet_brdf(sx, sy)
    m = FacetModel(gauss_surface_1024)
    tr = np.array([35.0, 40.0, 45.0, 50.0, 55.0])
    lum = m.luminance_pct(45.0, tr)
    quad = np.array(
        [
            100 * integrate_brdf(ana, 45.0, t, Cone(6.0), Cone(6.0), n_source=6, n_receptor=24)
            for t in tr
        ]
    )
    np.testing.assert_allclose(lum, quad, rtol=0.03)


def test_cone_overlap_equals_explicit_source_quadrature(
    gaussian_factory: Callable[..., HeightMap],
) -> None:
    """The isometry trick vs brute force: sample the source cone, reflect every facet of
    every source direction with its own weight, count what enters the detector cone.

    Differences: the trick carries the variation of w_k across the 3 deg source cone to
    first order only, and the grid is 0.05 deg; 0.5 % of the peak covers both and the
    256-point source sampling (without the first-order term it was 1.2 %).
    """
    surf = Surface.from_heightmap(gaussian_factory(128, 0.05, seed=3), slope_method="central")
    mx, my, mz = surf.normals
    a_s = a_d = math.radians(3.0)
    k = 256
    i = np.arange(k) + 0.5
    ct = 1 - i / k * (1 - math.cos(a_s))
    st = np.sqrt(1 - ct * ct)
    ph = i * math.pi * (3 - math.sqrt(5))
    ti = math.radians(45.0)
    rot = np.array([[math.cos(ti), 0, math.sin(ti)], [0, 1, 0], [-math.sin(ti), 0, math.cos(ti)]])
    srcs = np.stack([st * np.cos(ph), st * np.sin(ph), ct], axis=-1) @ rot.T
    tr = np.array([39.0, 42.0, 45.0, 47.5, 51.0])
    dets = np.stack([-np.sin(np.radians(tr)), 0 * tr, np.cos(np.radians(tr))], axis=-1)
    acc = np.zeros(tr.size)
    for wi in srcs:
        ox, oy, oz, w = K.reflect_numpy(mx, my, mz, wi, 1.55, 0.0, False)
        inside = np.stack([ox, oy, oz], axis=-1) @ dets.T >= math.cos(a_d)
        acc += w @ inside
    brute = 100 * acc / (k * mx.size)
    model = FacetModel(surf)
    lum = model.luminance_pct(45.0, tr)
    np.testing.assert_allclose(lum, brute, atol=0.005 * brute.max())
    exact = np.array([100 * model.reflected_fraction(45.0, t, Cone(6), Cone(6)) for t in tr])
    np.testing.assert_allclose(lum, exact, rtol=2e-3)


@pytest.mark.parametrize("backend", ["numba", "lean"])
@pytest.mark.parametrize("slope_rms", [0.03, 0.1])
def test_gloss_equals_explicit_source_and_receptor_quadrature(
    gaussian_factory: Callable[..., HeightMap], slope_rms: float, backend: str
) -> None:
    """ISO 2813 gloss by the translated-rectangle overlap vs Mihalik eq. 15 done by brute force.

    The truth samples the 0.75 x 2.5 deg source rectangle on a 12 x 12 grid
    (:func:`sample_aperture`), reflects every facet with the weight of that source
    direction and counts what :func:`aperture_contains` puts inside the receptor rectangle
    (in-plane x perpendicular as in apertures.py). The facet model neglects the variation of
    the weight across the source, which at 85 deg is +-6 % over the 0.75 deg in-plane
    extent: measured 0.04-0.2 % here, asserted 0.3 %. The same for the numba-free "lean"
    backend, which reads these rectangles from the slope histogram's cells.
    """
    surf = Surface.from_heightmap(gaussian_factory(64, slope_rms, seed=3), slope_method="central")
    mx, my, mz = surf.normals
    model = FacetModel(surf, backend=backend)  # type: ignore[arg-type]
    got = model.gloss((60, 85))
    for t in (60, 85):
        src, w_src = sample_aperture(ISO2813_SOURCE, float(t), 0.0, n=12)
        acc = 0.0
        for wi, w_s in zip(src, w_src, strict=True):
            ox, oy, oz, w = K.reflect_numpy(mx, my, mz, wi, 1.55, 0.0, False)
            wo = np.stack([ox, oy, oz], axis=-1)
            acc += w_s * float(w @ aperture_contains(ISO2813_RECEPTOR[t], t, 180.0, wo))
        brute = 100 * acc / (w_src.sum() * mx.size) / float(fresnel_dielectric(_wi(t)[2], 1.567))
        assert got[t] == pytest.approx(brute, rel=3e-3)


@pytest.mark.parametrize("backend", ["numba", "lean"])
@pytest.mark.parametrize(
    ("slope_rms", "n", "weighting"),
    [(0.05, 1.55, "radiometric"), (0.2, 1.55, "radiometric"), (0.2, 0.27 + 3.41j, "seed")],
)
def test_cone_overlap_matches_source_sampling_off_45_deg(
    gaussian_factory: Callable[..., HeightMap],
    slope_rms: float,
    n: complex,
    weighting: str,
    backend: str,
) -> None:
    """The stated accuracy of the isometry trick for the 6 deg cones (FacetModel docstring).

    The weight c / (m_z cos ti) F varies across the source cone like tan(ti). Taken at the
    cone's centre only, the error is first order for images straddling the detector edge
    (measured 1.8 % at ti = 45, 3.8 % at 60 in the flanks); with the first-order term
    (gradient x first moment of the cap-cap lens) what remains is second order. Measured
    against brute-force source sampling (64 x 64 maps, rms slope 0.05 / 0.2, specular
    +-10 deg): normal incidence 0.1 %, ti = 45 0.45 %, ti = 60 0.7 % (asserted 0.3 / 0.7 /
    1 %). Towards grazing incidence the source is split into sub-cones (facet._source_parts;
    unsplit, 85 deg read 8-10 % low): 75 deg 0.25 %, 85 deg 0.6 % (asserted 1 and 2 %, the
    issue's bound at 85). The conductor with the seed's Fresnel-only weight exercises the
    complex Fresnel derivative. The numba-free "lean" backend moves each facet to the centre
    of its slope histogram cell (half a 1e-3 bin at most), which on 4096 facets of rms slope
    0.2 leaves up to 0.36 % more (measured at normal incidence): its bounds are 0.2 % wider.
    """
    surf = Surface.from_heightmap(gaussian_factory(64, slope_rms, seed=3), slope_method="central")
    mx, my, mz = surf.normals
    model = FacetModel(surf, n=n, weighting=weighting, backend=backend)  # type: ignore[arg-type]
    nc = complex(n)
    for ti, tol0 in ((0.0, 0.003), (45.0, 0.007), (60.0, 0.01), (75.0, 0.01), (85.0, 0.02)):
        tol = tol0 + (0.002 if backend == "lean" else 0.0)
        tr = ti + np.array([-10.0, -5.0, 0.0, 5.0, 10.0])
        tr = tr[tr < 89.0]
        src, w_src = sample_aperture(Cone(6.0), ti, 0.0, n=12)
        dets = np.stack([-np.sin(np.radians(tr)), 0 * tr, np.cos(np.radians(tr))], axis=-1)
        acc = np.zeros(tr.size)
        for wi, w_s in zip(src, w_src, strict=True):
            ox, oy, oz, w = K.reflect_numpy(mx, my, mz, wi, nc.real, nc.imag, weighting == "seed")
            inside = np.stack([ox, oy, oz], axis=-1) @ dets.T >= math.cos(math.radians(3.0))
            acc += w_s * (w @ inside)
        brute = 100 * acc / (w_src.sum() * mx.size)
        np.testing.assert_allclose(model.luminance_pct(ti, tr), brute, rtol=tol)
        two = [model.reflected_fraction(ti, t, Cone(6.0), Cone(6.0)) for t in tr[[1, 2]]]
        np.testing.assert_allclose(100 * np.array(two), brute[[1, 2]], rtol=tol)


def test_source_reaching_the_horizon_needs_masking(gauss_surface_256: Surface) -> None:
    """theta_i + source half width >= 90 deg: without masking the weight of a source
    direction diverges at the horizon (brute force: 450-550 % of a mirror at 89 deg), so
    the unmasked model refuses with a clear error; a rectangle is never clipped."""
    m = FacetModel(gauss_surface_256)
    with pytest.raises(ValueError, match=r"cone of half width 3 deg at theta_i_deg = 87.*masking"):
        m.luminance_pct(87.0, [80.0, 85.0, 88.0])
    with pytest.raises(ValueError, match="horizon"):
        m.reflected_fraction(88.0, 85.0, Cone(6.0), Cone(6.0))
    masked = FacetModel(gauss_surface_256, masking=True)
    with pytest.raises(ValueError, match=r"rectangle of half width 0\.375"):
        masked.luminance_pct(89.7, [85.0], source=ISO2813_SOURCE, detector=ISO2813_RECEPTOR[85])
    lum = m.luminance_pct(86.9, [80.0, 85.0, 88.0])  # just inside: positive readings
    assert np.all(lum > 0)
    assert np.all(masked.luminance_pct(89.0, [80.0, 85.0, 88.0]) > 0)


def _masked_brute_force(
    model: FacetModel, ti: float, tr: NDArray[np.float64], rings: int
) -> NDArray[np.float64]:
    """Mihalik eq. 15 with masking by brute force: the 6 deg source cone sampled on its
    part above the horizon (the rest misses the sample), every facet reflected with its
    weight and the height-correlated Smith G2 of that source direction and its own mirror
    direction, counted inside the 6 deg receptor; over the whole cone's solid angle."""
    surf = model.surface
    src, w_src = sample_aperture(Cone(6.0), ti, 0.0, n=rings)
    dets = np.stack([-np.sin(np.radians(tr)), 0 * tr, np.cos(np.radians(tr))], axis=-1)
    acc = np.zeros(tr.size)
    for wi, w_s in zip(src, w_src, strict=True):
        if wi[2] <= 0.0:
            continue
        ox, oy, oz, w = K.reflect_numpy(surf.p, surf.q, np.empty(0), wi, 1.55, 0.0, False)
        wo = np.stack([ox, oy, oz], axis=-1)
        g2 = model.masking_g2(wi[None, :], wo)
        inside = wo @ dets.T >= math.cos(math.radians(3.0))
        acc += w_s * ((w * g2) @ inside)
    out: NDArray[np.float64] = 100 * acc / (w_src.sum() * surf.n_facets)
    return out


@pytest.mark.parametrize("slope_rms", [0.05, 0.2])
def test_masked_cones_up_to_89_deg_match_brute_force(
    gaussian_factory: Callable[..., HeightMap], slope_rms: float
) -> None:
    """Grazing goniometer cones with masking (the default of the CLI and the lab): the source
    is split into 169 sub-cones and clipped at the horizon from theta_i + 3 >= 90, and G2 is
    taken where the light leaves. Against brute force with per-facet G2 (64 x 64 maps, 4681
    source directions, specular -10..+2 deg): measured within 0.31 % at 85, 87, 88 and 89
    deg, 0.74 % at 86 (the last unclipped angle); asserted 1 % with 721 directions (issue 15
    asks 2 % at 85; G2 at the receptor's centre read 2.6 % high there)."""
    surf = Surface.from_heightmap(gaussian_factory(64, slope_rms, seed=3), slope_method="central")
    model = FacetModel(surf, masking=True)
    for ti in (85.0, 87.0, 89.0):
        tr = ti + np.array([-10.0, -5.0, -2.0, 0.0])
        brute = _masked_brute_force(model, ti, tr, rings=16)
        np.testing.assert_allclose(model.luminance_pct(ti, tr), brute, rtol=0.01)
        one = 100 * model.reflected_fraction(ti, ti, Cone(6.0), Cone(6.0))
        assert one == pytest.approx(brute[-1], rel=0.01)


def test_a_mirror_at_89_deg_reads_the_part_of_the_beam_above_the_horizon() -> None:
    """Flat mirror, equal 6 deg cones at 89 deg: every source direction above the horizon
    is mirrored into the receptor, so the reading is ``100 int F(cos theta) dOmega`` over
    the part of the source cone above the horizon, over the whole cone's solid angle (a fine
    quadrature of that cap). The sub-caps of the split blur the receptor's rim: asserted
    1.5 %."""
    mirror = FacetModel(Surface(p=np.zeros(100), q=np.zeros(100)), masking=True)
    src, w = sample_aperture(Cone(6.0), 89.0, 0.0, n=200)
    up = src[:, 2] > 0
    want = 100 * float(np.sum(fresnel_dielectric(src[up, 2], 1.55) * w[up])) / float(w.sum())
    assert 0.0 < want < 100 * 0.6  # less than 60 % of the beam reaches the sample
    got = float(mirror.luminance_pct(89.0, [89.0])[0])
    assert got == pytest.approx(want, rel=0.015)


def test_rect_luminance_grid_matches_exact_per_facet_rect(gauss_surface_256: Surface) -> None:
    """ISO 2813 rectangles through the luminance grid vs the exact per-facet overlap."""
    m = FacetModel(gauss_surface_256)
    for t in (20, 60, 85):
        tr = np.array([t - 1.0, float(t), t + 1.5])
        grid = m.luminance_pct(t, tr, source=ISO2813_SOURCE, detector=ISO2813_RECEPTOR[t])
        exact = np.array(
            [100 * m.reflected_fraction(t, x, ISO2813_SOURCE, ISO2813_RECEPTOR[t]) for x in tr]
        )
        np.testing.assert_allclose(grid, exact, rtol=5e-3, atol=1e-4 * exact.max())


def test_slope_density_equals_the_dense_histogram_at_bin_centres(
    gauss_surface_256: Surface,
) -> None:
    h = slope_histogram(gauss_surface_256.p, gauss_surface_256.q, bin_size=0.01)
    m = FacetModel(gauss_surface_256, slope_bin=0.01)
    pc = 0.5 * (h.p_edges[1:] + h.p_edges[:-1])
    qc = 0.5 * (h.q_edges[1:] + h.q_edges[:-1])
    pp, qq = np.meshgrid(pc, qc, indexing="ij")
    np.testing.assert_allclose(m.slope_density(pp, qq), h.density, rtol=1e-9, atol=1e-9)


def test_point_source_counts_facets_inside_the_detector(gauss_surface_256: Surface) -> None:
    mx, my, mz = gauss_surface_256.normals
    ox, oy, oz, w = K.reflect_numpy(mx, my, mz, _wi(30.0), 1.55, 0.0, False)
    m = FacetModel(gauss_surface_256)
    tr = np.array([26.0, 30.0, 33.0])
    expected = np.empty(3)
    for k, t in enumerate(tr):
        d = np.array([-math.sin(math.radians(t)), 0.0, math.cos(math.radians(t))])
        inside = ox * d[0] + oy * d[1] + oz * d[2] >= math.cos(math.radians(3.0))
        expected[k] = 100 * float(np.sum(w[inside])) / mx.size
        assert 100 * m.reflected_fraction(30.0, t, Cone(0.0), Cone(6.0)) == pytest.approx(
            expected[k], rel=1e-12
        )
    # through the grid (3 angles): the detector edge is smeared over one 0.05 deg node
    np.testing.assert_allclose(m.luminance_pct(30.0, tr, source=Cone(0.0)), expected, rtol=0.01)


def test_point_detector_reads_flux_per_steradian(gauss_surface_256: Surface) -> None:
    m = FacetModel(gauss_surface_256, slope_bin=0.02)
    f = m.brdf_point(40.0, 42.0)
    cos_r = math.cos(math.radians(42.0))
    got = m.luminance_pct(40.0, [42.0], source=Cone(0.0), detector=Cone(0.0))
    assert float(got[0]) == pytest.approx(100 * f * cos_r, rel=1e-12)
    # continuity: a tiny source cone gives nearly the same
    small = m.luminance_pct(40.0, [42.0], source=Cone(0.02), detector=Cone(0.0))
    assert float(small[0]) == pytest.approx(100 * f * cos_r, rel=0.05)


# --------------------------------------------------------------------------- reciprocity, albedo
@pytest.mark.parametrize("masking", [False, True])
def test_reciprocity(gauss_surface_256: Surface, masking: bool) -> None:
    m = FacetModel(gauss_surface_256, slope_bin=0.01, masking=masking)
    rng = np.random.default_rng(4)
    th_i, th_o = np.radians(rng.uniform(0, 80, 300)), np.radians(rng.uniform(0, 80, 300))
    ph_i = rng.uniform(0, 2 * np.pi, 300)
    ph_o = ph_i + np.pi + rng.normal(0, 0.15, 300)  # near the specular half-plane
    wi = np.stack([np.sin(th_i) * np.cos(ph_i), np.sin(th_i) * np.sin(ph_i), np.cos(th_i)], axis=-1)
    wo = np.stack([np.sin(th_o) * np.cos(ph_o), np.sin(th_o) * np.sin(ph_o), np.cos(th_o)], axis=-1)
    f1, f2 = m.brdf(wi, wo), m.brdf(wo, wi)
    assert np.count_nonzero(f1) > 20
    np.testing.assert_allclose(f1, f2, rtol=1e-12, atol=0)


@pytest.mark.parametrize("slope_rms", [0.05, 0.5])
def test_albedo_at_most_one(gaussian_factory: Callable[..., HeightMap], slope_rms: float) -> None:
    """Masked: albedo <= 1 at every incidence, because (1/N) sum_k c_k+/(m_z cos ti) is
    exactly 1 + Lambda(wi) (Smith normalisation) and G2 <= 1/(1 + Lambda(wi)). Unmasked:
    <= 1 while no facet faces away from the lamp; at grazing incidence on rough surfaces
    the unshadowed model over-counts the lit facets (documented in FacetModel)."""
    surf = Surface.from_heightmap(gaussian_factory(128, slope_rms, seed=9), slope_method="central")
    for n in (1.55, 0.27 + 3.41j):
        masked = FacetModel(surf, n=n, masking=True)
        for ti in (0.0, 30.0, 60.0, 80.0, 89.0):
            assert 0.0 < masked.brdf_hemisphere(ti, bin_deg=1.0).albedo <= 1.0
        plain = FacetModel(surf, n=n)
        for ti in (0.0, 30.0, 60.0, 80.0):
            t = math.radians(ti)
            facing_away = np.mean(-math.sin(t) * surf.p + math.cos(t) <= 0)
            if facing_away == 0.0:
                assert 0.0 < plain.brdf_hemisphere(ti, bin_deg=1.0).albedo <= 1.0
    # the albedo of a conductor mirror is its Fresnel reflectance, below 1 up to grazing
    mirror = FacetModel(Surface(p=np.zeros(4), q=np.zeros(4)), n=0.27 + 3.41j)
    assert mirror.brdf_hemisphere(89.0).albedo == pytest.approx(
        float(fresnel(math.cos(math.radians(89.0)), 0.27 + 3.41j))
    )


def test_masking_is_neutral_on_a_mirror_and_only_removes_light(
    flat_surface: Surface, gauss_surface_256: Surface
) -> None:
    """Lambda = 0 for a flat surface (G2 = 1); on a rough one G2 <= 1 everywhere, and most
    so at grazing angles."""
    flat = FacetModel(flat_surface, n=1.567, masking=True)
    assert flat.gloss() == pytest.approx({20: 100.0, 60: 100.0, 85: 100.0}, rel=1e-12)
    plain = FacetModel(gauss_surface_256)
    masked = FacetModel(gauss_surface_256, masking=True)
    tr = np.arange(60.0, 86.0, 1.0)
    lp, lm = plain.luminance_pct(75.0, tr), masked.luminance_pct(75.0, tr)
    assert np.all(lm <= lp) and lm.max() > 0
    g_plain, g_masked = plain.gloss(), masked.gloss()
    loss = {t: 1 - g_masked[t] / g_plain[t] for t in (20, 60, 85)}
    assert 0 <= loss[20] < loss[60] < loss[85]


def test_smith_lambda_of_gaussian_slopes_is_beckmann(gauss_surface_1024: Surface) -> None:
    """Lambda from the measured slopes vs the exact Beckmann Smith Lambda (a = sqrt2 sigma)."""
    sx, _ = _sigma(gauss_surface_1024)
    a = math.sqrt(2) * sx
    m = FacetModel(gauss_surface_1024, masking=True)
    for th_deg in (70.0, 80.0, 85.0):
        th = math.radians(th_deg)
        u = 1 / (a * math.tan(th))
        lam = 0.5 * (math.erf(u) - 1) + math.exp(-u * u) / (2 * u * math.sqrt(math.pi))
        for ph in (0.0, 1.0, 3.0):
            w = np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])
            got = float(m.smith_lambda(w))
            assert got == pytest.approx(lam, rel=0.05, abs=1e-4)
    assert float(m.smith_lambda(np.array([0.0, 0.0, 1.0]))) == 0.0


# --------------------------------------------------------------------------- rougher surfaces
def test_rougher_means_lower_peak_wider_fwhm_lower_gloss(
    gaussian_factory: Callable[..., HeightMap],
) -> None:
    tr = np.arange(0.0, 71.0, 0.5)
    results = []
    for s in (0.01, 0.03, 0.08):
        m = FacetModel(
            Surface.from_heightmap(gaussian_factory(256, s, seed=5), slope_method="central")
        )
        pm = peak_metrics(tr, m.luminance_pct(45.0, tr))
        results.append((pm.amplitude, pm.fwhm_deg, m.gloss((60,))[60]))
    amps, fwhms, g60s = zip(*results, strict=True)
    assert amps[0] > amps[1] > amps[2]
    assert fwhms[0] < fwhms[1] < fwhms[2]
    assert g60s[0] > g60s[1] > g60s[2]


# --------------------------------------------------------------------------- geometry / y sign
@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_plane_tilted_in_plus_y_reflects_towards_minus_y(backend: str) -> None:
    """z = b y (rows are y): m = (0, -b, 1)/sqrt(1+b^2), so
    wo = (-sin ti, -2 b cos ti/(1+b^2), cos ti (1-b^2)/(1+b^2)): the peak goes to -y.
    With the seed's eq. 4 (+dz/dy) it would go to +y."""
    b, ti = 0.05, 30.0
    i = np.arange(40)[:, None] * np.ones((1, 40))
    hm = HeightMap(z_um=b * i * 1.0, dx_um=1.0, dy_um=1.0, source="tilt-y")
    surf = Surface.from_heightmap(hm, level=False)
    m = FacetModel(surf, backend=backend)  # type: ignore[arg-type]
    t = math.radians(ti)
    wo = np.array(
        [-math.sin(t), -2 * b * math.cos(t) / (1 + b * b), math.cos(t) * (1 - b * b) / (1 + b * b)]
    )
    h = m.brdf_hemisphere(ti, bin_deg=0.5)
    a, c = np.unravel_index(int(np.argmax(h.f_sr)), h.f_sr.shape)
    th_o = math.degrees(math.acos(wo[2]))
    ph_o = math.degrees(math.atan2(wo[1], wo[0])) % 360
    assert h.theta_edges_deg[a] <= th_o < h.theta_edges_deg[a + 1]
    assert h.phi_edges_deg[c] <= ph_o < h.phi_edges_deg[c + 1]
    assert 180.0 < ph_o < 270.0  # the -y side
    # all the reflected flux is in that one bin
    proj = 0.5 * (
        math.sin(math.radians(h.theta_edges_deg[a + 1])) ** 2
        - math.sin(math.radians(h.theta_edges_deg[a])) ** 2
    )
    assert h.f_sr[a, c] * proj * math.radians(0.5) == pytest.approx(h.albedo, rel=1e-12)
    # the in-plane detector at the mirror angle sees it only partly (out of plane by beta)
    beta = math.degrees(math.asin(wo[1]))
    assert beta == pytest.approx(-2 * math.degrees(math.atan(b)) * math.cos(t), abs=0.05)


# --------------------------------------------------------------------------- protocol, errors
def test_facet_model_is_a_reflectance_model(flat_surface: Surface) -> None:
    assert isinstance(FacetModel(flat_surface), ReflectanceModel)


def test_bad_input_gives_clear_errors(flat_surface: Surface) -> None:
    m = FacetModel(flat_surface)
    with pytest.raises(ValueError, match="both be Cone or both be Rect"):
        m.reflected_fraction(60, 60, Cone(6), Rect(4.4, 11.7))
    with pytest.raises(ValueError, match="bin_deg must divide 90"):
        m.brdf_hemisphere(45.0, bin_deg=0.7)
    with pytest.raises(ValueError, match="no ISO 2813 geometry at 45"):
        m.gloss((45,))
    with pytest.raises(ValueError, match="theta_i_deg"):
        m.luminance_pct(95.0, [10.0])
    with pytest.raises(ValueError, match="theta_r_deg"):
        m.luminance_pct(45.0, [10.0, 91.0])
    with pytest.raises(ValueError, match="refractive index"):
        FacetModel(flat_surface, n=-1.0)
    with pytest.raises(ValueError, match="weighting"):
        FacetModel(flat_surface, weighting="fresnel")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="Surface"):
        FacetModel(np.zeros(3))  # type: ignore[arg-type]


def test_point_brdf_kernel_density_matches_beckmann_on_a_rough_gaussian_map(
    gaussian_factory: Callable[..., HeightMap],
) -> None:
    """Issue 15 item 3: the default P22 (Gaussian kernel density, Scott's bandwidth) of a
    1024^2 Gaussian map of rms slope 0.14 gives the analytic Gaussian (Beckmann) facet BRDF
    within 5 % wherever it is above 10 % of its peak and within 15 % above 1 %, in plane
    and out of plane. The 1e-3 histogram misses by up to ~50 % there."""
    surf = Surface.from_heightmap(gaussian_factory(1024, 0.14, seed=11), slope_method="central")
    sx, sy = _sigma(surf)
    ana = _gaussian_facet_brdf(sx, sy)
    m = FacetModel(surf)
    hist = FacetModel(surf, slope_bin=1e-3)
    worst_hist = 0.0
    for ti in (20.0, 45.0, 60.0):
        tr = np.arange(-85.0, 85.01, 0.5)
        wo = np.stack([-np.sin(np.radians(tr)), 0 * tr, np.cos(np.radians(tr))], axis=-1)
        # a few out-of-plane directions around the lobe
        th, ph = np.meshgrid(np.radians([ti - 5, ti, ti + 5]), np.radians([172.0, 186.0, 200.0]))
        wo_oop = np.stack(
            [np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1
        ).reshape(-1, 3)
        wo_all = np.concatenate([wo, wo_oop])
        fa = ana(_wi(ti), wo_all)
        peak = fa.max()
        r = np.abs(m.brdf(_wi(ti), wo_all) / np.where(fa > 0, fa, 1.0) - 1)
        assert np.all(r[fa > 0.1 * peak] < 0.05), (ti, r[fa > 0.1 * peak].max())
        assert np.all(r[fa > 0.01 * peak] < 0.15), (ti, r[fa > 0.01 * peak].max())
        assert np.any(fa[len(tr) :] > 0.1 * peak)  # the out-of-plane points are tested
        rh = np.abs(hist.brdf(_wi(ti), wo_all) / np.where(fa > 0, fa, 1.0) - 1)
        worst_hist = max(worst_hist, float(rh[fa > 0.01 * peak].max()))
        # brdf_point (the --point path) uses the same density: wo_oop[4] is (ti, 186 deg)
        assert m.brdf_point(ti, ti, 186.0) == pytest.approx(float(fa[len(tr) + 4]), rel=0.05)
    assert worst_hist > 0.15  # the old 1e-3 histogram fails the same bound


def test_gauss_legendre_rules_are_numpys_to_the_last_bit() -> None:
    """The cone table's 16-point rule is kept as literals (no numpy.polynomial import):
    the same doubles as numpy's leggauss, and other orders are numpy's own."""
    from numpy.polynomial.legendre import leggauss

    from goniolab.optics.facet_apertures import gauss_legendre

    for n in (16, 48, 5):
        x, w = gauss_legendre(n)
        want_x, want_w = leggauss(n)
        assert np.array_equal(x, want_x) and np.array_equal(w, want_w), n
    x, w = gauss_legendre(16)
    # an independent truth: the rule integrates x^30 exactly (2 / 31), and sums to 2
    assert float(np.sum(w * x**30)) == pytest.approx(2.0 / 31.0, rel=1e-13)
    assert float(np.sum(w)) == pytest.approx(2.0, rel=1e-15)
