"""The TUI's colour table marks a predicted colour made by a wavelength-free model.

The facet and analytic models have no wavelength in their scattering: their predicted
near-specular a*, b* are not a prediction of the surface's colour
(:func:`goniolab.colour.spectral.surface_colour_note`). ``goniolab runs colour`` says so per
row (``predicted_colour_note``); the TUI's live colour table must say the same, from the same
app-layer function (:func:`goniolab.app.colour_notes.predicted_colour_models`), not re-derived.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from goniolab.cli import main
from goniolab.scan.events import ColourPredicted, PointPredicted, RunState
from goniolab.tui.comparison import Comparison
from goniolab.tui.widgets import ColourNote, ColourTable
from tests.tui.test_lab import SIZE, make_app, set_form
from tests.tui.tui_scripted import settle, wait_until

NOTE = (
    "model is wavelength-independent: near-specular colour from surface scattering is not predicted"
)


def test_the_comparison_names_each_predicted_colours_model() -> None:
    c = Comparison()
    c.clear(run_id=1, theta_i_deg=45.0)
    for i, tr in enumerate((30.0, 40.0, 50.0, 60.0)):
        c.add_predicted(PointPredicted(run_id=1, index=i, theta_i_deg=45.0, theta_r_deg=tr,
                                       predicted_pct=1.0))  # fmt: skip
        if tr != 60.0:  # the last point has no predicted colour yet
            c.add_colour(ColourPredicted(run_id=1, index=i, theta_r_deg=tr, lab=(50.0, 0.0, 0.0)))
    # before the record is read nothing is claimed
    assert c.colour_arrays().predicted_model == (None, None, None, None)
    c.prediction_record = {"computed_by": {"kirchhoff": [30.0], "facet": [40.0, 50.0, 60.0]}}
    arr = c.colour_arrays()
    assert arr.predicted_model == ("kirchhoff", "facet", "facet", None)
    assert [n is not None and NOTE in n for n in arr.predicted_colour_note] == [
        False, True, True, False,
    ]  # fmt: skip
    # the legend names the angles with a predicted colour only (60 has none)
    (note,) = arr.predicted_colour_notes
    assert f"the facet {NOTE}" in note and "theta_r 40..50 deg" in note
    c.clear(run_id=2)
    assert c.prediction_record == {}


async def test_the_live_colour_table_marks_the_analytic_models_colours(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # make_app's sample is predicted by an analytic Beckmann model: wavelength-free
    app = make_app(tmp_path)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, app.ready.is_set)
        await set_form(
            pilot, app, theta_i_deg="45", theta_r_start_deg="30", theta_r_stop_deg="50",
            theta_r_step_deg="10", repeats="1",
        )  # fmt: skip
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await wait_until(pilot, lambda: len(app.comparison.predicted_lab) == 3)
        await wait_until(pilot, lambda: bool(app.comparison.prediction_record))
        app.redraw()
        await settle(pilot, app)
        table = app.query_one(ColourTable)
        c = app.comparison.colour_arrays()
        for k in range(3):
            assert str(table.get_cell_at((k, 5))) == f"{c.predicted_lab[k, 0]:.1f} †"
        legend = app.query_one(ColourNote)
        assert legend.display
        shown = str(legend.render())
        tooltip = legend.tooltip
        run_id = app.run_id
    # the same words as goniolab runs colour on the stored run
    store = tmp_path / "runs.sqlite"
    assert main(["runs", "colour", str(run_id), "--store", str(store), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    (note,) = doc["predicted_colour_notes"]
    assert "the analytic-beckmann " + NOTE in note and "theta_r 30..50 deg" in note
    # the legend: the rows' own note (its first words say what the mark means), the whole
    # note with its angles in the tooltip
    (row_note,) = {r["predicted_colour_note"] for r in doc["geometries"]}
    assert shown == f"† {row_note}" and row_note.startswith("predicted colour: the analytic")
    assert tooltip == f"† {note}"
    assert all(r["predicted_model"] == "analytic-beckmann" for r in doc["geometries"])
    # the runs browser's stored run carries the same record (screens.RunsScreen._show_run)
    stored = app.backend.load_run(run_id)
    assert stored.prediction["computed_by"] == {"analytic-beckmann": [30.0, 40.0, 50.0]}


def test_the_comparison_says_where_it_averaged_as_lab() -> None:
    # as tests/tui/test_comparison.py: with XYZ the repeats are averaged as spectra; a
    # point whose readings came without XYZ falls back to the mean L*a*b*, and says so
    from goniolab.scan.events import PointMeasured

    white = (94.811, 100.0, 107.304)
    c = Comparison()
    c.clear(run_id=1)
    for index, tr, xyz in ((0, 30.0, (20.0, 21.0, 22.0)), (1, 40.0, None)):
        for rep in range(2):
            c.add_measured(PointMeasured(
                run_id=1, index=index, repeat=rep, theta_i_deg=45.0, theta_r_deg=tr,
                luminance_pct=1.0, measured_theta_i_deg=45.0, measured_theta_r_deg=tr,
                lab=(50.0 + rep, 1.0, 2.0), xyz=xyz, white_xyz=None if xyz is None else white,
            ))  # fmt: skip
    assert c.lab_average_reason(0) is None
    (note,) = c.colour_arrays().averaging_notes
    assert note == (
        "measured colour (theta_r 40 deg): repeats averaged as L*a*b*, not as spectra: "
        "2 of its readings came without XYZ (their white unknown)"
    )
    assert c.colour_arrays().measured_lab[1][0] == 50.5  # the mean L* it says it took


async def test_a_record_that_cannot_be_read_is_said() -> None:
    # the colour table's marks come from the stored record: when it cannot be read the
    # table shows no mark, and the user is told why there is none
    from goniolab.tui.app import GonioApp
    from tests.tui.tui_scripted import ScriptedBackend

    class Broken(ScriptedBackend):
        def prediction_record(self, run_id: int) -> dict:
            raise OSError("database is locked")

    app = GonioApp(Broken(gated=False), poll_hz=0, autostart=True)
    async with app.run_test(size=SIZE) as pilot:
        await wait_until(pilot, lambda: app.run_state is RunState.DONE)
        await wait_until(pilot, lambda: any(n.title == "Prediction" for n in app._notifications))
        (msg,) = [n.message for n in app._notifications if n.title == "Prediction"]
    assert msg == "run 1: which model made its prediction could not be read: database is locked"
