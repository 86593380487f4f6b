"""docs/CALIBRATION.md's thresholds are the code's (docs that cannot go stale): each number
the doc states for a quality flag, the auto-exposure, the alignment's gates, the calibration
age and the reconnect window is read from the doc's own sentence and compared with the
constant or default the code uses. A changed constant fails here until the doc says it.
And docs/TWIN.md's alignment state file is what the code writes and reads.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = " ".join((ROOT / "docs" / "CALIBRATION.md").read_text(encoding="utf-8").split())


def _number(pattern: str) -> float:
    """The number the doc's sentence ``pattern`` holds in its ``(?P<x>...)`` group."""
    m = re.search(pattern, DOC)
    assert m, f"docs/CALIBRATION.md no longer says {pattern!r}"
    return float(m["x"])


def _code() -> dict[str, float]:
    from goniolab.config.sections import LabSection, SpectroConfig, TwinConfig
    from goniolab.optics.apertures import ISO2813_BLACK_GLASS_N
    from goniolab.scan.black_glass_fit import AlignGates
    from goniolab.scan.exposure import NOISE_FLOOR_FRACTION, SATURATED, AutoExposure

    auto, gates = AutoExposure(), AlignGates()
    return {
        "saturated": SATURATED,
        "noise floor": NOISE_FLOOR_FRACTION,
        "auto low": auto.low,
        "auto high": auto.high,
        "auto min us": auto.min_us,
        "auto max us": auto.max_us,
        "auto tries": auto.max_tries,
        "auto target": auto.target,
        "gate scale": gates.scale_tolerance,
        "gate rms %": 100 * gates.max_rms_rel,
        "gate sigma": gates.max_sigma_deg,
        "gate w": gates.max_s_weight_dev,
        "gate geometric": gates.max_geometric_gap_deg,
        "calibration age h": SpectroConfig.model_fields["calibration_max_age_h"].default,
        "reconnect s": LabSection.model_fields["reconnect_window_s"].default,
        "twin s_weight": TwinConfig.model_fields["s_weight"].default,
        "black glass n": ISO2813_BLACK_GLASS_N,
    }


#: what the doc says, as a pattern around the number
SAID = {
    "saturated": r"`saturated` \| `peak_fraction >= (?P<x>[\d.]+)`",
    "noise floor": r"`under_noise_floor` \| `peak_fraction < (?P<x>[\d.]+)`",
    "auto low": r"one outside `(?P<x>[\d.]+) \.\. [\d.]+` of full scale",
    "auto high": r"one outside `[\d.]+ \.\. (?P<x>[\d.]+)` of full scale",
    "auto min us": r"\(within (?P<x>\d+) \.\. \d+ us\)",
    "auto max us": r"\(within \d+ \.\. (?P<x>\d+) us\)",
    "auto tries": r"at most (?P<x>\d+) readings",
    "auto target": r"`t x (?P<x>[\d.]+) / peak_fraction`",
    "gate scale": r"`k` within `1 \+/- (?P<x>[\d.]+)`",
    "gate rms %": r"fit rms <= (?P<x>[\d.]+) %",
    "gate sigma": r"1-sigma of each zero <= (?P<x>[\d.]+) deg",
    "gate w": r"fitted `w` within `0\.5 \+/- (?P<x>[\d.]+)`",
    "gate geometric": r"`dL - dD` of the fit within (?P<x>[\d.]+) deg",
    "calibration age h": r"`\[spectro\] calibration_max_age_h` \((?P<x>[\d.]+) h\)",
    "reconnect s": r"`\[lab\] reconnect_window_s` \((?P<x>[\d.]+) s of lab clock",
    "twin s_weight": r"`\[sim\.twin\] s_weight = (?P<x>[\d.]+)`",
    "black glass n": r"Y_cert = 100 x .*?\((?:unpolarised, )?n = (?P<x>[\d.]+)\)",
}


def test_every_constant_has_its_sentence() -> None:
    assert set(SAID) == set(_code())


@pytest.mark.parametrize("name", sorted(SAID))
def test_doc_number_is_the_codes(name: str) -> None:
    said, code = _number(SAID[name]), _code()[name]
    assert said == pytest.approx(code), f"docs/CALIBRATION.md says {name} {said}, the code {code}"


def test_twin_md_alignment_state_example_is_what_the_code_writes_and_reads(tmp_path: Path) -> None:
    """docs/TWIN.md's alignment state file: ``write_alignment_state`` writes those lines for
    those values (its header abbreviated in the doc), and the config loader applies them."""
    from goniolab.config import load_lab_config
    from goniolab.config.alignment_state import write_alignment_state

    text = (ROOT / "docs" / "TWIN.md").read_text(encoding="utf-8")
    m = re.search(r"```toml\n(# goniolab alignment state: .*?)```", text, re.S)
    assert m, "docs/TWIN.md: the alignment state example is gone"
    shown = m[1].splitlines()
    table = shown[shown.index("[alignment]") + 1 :]
    values: dict[str, float | int] = {}
    for line in table:
        key, value = (s.strip() for s in line.split("="))
        values[key] = int(value) if key == "run" else float(value)
    config = tmp_path / "lab.toml"
    lab = (ROOT / "configs" / "lab-sim.toml").read_text(encoding="utf-8")
    config.write_text(lab + '\n[alignment]\nstate_file = "lab.alignment.toml"\n', encoding="utf-8")
    path = write_alignment_state(load_lab_config(config), values)
    written = path.read_text(encoding="utf-8").splitlines()
    assert written[0].startswith(shown[0].removesuffix("...").rstrip())
    assert written[written.index("[alignment]") + 1 :] == table
    loaded = load_lab_config(config).alignment
    assert (loaded.lamp_zero_deg, loaded.detector_zero_deg, loaded.sample_tilt_deg) == (
        values["lamp_zero_deg"], values["detector_zero_deg"], values["sample_tilt_deg"]
    )  # fmt: skip
    assert loaded.loaded_from == str(path)
