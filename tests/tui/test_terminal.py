"""``goniolab tui`` in a real terminal: tmux runs it, ``capture-pane`` reads the screen.

The app's output is streamed to the test through ``tmux pipe-pane`` into a FIFO, so the
test waits on the app's own output (``select``) instead of sleeping; then it reads the
rendered screen with ``capture-pane``, quits with ``q`` and waits for the exit with
``tmux wait-for``.
"""

from __future__ import annotations

import os
import re
import select
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
WAIT_S = 60.0  # upper bound only; the test returns as soon as the screen shows the run

pytestmark = pytest.mark.skipif(
    shutil.which("tmux") is None,
    reason="tmux is not installed (apt-get install -y tmux); needed to run goniolab tui "
    "in a real terminal",
)


def _wait_for_screen(fd: int, capture: Callable[[], str], pattern: str, deadline: float) -> str:
    """Each time the app writes to the terminal, read the screen; return it once it
    matches ``pattern`` (the wait is on the app's output, bounded by ``deadline``)."""
    screen = ""
    while (left := deadline - time.monotonic()) > 0:
        ready, _, _ = select.select([fd], [], [], left)
        if not ready:
            break
        if not os.read(fd, 1 << 20):
            break
        screen = capture()
        if re.search(pattern, screen):
            return screen
    raise AssertionError(f"goniolab tui never showed {pattern!r}; last screen:\n{screen}")


def test_goniolab_tui_runs_in_tmux(tmp_path: Path) -> None:
    sock = f"goniolab-test-{os.getpid()}"
    session = "tui"
    fifo = tmp_path / "pane.fifo"
    os.mkfifo(fifo)
    rc_file = tmp_path / "rc"
    cmd = [
        sys.executable,
        "-m",
        "goniolab.cli",
        "tui",
        "--config",
        str(REPO / "configs" / "lab-sim.toml"),
        "--time-scale",
        "0",
        "--store",
        str(tmp_path / "runs.sqlite"),
        "--autostart",
    ]
    shell = (
        # COLUMNS/LINES from the test environment would override the pane size.
        f"cd {shlex.quote(str(REPO))}; read _; env -u COLUMNS -u LINES {shlex.join(cmd)}; "
        f"echo $? > {shlex.quote(str(rc_file))}; tmux -L {sock} wait-for -S {sock}-done"
    )

    def tmux(*args: str) -> str:
        out = subprocess.run(
            ["tmux", "-L", sock, *args], check=True, capture_output=True, text=True, timeout=30
        )
        return out.stdout

    tmux("new-session", "-d", "-s", session, "-x", "140", "-y", "42", shell)
    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        tmux("pipe-pane", "-t", session, "-o", f"cat > {shlex.quote(str(fifo))}")
        tmux("send-keys", "-t", session, "Enter")  # release `read`: the app starts now
        screen = _wait_for_screen(
            fd,
            lambda: tmux("capture-pane", "-p", "-t", session),
            r"run 2: (running|done)",
            time.monotonic() + WAIT_S,
        )
        assert "goniolab — Simulated goniospectrophotometer (sim, sim clock x0)" in screen
        assert re.search(r"lamp\s+[-\d.]+\s+\w+\s+yes\s+ok", screen), screen  # homed, linked
        assert re.search(r"run 2: (running|done)", screen), screen
        # run 1 is the gloss log: --autostart takes the gloss reading before the scan
        assert "glossmeter log" in screen and "scan setup" in screen
        tmux("send-keys", "-t", session, "q")
        subprocess.run(["tmux", "-L", sock, "wait-for", f"{sock}-done"], check=True, timeout=60)
        assert rc_file.read_text().strip() == "0"
    finally:
        os.close(fd)
        subprocess.run(["tmux", "-L", sock, "kill-server"], capture_output=True, timeout=30)


def _running(pid: int) -> bool:
    """The process exists and has not ended (a zombie waiting for its reaper has ended)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")


def test_the_tui_ends_when_its_terminal_goes_away_just_after_the_first_frame(
    tmp_path: Path,
) -> None:
    # tmux kill-server right after the first frame: SIGHUP (and SIGCONT) while textual is
    # still starting. The app used to hang for good in textual's shutdown (its output
    # thread's queue, restoring a terminal that is gone) and kept the lab open; every TUI a
    # benchmark launched this way stayed behind. Now it releases the lab and ends.
    sock = f"goniolab-hup-{os.getpid()}"
    cmd = [sys.executable, "-m", "goniolab.cli", "tui", "--config",
           str(REPO / "configs" / "lab-sim.toml"), "--store", str(tmp_path / "runs.sqlite")]  # fmt: skip
    subprocess.run(["tmux", "-L", sock, "new-session", "-d", "-x", "120", "-y", "40", "-s", "b",
                    shlex.join(cmd)], check=True, timeout=30)  # fmt: skip
    try:
        pid = int(
            subprocess.run(["tmux", "-L", sock, "display", "-p", "-t", "b", "#{pane_pid}"],
                           check=True, capture_output=True, text=True, timeout=30).stdout
        )  # fmt: skip
        deadline = time.monotonic() + WAIT_S
        while "goniolab" not in subprocess.run(
            ["tmux", "-L", sock, "capture-pane", "-p", "-t", "b"], capture_output=True,
            text=True, timeout=30, check=False,
        ).stdout:  # fmt: skip
            assert time.monotonic() < deadline, "the TUI never showed its first frame"
            time.sleep(0.01)
    finally:
        subprocess.run(["tmux", "-L", sock, "kill-server"], check=False, timeout=30)
    end = time.monotonic() + 30.0
    while _running(pid) and time.monotonic() < end:
        time.sleep(0.1)
    still = _running(pid)
    if still:
        os.kill(pid, 9)
    assert not still, "goniolab tui kept running after its terminal went away"
