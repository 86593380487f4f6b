"""The realistic twin's instruments: the spectro's detector chain, backlash, the
glossmeter's drift, the per-session misalignments and the [sim.twin] config."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from drivers.timing import SimClock
from goniolab.config import ConfigError, configs_dir, load_lab_config
from goniolab.lab_wiring import draw_session
from sim.instruments import (
    GlossDrift,
    SimAxis,
    SimGlossmeter,
    SpectroChain,
    detector_response,
    lamp_spectrum,
)
from sim.motion import SimMotor
from sim.truth import SPECTRUM_WAVELENGTHS_NM, FlatSpecimen
from tests.twin_configs import ideal

N_WL = len(SPECTRUM_WAVELENGTHS_NM)


def test_halogen_lamp_and_silicon_detector_shapes() -> None:
    wl = np.asarray(SPECTRUM_WAVELENGTHS_NM)
    halogen = lamp_spectrum("halogen")
    # Planck at 3000 K: radiance ratio 700 nm / 450 nm = (450/700)^5 e^(c2/450T)-1 / ...
    c2 = 1.4388e7
    ratio = (450.0 / 700.0) ** 5 * math.expm1(c2 / (450 * 3000)) / math.expm1(c2 / (700 * 3000))
    i450, i700 = int(np.argmin(abs(wl - 450))), int(np.argmin(abs(wl - 700)))
    assert halogen[i700] / halogen[i450] == pytest.approx(ratio, rel=1e-9)
    led = lamp_spectrum("led")
    assert wl[int(np.argmax(led))] == 450.0  # the blue die
    assert detector_response()[i450] < 0.6 < detector_response()[int(np.argmin(abs(wl - 650)))]


def test_spectro_chain_is_unbiased_below_saturation_with_shot_noise_vs_exposure() -> None:
    chain = SpectroChain(
        stray_pct=0.0, flicker_pct=0.0, read_noise_counts=0.0, dark_counts_per_s=0.0
    )
    rng = np.random.default_rng(1)
    frac = np.full(N_WL, 1e-3)  # 0.1 % of the incident flux in every channel
    gain = chain.gain()
    peak = int(np.argmax(gain))
    for exposure, n in ((10_000, 400), (1_000, 400)):
        vals = np.array([chain.read(frac, exposure, rng)[0] for _ in range(n)])
        assert vals[:, peak].mean() == pytest.approx(0.1, rel=0.01)
        # shot noise only: counts N = 0.1 g t/10ms per pixel, P pixels per channel,
        # electrons 2NP, sigma(value) = 0.1/sqrt(2NP)
        counts = 0.1 * gain[peak] * exposure / 10_000 * chain.pixels_per_channel
        assert vals[:, peak].std() == pytest.approx(0.1 / math.sqrt(2 * counts), rel=0.15)
    # the blue end gets fewer counts (halogen x silicon), so it is noisier
    vals = np.array([chain.read(frac, 10_000, rng)[0] for _ in range(200)])
    assert vals[:, 0].std() > 3 * vals[:, peak].std()


def test_spectro_chain_saturates_and_reports_it() -> None:
    chain = SpectroChain(full_scale_pct=5.0, flicker_pct=0.0)
    rng = np.random.default_rng(2)
    frac = np.full(N_WL, 0.08)  # an 8 % specular peak, above the 5 % full scale at 10 ms
    values, peak = chain.read(frac, 10_000, rng)
    strongest = int(np.argmax(chain.gain()))
    # the strongest channels clip at the full well: they read the full scale, not 8 %;
    # the weak blue end is still linear
    assert peak == 1.0 and values[strongest] == pytest.approx(5.0, rel=0.01)
    assert values[0] == pytest.approx(8.0, rel=0.05)
    values, peak = chain.read(frac, 5_000, rng)  # half the exposure: 8 % < 10 % full scale
    assert peak < 1.0 and float(np.median(values)) == pytest.approx(8.0, rel=0.02)


def test_dark_current_and_stray_light_floor() -> None:
    chain = SpectroChain(flicker_pct=0.0, stray_pct=0.01, dark_counts_per_s=2000.0)
    rng = np.random.default_rng(3)
    vals = np.array([chain.read(np.zeros(N_WL), 50_000, rng)[0] for _ in range(300)])
    peak = int(np.argmax(chain.gain()))
    # the dark reference is subtracted (no offset), the stray light is not
    assert vals[:, peak].mean() == pytest.approx(0.01, rel=0.05)


def make_axis(backlash: float) -> SimAxis:
    clock = SimClock(0.0)
    motor = SimMotor(
        "lamp", speed_deg_s=20, accel_deg_s2=40, soft_limits_deg=(0, 85), homed=True, start_deg=45
    )
    return SimAxis("lamp", motor, clock, backlash_deg=backlash)


async def test_backlash_is_invisible_to_the_encoder_and_seen_by_the_optics() -> None:
    axis = make_axis(0.04)
    await axis.connect()
    await axis.move_to(50.0)
    assert await axis.wait_in_position(30.0) == pytest.approx(50.0)
    assert axis.actual_deg() == pytest.approx(50.0 - 0.02)
    await axis.move_to(40.0)
    assert await axis.wait_in_position(30.0) == pytest.approx(40.0)
    assert axis.actual_deg() == pytest.approx(40.0 + 0.02)


async def test_glossmeter_drifts_warms_up_and_recalibrates() -> None:
    clock = SimClock(0.0)
    drift = GlossDrift(drift_pct_per_h=0.5, temp_coeff_pct_per_c=0.05, warmup_c=4.0, noise_gu=0.0)

    class Truth:
        def gloss(self, angles: tuple[int, ...]) -> dict[int, float]:
            return {a: 80.0 for a in angles}

    gm = SimGlossmeter(Truth(), clock, drift=drift)  # type: ignore[arg-type]
    await gm.connect()
    first = await gm.measure()
    assert first.values_gu[60] == pytest.approx(80.0, abs=0.05)
    assert first.temperature_c == pytest.approx(23.0, abs=0.1)
    await clock.sleep(3600.0)
    later = await gm.measure()
    warm = 4.0 * (1 - math.exp(-3600.5 / 900.0))
    expected = 80.0 * (1 + 0.01 * (0.5 * 3600.5 / 3600 + 0.05 * warm))
    assert later.values_gu[60] == pytest.approx(expected, abs=0.051)
    assert later.temperature_c == pytest.approx(23.0 + warm, abs=0.051)
    t = clock.now()
    gain = 1 + 0.01 * (0.5 * t / 3600 + 0.05 * 4.0 * (1 - math.exp(-t / 900.0)))
    assert gm.calibrate_ppm() == round((gain - 1) * 1e6)  # ZGM1120 Calibrate: deviation
    assert (await gm.measure()).values_gu[60] == pytest.approx(80.0, abs=0.05)


def test_session_misalignments_are_seeded_and_within_their_ranges(tmp_path: Path) -> None:
    cfg = load_lab_config(configs_dir() / "lab-sim.toml")
    a, b = draw_session(cfg), draw_session(cfg)
    assert a == b  # same seed, same session
    t = cfg.sim.twin
    assert abs(a["lamp_zero_offset_deg"]) <= t.lamp_zero_range_deg
    assert abs(a["detector_zero_offset_deg"]) <= t.detector_zero_range_deg
    assert abs(a["sample_tilt_deg"]) <= t.sample_tilt_range_deg
    assert a["backlash_deg"] == t.backlash_deg
    other = cfg.model_copy(update={"sim": cfg.sim.model_copy(update={"seed": 2})})
    assert draw_session(other) != a
    path = tmp_path / "ideal.toml"
    path.write_text(ideal((configs_dir() / "lab-sim.toml").read_text()))
    assert draw_session(load_lab_config(path)) == {
        "sample_tilt_deg": 0.0,
        "lamp_zero_offset_deg": 0.0,
        "detector_zero_offset_deg": 0.0,
        "backlash_deg": 0.0,
    }


@pytest.mark.parametrize(
    ("line", "key"),
    [
        ("step_um = 5.0", "sim.twin.step_um"),
        ('mode = "perfect"', "sim.twin.mode"),
        ("sample_tilt_range_deg = -1", "sim.twin.sample_tilt_range_deg"),
        ('body = "purple"', "sim.twin.body"),
        ("full_scale_pct = 0", "sim.twin.full_scale_pct"),
    ],
)
def test_out_of_range_twin_settings_name_the_file_and_key(
    tmp_path: Path, line: str, key: str
) -> None:
    text = (configs_dir() / "lab-sim.toml").read_text().replace('mode = "realistic"', "")
    path = tmp_path / "bad.toml"
    path.write_text(text + "\n" + line + "\n")
    with pytest.raises(ConfigError) as err:
        load_lab_config(path)
    assert str(path) in str(err.value) and key in str(err.value)


def test_flat_mirror_specimen_is_aluminium() -> None:
    r = FlatSpecimen().reflectance(45.0)
    assert float(r.min()) > 0.87 and float(r.max()) < 0.93
