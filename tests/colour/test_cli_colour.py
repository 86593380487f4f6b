"""``goniolab predict colour`` and ``runs colour`` end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.cli import main


def _predict(capsys: pytest.CaptureFixture[str], *args: str) -> dict:
    assert main(["predict", "colour", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.slow
def test_flop_of_the_built_in_paints(capsys: pytest.CaptureFixture[str]) -> None:
    silver = _predict(capsys, "sample:silver-metallic")
    red = _predict(capsys, "sample:solid-red")
    # X-Rite: solids ~0-2, metallics ~10-17
    assert silver["flop_index"] > 10 and abs(red["flop_index"]) < 2
    assert [g["aspecular_deg"] for g in red["geometries"]] == [-15, 15, 25, 45, 75, 110]
    r45 = red["geometries"][3]
    assert r45["a"] > 30 and 0 < r45["h_deg"] < 60  # a red hue
    pearl = _predict(capsys, "sample:pearl")
    hues = [g["h_deg"] for g in pearl["geometries"][:3]]
    assert max(hues) - min(hues) > 5  # the interference colour shifts with angle


def test_bad_colour_options_are_one_line_errors(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["predict", "colour", "sample:flat", "--illuminant", "D66"]) == 2
    assert "unknown illuminant 'D66'" in capsys.readouterr().err
    paint = tmp_path / "p.toml"
    paint.write_text("[metallic]\narea_fraction = 2\nspread_deg = 5\n")
    assert main(["predict", "colour", "sample:flat", "--paint", str(paint)]) == 2
    assert "metallic area_fraction must be in [0, 1]" in capsys.readouterr().err
