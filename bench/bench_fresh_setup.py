"""A newcomer's first ``make run``: fresh clone to the TUI's first frame (issue 26).

Run:  python3 bench/bench_fresh_setup.py [--repo PATH] [--keep]

Clones the repository (default: this one) into a temporary directory, starts ``make run``
there in a detached tmux session (120 x 40, as a terminal would show it) and polls the screen
every 0.2 s. It reports, from the launch:

- when each stage line of the Makefile appeared (``goniolab: creating the virtual
  environment``, ``goniolab: installing goniolab ...``, ``goniolab: starting the TUI ...``)
  and how many lines pip printed meanwhile (what a newcomer watches);
- ``first frame``: the TUI on screen (its header, or "opening the lab...");
- ``lab widgets``: the lab's widgets on screen (the glossmeter log).

Then it quits the app (``q``) and removes the clone (``--keep`` keeps it). Needs git, make,
tmux and python3 (3.11+) on the PATH; pip reaches the package index the machine is set up
for. The issue's target: first frame within 60 s on 2 cores, progress visible meanwhile.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
STAGES = (
    ("venv", "goniolab: creating the virtual environment"),
    ("install", "goniolab: installing goniolab"),
    ("start", "goniolab: starting the TUI"),
)
TIMEOUT_S = 900.0
#: The TUI's first frame: its header, or the boot line while the lab's modules load.
FIRST_FRAME = ("goniolab \u2014", "opening the lab")
#: The lab's widgets: the glossmeter log's title (shown at every terminal size).
LAB_WIDGETS = "glossmeter log"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--repo", default=str(ROOT), help="repository to clone (default: this one)")
    ap.add_argument("--keep", action="store_true", help="keep the clone")
    ap.add_argument("--json", action="store_true", help="print JSON")
    args = ap.parse_args(argv)
    if shutil.which("tmux") is None:
        print("bench_fresh_setup: tmux is not installed", file=sys.stderr)
        return 2
    tmp = Path(tempfile.mkdtemp(prefix="goniolab-fresh-"))
    clone = tmp / "goniolab"
    subprocess.run(["git", "clone", "-q", args.repo, str(clone)], check=True)
    sock = f"goniolab-fresh-{os.getpid()}"
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH")}
    env["GONIOLAB_LOG_DIR"] = str(tmp / "logs")
    log = tmp / "make.log"
    cmd = f"cd {clone} && make run 2>&1 | tee {log}"
    t0 = time.perf_counter()
    subprocess.run(
        ["tmux", "-L", sock, "new-session", "-d", "-x", "120", "-y", "40", "-s", "f", cmd],
        env=env,
        check=True,
    )
    seen: dict[str, float] = {}
    first = lab = None
    try:
        while time.perf_counter() - t0 < TIMEOUT_S:
            pane = subprocess.run(
                ["tmux", "-L", sock, "capture-pane", "-p", "-t", "f"],
                capture_output=True,
                text=True,
                check=False,
            ).stdout
            now = time.perf_counter() - t0
            text = log.read_text(errors="replace") if log.exists() else ""
            for name, marker in STAGES:
                if name not in seen and marker in text:
                    seen[name] = now
            if "start" in seen and first is None and any(m in pane for m in FIRST_FRAME):
                first = now
            if "start" in seen and LAB_WIDGETS in pane:
                lab = now
                first = now if first is None else first
                break
            if "make: ***" in text:
                break
            time.sleep(0.2)
    finally:
        subprocess.run(["tmux", "-L", sock, "send-keys", "-t", "f", "q"], check=False)
        time.sleep(1.0)
        subprocess.run(["tmux", "-L", sock, "kill-server"], check=False)
    lines = log.read_text(errors="replace").splitlines() if log.exists() else []
    pip_lines = sum(1 for line in lines if not line.startswith(("goniolab:", ".venv/", "python")))
    out: dict[str, Any] = {
        "stages_s": {k: round(v, 1) for k, v in seen.items()},
        "pip_lines": pip_lines,
        "first_frame_s": None if first is None else round(first, 1),
        "lab_widgets_s": None if lab is None else round(lab, 1),
        "target_s": 60.0,
        "load_average": os.getloadavg(),
    }
    if args.keep:
        out["clone"] = str(clone)
    else:
        shutil.rmtree(tmp, ignore_errors=True)
    if args.json:
        print(json.dumps(out))
    else:
        for k, v in out["stages_s"].items():
            print(f"stage {k:8s} at {v:6.1f} s")
        print(f"pip printed {pip_lines} lines while it installed")
        print(f"first frame      {out['first_frame_s']} s (target <= 60 s)")
        print(f"lab widgets      {out['lab_widgets_s']} s")
        la = out["load_average"]
        print(f"load average {la[0]:.1f} {la[1]:.1f} {la[2]:.1f} (2 cores)")
    return 0 if first is not None and first <= 60.0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
