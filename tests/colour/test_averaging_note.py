"""A stored run whose repeats were averaged as L*a*b* instead of as spectra says why.

L*a*b* is not linear in the spectrum (CIE 15:2004 eq. 8.1's cube root), so the mean of the
repeats' L*a*b* is another number than the colour of their mean spectrum
(tests/scan/test_standards.py). Where :func:`goniolab.scan.colour.colour_rows` falls back
to it, the row says ``averaged = "lab"`` and ``averaged_reason``; ``runs colour`` (text and
JSON) and ``runs show`` print the note.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.scan.colour import PointColour, colour_rows
from goniolab.scan.plans import BrdfPlan
from goniolab.store import PointRow, RunStore
from tests.colour._spectral_runs import CONFIG

WL = [float(w) for w in np.arange(400.0, 701.0, 10.0)]
PC = PointColour(detector_cone_deg=6.0)


def _store(path: Path) -> tuple[Path, list[tuple[float, float, float]]]:
    """Run 1: theta_r 30 and 20 deg, two repeats each; at 30 deg the second repeat's
    spectrum was not stored (an older importer), only its L*a*b*. Returns the L*a*b* of the
    two 30 deg repeats."""
    plan = BrdfPlan(45.0, (30.0, 20.0), repeats=2, sample="sample:x")
    labs: list[tuple[float, float, float]] = []
    with RunStore(path) as s:
        rid = s.create_run(kind="brdf", plan=plan.to_dict(), config=CONFIG, sample="sample:x",
                           model={}, version="t")  # fmt: skip
        for k, t in enumerate((30.0, 20.0)):
            for r in range(2):
                values = [40.0 + 5 * r + 0.02 * (w - 550.0) for w in WL]
                c = PC.measured(WL, values, t)
                raw = {} if (k, r) == (0, 1) else {"wavelengths_nm": WL, "values": values}
                if k == 0:
                    labs.append(c.lab)
                s.add_point(rid, index=k, repeat=r, theta_i_deg=45.0, theta_r_deg=t,
                            measured_theta_i_deg=45.0, measured_theta_r_deg=t,
                            luminance_pct=1.0, raw=raw, timestamp=1.0 + k,
                            colour=c.as_dict())  # fmt: skip
    return path, labs


def test_the_rows_say_why_they_fell_back() -> None:
    def row(repeat: int, wl: list[float]) -> PointRow:
        values = [50.0 + repeat] * len(wl)
        lab = PC.measured(wl, values, 30.0).as_dict()
        raw = {"wavelengths_nm": wl, "values": values}
        return PointRow(0, repeat, 45.0, 30.0, 45.0, 30.0, 1.0, raw, 0.0, lab)

    both = [row(0, WL), row(1, WL)]
    (ok,) = colour_rows(both, {}, 45.0, PC)
    assert ok["averaged"] == "spectra" and "averaged_reason" not in ok
    (grids,) = colour_rows([row(0, WL), row(1, WL[::2])], {}, 45.0, PC)
    assert grids["averaged"] == "lab"
    assert grids["averaged_reason"] == "the repeats' spectra are on 2 different wavelength grids"
    (plain,) = colour_rows(both, {}, 45.0)
    assert plain["averaged"] == "lab" and "no colour settings" in plain["averaged_reason"]


def test_runs_colour_and_runs_show_say_why(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store, labs = _store(tmp_path / "s.sqlite")
    assert main(["runs", "colour", "1", "--store", str(store), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rows = {r["theta_r_deg"]: r for r in doc["geometries"]}
    assert rows[30.0]["averaged"] == "lab"
    assert rows[30.0]["averaged_reason"] == "repeat 1 has no stored spectrum"
    # the number is the mean of the two repeats' L*a*b*, as the reason says
    assert rows[30.0]["L"] == pytest.approx((labs[0][0] + labs[1][0]) / 2, abs=1e-9)
    assert rows[20.0]["averaged"] == "spectra" and "averaged_reason" not in rows[20.0]
    note = (
        "measured colour (theta_r 30 deg): repeats averaged as L*a*b*, not as spectra: "
        "repeat 1 has no stored spectrum"
    )
    assert doc["averaging_notes"] == [note]
    assert main(["runs", "colour", "1", "--store", str(store)]) == 0
    assert f"note: {note}" in capsys.readouterr().out
    assert main(["runs", "show", "1", "--store", str(store)]) == 0
    assert f"note: {note}" in capsys.readouterr().out
