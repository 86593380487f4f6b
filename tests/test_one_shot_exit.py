"""How a one-shot ``predict`` process ends (goniolab.cli.console): what the interpreter's
exit does for it still happens (its output whole, its log written, its cyclic garbage
finalized, a thread it left running waited for), less the modules' teardown.

Each check runs the console entry in a fresh interpreter (``python -m goniolab``, or
``console()`` under a test command) and looks at what the process left behind.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _env(tmp_path: Path) -> dict[str, str]:
    # stdout buffered, as a plain run has it (PYTHONUNBUFFERED would flush every write)
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("MALLOC_") and k not in ("PYTHONUNBUFFERED", "GLIBC_TUNABLES")
    }
    return {**env, "GONIOLAB_LOG_DIR": str(tmp_path / "log"), "PYTHONPATH": str(ROOT)}


def _map(tmp_path: Path) -> Path:
    rng = np.random.default_rng(5)
    path = tmp_path / "rough.npy"
    np.save(path, rng.normal(0.0, 0.05, (96, 96)))
    (tmp_path / "rough.npy.json").write_text('{"step_um": 1.0}')
    return path


def test_a_curve_reaches_its_reader_whole_and_the_log_has_the_command(tmp_path: Path) -> None:
    mp = _map(tmp_path)
    proc = subprocess.run(
        [sys.executable, "-m", "goniolab", "predict", "brdf", str(mp), "--theta-r", "0:70:0.1"],
        env=_env(tmp_path),
        cwd=tmp_path,
        capture_output=True,  # stdout a pipe, as `goniolab ... | less` has it
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    angles = [line.split()[0] for line in lines if line[:8].strip().replace(".", "").isdigit()]
    assert len(angles) == 701  # 0, 0.1, ... 70 deg: every row, the last one too
    assert angles[0] == "0.00" and angles[-1] == "70.00"
    log = (tmp_path / "log" / "goniolab.log").read_text()
    assert f"predict brdf {mp} --theta-r 0:70:0.1" in log


#: ``console()`` with ``predict stats`` replaced by ``{command}``; the finalizers write by
#: ``os`` calls bound beforehand (module globals are gone by the time they run).
_CONSOLE = """
import os, sys, threading, time
import goniolab.commands.predict as predict

def note(path, text, _open=os.open, _write=os.write, _close=os.close,
         _flags=os.O_WRONLY | os.O_CREAT):
    fd = _open(path, _flags, 0o644)
    _write(fd, text)
    _close(fd)

class Leaky:
    def __del__(self, _note=note, _path={path!r}):
        _note(_path, b'finalized at exit')

def cycle(args):
    x = Leaky()
    x.cycle = x
    return 0

def late_thread(args):
    def work():
        time.sleep(0.3)
        note({path!r}, b'written by a thread after the command')
    threading.Thread(target=work, daemon=False).start()
    return 0

def status_3(args):
    import atexit
    atexit.register(note, {path!r}, b'exit handler run')
    # printed after main() flushed stdout: only the end's own flush gets it out
    atexit.register(print, 'printed by an exit handler', end='')
    return 3

real_exit = os._exit
def spy(code, _note=note):
    _note({path!r} + '.quick', b'quick end')
    real_exit(code)
os._exit = spy

predict._cmd_stats = {command}
sys.argv = ['goniolab', 'predict', 'stats', 'sample:wittmann-3']
from goniolab.cli import console
console()
"""


def _console(tmp_path: Path, command: str) -> tuple[subprocess.CompletedProcess[str], str, bool]:
    """The process's result, what its command or exit left in the note file, and whether
    it ended by the quick end (``os._exit``)."""
    out = tmp_path / "left.txt"
    proc = subprocess.run(
        [sys.executable, "-c", _CONSOLE.format(path=str(out), command=command)],
        env=_env(tmp_path),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    quick = (tmp_path / "left.txt.quick").exists()
    return proc, out.read_text() if out.exists() else "", quick


def test_the_commands_cyclic_garbage_is_finalized_at_the_end(tmp_path: Path) -> None:
    proc, left, quick = _console(tmp_path, "cycle")
    assert (proc.returncode, left, quick) == (0, "finalized at exit", True)


def test_the_quick_end_runs_the_exit_handlers_flushes_and_keeps_the_status(
    tmp_path: Path,
) -> None:
    proc, left, quick = _console(tmp_path, "status_3")
    assert quick
    assert proc.returncode == 3
    assert left == "exit handler run"
    assert proc.stdout == "printed by an exit handler"


def test_a_thread_the_command_left_running_is_waited_for(tmp_path: Path) -> None:
    # the quick end would cut it off: the interpreter's exit, which joins it, is taken
    proc, left, quick = _console(tmp_path, "late_thread")
    assert (proc.returncode, left, quick) == (0, "written by a thread after the command", False)


def test_a_profiler_wrapping_the_command_still_writes_its_file(tmp_path: Path) -> None:
    mp = _map(tmp_path)
    prof = tmp_path / "predict.prof"
    cmd = [sys.executable, "-m", "cProfile", "-o", str(prof), "-m", "goniolab"]
    proc = subprocess.run(
        [*cmd, "predict", "stats", str(mp)],
        env=_env(tmp_path),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    import pstats

    assert pstats.Stats(str(prof)).total_calls > 0  # type: ignore[attr-defined]
