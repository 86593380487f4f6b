"""Signal level from the instrument's own data, per-reading quality, the wire spectrum
(issue 21, items 2, 4 and 5), on the twin in-process and on the wire."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.profiles import load_stil_profile
from goniolab.cli import main
from goniolab.config import configs_dir
from goniolab.store import RunStore
from tests.scan.test_integration import lab_config


def realistic(tmp_path: Path, base: str, body: str = "red", name: str = "lab.toml") -> Path:
    """A shipped sim config with the realistic twin, an aligned session and ``body``."""
    cfg = lab_config(tmp_path, base=base, twin="realistic", name=name)
    text = cfg.read_text()
    text = text.replace('mode = "realistic"', f'mode = "realistic"\nbody = "{body}"', 1)
    for key in ("lamp_zero_range_deg", "detector_zero_range_deg", "sample_tilt_range_deg"):
        text = text.replace(f"# {key} = 0.5", f"{key} = 0.0")
    cfg.write_text(text)
    return cfg


def scan(cfg: Path, store: Path, *extra: str) -> tuple[int, list[object]]:
    code = main(["scan", "--config", str(cfg), "--time-scale", "0", "--json",
                 "--store", str(store), *extra])  # fmt: skip
    with RunStore(str(store)) as s:
        return code, list(s.points(s.list_runs()[0].id))


def test_the_level_profile_parses_the_signal_level() -> None:
    # the simulator's protocol (UNCONFIRMED for a real Ruby): the level rides on the Y line
    p = load_stil_profile(configs_dir() / "profiles" / "stil-ruby-level.toml")
    line = p.reply_measure[0].format(luminance_pct=12.3456, peak_fraction=0.421)
    assert line == "Y=12.3456 PEAK=0.4210"
    assert p.reply_measure[0].format(luminance_pct=1.0, peak_fraction=-1) == "Y=1.0000 PEAK=-1.0000"


@pytest.mark.wire
@pytest.mark.slow
def test_colour_over_the_wire_is_the_twins_spectrum(tmp_path: Path) -> None:
    # issue 21: over the wire the STIL built a grey spectrum from the luminance (solid red
    # a* 0.1 over the wire, 42.3 in-process); now the wire carries the twin's own spectrum
    # and its signal level, so auto-exposure works there too
    args = ("--theta-r", "20,30", "--repeats", "3")
    wire = realistic(tmp_path, "lab-sim-wire.toml", name="wire.toml")
    inproc = realistic(tmp_path, "lab-sim.toml", name="inproc.toml")
    code_w, pts_w = scan(wire, tmp_path / "w.sqlite", *args)
    code_i, pts_i = scan(inproc, tmp_path / "i.sqlite", *args)
    assert code_w == 0 and code_i == 0
    a_w = np.mean([p.colour["a"] for p in pts_w if p.index >= 0])  # type: ignore[attr-defined]
    a_i = np.mean([p.colour["a"] for p in pts_i if p.index >= 0])  # type: ignore[attr-defined]
    assert a_i > 30.0  # a red
    assert a_w == pytest.approx(a_i, abs=2.0)
    for p in pts_w:
        assert p.raw["peak_fraction"] is not None and p.raw["quality"] == "ok"  # type: ignore[attr-defined]
    # auto-exposure (the default) left the fixed 10 ms for these dark diffuse geometries
    assert {p.raw["exposure_us"] for p in pts_w} != {10_000}  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    "base", ["lab-sim.toml", pytest.param("lab-sim-wire.toml", marks=pytest.mark.wire)]
)
def test_a_saturated_mirror_reference_is_refused_not_scaled(
    tmp_path: Path, base: str, capsys: pytest.CaptureFixture[str]
) -> None:
    # issue 21: --mirror-reference at a fixed exposure over the wire gave a mirror level of
    # 13 % (clipped) and every reading 6x too high; the clipped readings are now flagged
    # and the reference refused, in-process and over the wire
    cfg = realistic(tmp_path, base, body="white")
    code, pts = scan(cfg, tmp_path / "s.sqlite", "--theta-r", "30", "--repeats", "1",
                     "--mirror-reference", "--no-auto-exposure")  # fmt: skip
    err = capsys.readouterr().err
    assert code != 0
    assert "every mirror reference reading is flagged (saturated)" in err
    mirror = [p for p in pts if p.index < 0]  # type: ignore[attr-defined]
    assert mirror and all(p.raw["quality"] == "saturated" for p in mirror)  # type: ignore[attr-defined]
    # the flag and the level are exported with the reading
    out = tmp_path / "run.csv"
    assert main(["runs", "export", "1", "--store", str(tmp_path / "s.sqlite"), "-o", str(out)]) == 0
    head, first = out.read_text().splitlines()[:2]
    cols = dict(zip(head.split(","), first.split(","), strict=True))
    assert cols["index"] == "-1" and cols["quality"] == "saturated"
    assert float(cols["peak_fraction"]) >= 0.999
    # with auto-exposure (the default) the same reference is read unclipped and used
    code, pts = scan(cfg, tmp_path / "t.sqlite", "--theta-r", "30", "--repeats", "1",
                     "--mirror-reference")  # fmt: skip
    assert code == 0
    ref = next(p for p in pts if p.index == 0).raw["reference"]  # type: ignore[attr-defined]
    assert ref["method"] == "spectral"
    # the mirror reads its certified ~89.8 % of a perfect mirror (stray light aside)
    assert ref["reference_luminance_pct"] == pytest.approx(ref["certified_luminance_pct"], rel=0.02)


def test_the_twins_stray_light_grows_with_the_flux() -> None:
    # noise-free chain (no shot/read noise, no flicker, no dark): a channel that receives
    # nothing reads the floor plus stray_rel x the mean light of the others
    from sim.instruments import SpectroChain

    chain = SpectroChain(read_noise_counts=0.0, dark_counts_per_s=0.0, flicker_pct=0.0,
                         electrons_per_count=1e9, full_scale_pct=100.0)  # fmt: skip
    rng = np.random.default_rng(0)
    dark = int(np.argmax(chain.gain()))  # the most sensitive channel stays unlit
    for level in (0.0, 0.2, 0.5):
        f = np.full(41, level)
        f[dark] = 0.0
        values, peak = chain.read(f, 10_000, rng)
        assert peak < 0.999
        want = chain.stray_pct + chain.stray_rel * 100 * level * 40 / 41
        # counts are whole numbers: ~650 per % in that channel
        assert values[dark] == pytest.approx(want, abs=1e-3)


def test_a_flagged_reading_is_shown_and_kept_off_the_live_curve() -> None:
    from goniolab.scan.events import PointMeasured
    from goniolab.tui.comparison import Comparison

    c = Comparison()
    kw = {"run_id": 1, "timestamp": 0.0, "theta_i_deg": 45.0, "theta_r_deg": 45.0,
          "measured_theta_i_deg": 45.0, "measured_theta_r_deg": 45.0}  # fmt: skip
    c.add_measured(PointMeasured(index=0, repeat=0, luminance_pct=3.0, quality="ok", **kw))
    c.add_measured(PointMeasured(index=0, repeat=1, luminance_pct=0.5, quality="saturated", **kw))
    assert c.readings == {0: [3.0]} and c.flagged == {"saturated": 1}
    from goniolab.commands.scan import point_detail

    bad = PointMeasured(index=0, repeat=1, luminance_pct=0.5, quality="saturated", **kw)
    assert point_detail(bad, None).endswith("[SATURATED]")


def test_the_twins_polarisation_sensitivity_weights_the_glass_s_and_p() -> None:
    # a detector answering 60 % to s- and 40 % to p-polarised light reads the black glass
    # at 60 deg as 0.6 R_s + 0.4 R_p (Fresnel, n = 1.567) where an insensitive one reads
    # the mean; the (unpolarising) Al mirror table reads the same either way
    import math

    from goniolab.optics.fresnel import fresnel_dielectric_sp
    from sim.instruments import SimSpectro, SpectroChain
    from sim.truth import FlatSpecimen

    r_s, r_p = (float(x) for x in fresnel_dielectric_sp(math.cos(math.radians(60.0)), 1.567))
    for w in (0.5, 0.6):
        spectro = SimSpectro(FlatSpecimen(n=1.567, name="black glass"), None, None, None,  # type: ignore[arg-type]
                             chain=SpectroChain(s_weight=w))  # fmt: skip
        f = spectro._spectral(60.0, 60.0)
        assert f == pytest.approx(np.full(41, w * r_s + (1 - w) * r_p), rel=1e-9)
        spectro.model = FlatSpecimen()
        mirror = spectro._spectral(60.0, 60.0)
        assert mirror == pytest.approx(FlatSpecimen().reflectance(60.0), rel=1e-9)


@pytest.mark.parametrize(("theta", "sigma"), [(0.0, 0.2), (60.0, 0.05), (80.0, 0.2), (85.0, 0.3)])
def test_smith_shadowing_matches_its_defining_integral(theta: float, sigma: float) -> None:
    # Smith (1967): Lambda = (1/mu) int_mu^inf (q - mu) p(q) dq, mu = cot(theta), p the
    # Gaussian slope density of rms sigma; G1 = 1 / (1 + Lambda). Integrated numerically.
    import math

    from scipy.integrate import quad

    from sim.truth import smith_shadowing

    g = float(smith_shadowing(theta, sigma))
    if theta == 0.0:
        assert g == 1.0
        return
    mu = 1.0 / math.tan(math.radians(theta))

    def p(q: float) -> float:
        return math.exp(-0.5 * (q / sigma) ** 2) / (sigma * math.sqrt(2 * math.pi))

    lam = quad(lambda q: (q - mu) * p(q), mu, math.inf)[0] / mu
    assert g == pytest.approx(1.0 / (1.0 + lam), rel=1e-9)
    if theta == 80.0:
        assert g < 0.9  # a rough coat shadows itself at grazing incidence
