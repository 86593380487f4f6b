"""Soak test: the simulated lab on the wire under random injected faults (issue 10).

Run:  .venv/bin/python bench/soak_wire.py [--readings 1000] [--points 500] [--seed 1]
      [--timeout-rate 0.01] [--garble-rate 0.01] [--disconnect-rate 0.005]
      [--no-arm-drops] [--json]

The real drivers talk to the simulated lab over Modbus TCP and two ptys (``mode =
"drivers"``, ``start_sim_servers = true``, lab clock at scale 0 so moves and exposures take
no wall time). Once the lab is open (opening is not retried: a user sees one line and
starts again) every device gets random faults (:class:`sim.faults.FaultSpec`): replies
that never come (the drivers' timeout, 1 s here, is real time), garbled frames, and links
that drop and come back ``recover_after_s`` (0.5 s of lab clock) later (the pty is
unpublished and re-published; the Modbus server closes the arms' connection and drops the
unit's requests until it is back; ``--no-arm-drops``: the arms' link never drops). Then:

1. ``gloss log``: ``--readings`` glossmeter readings requested one by one
   (:class:`goniolab.session.GlossSession`, which reconnects after a lost link);
2. the arms are homed (before the arms' faults are switched on: homing is not retried);
3. ``scan``: a ``--points``-point BRDF scan, theta_i 45 deg, theta_r 0..70 deg
   (:class:`goniolab.session.ScanSession`: readings and moves retried after a timeout, a
   garbled reply or a lost link, every reading committed before the next).

Reported: faults injected per kind and per device, the drivers' retries and reconnects,
readings requested / stored / lost (must be 0), runs left ``running`` (must be 0), process
RSS (after opening, after each phase, growth once warm: sampled every 100 gloss readings
and 50 points), wall time per gloss reading and per scan point. Exit status 1 if anything was lost or left running.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from goniolab.config import load_lab_config
from goniolab.scan.events import EventBus, GlossRead, InstrumentError, PointMeasured
from goniolab.scan.plans import BrdfPlan, GlossPlan
from goniolab.session import GlossSession, ScanSession
from goniolab.store import RunStore
from sim.faults import FaultSpec

CONFIG = """
[lab]
mode = "drivers"
start_sim_servers = true
time_scale = 0.0
store = "{store}"

[sample]
map = "sample:wittmann-3"

[goniometer.lamp]
port = 0
unit_id = 1
timeout_s = {timeout_s}

[goniometer.detector]
port = 0
unit_id = 2
limits_deg = [0.0, 70.0]
timeout_s = {timeout_s}

[spectro]
port = "{work}/spectro"
timeout_s = {timeout_s}

[glossmeter]
port = "{work}/gloss"
timeout_s = {timeout_s}

[sim]
seed = {seed}
"""


def rss_mib() -> tuple[float, float]:
    """(current, peak) resident set size of this process, MiB (Linux /proc)."""
    fields = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            fields[key] = int(value.split()[0]) / 1024
    return fields.get("VmRSS", float("nan")), fields.get("VmHWM", float("nan"))


async def soak(
    *,
    readings: int,
    points: int,
    seed: int = 1,
    timeout_rate: float = 0.01,
    garble_rate: float = 0.01,
    disconnect_rate: float = 0.005,
    late_rate: float = 0.0,
    late_s: float = 1.5,
    freeze_store_s: float = 0.0,
    arm_drops: bool = True,
    timeout_s: float = 1.0,
    workdir: Path,
) -> dict[str, Any]:
    """Run the soak in ``workdir``; return the figures (see the module docstring)."""
    cfg_path = workdir / "soak.toml"
    store_path = workdir / "soak.sqlite"
    cfg_path.write_text(
        CONFIG.format(
            store=store_path,
            work=workdir,
            seed=seed,
            timeout_s=timeout_s,
        )
    )
    cfg = load_lab_config(cfg_path)
    bus = EventBus()
    events: Counter[str] = Counter()
    queue = bus.subscribe()

    rss_samples: list[tuple[str, float]] = []
    messages: list[str] = []

    frozen: dict[str, Any] = {"after_point": 2, "done": None}

    def freeze_store() -> None:
        """Hold the store's write lock from another connection for ``freeze_store_s``
        (another program locking the file; past the store's busy timeout the scan pauses
        with the arms parked and goes on once the store is back)."""
        import sqlite3

        con = sqlite3.connect(store_path, isolation_level=None)
        try:
            con.execute("BEGIN EXCLUSIVE")
            time.sleep(freeze_store_s)
            con.execute("COMMIT")
        finally:
            con.close()

    async def count_events() -> None:
        """Count retried / fatal instrument errors; sample the RSS every 100 gloss readings
        and every 50 scan points (a leak grows with the count, warm-up does not); freeze the
        store once the scan has stored a few points."""
        while (ev := await queue.get()) is not None:
            if isinstance(ev, InstrumentError):
                events[f"{ev.device} {'fatal' if ev.fatal else 'retried'}"] += 1
                messages.append(f"{'FATAL ' if ev.fatal else ''}{ev.device}: {ev.message}")
            elif isinstance(ev, GlossRead | PointMeasured):
                kind = "gloss" if isinstance(ev, GlossRead) else "point"
                events[kind] += 1
                if events[kind] % (100 if kind == "gloss" else 50) == 0:
                    rss_samples.append((f"{kind} {events[kind]}", rss_mib()[0]))
                if (
                    kind == "point"
                    and freeze_store_s > 0
                    and frozen["done"] is None
                    and events["point"] >= frozen["after_point"]
                ):
                    frozen["done"] = asyncio.get_running_loop().run_in_executor(None, freeze_store)

    counter = asyncio.create_task(count_events())
    out: dict[str, Any] = {"seed": seed, "rates": {"timeout": timeout_rate, "garble": garble_rate,
                                                   "disconnect": disconnect_rate,
                                                   "late": late_rate},
                           "late_s": late_s, "freeze_store_s": freeze_store_s,
                           "arm_drops": arm_drops}  # fmt: skip
    with RunStore(store_path) as store:
        async with ScanSession.open(cfg, store, bus=bus) as session:
            lab = session.lab
            assert lab.sims is not None
            # the lab opens and the arms home without faults (neither is retried: a user
            # sees one line and starts again); the readings and the scan meet them
            faults = FaultSpec(
                timeout_rate=timeout_rate,
                garble_rate=garble_rate,
                disconnect_rate=disconnect_rate,
                recover_after_s=0.5,
                late_rate=late_rate,
                late_s=late_s,
            )
            lab.sims.spectro.faults.spec = lab.sims.glossmeter.faults.spec = faults
            rss_start, _ = rss_mib()
            # 1. gloss readings
            gloss = GlossSession.of_lab(lab, store, bus=bus)
            logger = await gloss.start(GlossPlan(count=readings, sample=cfg.sample.map))
            t0 = time.perf_counter()
            g = await logger.run()
            gloss_s = time.perf_counter() - t0
            stored_gloss = len(store.gloss_readings(g.run_id))
            out["gloss"] = {
                "requested": readings, "stored": stored_gloss, "lost": readings - stored_gloss,
                "state": g.state.value, "reason": g.reason, "reconnects": g.reconnects,
                "ms_per_reading": round(1e3 * gloss_s / max(stored_gloss, 1), 2),
            }  # fmt: skip
            rss_mid, _ = rss_mib()
            # 2. the scan
            if not await session.homed():
                await session.home()
            lab.sims.lamp.faults.spec = lab.sims.detector.faults.spec = FaultSpec(
                timeout_rate=timeout_rate,
                garble_rate=garble_rate,
                disconnect_rate=disconnect_rate if arm_drops else 0.0,
                recover_after_s=0.5,
            )
            angles = tuple(float(a) for a in np.round(np.linspace(0.0, 70.0, points), 6))
            plan = BrdfPlan(45.0, angles, repeats=1, sample=cfg.sample.map)
            prepared = await session.prepare(plan)
            runner = session.start(prepared)
            t0 = time.perf_counter()
            r = await session.run(runner)
            scan_s = time.perf_counter() - t0
            stored_points = store.count_points(r.run_id)
            out["scan"] = {
                "requested": points, "stored": stored_points, "lost": points - stored_points,
                "state": r.state.value, "reason": r.reason,
                "ms_per_point": round(1e3 * scan_s / max(stored_points, 1), 2),
                **_geometry_check(store.points(r.run_id), _answered(session.lab)),
            }  # fmt: skip
            if frozen["done"] is not None:
                await frozen["done"]
            per_device = {
                name: dict(getattr(lab.sims, name).faults.injected)
                for name in ("lamp", "detector", "spectro", "glossmeter")
            }
            per_kind: Counter[str] = Counter()
            for counts in per_device.values():
                per_kind.update(counts)
            out["faults_injected"] = {"by_kind": dict(per_kind), "by_device": per_device}
        rss_end, rss_peak = rss_mib()
        out["runs_left_running"] = sum(1 for rec in store.list_runs() if rec.status == "running")
    bus.close()
    await counter
    out["instrument_errors"] = {k: v for k, v in events.items() if k not in ("gloss", "point")}
    out["last_instrument_errors"] = messages[-6:]
    # growth once warm: from the first sample of each phase (caches, lazy imports and the
    # twin's tables are built by then) to the last one
    warm = {
        kind: [v for label, v in rss_samples if label.startswith(kind)]
        for kind in ("gloss", "point")
    }
    out["rss_mib"] = {
        "after_open": round(rss_start, 1),
        "after_gloss": round(rss_mid, 1),
        "after_scan": round(rss_end, 1),
        "growth": round(rss_end - rss_start, 1),
        "growth_gloss_warm": round(warm["gloss"][-1] - warm["gloss"][0], 1)
        if len(warm["gloss"]) > 1
        else None,
        "growth_scan_warm": round(warm["point"][-1] - warm["point"][0], 1)
        if len(warm["point"]) > 1
        else None,
        "peak": round(rss_peak, 1),
        "samples": [(label, round(v, 1)) for label, v in rss_samples],
    }
    return out


def _answered(lab: Any) -> list[tuple[float, float, str]]:
    """What the wire STIL answered, at which geometry (sim.wire.serial.StilPtyDevice)."""
    stil = getattr(lab.server, "spectro", None) if lab.server is not None else None
    return list(getattr(stil, "answered", []))


def _geometry_check(points: Any, answered: list[tuple[float, float, str]]) -> dict[str, int]:
    """Each stored reading against the STIL's answers: the answer carrying its value must
    have been given at its geometry (within 1 deg: the twin's zero offsets and tilt), else
    the reading is stored at the wrong angle (a late reply taken for the next request).
    Readings whose value no answer carries are counted apart (a profile whose first reply
    line is not the luminance cannot be checked this way)."""
    by_value: dict[float, list[float]] = {}
    for _ti, tr, line in answered:
        try:
            value = round(float(line.split("=", 1)[1].split()[0]), 4)
        except (IndexError, ValueError):
            continue
        by_value.setdefault(value, []).append(tr)
    off = unmatched = 0
    for p in points:
        angles = by_value.get(round(float(p.luminance_pct), 4))
        if not angles:
            unmatched += 1
        elif min(abs(a - p.theta_r_deg) for a in angles) > 1.0:
            off += 1
    return {"readings_off_geometry": off, "readings_unmatched": unmatched}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--readings", type=int, default=1000)
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout-rate", type=float, default=0.01)
    ap.add_argument("--garble-rate", type=float, default=0.01)
    ap.add_argument("--disconnect-rate", type=float, default=0.005)
    ap.add_argument(
        "--late-rate", type=float, default=0.0, help="serial answers --late-s late (default 0)"
    )
    ap.add_argument("--late-s", type=float, default=1.5, help="how late, s (default 1.5)")
    ap.add_argument(
        "--freeze-store-s",
        type=float,
        default=0.0,
        help="hold the store's write lock this long after the scan's 2nd point (default 0)",
    )
    ap.add_argument(
        "--no-arm-drops",
        action="store_true",
        help="the arms get timeouts and garbled frames only (their link never drops)",
    )
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="goniolab-soak-") as tmp:
        t0 = time.perf_counter()
        out = asyncio.run(
            soak(
                readings=args.readings,
                points=args.points,
                seed=args.seed,
                timeout_rate=args.timeout_rate,
                garble_rate=args.garble_rate,
                disconnect_rate=args.disconnect_rate,
                late_rate=args.late_rate,
                late_s=args.late_s,
                freeze_store_s=args.freeze_store_s,
                arm_drops=not args.no_arm_drops,
                workdir=Path(tmp),
            )
        )
        out["wall_s"] = round(time.perf_counter() - t0, 1)
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        for key, value in out.items():
            print(f"{key:20s} {value}")
    bad = (
        out["gloss"]["lost"]
        or out["scan"]["lost"]
        or out["runs_left_running"]
        or out["scan"]["readings_off_geometry"]
    )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
