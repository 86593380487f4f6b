"""``goniolab runs list | show RUN | export RUN``: browse and export the run store."""

from __future__ import annotations

import argparse
import datetime as dt
import itertools
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from goniolab.errors import UserError

if TYPE_CHECKING:  # sqlite3 and the plans load when a command runs, not at --help
    from goniolab.store import RunRecord, RunStore

__all__ = ["angles_text", "open_store", "plan_text", "register", "run_summary", "store_path"]


def store_path(store_arg: str | None, config_arg: str | None = None) -> Path | str:
    """The store chosen by ``--store``, else config ``[lab] store``, else the default."""
    from goniolab.store import resolve_store_path

    config_store: str | None = None
    if config_arg:
        from goniolab.config import load_lab_config

        config_store = load_lab_config(config_arg).lab.store
    return resolve_store_path(store_arg, config_store)


def open_store(store_arg: str | None, config_arg: str | None = None) -> RunStore:
    """Open the chosen store for reading (nothing is created or written; it must exist)."""
    from goniolab.store import RunStore, StoreError

    try:
        return RunStore(store_path(store_arg, config_arg), readonly=True)
    except StoreError as exc:
        raise UserError(str(exc)) from exc


def _when(ts: float | None) -> str:
    if ts is None:
        return "-"
    return dt.datetime.fromtimestamp(ts, tz=dt.UTC).strftime("%Y-%m-%d %H:%M:%S")


def _get_run(store: RunStore, run_id: int) -> RunRecord:
    from goniolab.store import StoreError

    try:
        return store.get_run(run_id)
    except StoreError as exc:
        raise UserError(str(exc)) from exc


def run_summary(store: RunStore, rec: RunRecord) -> dict[str, Any]:
    """The summary of a stored run, recomputed from its stored readings and predictions."""
    if rec.kind == "brdf":
        from goniolab.scan.plans import BrdfPlan, PlanError
        from goniolab.scan.summary import summarize_brdf  # numpy: only when a run is shown

        try:
            plan = BrdfPlan.from_dict(rec.plan)
        except PlanError as exc:
            raise UserError(f"store {store.location}: run {rec.id}: {exc}") from exc
        return summarize_brdf(plan, store.points(rec.id), store.predictions(rec.id))
    if rec.kind in ("align", "calibration"):
        # the result is the run's record (what the alignment found, the calibration's check)
        key = "alignment" if rec.kind == "align" else "calibration"
        return {"readings": store.count_points(rec.id), key: rec.model.get(key)}
    from goniolab.scan.plans import gloss_statistics

    rows = store.gloss_readings(rec.id)
    return {
        "readings": len(rows),
        "statistics": gloss_statistics([r.values_gu for r in rows]).as_dict(),
    }


def _cmd_list(args: argparse.Namespace) -> int:
    path = store_path(args.store, args.config)
    if isinstance(path, Path) and not path.exists():
        # a fresh installation (or a mistyped --store): nothing to list, nothing created
        if args.json:
            print("[]")
        print(f"no runs: store {path} does not exist yet", file=sys.stderr)
        return 0
    with open_store(args.store, args.config) as store:
        runs = store.list_runs(limit=args.limit)
        if args.json:
            print(json.dumps([_brief(store, r) for r in runs], indent=2))
            return 0
        if not runs:
            print(f"no runs in {store.location}", file=sys.stderr)
            return 0
        print(
            f"{'RUN':>5}  {'KIND':5}  {'STATUS':11}  {'READINGS':>8}  {'CREATED (UTC)':19}  SAMPLE"
        )
        for r in runs:
            b = _brief(store, r)
            status = "interrupted" if b["interrupted"] else r.status
            print(
                f"{r.id:>5}  {r.kind:5}  {status:11}  {b['readings']:>8}  "
                f"{_when(r.created_at):19}  {r.sample}"
            )
    return 0


def interrupted(store: RunStore, r: RunRecord) -> bool:
    """A run stored as running/paused that no runner holds (its process died)."""
    return r.status in ("running", "paused") and store.is_claimed(r.id) is False


def _brief(store: RunStore, r: RunRecord) -> dict[str, Any]:
    n = store.count_points(r.id) if r.kind != "gloss" else len(store.gloss_readings(r.id))
    return {
        "id": r.id,
        "kind": r.kind,
        "status": r.status,
        "interrupted": interrupted(store, r),
        "reason": r.reason,
        "sample": r.sample,
        "readings": n,
        "created_at": r.created_at,
        "finished_at": r.finished_at,
    }


def angles_text(angles_deg: Sequence[float]) -> str:
    """``"0:70:1 deg (71 angles)"`` for an evenly spaced increasing list (the ``--theta-r``
    range that gives it), else ``"a, b, c deg"``."""
    a = [float(v) for v in angles_deg]
    if len(a) >= 3:
        step = a[1] - a[0]
        if step > 0 and all(abs((y - x) - step) < 1e-9 for x, y in itertools.pairwise(a)):
            return f"{a[0]:g}:{a[-1]:g}:{step:g} deg ({len(a)} angles)"
    return ", ".join(f"{v:g}" for v in a) + " deg"


def plan_text(plan: dict[str, Any]) -> str:
    """One readable line for a stored plan (``--json`` gives the plan as stored)."""
    if plan.get("kind") == "gloss":
        count = plan.get("count", 0)
        angles = "/".join(str(a) for a in plan.get("angles_deg", []))
        return f"gloss {angles} deg, " + (f"{count} readings" if count else "until stopped")
    try:
        return (
            f"theta_i {float(plan['theta_i_deg']):g} deg, "
            f"theta_r {angles_text(plan['theta_r_deg'])}, repeats {plan['repeats']}, "
            f"dwell {float(plan['dwell_s']):g} s, exposure {plan['exposure_us']} us"
            + (", mirror reference" if plan.get("mirror_reference") else "")
        )
    except (KeyError, TypeError, ValueError):
        return json.dumps(plan, sort_keys=True)


def run_colour(store: RunStore, rec: RunRecord) -> list[dict[str, Any]]:
    """Per-geometry measured and predicted colour of a BRDF run ([] for gloss runs)."""
    if rec.kind != "brdf":
        return []
    from goniolab.scan.colour import PointColour, colour_rows

    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    try:
        pc: PointColour | None = PointColour.from_snapshot(rec.config)
    except (TypeError, ValueError, AttributeError):
        pc = None  # a damaged snapshot: repeats averaged as L*a*b*
    return colour_rows(store.points(rec.id), store.predicted_colours(rec.id), theta_i, pc)


def _f(v: Any, fmt: str = "6.1f") -> str:
    return "-" if v is None else format(float(v), fmt)


def colour_text(rows: list[dict[str, Any]]) -> list[str]:
    """Lines of the colour table (one per geometry) printed by ``runs show/colour``."""
    from goniolab.scan.colour import flop_of_rows

    out = [
        "  theta_r  aspec     L*     a*     b*     C*      h   pred L*  a*     b*    dE00  rep dE00"
    ]
    for r in rows:
        out.append(
            f"  {r['theta_r_deg']:7.2f} {r['aspecular_deg']:6.1f} {_f(r.get('L'))} "
            f"{_f(r.get('a'))} {_f(r.get('b'))} {_f(r.get('C'))} {_f(r.get('h_deg'))}   "
            f"{_f(r.get('predicted_L'))} {_f(r.get('predicted_a'))} {_f(r.get('predicted_b'))}"
            f" {_f(r.get('dE2000'), '6.2f')}  {_f(r.get('dE00_repeat_mean'), '7.3f')}"
        )
    fi = flop_of_rows(rows)
    fi_p = flop_of_rows(rows, "predicted_L")
    if fi is not None or fi_p is not None:
        out.append(f"  flop index: measured {_f(fi, '.2f')}, predicted {_f(fi_p, '.2f')}")
    return out


def _cmd_show(args: argparse.Namespace) -> int:
    with open_store(args.store, args.config) as store:
        rec = _get_run(store, args.run)
        summary = run_summary(store, rec)
        colour = run_colour(store, rec)
        if args.json:
            doc = {
                "run": rec.as_dict(),
                "interrupted": interrupted(store, rec),
                "summary": summary,
                "colour": colour,
            }
            print(json.dumps(doc, indent=2))
            return 0
        status = rec.status
        if interrupted(store, rec):
            status += " (interrupted: no goniolab process is measuring it)"
        print(f"run {rec.id} ({rec.kind}) on {rec.sample or '-'}: {status}")
        if rec.reason:
            print(f"  reason: {rec.reason}")
        print(f"  created {_when(rec.created_at)} UTC, finished {_when(rec.finished_at)} UTC")
        print(f"  goniolab {rec.version}; model {json.dumps(rec.model, sort_keys=True)}")
        print(f"  plan: {plan_text(rec.plan)}")
        if rec.kind == "brdf":
            from goniolab.commands.scan import format_summary

            print(format_summary(summary))
            if any("L" in r for r in colour):
                print("  colour (reflectance factor, per geometry):")
                print("\n".join(colour_text(colour)))
        elif rec.kind in ("align", "calibration"):
            print(f"  readings: {summary['readings']} (the result: the model's {rec.kind} record)")
        else:
            predicted = rec.model.get("predicted_gu") or {}
            for angle, st in summary["statistics"].items():
                pred = predicted.get(angle)
                print(
                    f"  G{angle}: {st['mean_gu']:.1f} +- {st['std_gu']:.1f} GU (n = {st['n']})"
                    + ("" if pred is None else f", predicted {float(pred):.1f} GU")
                )
        if rec.status != "done" and rec.kind == "brdf":
            print(f"  continue it with: goniolab scan resume {rec.id}")
    return 0


def _cmd_colour(args: argparse.Namespace) -> int:
    from goniolab.scan.colour import compare_rows, flop_of_rows

    with open_store(args.store, args.config) as store:
        rec = _get_run(store, args.run)
        if rec.kind != "brdf":
            raise UserError(f"run {rec.id} is a {rec.kind} run: colour needs a scan (brdf) run")
        rows = run_colour(store, rec)
        other_rows: list[dict[str, Any]] = []
        if args.vs is not None:
            other = _get_run(store, args.vs)
            if other.kind != "brdf":
                raise UserError(f"run {other.id} is a {other.kind} run: --vs needs a scan run")
            other_rows = run_colour(store, other)
    if not any("L" in r for r in rows):
        raise UserError(f"run {rec.id} has no measured colour (no readings, or no usable spectra)")
    doc: dict[str, Any] = {
        "run": rec.id,
        "colour_settings": rec.config.get("colour", {}),
        "geometries": rows,
        "flop_index": flop_of_rows(rows),
        "predicted_flop_index": flop_of_rows(rows, "predicted_L"),
    }
    if args.vs is not None:
        pairs = compare_rows(rows, other_rows)
        if not pairs:
            raise UserError(f"runs {rec.id} and {args.vs} share no detector angle with colour")
        doc["vs"] = {
            "run": args.vs,
            "pairs": pairs,
            "flop_index": flop_of_rows(other_rows),
            "max_dE2000": max(p["dE2000"] for p in pairs),
            "mean_dE2000": sum(p["dE2000"] for p in pairs) / len(pairs),
        }
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"run {rec.id} on {rec.sample or '-'}: colour per geometry")
    print("\n".join(colour_text(rows)))
    if args.vs is not None:
        v = doc["vs"]
        print(f"vs run {args.vs}:")
        print("  theta_r  aspec     L*     a*     b*  |  L*     a*     b*   dE*ab   dE94  dE2000")
        for p in v["pairs"]:
            print(
                f"  {p['theta_r_deg']:7.2f} {p['aspecular_deg']:6.1f} {p['L']:6.1f} {p['a']:6.1f}"
                f" {p['b']:6.1f} | {p['other_L']:6.1f} {p['other_a']:6.1f} {p['other_b']:6.1f}"
                f" {p['dE76']:6.2f} {p['dE94']:6.2f} {p['dE2000']:6.2f}"
            )
        print(f"  dE2000: mean {v['mean_dE2000']:.2f}, max {v['max_dE2000']:.2f}")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from goniolab.export import FORMATS, export_run, format_for_path

    fmt = args.format
    if args.json and not args.output:
        # like every command's --json: the answer on stdout as JSON, i.e. the JSON export
        if fmt not in (None, "json"):
            raise UserError(
                f"runs export --json --format {fmt}: --json prints the run as JSON on stdout; "
                f"give -o FILE to write {fmt} (then --json reports what was written)"
            )
        fmt = "json"
    if fmt is None:
        fmt = (format_for_path(args.output) if args.output else None) or "csv"
    if fmt in ("netcdf", "parquet") and not args.output:
        raise UserError(
            f"runs export --format {fmt}: a binary format needs -o FILE (e.g. -o run{FORMATS[fmt]})"
        )
    with open_store(args.store, args.config) as store:
        _get_run(store, args.run)
        try:
            text = export_run(store, args.run, fmt, args.output)
        except OSError as exc:
            raise UserError(f"cannot write {args.output}: {exc.strerror or exc}") from exc
    if args.output:
        if args.json:
            doc = {"run_id": args.run, "format": fmt, "output": str(Path(args.output).resolve())}
            print(json.dumps(doc, indent=2))
        else:
            print(f"run {args.run} written to {args.output} ({fmt})", file=sys.stderr)
    else:
        sys.stdout.write(text if text.endswith("\n") or not text else text + "\n")
    return 0


def _cmd_migrate(args: argparse.Namespace) -> int:
    """Copy every run of an SQLite store (or another store) into the target store."""
    from goniolab.store import RunStore, StoreError, is_store_url

    source = args.source if is_store_url(args.source) else Path(args.source).expanduser()
    target = store_path(args.store, args.config)
    if str(source) == str(target):
        raise UserError(f"runs migrate: {args.source} is the target store itself")
    try:
        src = RunStore(source, readonly=True)
    except StoreError as exc:
        raise UserError(str(exc)) from exc
    moved: list[dict[str, Any]] = []
    with src:
        try:
            dst = RunStore(target)
        except StoreError as exc:
            raise UserError(str(exc)) from exc
        with dst:
            for rec in sorted(src.list_runs(), key=lambda r: r.id):
                if rec.status in ("running", "paused") and src.is_claimed(rec.id):
                    raise UserError(
                        f"run {rec.id} of {src.location} is being measured right now; "
                        "migrate when it has finished"
                    )
                new_id, copied = dst.copy_run_from(src, rec.id)
                moved.append({"from": rec.id, "to": new_id, "copied": copied})
                if not args.json:
                    what = "copied as" if copied else "already there as"
                    print(f"run {rec.id} ({rec.kind}, {rec.status}): {what} run {new_id}")
            where = dst.location
    if args.json:
        print(json.dumps({"source": src.location, "target": where, "runs": moved}, indent=2))
    else:
        n = sum(1 for m in moved if m["copied"])
        print(f"{n} of {len(moved)} runs copied from {src.location} to {where}", file=sys.stderr)
    return 0


def register(subparsers: Any) -> None:
    """Add ``runs`` and its sub-commands."""
    p = subparsers.add_parser("runs", help="list, show and export stored runs")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--store",
        help="SQLite store file or postgresql:// URL (default: config [lab] store or the "
        "user data dir)",
    )
    common.add_argument("--config", help="lab config TOML whose [lab] store to use")
    sub = p.add_subparsers(dest="runs_command", metavar="ACTION", required=True)

    pl = sub.add_parser("list", parents=[common], help="list runs, newest first")
    pl.add_argument("--limit", type=int, default=None, help="show at most N runs")
    pl.add_argument("--json", action="store_true", help="print JSON")
    pl.set_defaults(func=_cmd_list)

    ps = sub.add_parser("show", parents=[common], help="show one run and its summary")
    ps.add_argument("run", type=int, metavar="RUN")
    ps.add_argument("--json", action="store_true", help="print JSON")
    ps.set_defaults(func=_cmd_show)

    pc = sub.add_parser(
        "colour",
        parents=[common],
        help="measured vs predicted colour per geometry (dE76/94/2000, flop index)",
    )
    pc.add_argument("run", type=int, metavar="RUN")
    pc.add_argument("--vs", type=int, metavar="RUN", help="compare with another run")
    pc.add_argument("--json", action="store_true", help="print JSON")
    pc.set_defaults(func=_cmd_colour)

    pe = sub.add_parser(
        "export",
        parents=[common],
        help="export one run: CSV/JSON (one row per reading), netCDF or Parquet",
        description="Export one run. CSV and JSON go to stdout unless -o FILE; netCDF "
        "(xarray + h5netcdf, CF-style units, the run's metadata as attributes) and Parquet "
        "(pyarrow, the run record in the schema metadata) need -o FILE. Timestamps are "
        "ISO 8601 UTC.",
    )
    pe.add_argument("run", type=int, metavar="RUN")
    pe.add_argument(
        "--format",
        choices=("csv", "json", "netcdf", "parquet"),
        default=None,
        help="file format (default: from the -o suffix .csv/.json/.nc/.parquet, else csv)",
    )
    pe.add_argument("-o", "--output", help="write to FILE instead of stdout")
    pe.add_argument(
        "--json",
        action="store_true",
        help="without -o: the run as JSON on stdout (--format json); with -o: print what "
        "was written as JSON on stdout",
    )
    pe.set_defaults(func=_cmd_export)

    pm = sub.add_parser(
        "migrate",
        parents=[common],
        help="copy every run of an SQLite store into this store (e.g. a shared PostgreSQL)",
        description="Copy the runs of --from (an instrument's SQLite file) into the store "
        "chosen by --store/--config (e.g. postgresql://lab@dbhost/goniolab). Runs get new ids; "
        "a run already copied is skipped, so the command can be re-run.",
    )
    pm.add_argument("--from", dest="source", required=True, metavar="STORE")
    pm.add_argument("--json", action="store_true", help="print the id mapping as JSON")
    pm.set_defaults(func=_cmd_migrate)
