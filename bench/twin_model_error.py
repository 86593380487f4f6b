"""The realistic twin's model error per sample: prediction vs the twin's noise-free truth.

For every sample of the library: the facet-model prediction from the profilometer map
(what goniolab predicts) and the twin's truth (sim/truth.py: finer surface, sub-resolution
roughness, waviness, scalar Kirchhoff) read through the same instruments without noise:
peak amplitude and FWHM of the in-plane curve at theta_i = 45 deg (theta_r 0..70 deg,
6 deg cones) and ISO 2813 gloss at 20/60/85 deg. Prints a Markdown table (docs/TWIN.md
quotes it) and the cost of building each truth; ``--write docs/TWIN.md`` puts the table
between the file's ``<!-- generated: bench/twin_model_error.py -->`` and
``<!-- end generated -->`` lines (tests/test_docs_fresh.py checks the predicted columns
against the code).

    .venv/bin/python bench/twin_model_error.py [--samples a,b] [--no-cache] [--write docs/TWIN.md]
"""

from __future__ import annotations

import argparse
import re
import time
from pathlib import Path
from typing import Any

import numpy as np

from goniolab.model_cache import model_for
from goniolab.optics.apertures import Cone
from goniolab.optics.metrics import peak_metrics
from goniolab.surfaces.resolve import resolve_map
from goniolab.surfaces.synthetic import sample_info, sample_names
from sim.truth import TwinSettings, truth_for

#: theta_i of the in-plane curve, deg; the cones' full angle, deg.
THETA_I_DEG = 45.0
CONE_DEG = 6.0
HEADER = (
    "| sample | peak % pred / twin | FWHM deg pred / twin | G20 pred / twin | G60 pred / twin "
    "| G85 pred / twin |\n|---|---|---|---|---|---|"
)
BEGIN = "<!-- generated: bench/twin_model_error.py -->"
END = "<!-- end generated -->"


def predicted(name: str, step_deg: float = 0.25) -> tuple[Any, dict[int, float]]:
    """The prediction of goniolab (the sample's default model): peak metrics of the in-plane
    curve and ISO 2813 gloss per geometry."""
    tr = np.arange(0.0, 70.0 + 1e-9, step_deg)
    cone = Cone(CONE_DEG)
    model = model_for(f"sample:{name}", n=sample_info(name).n.real)
    pred = model.luminance_pct(THETA_I_DEG, tr, source=cone, detector=cone)
    return peak_metrics(tr, pred), dict(model.gloss())


def row(name: str, pp: Any, pm: Any, gp: dict[int, float], gm: dict[int, float]) -> str:
    """One Markdown row: prediction / twin per column."""

    def fw(v: float) -> str:
        return "-" if not np.isfinite(v) else f"{v:.2f}"

    return (
        f"| {name} | {pp.amplitude:.3g} / {pm.amplitude:.3g} | {fw(pp.fwhm_deg)} / "
        f"{fw(pm.fwhm_deg)} | {gp[20]:.1f} / {gm[20]:.1f} | {gp[60]:.1f} / {gm[60]:.1f} | "
        f"{gp[85]:.1f} / {gm[85]:.1f} |"
    )


def write_table(path: Path, table: str) -> None:
    """Replace the generated block of ``path`` with ``table``."""
    text = path.read_text()
    block = re.compile(re.escape(BEGIN) + r"\n.*?" + re.escape(END), re.S)
    if not block.search(text):
        raise SystemExit(f"{path}: no {BEGIN} ... {END} block")
    path.write_text(block.sub(lambda _: f"{BEGIN}\n{table}\n{END}", text))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", default="", help="comma-separated names (default: all)")
    ap.add_argument("--no-cache", action="store_true", help="build every table afresh")
    ap.add_argument("--step", type=float, default=0.25, help="theta_r step, deg")
    ap.add_argument("--write", type=Path, help="put the table into this Markdown file")
    args = ap.parse_args()
    names = [n for n in args.samples.split(",") if n] or sample_names()
    import platformdirs

    cache = None if args.no_cache else str(platformdirs.user_cache_dir("goniolab")) + "/twin"
    settings = TwinSettings(cache_dir=cache)
    tr = np.arange(0.0, 70.0 + 1e-9, args.step)
    cone = Cone(CONE_DEG)
    rows = []
    for name in names:
        spec = f"sample:{name}"
        info = sample_info(name)
        n = info.n.real
        pp, g_pred = predicted(name, args.step)
        t0 = time.perf_counter()
        optics = truth_for(
            resolve_map(spec),
            n=n,
            body=str(info.params.get("body", "black")),
            settings=settings,
            name=spec,
        )
        t_truth = time.perf_counter() - t0
        t1 = time.perf_counter()
        meas = optics.luminance_pct(THETA_I_DEG, tr, source=cone, detector=cone)
        g_meas = optics.gloss()
        t_read = time.perf_counter() - t1
        optics.save_cache()
        pm = peak_metrics(tr, meas)
        rows.append(
            (name, pp, pm, g_pred, g_meas, t_truth, optics.build_seconds, optics.ffts, t_read)
        )
        print(
            f"# {name}: truth {t_truth:.1f} s, {optics.ffts} tables {optics.build_seconds:.1f} s, "
            f"readings {t_read:.1f} s",
            flush=True,
        )
    table = "\n".join([HEADER, *(row(name, pp, pm, gp, gm) for name, pp, pm, gp, gm, *_ in rows)])
    print()
    print(table)
    if args.write:
        write_table(args.write, table)


if __name__ == "__main__":
    main()
