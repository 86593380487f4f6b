"""Scan sequencer overhead per reading, and the TUI's first frame (issue 13).

Run:  .venv/bin/python bench/bench_scan.py [--points 71] [--repeats 5] [--runs 5] [--json]

Sequencer: the :class:`goniolab.scan.runner.ScanRunner` loop (checkpoint, move, dwell,
read, commit the reading to the store, publish events, progress) over
``--points x --repeats`` readings with a simulated clock at time scale 0, against

- null instruments: a goniometer and a spectro that answer at once (their own cost is
  nil), so the time per reading is the sequencer's own overhead (target <= 1 ms);
- the in-process simulated lab (``configs/lab-sim.toml`` at --time-scale 0), whose
  instrument models add their own cost.

Each runs with the run store on a RAM file system (``/dev/shm`` when there is one) and
on the disk: the store commits every reading with ``synchronous=FULL`` (nothing lost on a
crash), so on a disk each reading also pays an fsync, a price of the durability rule that
the table shows apart. No prediction (the model is benchmarked in bench_whole.py).

TUI: ``goniolab tui --config configs/lab-sim.toml`` under tmux (when installed), polling
``capture-pane`` every 10 ms from the launch until the title ``goniolab`` is on the screen
(the first frame, target <= 1 s; it says "opening the lab..." while the lab's modules load)
and until the lab's widgets are (``scan setup``), median of ``--runs`` launches; and in
process with textual's ``App.run_test``: from constructing the app (backend built) to its
first mounted screen.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivers.base import AxisStatus, SpectroReading  # noqa: E402
from drivers.timing import SimClock  # noqa: E402
from goniolab.scan.events import EventBus  # noqa: E402
from goniolab.scan.plans import BrdfPlan  # noqa: E402
from goniolab.scan.runner import ArmMotion, ScanRunner  # noqa: E402
from goniolab.store import RunStore  # noqa: E402


class NullAxis:
    """An arm that is always homed and where it was sent."""

    def __init__(self) -> None:
        self.pos = 0.0

    async def status(self) -> AxisStatus:
        return AxisStatus(position_deg=self.pos, homed=True)


class NullGoniometer:
    """Moves instantly, never refuses a geometry."""

    min_separation_deg = 0.0

    def __init__(self) -> None:
        self.lamp, self.detector = NullAxis(), NullAxis()

    def check_geometry(self, theta_i_deg: float, theta_r_deg: float) -> None:
        return None

    async def home(self, timeout_s: float) -> None:
        return None

    async def move_to(self, ti: float, tr: float, timeout_s: float) -> tuple[float, float]:
        self.lamp.pos, self.detector.pos = ti, tr
        return ti, tr

    async def positions_deg(self) -> tuple[float, float]:
        return self.lamp.pos, self.detector.pos

    async def park(self, timeout_s: float) -> None:
        return None

    async def stop(self) -> None:
        return None


class NullSpectro:
    """Answers every reading at once with the same spectrum."""

    READING = SpectroReading(
        wavelengths_nm=tuple(380.0 + 10 * k for k in range(41)),
        values=(50.0,) * 41,
        luminance_pct=50.0,
        exposure_us=1000,
    )

    async def set_exposure_us(self, exposure_us: int) -> None:
        return None

    async def measure(self) -> SpectroReading:
        return self.READING


async def _scan(
    store_path: Path, points: int, repeats: int, lab: Any | None
) -> tuple[float, float]:
    plan = BrdfPlan(
        theta_i_deg=45.0,
        theta_r_deg=tuple(float(t) for t in range(points)),
        repeats=repeats,
        exposure_us=1000,
        sample="sample:flat",
    )
    store = RunStore(store_path)
    with store:
        run_id = store.create_run(
            kind="brdf", plan=plan.to_dict(), config={}, sample=plan.sample, model={}, version=""
        )
        if lab is None:
            gonio, spectro, clock = NullGoniometer(), NullSpectro(), SimClock(0.0)
        else:
            gonio, spectro, clock = lab.goniometer, lab.spectro, lab.clock
        bus = EventBus()
        q = bus.subscribe()

        async def drain() -> None:
            while await q.get() is not None:
                pass

        consumer = asyncio.create_task(drain())
        runner = ScanRunner(
            goniometer=gonio,  # type: ignore[arg-type]
            spectro=spectro,  # type: ignore[arg-type]
            clock=clock,
            plan=plan,
            store=store,
            run_id=run_id,
            bus=bus,
            motion=ArmMotion(1e9, 1e12, 1e9, 1e12),
        )
        t0, c0 = time.perf_counter(), time.process_time()
        result = await runner.run()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        bus.close()
        await consumer
        assert result.state.value == "done", result
        return wall / (points * repeats), cpu / (points * repeats)


async def _lab_scan(store_path: Path, points: int, repeats: int) -> tuple[float, float]:
    from goniolab.config import load_lab_config
    from goniolab.lab_wiring import Lab

    cfg = load_lab_config(ROOT / "configs" / "lab-sim.toml")
    async with Lab.from_config(cfg, time_scale=0.0) as lab:
        await lab.goniometer.home(120.0)
        return await _scan(store_path, points, repeats, lab)


def sequencer(points: int, repeats: int, runs: int) -> dict[str, float]:
    shm = Path("/dev/shm")
    ram_dir = Path(tempfile.mkdtemp(dir=shm if shm.is_dir() else None))
    disk_dir = Path(tempfile.mkdtemp(dir=ROOT))
    out: dict[str, float] = {}
    try:
        for where, d in (("ram", ram_dir), ("disk", disk_dir)):
            null = [asyncio.run(_scan(d / f"n{k}.db", points, repeats, None)) for k in range(runs)]
            out[f"null_{where}_ms"] = 1e3 * statistics.median(r[0] for r in null)
            out[f"null_{where}_cpu_ms"] = 1e3 * statistics.median(r[1] for r in null)
            lab = [asyncio.run(_lab_scan(d / f"l{k}.db", points, repeats)) for k in range(runs)]
            out[f"sim_{where}_ms"] = 1e3 * statistics.median(r[0] for r in lab)
            out[f"sim_{where}_cpu_ms"] = 1e3 * statistics.median(r[1] for r in lab)
    finally:
        shutil.rmtree(ram_dir, ignore_errors=True)
        shutil.rmtree(disk_dir, ignore_errors=True)
    return out


def tui_tmux(runs: int) -> tuple[list[float], list[float]] | None:
    """Launch-to-first-frame and launch-to-lab-widgets times of the TUI in tmux, or None
    without tmux."""
    if shutil.which("tmux") is None:
        return None
    goniolab = str(Path(sys.executable).parent / "goniolab")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    times: list[float] = []
    lab_times: list[float] = []
    for k in range(runs + 1):  # the first launch writes the bytecode caches: not counted
        sock = f"goniolab-bench-{os.getpid()}-{k}"  # a fresh server per launch
        store = Path(tempfile.mkdtemp()) / "runs.db"
        cmd = [goniolab, "tui", "--config", str(ROOT / "configs" / "lab-sim.toml"),
               "--store", str(store)]  # fmt: skip
        t0 = time.perf_counter()
        started = subprocess.run(["tmux", "-L", sock, "new-session", "-d", "-x", "120", "-y",
                                  "40", "-s", "b", " ".join(cmd)], env=env, check=False)  # fmt: skip
        if started.returncode != 0:
            continue
        seen = lab = None
        while time.perf_counter() - t0 < 30.0:
            pane = subprocess.run(
                ["tmux", "-L", sock, "capture-pane", "-p", "-t", "b"],
                capture_output=True,
                text=True,
            ).stdout
            if seen is None and "goniolab" in pane:
                seen = time.perf_counter() - t0
            if "scan setup" in pane:
                lab = time.perf_counter() - t0
                break
            time.sleep(0.01)
        subprocess.run(["tmux", "-L", sock, "kill-server"], check=False)
        shutil.rmtree(store.parent, ignore_errors=True)
        if seen is not None and lab is not None and k > 0:
            times.append(seen)
            lab_times.append(lab)
    return times, lab_times


def tui_in_process(runs: int) -> list[float]:
    from goniolab.tui.app import GonioApp
    from goniolab.tui.session_backend import SessionBackend

    async def once(store: Path) -> float:
        t0 = time.perf_counter()
        backend = SessionBackend(str(ROOT / "configs" / "lab-sim.toml"), store_path=str(store))
        app = GonioApp(backend)
        async with app.run_test(size=(120, 40)) as pilot:
            await pilot.pause()
            first = time.perf_counter() - t0
            await app.action_quit()
        return first

    out = []
    for _ in range(runs):
        d = Path(tempfile.mkdtemp())
        out.append(asyncio.run(once(d / "runs.db")))
        shutil.rmtree(d, ignore_errors=True)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=71)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    seq = sequencer(args.points, args.repeats, args.runs)
    tmux = tui_tmux(args.runs)
    inproc = tui_in_process(args.runs)
    out: dict[str, Any] = {
        "readings_per_scan": args.points * args.repeats,
        "sequencer_ms_per_reading": seq,
        "tui_first_frame_tmux_s": None if tmux is None else statistics.median(tmux[0]),
        "tui_lab_widgets_tmux_s": None if tmux is None else statistics.median(tmux[1]),
        "tui_first_frame_in_process_s": statistics.median(inproc),
        "load_average": (load0, os.getloadavg()[0]),
        "runs": args.runs,
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(
        f"scan sequencer, {out['readings_per_scan']} readings per scan at time scale 0, median "
        f"of {args.runs} scans, load average {load0:.1f} / {os.getloadavg()[0]:.1f}"
    )
    print(f"{'instruments':24}{'store in RAM':>14}{'(CPU)':>10}{'store on disk':>15}{'(CPU)':>10}")
    for label, key in (("null (sequencer only)", "null"), ("in-process sim lab", "sim")):
        print(
            f"{label:24}{seq[key + '_ram_ms']:12.3f}ms{seq[key + '_ram_cpu_ms']:8.3f}ms"
            f"{seq[key + '_disk_ms']:13.3f}ms{seq[key + '_disk_cpu_ms']:8.3f}ms"
        )
    print("(milliseconds per reading: wall, and this process's CPU time)")
    tm = out["tui_first_frame_tmux_s"]
    print(
        "TUI first frame: "
        + (
            "tmux not installed"
            if tm is None
            else f"{tm:.2f} s launch to screen (tmux), the lab's widgets at "
            f"{out['tui_lab_widgets_tmux_s']:.2f} s"
        )
        + f", {out['tui_first_frame_in_process_s']:.2f} s in process (run_test)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
