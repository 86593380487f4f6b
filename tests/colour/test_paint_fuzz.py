"""Property-based fuzzing of the paint files ``predict colour --paint FILE.toml`` reads
(hypothesis, a deadline per case): any key of a built-in paint set to a hostile value,
removed, or an unknown key added, loads as a paint or raises one error line -- nothing else
escapes -- and a paint that loads evaluates: coat index, body term and flake lobe at a few
wavelengths and directions are finite, or the paint says in one line why it cannot."""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from goniolab.app.colours import load_paint_file
from goniolab.colour.dispersion import DispersionError
from goniolab.colour.paint import PaintError
from goniolab.config import configs_dir
from goniolab.errors import UserError
from tests._fuzz import DELETE, fuzz_settings, leaves, set_path, toml_document

FUZZ = fuzz_settings(60)

SAMPLES = tomllib.loads((configs_dir() / "samples.toml").read_text(encoding="utf-8"))["samples"]
PAINTS = {name: t["paint"] for name, t in SAMPLES.items() if "paint" in t}
WAVELENGTHS_NM = np.array([380.0, 550.0, 780.0])


_numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1, 0.0, -0.0, 1e-300, 0.5, 0.999, 1.0, 1.0000001, 1.5, 90.0,
                     89.9999, 180.0, 1e6, 1e300, 2**63 - 1]),
)  # fmt: skip
_values = st.one_of(
    st.just(DELETE),
    st.booleans(),
    _numbers,
    st.sampled_from(["", "table", "cauchy", "sellmeier", "aluminium", "x", "nope.csv"]),
    st.lists(_numbers, max_size=4),
    st.fixed_dictionaries(
        {"wavelengths_nm": st.lists(_numbers, max_size=4), "values": st.lists(_numbers, max_size=4)}
    ),
    st.dictionaries(st.sampled_from(["kind", "A", "B", "C", "file", "x"]),
                    st.one_of(_numbers, st.sampled_from(["cauchy", "table", "sellmeier"])),
                    max_size=3),
)  # fmt: skip


def _evaluate(paint: Any) -> None:
    """What a prediction asks of a paint; a ValueError of the paint's own (one line) is a
    clear refusal, anything else a bug."""
    try:
        n = paint.coat_n(WAVELENGTHS_NM)
        body = paint.body_term(WAVELENGTHS_NM)
        wi = np.array([[0.0, math.sin(0.7), math.cos(0.7)]])
        wo = np.array([[0.0, -math.sin(0.5), math.cos(0.5)]])
        flakes = paint.flake_brdf(wi, wo, WAVELENGTHS_NM) if paint.has_flakes else np.zeros(1)
    except (PaintError, DispersionError) as exc:
        assert "\n" not in str(exc) and str(exc), exc
        return
    assert np.all(np.isfinite(n)) and np.all(n > 1.0)
    assert np.all(np.isfinite(body)) and np.all(body >= 0.0)
    assert np.all(np.isfinite(flakes)) and np.all(flakes >= 0.0)


@pytest.mark.parametrize("name", sorted(PAINTS))
def test_any_value_in_any_key_of_a_paint(tmp_path: Path, name: str) -> None:
    original = PAINTS[name]
    paths = [*leaves(original), ("typo",), ("body", "typo")]

    @FUZZ
    @given(st.data())
    def run(data: st.DataObject) -> None:
        doc = copy.deepcopy(original)
        for _ in range(data.draw(st.integers(1, 3), label="changes")):
            set_path(doc, data.draw(st.sampled_from(paths), label="key"), data.draw(_values))
        path = tmp_path / "paint.toml"
        path.write_text(toml_document(doc))
        try:
            paint = load_paint_file(str(path))
        except UserError as exc:
            message = str(exc)
            assert message.startswith(str(path)) and "\n" not in message, message
            assert len(message) < 600, message
            return
        _evaluate(paint)

    run()


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        # each escaped as a traceback (AttributeError / TypeError) before the fuzz found it
        ('body = "x"\n', "paint.toml: body: expected a table, got 'x'"),
        ("metallic = true\n", "paint.toml: metallic: expected a table, got True"),
        ("coat = false\n", "paint.toml: coat: expected a number or a table with a kind"),
        ('coat = ""\n', "paint.toml: coat: expected a number or a table with a kind, got ''"),
        # loaded, then gave an infinite flake lobe
        ("coat = 1.2e16\n", "coat: index 1.2e+16..1.2e+16 over 380-780 nm is outside (1, 4]"),
        ("coat = 0.0\n", "coat: Constant gives an index with n <= 0"),
    ],
)
def test_hostile_paint_values_are_one_line_errors(tmp_path: Path, text: str, needle: str) -> None:
    path = tmp_path / "paint.toml"
    path.write_text(text)
    with pytest.raises(UserError) as info:
        load_paint_file(str(path))
    message = str(info.value)
    assert message.startswith(str(path)) and needle in message and "\n" not in message, message


def test_a_body_that_barely_scatters_is_a_clear_absorber() -> None:
    """S -> 0: the KM layer is a clear absorber over its substrate, R = Rg exp(-2 K X)
    (Kubelka 1948); S = 2e-256 made (K/S)^2 overflow and the body term negative."""
    from goniolab.colour.km import km_reflectance

    k, x, rg = 0.6, 2.0, 0.3
    r = km_reflectance(k, 2e-256, x, rg)
    assert float(r) == pytest.approx(rg * math.exp(-2 * k * x), rel=1e-9)
    assert float(km_reflectance(1e200, 1.0, 1.0, rg)) == 0.0  # opaque black, not NaN
