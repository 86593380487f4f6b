"""The default prediction path (``--model auto``, masking on) is lean in every regime (issue 26).

- ``auto`` decides from the map's statistics (numpy) before it builds a model: a map it
  sends to the facet model imports no wave-optics module, no numba and no scipy; one it
  sends to the wave models imports no numba (their sums run on numpy, their FFTs on scipy's
  pocketfft loaded without scipy) and forms no facet slopes;
- the facet model of ``auto`` runs, with masking, on the slope-histogram cells: held to an
  analytic truth here (a Gaussian slope distribution: the Beckmann facet BRDF with the
  closed-form Smith masking, integrated over the goniometer's cones) and to the per-facet
  kernels in test_lean_backend.py.

Each probe runs in a fresh interpreter and looks at ``sys.modules``; no timing is asserted
(``bench/bench_lean.py`` measures it).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.special import erf

from goniolab.optics.apertures import Cone, integrate_brdf
from goniolab.optics.facet import FacetModel
from goniolab.optics.fresnel import fresnel
from goniolab.optics.surface import Surface

ROOT = Path(__file__).resolve().parents[2]


def _gaussian_map(path: Path, n: int, sq_um: float, corr_um: float, step_um: float) -> str:
    """Periodic Gaussian surface of rms height ``sq_um``, Gaussian ACF of length ``corr_um``."""
    rng = np.random.default_rng(3)
    f = np.fft.fftfreq(n, step_um)
    filt = np.exp(-0.5 * (math.pi * corr_um) ** 2 * (f[:, None] ** 2 + f[None, :] ** 2))
    z = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * filt))
    z *= sq_um / z.std()
    np.save(path, z)
    path.with_name(path.name + ".json").write_text(json.dumps({"dx_um": step_um, "dy_um": step_um}))
    return str(path)


def _probe(argv: list[str]) -> tuple[dict[str, object], set[str]]:
    """Run ``goniolab`` with ``argv`` in a fresh interpreter: its JSON output and the modules
    it loaded."""
    code = (
        "import contextlib, io, json, sys\n"
        "from goniolab.cli import main\n"
        "buf = io.StringIO()\n"
        "with contextlib.redirect_stdout(buf):\n"
        f"    rc = main({argv!r})\n"
        "assert rc == 0, rc\n"
        "print(json.dumps({'out': json.loads(buf.getvalue()), 'mods': sorted(sys.modules)}))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    return result["out"], set(result["mods"])


def _top(mods: set[str]) -> set[str]:
    return {m.split(".")[0] for m in mods}


def test_auto_on_a_rough_map_picks_facet_and_imports_no_numba_or_scipy(
    tmp_path: Path,
) -> None:
    # Sq 1 um at 45 deg and 550 nm: g = (4 pi 1 cos45 / 0.55)^2 = 261 >= 20 (facet)
    mp = _gaussian_map(tmp_path / "rough.npy", 192, 1.0, 12.0, 1.0)
    out, mods = _probe(["predict", "brdf", mp, "--theta-i", "45", "--theta-r", "0:70:5", "--json"])
    assert isinstance(out["model"], dict)
    assert out["model"]["auto"] == "facet", out["model"]
    assert set(out["models"]) == {"facet"}  # type: ignore[arg-type]
    assert "goniolab.optics.facet" in mods  # the probe really predicted
    assert not {"numba", "scipy", "llvmlite"} & _top(mods), sorted(_top(mods))
    # neither the compiled kernels nor the facet model's per-pixel ones (the face still
    # touches model.kirchhoff to set its progress display, which imports that module)
    assert not {"goniolab.optics._cell_kernels_numba", "goniolab.optics._kernels"} & mods


def test_auto_on_a_smooth_map_runs_the_wave_models_without_numba_or_facet_slopes(
    tmp_path: Path,
) -> None:
    # Sq 20 nm, l 2 um, 0.5 um steps: g = 0.09-0.28 at 20-60 deg (Rayleigh-Rice, Kirchhoff)
    mp = _gaussian_map(tmp_path / "smooth.npy", 256, 0.02, 2.0, 0.5)
    out, mods = _probe(["predict", "gloss", mp, "--json"])
    models = out["model"]
    assert isinstance(models, dict)
    assert {models["G20"], models["G60"], models["G85"]} <= {"kirchhoff", "rayleigh-rice"}
    assert "kirchhoff" in {models["G20"], models["G60"]}, models
    assert "goniolab.optics.kirchhoff" in mods
    assert not {"numba", "llvmlite"} & _top(mods), sorted(_top(mods))
    assert "goniolab.optics._cell_kernels_numba" not in mods


def test_the_numba_sums_stay_choosable_for_the_wave_models() -> None:
    """``backend="numba"`` still selects the compiled sums, which load numba on first use."""
    code = (
        "import json, sys, numpy as np\n"
        "from goniolab.optics.heightmap import HeightMap\n"
        "from goniolab.optics.kirchhoff import KirchhoffModel\n"
        "z = 0.02 * np.sin(np.arange(64)[:, None] / 3.0) * np.cos(np.arange(64)[None, :] / 4.0)\n"
        "hm = HeightMap(z_um=z, dx_um=0.5, dy_um=0.5)\n"
        "before = 'numba' in sys.modules\n"
        "a = KirchhoffModel(hm, backend='numpy').luminance_pct(30.0, [30.0, 35.0])\n"
        "mid = 'numba' in sys.modules\n"
        "b = KirchhoffModel(hm, backend='numba').luminance_pct(30.0, [30.0, 35.0])\n"
        "print(json.dumps([before, mid, 'numba' in sys.modules, list(a), list(b)]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    before, mid, after, a, b = json.loads(done.stdout.strip().splitlines()[-1])
    assert (before, mid, after) == (False, False, True)
    np.testing.assert_allclose(b, a, rtol=1e-9)


# ------------------------------------------------------------------ analytic truth
def _beckmann_lambda(cos_t: np.ndarray, sigma: float) -> np.ndarray:
    """Smith Lambda of an isotropic Gaussian slope distribution of per-axis rms ``sigma``
    (Walter et al. 2007, eq. 27 with alpha_b = sqrt(2) sigma; Heitz 2014, eq. 72):
    ``(erf(a) - 1)/2 + exp(-a^2)/(2 a sqrt(pi))``, ``a = cot t / (sqrt 2 sigma)``."""
    c = np.clip(cos_t, 1e-12, 1.0)
    a = c / np.sqrt(1.0 - c * c + 1e-300) / (math.sqrt(2.0) * sigma)
    return 0.5 * (erf(a) - 1.0) + np.exp(-a * a) / (2.0 * a * math.sqrt(math.pi))


def _beckmann_smith_brdf(sigma: float, n: float):  # type: ignore[no-untyped-def]
    """The facet BRDF of Gaussian slopes, ``F P22 G2 / (4 cos ti cos to cos^4 th)``, with
    ``P22 = exp(-(p^2 + q^2)/(2 sigma^2)) / (2 pi sigma^2)`` and the height-correlated Smith
    ``G2 = 1 / (1 + Lambda(wi) + Lambda(wo))`` (Heitz 2014, eq. 99): closed form."""

    def f(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        wi, wo = np.broadcast_arrays(wi, wo)
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        hz = h[..., 2]
        p, q = -h[..., 0] / hz, -h[..., 1] / hz
        p22 = np.exp(-(p * p + q * q) / (2 * sigma**2)) / (2 * math.pi * sigma**2)
        g2 = 1.0 / (1.0 + _beckmann_lambda(wi[..., 2], sigma) + _beckmann_lambda(wo[..., 2], sigma))
        ci = np.clip(np.sum(wi * h, axis=-1), 0.0, 1.0)
        out = fresnel(ci, n) * p22 * g2 / (4 * wi[..., 2] * wo[..., 2] * hz**4)
        return np.where((wi[..., 2] > 0) & (wo[..., 2] > 0), out, 0.0)

    return f


@pytest.mark.parametrize(("sigma", "theta_i"), [(0.1, 30.0), (0.1, 60.0), (0.25, 45.0)])
def test_masked_facet_curve_on_slope_cells_equals_beckmann_with_smith_masking(
    sigma: float, theta_i: float
) -> None:
    """2**20 facets with independent Gaussian slopes (per-axis rms ``sigma``): the lean
    (slope-cell) goniometer curve with masking against the closed-form Beckmann BRDF with
    Smith masking, integrated over the same 6 deg cones (:func:`integrate_brdf`).

    The binning error is the cells': each facet moves by at most half a 1e-3 bin (its
    mirror direction by 0.06 deg against 6 deg cones), measured here below 1.5e-4 of the
    peak against the per-facet path (the numpy twins of the kernels over every facet;
    asserted 2e-3, as test_lean_backend.py does over rms slopes 0.003-0.3). Against the
    closed form, 3 % of the peak (measured 2.5 %, at sigma 0.25 and 62 deg; the per-facet
    path is off by the same): the model's Lambda is tabulated from a 2**17-facet subsample
    on a 0.5 x 5 deg grid, the cone response neglects its second order (0.5 % at 45 deg,
    test_facet.py) and 2**20 facets carry about 1 % of sampling noise per cone."""
    rng = np.random.default_rng(11)
    m = 1 << 20
    surf = Surface(
        p=rng.normal(0.0, sigma, m), q=rng.normal(0.0, sigma, m), dx_um=1.0, dy_um=1.0,
        source=f"gaussian slopes {sigma}",
    )  # fmt: skip
    model = FacetModel(surf, n=1.5, masking=True, backend="lean")
    tr = np.arange(0.0, 80.0, 2.5)
    tr = tr[tr < 88.0 - 3.0]
    got = model.luminance_pct(theta_i, tr, source=Cone(6.0), detector=Cone(6.0))
    brdf = _beckmann_smith_brdf(sigma, 1.5)
    want = np.array(
        [100.0 * integrate_brdf(brdf, theta_i, float(t), Cone(6.0), Cone(6.0)) for t in tr]
    )
    peak = float(want.max())
    per_facet = FacetModel(surf, n=1.5, masking=True, backend="numpy").luminance_pct(
        theta_i, tr, source=Cone(6.0), detector=Cone(6.0)
    )
    np.testing.assert_allclose(got, per_facet, atol=2e-3 * float(per_facet.max()))
    assert abs(float(got.max()) - peak) <= 0.03 * peak
    np.testing.assert_allclose(got, want, atol=0.03 * peak)
    # and the measured Smith Lambda the model uses is the closed form's
    t = np.radians(np.array([30.0, 60.0, 75.0]))
    w = np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], axis=-1)
    np.testing.assert_allclose(
        model.smith_lambda(w), _beckmann_lambda(np.cos(t), sigma), rtol=0.03, atol=1e-3
    )
