"""``goniolab samples``: the built-in synthetic samples usable as ``sample:NAME``, and
``goniolab samples save NAME FILE``: one of them written as a height-map file in any format
goniolab reads (``.sur``, ``.sdf``, ``.gwy``, ``.npy`` + sidecar, ``.csv``, ``.txt``), so
that every file-based example has a file to start from."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

__all__ = ["register"]


def _cmd_samples(args: argparse.Namespace) -> int:
    from goniolab.app.sample_maps import list_samples

    infos = list_samples()
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


def _cmd_save(args: argparse.Namespace) -> int:
    from goniolab.app.sample_maps import save_sample

    saved = save_sample(
        args.name,
        args.file,
        size=args.size,
        seed=args.seed,
        step_um=args.step_um,
        fmt=args.format,
        force=args.force,
    )
    if args.json:
        print(json.dumps(saved.as_dict()))
    else:
        ny, nx = saved.shape
        dx, dy = saved.dx_um, saved.dy_um
        print(
            f"goniolab: wrote {saved.sample} to {saved.file} ({nx} x {ny} points, step "
            f"{dx:g} um, field {nx * dx:g} x {ny * dy:g} um)",
            file=sys.stderr,
        )
    return 0


def register(subparsers: Any) -> None:
    """Add ``goniolab samples`` and ``goniolab samples save``."""
    p = subparsers.add_parser(
        "samples",
        help="list the built-in samples (sample:NAME), or save one as a height-map file",
    )
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_samples)
    sub = p.add_subparsers(dest="samples_command", metavar="ACTION")
    ps = sub.add_parser(
        "save",
        help="write a built-in sample as a height-map file",
        description="Write a built-in sample as a height-map file in the format of the "
        "file's extension (or --format): .sur, .sdf, .gwy, .npy (+ .json sidecar), .csv, .txt.",
    )
    ps.add_argument("name", metavar="NAME", help="a name from 'goniolab samples'")
    ps.add_argument("file", metavar="FILE", help="where to write it")
    ps.add_argument(
        "--size", type=int, default=None, help="points per side (default: 512, the library's)"
    )
    ps.add_argument(
        "--step-um", type=float, default=None, help="lateral step in um (default: 1 um)"
    )
    ps.add_argument("--seed", type=int, default=None, help="random seed (default: the library's)")
    ps.add_argument(
        "--format",
        default=None,
        help="npy, csv, txt, sdf, sdf-ascii, sdf-int16, sdf-int32, sur, sur-int16, gwy "
        "(default: from the extension)",
    )
    ps.add_argument("--force", action="store_true", help="overwrite an existing file")
    ps.add_argument("--json", action="store_true", help="print what was written as JSON")
    ps.set_defaults(func=_cmd_save)
