"""What the TUI says in one line (issue 27): the status line keeps the run's state, its points
and both arms on an 80-column line (at 80 x 24 the detector's angle and state were cut off);
an opened stored run counts its readings as the run list does."""

from __future__ import annotations

from goniolab.tui.widgets import status_text

ARMS = {"lamp": ("45.00", "idle"), "detector": ("25.00", "moving")}
RUN = "run 3: running  26/71  ETA 29 s  (predicted by facet)"


def test_a_wide_line_says_everything_in_full() -> None:
    assert status_text(RUN, ARMS, 200) == (
        "run 3: running  26/71  ETA 29 s  (predicted by facet)  |  "
        "lamp 45.00 idle  detector 25.00 moving"
    )


def test_80_columns_keep_state_points_eta_model_and_both_arms() -> None:
    text = status_text(RUN, ARMS, 78)  # 80 columns less the padding
    assert text == "run 3: running  26/71  ETA 29 s  (facet)  |  θi 45.00 idle  θr 25.00 moving"
    assert len(text) <= 78


def test_both_arms_in_one_state_share_it_and_a_narrow_line_drops_the_model_first() -> None:
    idle = {"lamp": ("20.00", "idle"), "detector": ("30.00", "idle")}
    run = "run 1: done  11/11  (predicted by scripted-gaussian)"
    assert status_text(run, idle, 66) == "run 1: done  11/11  (scripted-gaussian)  |  θi 20.00 θr 30.00 idle"  # fmt: skip
    assert status_text(run, idle, 60) == "run 1: done  11/11  |  lamp 20.00 idle  detector 30.00 idle"  # fmt: skip
    assert status_text(run, idle, 45) == "run 1: done  11/11  |  θi 20.00 θr 30.00 idle"
    assert status_text(run, idle, 20) == "run 1: done  11/11 …"


def test_an_opened_run_says_its_readings_as_the_run_list_counts_them() -> None:
    """issue 27: the runs browser's title said "0 readings" for an alignment run of 288
    and for a gloss log (the loaded run carries no BRDF points for them)."""
    from goniolab.tui.screens import run_title
    from goniolab.tui.view_model import RunSummary

    loaded = RunSummary(3, 0.0, "align", "sample:wittmann-3", "done", 0)
    listed = RunSummary(3, 0.0, "align", "sample:wittmann-3", "done", 288)
    assert run_title(loaded, listed) == (
        "run 3: sample:wittmann-3, align, done, 288 readings "
        "(not drawn here: goniolab plot 3 -o align.png)"
    )
    gloss = RunSummary(1, 0.0, "gloss", "sample:wittmann-3", "running", 74)
    assert run_title(gloss, None) == "run 1: sample:wittmann-3, gloss, running, 74 readings"
