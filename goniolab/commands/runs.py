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

from goniolab import jsonout
from goniolab.errors import UserError
from goniolab.textsafe import escaped_stdout

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
        except (PlanError, KeyError, TypeError, ValueError) as exc:
            raise UserError(
                f"store {store.location}: run {rec.id}: its stored plan cannot be read: {exc}"
            ) from exc
        from goniolab.store import StoreError

        try:
            return summarize_brdf(plan, store.points(rec.id), store.predictions(rec.id))
        except StoreError as exc:
            raise UserError(str(exc)) from exc
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
    from goniolab.store import StoreError

    path = store_path(args.store, args.config)
    if isinstance(path, Path) and not path.exists():
        # a fresh installation (or a mistyped --store): nothing to list, nothing created
        if args.json:
            print("[]")
        print(f"no runs: store {path} does not exist yet", file=sys.stderr)
        return 0
    with open_store(args.store, args.config) as store:
        try:
            briefs = store.list_briefs(
                limit=args.limit,
                operator=args.operator,
                tag=args.tag,
                sample_id=args.sample_id,
                text=args.search,
            )
        except StoreError as exc:
            raise UserError(str(exc)) from exc
        if args.json:
            print(jsonout.dumps([_brief(store, r, n) for r, n in briefs], indent=2))
            return 0
        if not briefs:
            filtered = any(
                v is not None for v in (args.operator, args.tag, args.sample_id, args.search)
            )
            print(f"no runs{' match' if filtered else ''} in {store.location}", file=sys.stderr)
            return 0
        print(
            f"{'RUN':>5}  {'KIND':5}  {'STATUS':11}  {'READINGS':>8}  {'CREATED (UTC)':19}  SAMPLE"
        )
        for r, n in briefs:
            b = _brief(store, r, n)
            status = "damaged" if r.damage else "interrupted" if b["interrupted"] else r.status
            readings = "?" if n is None else str(n)
            extra = "".join(
                f"  {label}{safe_text(v)}"
                for label, v in (
                    ("id:", r.sample_id),
                    ("by ", r.operator),
                    ("#", " #".join(r.tags)),
                )
                if v
            )
            print(
                f"{r.id:>5}  {safe_text(r.kind):5}  {status:11}  {readings:>8}  "
                f"{_when(r.created_at):19}  {safe_text(r.sample)}{extra}"
            )
            if r.damage:
                print(f"       damaged: {safe_text(r.damage)}")
            elif n is None:
                print("       damaged: its readings cannot be counted (a damaged page)")
    return 0


def safe_text(text: str) -> str:
    """``text`` with control characters (terminal escape sequences) shown as ``\\xNN``."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else f"\\x{ord(c):02x}" for c in text)


def interrupted(store: RunStore, r: RunRecord) -> bool:
    """A run stored as running/paused that no runner holds (its process died)."""
    return r.status in ("running", "paused") and store.is_claimed(r.id) is False


def _brief(store: RunStore, r: RunRecord, readings: int | None) -> dict[str, Any]:
    doc = {
        "id": r.id,
        "uuid": r.uuid,
        "kind": r.kind,
        "status": r.status,
        "interrupted": interrupted(store, r),
        "reason": r.reason,
        "sample": r.sample,
        "sample_id": r.sample_id,
        "operator": r.operator,
        "tags": list(r.tags),
        "notes": r.notes,
        "readings": readings,
        "created_at": r.created_at,
        "finished_at": r.finished_at,
    }
    if r.damage:
        doc["damage"] = r.damage
    return doc


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
    return "-".rjust(len(format(0.0, fmt))) if v is None else format(float(v), fmt)


def colour_text(rows: list[dict[str, Any]], theta_i_deg: float = 45.0) -> list[str]:
    """Lines of the colour table (one per geometry) printed by ``runs show/colour``: the
    measured and predicted L*a*b*, the signed dL*, dC*, dH* (predicted - measured) and
    dE*ab, dE94, dE00 (:mod:`goniolab.colour.difference`); the flop index at 45 deg only."""
    from goniolab.colour.difference import differences
    from goniolab.colour.multiangle import flop_index_note, flop_of_rows

    out = [
        "  theta_r  aspec     L*     a*     b*     C*      h |  pred L*     a*     b* |"
        "    dL*    dC*    dH*  dE*ab   dE94   dE00  rep dE00"
    ]
    for r in rows:
        d: dict[str, Any] = {}
        if r.get("L") is not None and r.get("predicted_L") is not None:
            m = [r["L"], r["a"], r["b"]]
            p_ = [r["predicted_L"], r["predicted_a"], r["predicted_b"]]
            d = {k: float(v) for k, v in differences(m, p_).items()}
        out.append(
            f"  {r['theta_r_deg']:7.2f} {r['aspecular_deg']:6.1f} {_f(r.get('L'))} "
            f"{_f(r.get('a'))} {_f(r.get('b'))} {_f(r.get('C'))} {_f(r.get('h_deg'))} |   "
            f"{_f(r.get('predicted_L'))} {_f(r.get('predicted_a'))} {_f(r.get('predicted_b'))} |"
            + "".join(
                f" {_f(d.get(k), '6.2f')}" for k in ("dL", "dC", "dH", "dE76", "dE94", "dE00")
            )
            + f"  {_f(r.get('dE00_repeat_mean'), '7.3f')}"
        )
    fi = flop_of_rows(rows, theta_i_deg)
    fi_p = flop_of_rows(rows, theta_i_deg, "predicted_L")
    note = flop_index_note(theta_i_deg)
    if note:
        out.append(f"  {note}")
    elif fi is not None or fi_p is not None:
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
            print(jsonout.dumps(doc, indent=2))
            return 0
        status = rec.status
        if interrupted(store, rec):
            status += " (interrupted: no goniolab process is measuring it)"
        print(f"run {rec.id} ({safe_text(rec.kind)}) on {safe_text(rec.sample) or '-'}: {status}")
        print(f"  uuid {rec.uuid}")
        for label, value in (
            ("physical sample id", rec.sample_id),
            ("operator", rec.operator),
            ("tags", ", ".join(rec.tags)),
            ("notes", rec.notes),
        ):
            if value:
                print(f"  {label}: {safe_text(value)}")
        if rec.reason:
            print(f"  reason: {safe_text(rec.reason)}")
        print(f"  created {_when(rec.created_at)} UTC, finished {_when(rec.finished_at)} UTC")
        print(f"  goniolab {rec.version}; model {json.dumps(rec.model, sort_keys=True)}")
        print(f"  plan: {plan_text(rec.plan)}")
        if rec.kind == "brdf":
            from goniolab.commands.scan import format_summary

            print(format_summary(summary))
            if any("L" in r for r in colour):
                print("  colour (reflectance factor, per geometry):")
                theta_i = float(rec.plan.get("theta_i_deg", 45.0))
                print("\n".join(colour_text(colour, theta_i)))
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
            from goniolab.commands.scan import resume_command

            print(f"  continue it with: {resume_command(rec.id, store)}")
    return 0


def _cmd_colour(args: argparse.Namespace) -> int:
    from goniolab.commands._colour import colour_report, colour_report_text, load_tolerance

    tolerance = load_tolerance(args.tolerance)
    with open_store(args.store, args.config) as store:
        rec = _get_run(store, args.run)
        if rec.kind != "brdf":
            raise UserError(f"run {rec.id} is a {rec.kind} run: colour needs a scan (brdf) run")
        other = None
        if args.vs is not None:
            other = _get_run(store, args.vs)
            if other.kind != "brdf":
                raise UserError(f"run {other.id} is a {other.kind} run: --vs needs a scan run")
        doc = colour_report(
            store,
            rec,
            other,
            tolerance=tolerance,
            illuminants=list(args.illuminant),
            metamerism=bool(args.metamerism),
        )
    if args.json:
        print(jsonout.dumps(doc, indent=2))
        return 0
    print(f"run {rec.id} on {rec.sample or '-'}: colour per geometry")
    print("\n".join(colour_report_text(doc)))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from goniolab.export import EXPORTERS, export_run, resolve_format

    fmt = args.format
    if args.json and not args.output:
        # like every command's --json: the answer on stdout as JSON, i.e. the JSON export
        if fmt not in (None, "json"):
            raise UserError(
                f"runs export --json --format {fmt}: --json prints the run as JSON on stdout; "
                f"give -o FILE to write {fmt} (then --json reports what was written)"
            )
        fmt = "json"
    try:
        fmt = resolve_format(fmt, args.output)
    except ValueError as exc:  # issue 27: `-o run.xlsx` wrote CSV silently
        raise UserError(f"runs export: {exc}") from None
    if EXPORTERS[fmt].binary and not args.output:
        raise UserError(
            f"runs export --format {fmt}: a binary format needs -o FILE "
            f"(e.g. -o run{EXPORTERS[fmt].suffix})"
        )
    from goniolab.store import StoreError

    with open_store(args.store, args.config) as store:
        _get_run(store, args.run)
        try:
            text = export_run(store, args.run, fmt, args.output)
        except OSError as exc:
            raise UserError(
                f"cannot write {args.output}: {exc.strerror or exc}"
                + (f" ({args.output} is left as it was)" if Path(args.output).exists() else "")
            ) from exc
        except StoreError as exc:
            raise UserError(str(exc)) from exc
    if args.output:
        if args.json:
            doc = {"run_id": args.run, "format": fmt, "output": str(Path(args.output).resolve())}
            print(jsonout.dumps(doc, indent=2))
        else:
            print(f"run {args.run} written to {args.output} ({fmt})", file=sys.stderr)
    else:
        sys.stdout.write(text if text.endswith("\n") or not text else text + "\n")
    return 0


def _same_store(src: RunStore, dst: RunStore) -> bool:
    """Whether two open stores are one (a symlink, a relative path, another spelling of
    the URL): the same store UUID, or for files the same file."""
    a, b = src.store_uuid, dst.store_uuid
    if a is not None and b is not None:
        return a == b
    if not (src.is_postgres or dst.is_postgres):
        try:
            return src.path.resolve().samefile(dst.path.resolve())
        except OSError:
            return False
    return False


def _cmd_import(args: argparse.Namespace) -> int:
    """Import JSON exports (matched by run UUID); one line per file, errors per file."""
    from goniolab.store import RunStore, StoreError, import_json_export

    target = store_path(args.store, args.config)
    try:
        dst = RunStore(target)
    except StoreError as exc:
        raise UserError(str(exc)) from exc
    done: list[dict[str, Any]] = []
    failed = 0
    with dst:
        for name in args.files:
            try:
                here, action, uuid = import_json_export(dst, name)
            except StoreError as exc:
                failed += 1
                print(f"goniolab: error: runs import: {exc}", file=sys.stderr)
                done.append({"file": name, "error": str(exc)})
                continue
            done.append({"file": name, "run_id": here, "uuid": uuid, "action": action})
            if not args.json:
                print(f"{name}: run {here} ({uuid}) {action}; no spectra in a JSON export")
    if args.json:
        print(json.dumps(done, indent=2))
    return 2 if failed else 0


def _cmd_migrate(args: argparse.Namespace) -> int:
    """Copy every run of an SQLite store (or another store) into the target store, matched
    by run UUID: new runs are copied, partial copies brought up to date."""
    from goniolab.store import RunStore, StoreError, is_store_url

    source = args.source if is_store_url(args.source) else Path(args.source).expanduser()
    target = store_path(args.store, args.config)
    if isinstance(source, Path) and isinstance(target, Path):
        same = source.resolve() == target.resolve() or (
            source.exists() and target.exists() and source.samefile(target)
        )
        if same:
            raise UserError(f"runs migrate: --from {args.source} is the target store itself")
    try:
        src = RunStore(source, readonly=True)
    except StoreError as exc:
        raise UserError(str(exc)) from exc
    moved: list[dict[str, Any]] = []
    errors = 0
    with src:
        try:
            dst = RunStore(target)
        except StoreError as exc:
            raise UserError(str(exc)) from exc
        with dst:
            if _same_store(src, dst):
                raise UserError(
                    f"runs migrate: --from {src.location} is the target store {dst.location} "
                    "itself (the same store UUID)"
                )
            try:
                runs = sorted(src.list_runs(), key=lambda r: r.id)
            except StoreError as exc:
                raise UserError(str(exc)) from exc
            for rec in runs:
                entry: dict[str, Any] = {"from": rec.id, "uuid": rec.uuid}
                if rec.status in ("running", "paused") and src.is_claimed(rec.id):
                    entry.update(to=None, copied=False, action="skipped")
                    why = "being measured right now; run migrate again when it has finished"
                    entry["reason"] = why
                    moved.append(entry)
                    if not args.json:
                        print(f"run {rec.id} ({rec.kind}, {rec.status}): skipped: {why}")
                    continue
                try:
                    new_id, action = dst.copy_run_from(src, rec.id)
                except StoreError as exc:
                    errors += 1
                    entry.update(to=None, copied=False, action="error", error=str(exc))
                    moved.append(entry)
                    print(f"run {rec.id}: not copied: {exc}", file=sys.stderr)
                    continue
                entry.update(to=new_id, copied=action == "copied", action=action)
                moved.append(entry)
                if not args.json:
                    what = {
                        "copied": "copied as",
                        "updated": "brought up to date in",
                        "unchanged": "already there as",
                    }[action]
                    print(f"run {rec.id} ({rec.kind}, {rec.status}): {what} run {new_id}")
            where = dst.location
    if args.json:
        print(json.dumps({"source": src.location, "target": where, "runs": moved}, indent=2))
    else:
        n = sum(1 for m in moved if m["action"] == "copied")
        u = sum(1 for m in moved if m["action"] == "updated")
        print(
            f"{n} of {len(moved)} runs copied, {u} updated, from {src.location} to {where}"
            + (f"; {errors} could not be read" if errors else ""),
            file=sys.stderr,
        )
    return 1 if errors else 0


def _cmd_annotate(args: argparse.Namespace) -> int:
    """Set a run's operator, physical sample id, notes and tags."""
    from goniolab.commands.scan import run_meta_args
    from goniolab.store import RunStore, StoreError

    meta = run_meta_args(args)
    tags: list[str] | None = None
    try:
        with RunStore(store_path(args.store, args.config), create=False) as store:
            rec = store.get_run(args.run, allow_damaged=True)
            if meta.tags or args.untag:
                tags = [t for t in (*rec.tags, *meta.tags) if t not in set(args.untag)]
            rec = store.set_meta(
                args.run,
                operator=args.operator,
                sample_id=args.sample_id,
                notes=args.note,
                tags=tags,
            )
    except StoreError as exc:
        raise UserError(str(exc)) from exc
    if args.json:
        print(json.dumps(rec.as_dict(), indent=2))
    else:
        print(
            f"run {rec.id} ({rec.uuid}): operator {rec.operator or '-'}, sample id "
            f"{rec.sample_id or '-'}, tags {', '.join(rec.tags) or '-'}"
            + (f", notes {safe_text(rec.notes)!r}" if rec.notes else ""),
            file=sys.stderr,
        )
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
    pl.add_argument("--operator", help="only the runs of this operator")
    pl.add_argument("--tag", help="only the runs with this tag")
    pl.add_argument("--sample-id", help="only the runs of this physical sample id")
    pl.add_argument(
        "--search",
        metavar="TEXT",
        help="only runs whose sample, sample id, operator, notes or tags contain TEXT",
    )
    pl.add_argument("--json", action="store_true", help="print JSON")
    pl.set_defaults(func=escaped_stdout(_cmd_list))  # stored names may hold escapes

    ps = sub.add_parser("show", parents=[common], help="show one run and its summary")
    ps.add_argument("run", type=int, metavar="RUN")
    ps.add_argument("--json", action="store_true", help="print JSON")
    ps.set_defaults(func=escaped_stdout(_cmd_show))

    pc = sub.add_parser(
        "colour",
        parents=[common],
        help="measured vs predicted colour per geometry (dL*/dC*/dH*, dE76/94/2000, CMC, "
        "tolerances per angle, flop index, metamerism)",
    )
    pc.add_argument("run", type=int, metavar="RUN")
    pc.add_argument("--vs", type=int, metavar="RUN", help="compare with another run")
    pc.add_argument("--json", action="store_true", help="print JSON")
    from goniolab.commands._colour import add_runs_colour_options

    add_runs_colour_options(pc)
    pc.set_defaults(func=_cmd_colour)
    from goniolab.commands._colour import register_runs_spectra

    register_runs_spectra(sub, common)

    from goniolab.export import EXPORTERS

    pe = sub.add_parser(
        "export",
        parents=[common],
        help="export one run: CSV/JSON (one row per reading), netCDF or Parquet",
        description="Export one run. Text formats go to stdout unless -o FILE; binary ones "
        "need -o FILE. Formats: "
        + "; ".join(
            f"{e.name} ({'/'.join(e.suffixes)}{', needs -o' if e.binary else ''}): {e.description}"
            for e in EXPORTERS.values()
        )
        + ". A suffix no format has is refused unless --format is given.",
    )
    pe.add_argument("run", type=int, metavar="RUN")
    pe.add_argument(
        "--format",
        choices=tuple(EXPORTERS),
        default=None,
        help="file format (default: from the -o suffix "
        + "/".join(e.suffix for e in EXPORTERS.values())
        + ", else csv)",
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
        "chosen by --store/--config (e.g. postgresql://lab@dbhost/goniolab). Runs get new ids "
        "and keep their UUID: a run already copied is matched by it (skipped, or brought up "
        "to date when it was copied before it finished), so the command can be re-run; a "
        "store is never migrated into itself.",
    )
    pm.add_argument("--from", dest="source", required=True, metavar="STORE")
    pm.add_argument("--json", action="store_true", help="print the id mapping as JSON")
    pm.set_defaults(func=_cmd_migrate)

    pi = sub.add_parser(
        "import",
        parents=[common],
        help="read runs exported with 'runs export --format json' back into a store",
        description="Read runs exported with 'goniolab runs export RUN --format json' back "
        "into the store chosen by --store/--config. A run keeps its UUID, creation time and "
        "identity; one the store already holds is matched by its UUID (left as it is, or "
        "brought up to date), never duplicated. A JSON export carries no spectra: an "
        "imported scan has its luminance, colour and predictions, not its spectra.",
    )
    pi.add_argument("files", nargs="+", metavar="FILE", help="JSON export(s) of goniolab runs")
    pi.add_argument("--json", action="store_true", help="print what was imported as JSON")
    pi.set_defaults(func=_cmd_import)

    pa = sub.add_parser(
        "annotate",
        parents=[common],
        help="set a run's operator, physical sample id, notes and tags",
    )
    pa.add_argument("run", type=int, metavar="RUN")
    from goniolab.commands.scan import add_run_meta_args

    add_run_meta_args(pa)
    pa.add_argument("--untag", action="append", default=[], metavar="TAG", help="remove a tag")
    pa.add_argument("--json", action="store_true", help="print the run record as JSON")
    pa.set_defaults(func=_cmd_annotate)
