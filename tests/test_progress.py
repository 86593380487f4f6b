"""The progress display (goniolab.progress): rich on a terminal, plain lines for pipes and logs."""

from __future__ import annotations

import io
import math

import pytest

from goniolab.progress import (
    CallbackProgress,
    NullProgress,
    ProgressUpdate,
    TerminalProgress,
    auto_progress,
    terminal_progress,
)
from goniolab.scan.events import Progress


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _events(total: int) -> list[Progress]:
    return [
        Progress(run_id=1, done=k, total=total, eta_s=float(total - k)) for k in range(1, total + 1)
    ]


def test_a_terminal_gets_a_rich_bar_with_count_eta_and_messages() -> None:
    out = _Terminal()
    bar = TerminalProgress(out)
    for ev in _events(10):
        bar.advance(ev.done, total=ev.total, eta_s=ev.eta_s, detail=f"theta_r={ev.done}")
        if ev.done == 4:
            bar.message("goniolab: warning: spectro: retrying")
    bar.finish()
    text = out.getvalue()
    assert "10/10" in text and "ETA 0s" in text and "theta_r=10" in text
    assert "goniolab: warning: spectro: retrying" in text
    assert "\\x1b[" in repr(text)  # drawn in place with terminal controls, not line by line


def test_a_pipe_gets_one_plain_line_per_ten_percent() -> None:
    out = io.StringIO()
    bar = TerminalProgress(out)
    for ev in _events(30):  # 18 s of lab clock at twice real time: 9 s of wall time
        bar.advance(ev.done, total=ev.total, eta_s=ev.eta_s / 2.0)
    bar.finish()
    lines = out.getvalue().splitlines()
    assert len(lines) == 11  # the first reading, then each 10 %
    assert lines[0].startswith("[#.") and " 1/30 ETA " in lines[0]
    assert " 12/30 ETA 9s " in lines[4]  # 18 s of lab clock at twice real time
    assert lines[-1] == f"[{'#' * 30}] 30/30 ETA 0s "


def test_at_clock_scale_0_the_eta_is_the_measured_wall_rate() -> None:
    """issue 27: at --time-scale 0 the motion model's ETA is 0 while the readings still take
    wall time (15-20 s read "ETA 0s"): the ETA is the measured seconds per reading times
    the readings left, "?" until one was timed, 0 at the end."""
    bar = TerminalProgress(io.StringIO())
    # at scale 0 the scan gives no ETA (goniolab.app.lab_scan.report_events): eta_s=None
    assert math.isnan(bar.eta_s(0, 10, None, now_s=100.0))
    assert bar.eta_s(2, 10, None, now_s=104.0) == pytest.approx(2.0 * 8)  # 2 s per reading
    assert bar.eta_s(5, 10, None, now_s=105.0) == pytest.approx(1.0 * 5)
    assert bar.eta_s(10, 10, None, now_s=110.0) == 0.0
    real_time = TerminalProgress(io.StringIO())
    assert real_time.eta_s(1, 3, 18.0 / 2.0, 0.0) == 9.0


def test_a_batch_counts_its_steps_itself_with_a_measured_eta() -> None:
    """``with terminal_progress(n, label) as p: p.advance()``: the API a batch of maps uses
    (no done count, no ETA of its own: the measured pace gives it)."""
    out = io.StringIO()
    with terminal_progress(4, "maps", stream=out) as p:
        p.message("goniolab: a.npy: no such file")
        for name in ("a", "b", "c", "d"):
            p.advance(detail=name)
    lines = out.getvalue().splitlines()
    assert lines[0] == "goniolab: a.npy: no such file"
    assert [line.split("] ")[1].split(" ETA")[0] for line in lines[1:]] == [
        "1/4", "2/4", "3/4", "4/4",
    ]  # fmt: skip
    assert " 1/4 ETA ? a" in lines[1]  # nothing timed yet after the first step
    assert lines[-1].endswith("4/4 ETA 0s d")


def test_the_callback_adapter_hands_over_every_update() -> None:
    got: list[ProgressUpdate] = []
    p = CallbackProgress(got.append, label="run 3")
    p.start(2)
    p.advance(1, eta_s=5.0, detail="theta_r=10")
    p.message("goniolab: warning: spectro: retrying")
    p.advance()  # one more: 2 of 2
    p.finish()
    assert [(u.kind, u.done, u.total) for u in got] == [
        ("start", 0, 2), ("advance", 1, 2), ("message", 1, 2), ("advance", 2, 2),
        ("finish", 2, 2),
    ]  # fmt: skip
    assert got[1].eta_s == 5.0 and got[1].detail == "theta_r=10" and got[1].label == "run 3"
    assert got[2].text == "goniolab: warning: spectro: retrying"
    assert got[3].eta_s == 0.0  # the end


def test_outside_a_kernel_progress_goes_to_stderr_and_nothing_to_stdout(
    capsys: pytest.CaptureFixture[str],
) -> None:
    p = auto_progress(2)
    assert isinstance(p, TerminalProgress) and not p.jupyter
    p.advance()
    p.advance()
    p.finish()
    out, err = capsys.readouterr()
    assert out == "" and "2/2 ETA 0s" in err
    silent = NullProgress()
    silent.advance(1, total=1)
    silent.message("x")
    silent.finish()
    assert capsys.readouterr() == ("", "")
