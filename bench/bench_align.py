"""Recovery of ``scan --plan align`` on the realistic twin over many sessions.

Each seed draws both arms' zero offsets and the sample tilt uniformly in +/-1 deg
(``[sim.twin] *_range_deg = 1.0``, 0.02 deg backlash); the plan runs at --time-scale 0 and
its estimates are compared with the drawn truth (``goniolab.lab_wiring.draw_session``).

    .venv/bin/python bench/bench_align.py [--seeds 0:20] [--sample sample:wittmann-3]
        [--s-weight 0.51]

``--s-weight`` sets the twin's spectro's polarisation sensitivity (``[sim.twin] s_weight``,
its share of response to s-polarised light; default the twin's own, 0.51); the black glass
polarises, and the fit finds ``w`` with three or more incidences (printed with its sigma
and the zeros' sigma).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import resource
import tempfile
from pathlib import Path

import numpy as np

KEYS = (
    ("lamp_zero_deg", "lamp_zero_offset_deg"),
    ("detector_zero_deg", "detector_zero_offset_deg"),
    ("sample_tilt_deg", "sample_tilt_deg"),
)


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def config_text(seed: int, sample: str, store: Path, s_weight: float | None = None) -> str:
    """configs/lab-sim.toml with ``seed``, ``sample``, all three ranges at 1 deg and the
    spectro's ``s_weight``."""
    from goniolab.config import configs_dir

    text = (configs_dir() / "lab-sim.toml").read_text().replace("seed = 1", f"seed = {seed}")
    text = text.replace('map = "sample:wittmann-3"', f'map = "{sample}"')
    for key in ("lamp_zero_range_deg", "detector_zero_range_deg", "sample_tilt_range_deg"):
        text = text.replace(f"# {key} = 0.5", f"{key} = 1.0")
    if s_weight is not None:
        text = text.replace('mode = "realistic"', f'mode = "realistic"\ns_weight = {s_weight}', 1)
    return text.replace('store = ""', f'store = "{store}"')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0:20", help="first:stop (stop excluded)")
    ap.add_argument("--sample", default="sample:wittmann-3")
    ap.add_argument(
        "--s-weight", type=float, default=None, help="spectro's s share (the twin's 0.51)"
    )
    args = ap.parse_args()
    from goniolab.cli import main as cli
    from goniolab.config import load_lab_config
    from goniolab.lab_wiring import draw_session

    first, stop = (int(v) for v in args.seeds.split(":"))
    errors = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(first, stop):
            cfg = Path(tmp) / f"lab{seed}.toml"
            store = Path(tmp) / f"runs{seed}.sqlite"
            cfg.write_text(config_text(seed, args.sample, store, args.s_weight))
            truth = draw_session(load_lab_config(cfg))
            out, c0 = io.StringIO(), _cpu()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
                code = cli(["scan", "--config", str(cfg), "--plan", "align", "--time-scale",
                            "0", "--json"])  # fmt: skip
            if code != 0:
                print(f"seed {seed}: align failed (exit {code})")
                continue
            got = json.loads(out.getvalue())
            err = [got[k] - truth[t] for k, t in KEYS]
            errors.append(err)
            print(
                f"seed {seed:3d}: true " + " ".join(f"{truth[t]:+.3f}" for _, t in KEYS)
                + "  error " + " ".join(f"{e:+.4f}" for e in err)
                + f"  sigma {got['standard_fit']['lamp_zero_sigma_deg']:.3f}"
                + f"  w {got['standard_fit']['s_weight']:.4f}"
                + f" +- {got['standard_fit']['s_weight_sigma']:.4f}"
                + f"  ({got['readings']} readings, {_cpu() - c0:.1f} s CPU)",
                flush=True,
            )  # fmt: skip
    e = np.abs(np.asarray(errors))
    print(f"{len(errors)} sessions; largest |error| lamp zero / detector zero / tilt: "
          + " / ".join(f"{v:.4f}" for v in e.max(axis=0)) + " deg")  # fmt: skip


if __name__ == "__main__":
    main()
