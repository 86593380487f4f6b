"""``goniolab runs list | show RUN | export RUN``: browse and export the run store."""

from __future__ import annotations

import argparse
import datetime as dt
import itertools
import json
import sys
from collections.abc import Sequence
from typing import Any

from goniolab import jsonout
from goniolab.commands._help import RUN_HELP
from goniolab.errors import UserError
from goniolab.textsafe import escaped_stdout

__all__ = ["angles_text", "colour_text", "plan_text", "register", "safe_text"]


def _when(ts: float | None) -> str:
    if ts is None:
        return "-"
    return dt.datetime.fromtimestamp(ts, tz=dt.UTC).strftime("%Y-%m-%d %H:%M:%S")


def _cmd_list(args: argparse.Namespace) -> int:
    from goniolab.app.stored_runs import list_runs

    listing = list_runs(
        args.store,
        args.config,
        limit=args.limit,
        operator=args.operator,
        tag=args.tag,
        sample_id=args.sample_id,
        text=args.search,
    )
    if not listing.exists:
        if args.json:
            print("[]")
        print(f"no runs: store {listing.location} does not exist yet", file=sys.stderr)
        return 0
    if args.json:
        print(jsonout.dumps([b.as_dict() for b in listing.runs], indent=2))
        return 0
    if not listing.runs:
        print(
            f"no runs{' match' if listing.filtered else ''} in {listing.location}", file=sys.stderr
        )
        return 0
    # the kind column as wide as its longest ("calibration", "glosscal"), at least 5
    kw = max([5, *(len(safe_text(b.record.kind)) for b in listing.runs)])
    print(
        f"{'RUN':>5}  {'KIND':{kw}}  {'STATUS':11}  {'READINGS':>8}  {'CREATED (UTC)':19}  SAMPLE"
    )
    for b in listing.runs:
        r, n = b.record, b.readings
        status = "damaged" if r.damage else "interrupted" if b.interrupted else r.status
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
            f"{r.id:>5}  {safe_text(r.kind):{kw}}  {status:11}  {readings:>8}  "
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
    from goniolab.app.colour_notes import averaging_notes

    out.extend(f"  note: {n}" for n in averaging_notes(rows))
    fi = flop_of_rows(rows, theta_i_deg)
    fi_p = flop_of_rows(rows, theta_i_deg, "predicted_L")
    note = flop_index_note(theta_i_deg)
    if note:
        out.append(f"  {note}")
    elif fi is not None or fi_p is not None:
        out.append(f"  flop index: measured {_f(fi, '.2f')}, predicted {_f(fi_p, '.2f')}")
    return out


def _cmd_show(args: argparse.Namespace) -> int:
    from goniolab.app.stored_runs import show_run

    view = show_run(args.run, args.store, args.config)
    rec, summary, colour = view.record, view.summary, view.colour
    if args.json:
        print(jsonout.dumps(view.as_dict(), indent=2))
        return 0
    status = rec.status
    if view.interrupted:
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
        from goniolab.app.colour_notes import calibration_note
        from goniolab.commands.scan import format_summary

        print(format_summary(summary))
        print(f"  {calibration_note(rec.model)}")
        if any("L" in r for r in colour):
            print("  colour (reflectance factor, per geometry):")
            theta_i = float(rec.plan.get("theta_i_deg", 45.0))
            print("\n".join(colour_text(colour, theta_i)))
    elif rec.kind == "glosscal":
        from goniolab.app.lab_gloss import describe_calibration_record

        for line in describe_calibration_record(summary.get("gloss_calibration") or {}):
            print(f"  {safe_text(line)}")
    elif rec.kind in ("align", "calibration"):
        print(f"  readings: {summary['readings']} (the result: the model's {rec.kind} record)")
        result = summary.get("alignment") or {}
        for label, key in (
            ("lamp arm zero offset", "lamp_zero_deg"),
            ("detector arm zero offset", "detector_zero_deg"),
            ("sample tilt", "sample_tilt_deg"),
        ):
            if isinstance(result.get(key), int | float):
                print(f"  {label}: {result[key]:+.3f} deg")
    else:
        predicted = rec.model.get("predicted_gu") or {}
        by = rec.model.get("computed_by") or {}  # the model of each predicted gloss
        for angle, st in summary["statistics"].items():
            pred = predicted.get(angle)
            model = f" ({safe_text(str(by[angle]))})" if angle in by else ""
            print(
                f"  G{angle}: {st['mean_gu']:.1f} +- {st['std_gu']:.1f} GU (n = {st['n']})"
                + ("" if pred is None else f", predicted {float(pred):.1f} GU{model}")
            )
        for w in rec.model.get("warnings") or []:
            print(f"  prediction warning: {safe_text(str(w))}")
        # the calibration the readings rest on (gloss calibrate; gloss log records it)
        from goniolab.app.lab_gloss import describe_gloss_calibration

        cal = rec.model.get("glossmeter_calibration")
        if isinstance(cal, dict):
            print(f"  glossmeter calibration: {safe_text(describe_gloss_calibration(cal))}")
            for w in cal.get("warnings") or []:
                print(f"  calibration warning: {safe_text(str(w))}")
        else:
            print("  glossmeter calibration: not recorded with this run (logged before "
                  "gloss runs recorded it)")  # fmt: skip
    if view.resume is not None:
        print(f"  continue it with: {view.resume}")
    return 0


def _cmd_colour(args: argparse.Namespace) -> int:
    from goniolab.app.colours import runs_colour
    from goniolab.commands._colour import colour_report_text

    report = runs_colour(
        args.run,
        vs=args.vs,
        tolerance=args.tolerance,
        illuminants=list(args.illuminant),
        metamerism=bool(args.metamerism),
        store=args.store,
        config=args.config,
    )
    if args.json:
        print(jsonout.dumps(report.doc, indent=2))
        return 0
    print(f"run {report.record.id} on {report.record.sample or '-'}: colour per geometry")
    print("\n".join(colour_report_text(report.doc)))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from goniolab.app.stored_runs import export_run

    fmt = args.format
    if args.json and not args.output:
        # like every command's --json: the answer on stdout as JSON, i.e. the JSON export
        if fmt not in (None, "json"):
            raise UserError(
                f"runs export --json --format {fmt}: --json prints the run as JSON on stdout; "
                f"give -o FILE to write {fmt} (then --json reports what was written)"
            )
        fmt = "json"
    done = export_run(
        args.run, fmt, args.output, store=args.store, config=args.config,
        spectra=not args.no_spectra,
    )  # fmt: skip
    if done.output is None:
        text = done.text
        sys.stdout.write(text if text.endswith("\n") or not text else text + "\n")
    elif args.json:
        doc = {"run_id": args.run, "format": done.format, "output": str(done.output.resolve())}
        print(jsonout.dumps(doc, indent=2))
    else:
        print(f"run {args.run} written to {args.output} ({done.format})", file=sys.stderr)
    return 0


def _cmd_import(args: argparse.Namespace) -> int:
    """Import JSON exports (matched by run UUID); one line per file, errors per file."""
    from goniolab.app.stored_runs import import_runs

    done = import_runs(args.files, args.store, args.config)
    for row in done:
        if "error" in row:
            print(f"goniolab: error: runs import: {row['error']}", file=sys.stderr)
        elif not args.json:
            spectra = (
                f"{row['spectra']} measured and {row['predicted_spectra']} predicted spectra"
                if row["spectra"] or row["predicted_spectra"]
                else "no spectra in the file"
            )
            print(f"{row['file']}: run {row['run_id']} ({row['uuid']}) {row['action']}; {spectra}")
    if args.json:
        print(json.dumps(done, indent=2))
    return 2 if any("error" in row for row in done) else 0


def _cmd_migrate(args: argparse.Namespace) -> int:
    """Copy every run of an SQLite store (or another store) into the target store, matched
    by run UUID: new runs are copied, partial copies brought up to date."""
    from goniolab.app.stored_runs import migrate_runs

    def said(entry: dict[str, Any], rec: Any) -> None:  # rec: the source run's record
        action = entry["action"]
        if action == "error":
            print(f"run {rec.id}: not copied: {entry['error']}", file=sys.stderr)
        elif args.json:
            return
        elif action == "skipped":
            print(f"run {rec.id} ({rec.kind}, {rec.status}): skipped: {entry['reason']}")
        else:
            what = {
                "copied": "copied as",
                "updated": "brought up to date in",
                "unchanged": "already there as",
            }[action]
            print(f"run {rec.id} ({rec.kind}, {rec.status}): {what} run {entry['to']}")

    done = migrate_runs(args.source, args.store, args.config, on_run=said)
    if args.json:
        print(json.dumps({"source": done.source, "target": done.target, "runs": done.runs},
                         indent=2))  # fmt: skip
    else:
        n = sum(1 for m in done.runs if m["action"] == "copied")
        u = sum(1 for m in done.runs if m["action"] == "updated")
        print(
            f"{n} of {len(done.runs)} runs copied, {u} updated, from {done.source} to "
            f"{done.target}" + (f"; {done.errors} could not be read" if done.errors else ""),
            file=sys.stderr,
        )
    return 1 if done.errors else 0


def _cmd_annotate(args: argparse.Namespace) -> int:
    """Set a run's operator, physical sample id, notes and tags."""
    from goniolab.app.stored_runs import annotate_run
    from goniolab.commands.scan import run_meta_args

    meta = run_meta_args(args)
    rec = annotate_run(
        args.run,
        store=args.store,
        config=args.config,
        operator=args.operator,
        sample_id=args.sample_id,
        notes=args.note,
        add_tags=meta.tags,
        remove_tags=args.untag,
    )
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
        help="run store: SQLite file or postgresql:// URL (default: the config's [lab] store, "
        "else goniolab.sqlite in the user data dir: goniolab --version)",
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
    ps.add_argument("run", type=int, metavar="RUN", help=RUN_HELP)
    ps.add_argument("--json", action="store_true", help="print JSON")
    ps.set_defaults(func=escaped_stdout(_cmd_show))

    pc = sub.add_parser(
        "colour",
        parents=[common],
        help="measured vs predicted colour per geometry (dL*/dC*/dH*, dE76/94/2000, CMC, "
        "tolerances per angle, flop index, metamerism)",
    )
    pc.add_argument("run", type=int, metavar="RUN", help=RUN_HELP)
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
    pe.add_argument("run", type=int, metavar="RUN", help=RUN_HELP)
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
        "--no-spectra",
        action="store_true",
        help="leave a scan's spectra out: no R_<nm> / predicted_R_<nm> columns (CSV, "
        "Parquet), no 'spectra' (JSON), no spectral variables (netCDF)",
    )
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
    pm.add_argument(
        "--from",
        dest="source",
        required=True,
        metavar="STORE",
        help="the SQLite store file to copy from",
    )
    pm.add_argument("--json", action="store_true", help="print the id mapping as JSON")
    pm.set_defaults(func=_cmd_migrate)

    pi = sub.add_parser(
        "import",
        parents=[common],
        help="read runs exported with 'runs export --format json' (or parquet) back into a store",
        description="Read runs exported with 'goniolab runs export RUN --format json' (or "
        "-o FILE.parquet) back into the store chosen by --store/--config. A run keeps its UUID, creation time and "
        "identity; one the store already holds is matched by its UUID (left as it is, or "
        "brought up to date), never duplicated. A scan's spectra (R_<nm>, predicted_R_<nm>) "
        "are stored back: exported again, it gives the same spectra. Not in an export, so "
        "not imported: the spectro's raw reading beside a referenced spectrum, the mirror "
        "reference's spectrum, the exposure.",
    )
    pi.add_argument(
        "files", nargs="+", metavar="FILE", help="JSON or Parquet export(s) of goniolab runs"
    )
    pi.add_argument("--json", action="store_true", help="print what was imported as JSON")
    pi.set_defaults(func=_cmd_import)

    pa = sub.add_parser(
        "annotate",
        parents=[common],
        help="set a run's operator, physical sample id, notes and tags",
    )
    pa.add_argument("run", type=int, metavar="RUN", help=RUN_HELP)
    from goniolab.commands.scan import add_run_meta_args

    add_run_meta_args(pa)
    pa.add_argument("--untag", action="append", default=[], metavar="TAG", help="remove a tag")
    pa.add_argument("--json", action="store_true", help="print the run record as JSON")
    pa.set_defaults(func=_cmd_annotate)
