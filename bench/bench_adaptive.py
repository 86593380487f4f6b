"""Adaptive against uniform sampling, measured on the realistic twin.

For each sample and point count the same session (seed, misalignment, twin truth) scans
theta_i = 45 deg, theta_r 0..70 deg (``--range``) with a uniform grid and with ``--adaptive`` (the same
number of readings, :mod:`goniolab.scan.adaptive`), both with auto-exposure. Each scan's
readings are interpolated linearly and compared with the twin's noise-free truth on a
0.05 deg grid, at the geometry the sample really sees (the session's zero offsets and tilt,
after the ``[alignment]`` corrections when ``--aligned``). Run time: the dry run's
estimate and the lab clock's elapsed time of the run (moves, exposures, park), both from
the park position.

    .venv/bin/python bench/bench_adaptive.py [--samples wittmann-1,wittmann-3] [--n 36,71]
        [--seeds 1,2] [--aligned --range 1:69]
"""

from __future__ import annotations

import argparse
import asyncio
import re
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def config_text(sample: str, seed: int, store: Path) -> str:
    text = (REPO / "configs" / "lab-sim.toml").read_text()
    text = text.replace('map = "sample:wittmann-3"', f'map = "sample:{sample}"')
    text = text.replace("seed = 1", f"seed = {seed}")
    return re.sub(r"(?m)^store = .*$", f'store = "{store}"', text)


async def one(
    sample: str, seed: int, counts: list[int], aligned: bool, tmp: Path, lo: float, hi: float
) -> list[str]:
    from goniolab.config import load_lab_config
    from goniolab.lab_wiring import draw_session
    from goniolab.scan.adaptive import reconstruction_error
    from goniolab.scan.plans import BrdfPlan
    from goniolab.session import ScanSession
    from goniolab.store import RunStore
    from sim.instruments import effective_angles
    from sim.spectro_chain import y_weights

    cfg_path = tmp / f"{sample}-{seed}.toml"
    cfg_path.write_text(config_text(sample, seed, tmp / f"{sample}-{seed}.sqlite"))
    cfg = load_lab_config(cfg_path)
    drawn = draw_session(cfg)
    if aligned:  # as after `scan --plan align`: the requested angles are the seen ones
        a = cfg.alignment.model_copy(
            update={
                "lamp_zero_deg": drawn["lamp_zero_offset_deg"],
                "detector_zero_deg": drawn["detector_zero_offset_deg"],
                "sample_tilt_deg": drawn["sample_tilt_deg"],
            }
        )
        cfg = cfg.model_copy(update={"alignment": a})
    rows = []
    with RunStore(tmp / f"{sample}-{seed}.sqlite") as store:
        async with ScanSession.open(cfg, store, time_scale=0.0) as session:
            await session.home()
            spectro = session.lab.sims.spectro  # type: ignore[union-attr]
            corr = session.lab.goniometer.corrections_deg
            dense = np.arange(lo, hi + 1e-4, 0.05)
            stray = spectro.chain.stray_pct if spectro.chain is not None else 0.0
            spec = f"sample:{sample}"
            await session.lab.prepare_sample(spec)
            session.lab.put_sample(await session.models.get(spec), spec)

            def truth_at(d: float) -> float:
                ti, tr = effective_angles(
                    45.0 + corr[0], d + corr[1],
                    sample_tilt_deg=drawn["sample_tilt_deg"],
                    lamp_zero_offset_deg=drawn["lamp_zero_offset_deg"],
                    detector_zero_offset_deg=drawn["detector_zero_offset_deg"],
                )  # fmt: skip
                return float(np.dot(y_weights(), 100.0 * spectro._spectral(ti, tr) + stray))

            truth = np.array(await asyncio.to_thread(lambda: [truth_at(d) for d in dense]))
            peak = float(truth.max())
            for n in counts:
                uniform = BrdfPlan(45.0, tuple(float(v) for v in np.linspace(lo, hi, n).round(9)),
                                   sample=spec, auto_exposure=True)  # fmt: skip
                adaptive = await session.adaptive_plan(uniform)
                for plan in (uniform, adaptive):
                    g = cfg.goniometer.park  # both start from the park position
                    await session.lab.goniometer.move_to(g.theta_i_deg, g.theta_r_deg, 60.0)
                    scan = await session.prepare(plan)
                    t0 = session.lab.clock.now()
                    result = await session.run(session.start(scan))
                    lab_s = session.lab.clock.now() - t0
                    pts = store.points(result.run_id)
                    x = [p.theta_r_deg for p in pts]
                    y = [p.luminance_pct for p in pts]
                    rms, worst = reconstruction_error(x, y, dense, truth)
                    rows.append(
                        f"| {sample} | {seed} | {n} | {plan.sampling} | {rms:.4f} | {worst:.4f} "
                        f"| {100 * rms / peak:.2f} | {100 * worst / peak:.1f} "
                        f"| {scan.check.eta_s:.1f} | {lab_s:.1f} |"
                    )
                    print(rows[-1], flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", default="wittmann-1,wittmann-3,wittmann-2,gaussian-s0.05")
    ap.add_argument("--n", default="36,71")
    ap.add_argument("--seeds", default="1")
    ap.add_argument("--aligned", action="store_true")
    ap.add_argument("--range", default="0:70", help="theta_r start:stop, deg (aligned: 1:69)")
    args = ap.parse_args()
    print("| sample | seed | n | sampling | rms error % | max error % | rms / peak % "
          "| max / peak % | estimated s | lab clock s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    lo, hi = (float(v) for v in args.range.split(":"))
    with tempfile.TemporaryDirectory() as tmp:
        for sample in args.samples.split(","):
            for seed in (int(s) for s in args.seeds.split(",")):
                asyncio.run(one(sample, seed, [int(v) for v in args.n.split(",")],
                                args.aligned, Path(tmp), lo, hi))  # fmt: skip


if __name__ == "__main__":
    main()
