"""``goniolab samples``: the built-in synthetic samples usable as ``sample:NAME``."""

from __future__ import annotations

import argparse
import json
from typing import Any

from goniolab.errors import UserError

__all__ = ["register"]


def _cmd_samples(args: argparse.Namespace) -> int:
    from goniolab.surfaces.samples import SampleError, sample_info, sample_names

    try:
        infos = [sample_info(name) for name in sample_names()]
    except SampleError as exc:
        raise UserError(str(exc)) from None
    rows = [
        {
            "name": i.name,
            "spec": f"sample:{i.name}",
            "description": i.description,
            "n": i.n.real if i.n.imag == 0 else [i.n.real, i.n.imag],
            "seed_ra_nm": i.seed_ra_nm,
            "seed_g60": i.seed_g60,
        }
        for i in infos
    ]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0

    def ref(v: float | None) -> str:
        return "-" if v is None else f"{v:g}"

    print(f"{'NAME':16}  {'n':>5}  {'Ra nm':>6}  {'G60':>5}  DESCRIPTION")
    for r, i in zip(rows, infos, strict=True):
        n = f"{i.n.real:g}" if i.n.imag == 0 else f"{i.n.real:g}+{i.n.imag:g}i"
        print(
            f"{r['name']:16}  {n:>5}  {ref(i.seed_ra_nm):>6}  {ref(i.seed_g60):>5}  "
            f"{r['description']}"
        )
    print("(Ra and G60: the seed paper's measurements, Wittmann et al. 2021, table 1)")
    return 0


def register(subparsers: Any) -> None:
    """Add ``goniolab samples``."""
    p = subparsers.add_parser("samples", help="list the built-in samples (sample:NAME)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_samples)
