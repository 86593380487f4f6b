"""How right the live ETA is (issue 27): a scan or an alignment on the simulated lab, the
ETA of each Progress event against the wall time the run really took after it.

    .venv/bin/python bench/bench_eta.py [--plan sweep|align] [--time-scale 1]
        [--theta-r 0:70:1] [--every 8]

Prints, for every ``--every``-th reading, the ETA, the time really left (wall seconds
from that event to the end of the run: a scan's park move included, an alignment's last
reading) and the error; then the largest error (relative, at least 1 s) from the fifth
reading on. The ETA comes from :class:`goniolab.scan.eta.EtaEstimator` (measured rates of
moves, dwells and readings).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import tempfile
import time
import warnings
from pathlib import Path

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "lab-sim.toml"


async def measure(plan_kind: str, time_scale: float, theta_r: str) -> list[tuple[int, int, float, float]]:  # fmt: skip
    """(done, total, eta_s, wall time) of every Progress event of one run."""
    from goniolab.config import load_lab_config
    from goniolab.scan.align import AlignPlan
    from goniolab.scan.events import Progress
    from goniolab.scan.plans import BrdfPlan, parse_angles
    from goniolab.session import ScanSession
    from goniolab.store import RunStore

    cfg = load_lab_config(CONFIG)
    seen: list[tuple[int, int, float, float]] = []
    with tempfile.TemporaryDirectory() as tmp, RunStore(str(Path(tmp) / "runs.sqlite")) as store:
        async with ScanSession.open(cfg, store, time_scale=time_scale) as session:
            publish = session.bus.publish

            def record(ev: object) -> None:
                if isinstance(ev, Progress):
                    seen.append((ev.done, ev.total, ev.eta_s, time.monotonic()))
                publish(ev)  # type: ignore[arg-type]

            session.bus.publish = record  # type: ignore[method-assign]
            if plan_kind == "align":
                await session.align(AlignPlan(sample=cfg.sample.map), save_state=False)
            else:
                plan = BrdfPlan(45.0, parse_angles(theta_r), sample=cfg.sample.map)
                if not await session.homed():
                    await session.home()
                scan = await session.prepare(plan)
                await session.run(session.start(scan))
                # a scan's ETA holds its park move: the time left ends with the run
                last = seen[-1]
                seen.append((last[0], last[1], 0.0, time.monotonic()))
    return seen


def main() -> None:
    # the CLI's own filter of colour-science's shape notice (a notice, not a result)
    warnings.filterwarnings("ignore", message=".*illuminant shape to.*")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plan", choices=("sweep", "align"), default="sweep")
    ap.add_argument("--time-scale", type=float, default=1.0)
    ap.add_argument("--theta-r", default="0:70:1")
    ap.add_argument("--every", type=int, default=8)
    args = ap.parse_args()
    seen = asyncio.run(measure(args.plan, args.time_scale, args.theta_r))
    end = seen[-1][3]
    print(f"{args.plan} at --time-scale {args.time_scale:g}: {seen[-1][0]} readings, "
          f"{end - seen[0][3]:.1f} s")  # fmt: skip
    print("  done/total    ETA s   left s   error s")
    worst = 0.0
    for i, (done, total, eta, t) in enumerate(seen):
        left = end - t
        err = eta - left
        if done >= 5 and math.isfinite(err):
            worst = max(worst, abs(err) / max(left, 1.0))
        if i % args.every == 0 or i == len(seen) - 1:
            print(f"  {done:4d}/{total:<4d} {eta:9.2f} {left:8.2f} {err:+9.2f}")
    print(f"largest |error| / max(left, 1 s) from the fifth reading on: {worst:.2f}")


if __name__ == "__main__":
    main()
