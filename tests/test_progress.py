"""The scan's progress display: rich on a terminal, plain lines for pipes and logs."""

from __future__ import annotations

import io

from goniolab.commands.scan import ProgressBar
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
    bar = ProgressBar(out, clock_scale=1.0)
    for ev in _events(10):
        bar.update(ev, f"theta_r={ev.done}")
        if ev.done == 4:
            bar.message("goniolab: warning: spectro: retrying")
    bar.close()
    text = out.getvalue()
    assert "10/10" in text and "ETA 0s" in text and "theta_r=10" in text
    assert "goniolab: warning: spectro: retrying" in text
    assert "\\x1b[" in repr(text)  # drawn in place with terminal controls, not line by line


def test_a_pipe_gets_one_plain_line_per_ten_percent() -> None:
    out = io.StringIO()
    bar = ProgressBar(out, clock_scale=2.0)
    for ev in _events(30):
        bar.update(ev, "")
    bar.close()
    lines = out.getvalue().splitlines()
    assert len(lines) == 11  # the first reading, then each 10 %
    assert lines[0].startswith("[#.") and " 1/30 ETA " in lines[0]
    assert " 12/30 ETA 9s " in lines[4]  # 18 s of lab clock at twice real time
    assert lines[-1] == f"[{'#' * 30}] 30/30 ETA 0s "
