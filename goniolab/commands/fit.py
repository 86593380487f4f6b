"""``goniolab fit colour RUN``: fit a paint to a measured multi-angle run.

The run's measured L*a*b* per geometry (mean over repeats; geometries closer than
``--min-aspecular`` to the specular direction are left out: there the gloss of the coat
surface, not the paint, sets the colour) are fitted with the model the run was predicted
with -- its sample's coat surface model (``--model`` to choose another, ``--no-surface``
for the paint alone) over the sample's paint (``--paint FILE.toml`` for another start) --
through :func:`goniolab.colour.paint_fit.fit_paint`: K/S of the body, the flake populations'
area and spread (and a pearl's film), and the coat index, each with its 1-sigma
uncertainty, and the residual dE2000 per geometry. ``--save FILE.toml`` writes the fitted
paint in the format ``--paint`` reads (``goniolab predict colour MAP --paint FILE.toml``).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path
from typing import Any

from goniolab.commands._help import RUN_HELP
from goniolab.errors import UserError, a_run_of_kind
from goniolab.model_registry import model_names

__all__ = ["register", "toml_text"]


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        if not math.isfinite(float(v)):
            raise UserError(f"cannot write {v!r} to TOML")
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise UserError(f"cannot write {type(v).__name__} to TOML")


def toml_text(doc: dict[str, Any], header: str = "") -> str:
    """A small TOML writer for a paint table: scalars and inline tables at the top,
    one ``[section]`` per nested table."""
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    sections = {k: v for k, v in doc.items() if isinstance(v, dict) and k != "coat"}
    for k, v in doc.items():
        if k not in sections:
            lines.append(f"{k} = {_toml_value(v)}")
    for name, table in sections.items():
        lines.append("")
        lines.append(f"[{name}]")
        lines.extend(f"{k} = {_toml_value(v)}" for k, v in table.items())
    return "\n".join(lines) + "\n"


def _say(args: argparse.Namespace, text: str) -> None:
    """Progress on stderr while a terminal watches."""
    if sys.stderr.isatty() and not args.json:
        print(text, file=sys.stderr, flush=True)


def _settings_of(rec: Any) -> tuple[Any, str, float, float]:
    """Colour settings, scale and the cones a run was measured and predicted with."""
    from goniolab.colour.spectra import ColourError, ColourSettings

    model = rec.model or {}
    config = rec.config or {}
    col = model.get("colour") or config.get("colour") or {}
    try:
        settings = ColourSettings(
            str(col.get("illuminant", "D65")),
            str(col.get("observer", "10")),
            col.get("method", "ASTM E308"),
        ).validated()
    except ColourError as exc:
        raise UserError(f"run {rec.id}: colour settings: {exc}") from None
    scale = str(col.get("scale", "diffuser"))
    src = model.get("source_cone_deg", (config.get("goniometer") or {}).get("source_cone_deg", 6.0))
    det = model.get(
        "detector_cone_deg",
        col.get("detector_cone_deg", (config.get("spectro") or {}).get("detector_cone_deg", 6.0)),
    )
    return settings, scale, float(src), float(det)


def _cmd_fit_colour(args: argparse.Namespace) -> int:
    import numpy as np

    from goniolab.colour.paint import Paint
    from goniolab.colour.paint_fit import FitError, fit_paint
    from goniolab.commands.runs import _get_run, open_store, run_colour

    if not (math.isfinite(args.min_aspecular) and args.min_aspecular >= 0):
        raise UserError(f"--min-aspecular {args.min_aspecular:g}: must be >= 0 deg")
    with open_store(args.store, args.config) as store:
        rec = _get_run(store, args.run)
        if rec.kind != "brdf":
            raise UserError(
                f"run {rec.id} is {a_run_of_kind(rec.kind)}: a colour fit needs a scan run"
            )
        rows = run_colour(store, rec)
    coloured = [r for r in rows if "L" in r]
    if not coloured:
        raise UserError(
            f"run {rec.id} has no measured colour (no readings, or no usable spectra): "
            "nothing to fit"
        )
    used = [r for r in coloured if abs(float(r["aspecular_deg"])) >= args.min_aspecular]
    skipped = [r for r in coloured if r not in used]
    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    settings, scale, src_deg, det_deg = _settings_of(rec)
    if scale not in ("diffuser", "mirror"):
        raise UserError(f"run {rec.id}: colour scale {scale!r} is neither diffuser nor mirror")

    # the starting paint: --paint, else the run's sample's
    if args.paint:
        from goniolab.commands._colour import load_paint_file

        paint: Paint = load_paint_file(args.paint)
    else:
        from goniolab.model_cache import paint_for

        paint = paint_for(rec.sample or None)
    if paint.body is None and not paint.has_flakes and not args.params:
        raise UserError(
            f"run {rec.id}: its sample {rec.sample or '-'} has no paint (no body, no flakes) "
            "to fit; give a starting paint with --paint FILE.toml"
        )
    names = [p.strip() for p in args.params.split(",") if p.strip()] if args.params else None

    # the model: the coat surface of the run's sample (or none) + the paint
    from goniolab.colour.spectra import ColourError, standard_grid_nm
    from goniolab.colour.spectral import SpectralPredictor
    from goniolab.optics.apertures import Cone

    try:
        wl = standard_grid_nm(args.step_nm)
        surface = None
        if not args.no_surface:
            if not rec.sample:
                raise UserError(
                    f"run {rec.id} names no sample: its coat surface is unknown (use --no-surface)"
                )
            from goniolab.model_cache import model_for, surface_factory

            _say(args, f"building the coat-surface model of {rec.sample} ...")
            model_name = args.model or str(rec.model.get("model_name") or "auto")
            n = complex(paint.coat.index(589.3))
            surface = surface_factory(model_for(rec.sample, n=n, model=model_name))
        predictor = SpectralPredictor(
            surface, paint, source=Cone(src_deg), detector=Cone(det_deg), wavelengths_nm=wl
        )
        tr = np.array([float(r["theta_r_deg"]) for r in used])
        lab = np.array([[r["L"], r["a"], r["b"]] for r in used])
        _say(args, f"fitting {len(used)} geometries ...")
        fit = fit_paint(
            predictor,
            theta_i,
            tr,
            lab,
            parameters=names,
            settings=settings,
            scale=scale,  # type: ignore[arg-type]
            metric=args.metric,
        )
    except (FitError, ColourError, ValueError) as exc:
        if isinstance(exc, UserError):
            raise
        raise UserError(f"run {rec.id}: {' '.join(str(exc).split())}") from None

    geometries: list[dict[str, Any]] = []
    for k, r in enumerate(used):
        geometries.append(
            {
                "theta_r_deg": float(r["theta_r_deg"]),
                "aspecular_deg": float(r["aspecular_deg"]),
                "measured": [float(v) for v in fit.measured_lab[k]],
                "fitted": [float(v) for v in fit.fitted_lab[k]],
                "start": [float(v) for v in fit.start_lab[k]],
                "dE2000": float(fit.dE2000[k]),
                "start_dE2000": float(fit.start_dE2000[k]),
            }
        )
    corr = [
        [None if not math.isfinite(float(c)) else round(float(c), 4) for c in row]
        for row in fit.correlation
    ]
    saved = None
    if args.save:
        saved = _save(args.save, fit, rec)
    doc: dict[str, Any] = {
        "run": rec.id,
        "sample": rec.sample,
        "theta_i_deg": theta_i,
        "illuminant": settings.illuminant,
        "observer": settings.observer,
        "scale": scale,
        "metric": args.metric,
        "surface": None if predictor.surface is None else predictor.surface.name,
        "parameters": [p.as_dict() for p in fit.parameters],
        "correlation": corr,
        "geometries": geometries,
        "skipped_aspecular_deg": [float(r["aspecular_deg"]) for r in skipped],
        "minimised": (
            "sum of squared dE2000 (local metric of each measured colour)"
            if args.metric == "de2000"
            else "sum of squared CIE 1976 L*a*b* differences (dE*ab^2)"
        ),
        "mean_dE2000": fit.mean_dE2000,
        "start_mean_dE2000": fit.start_mean_dE2000,
        "dE2000_worse_after_fit": fit.mean_dE2000 > fit.start_mean_dE2000,
        "residual_rms": fit.residual_rms,
        "dof": fit.dof,
        "evaluations": fit.evaluations,
        "paint": fit.paint.describe(),
        "saved": saved,
    }
    if doc["dE2000_worse_after_fit"]:
        print(
            f"goniolab: warning: the fit minimised {doc['minimised']}; its mean dE2000 rose "
            f"from {fit.start_mean_dE2000:.2f} to {fit.mean_dE2000:.2f} "
            "(--metric de2000 minimises dE2000 itself)",
            file=sys.stderr,
        )
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(
        f"run {rec.id} on {rec.sample or '-'}: paint fitted to {len(used)} geometries "
        f"({settings.illuminant}, {settings.observer}, {scale} scale; surface "
        f"{doc['surface'] or 'none'}; minimising {'dE2000' if args.metric == 'de2000' else 'dE*ab'})"
    )
    for r in skipped:
        print(
            f"  aspecular {float(r['aspecular_deg']):g} deg left out "
            f"(closer than --min-aspecular {args.min_aspecular:g} to specular)"
        )
    print("  parameter                      start       fitted    +- 1 sigma")
    for p in fit.parameters:
        if p.at_bound:
            sig = "on a bound"
        elif not math.isfinite(p.sigma):
            sig = "not determined by the data"
        else:
            sig = f"{p.sigma:.4g}"
        unit = f" {p.unit}" if p.unit else ""
        print(f"  {p.name:<26} {p.start:>10.4g}   {p.value:>10.4g}    {sig}{unit}")
    print("  theta_r  aspec   measured L* a* b*       fitted L* a* b*     dE2000 (start)")
    for g in geometries:
        m, f = g["measured"], g["fitted"]
        print(
            f"  {g['theta_r_deg']:7.2f} {g['aspecular_deg']:6.1f}  {m[0]:6.1f} {m[1]:6.1f} "
            f"{m[2]:6.1f}    {f[0]:6.1f} {f[1]:6.1f} {f[2]:6.1f}   {g['dE2000']:6.2f} "
            f"({g['start_dE2000']:.2f})"
        )
    print(
        f"  mean dE2000 {fit.mean_dE2000:.2f} (start {fit.start_mean_dE2000:.2f}); "
        f"rms residual {fit.residual_rms:.3f} ({'dE2000' if args.metric == 'de2000' else 'dE*ab'}"
        f" per component), {fit.dof} degrees of freedom"
    )
    if saved:
        print(f"  fitted paint written to {saved}")
    return 0


def _save(path: str, fit: Any, rec: Any) -> str:
    from goniolab.colour.paint import PaintError, paint_to_dict

    out = Path(path)
    if out.suffix.lower() != ".toml":
        raise UserError(f"--save {out}: the fitted paint is written as TOML (.toml)")
    try:
        doc, tables = paint_to_dict(fit.paint, stem=out.stem)
    except PaintError as exc:
        raise UserError(f"--save {out}: {exc}") from None
    lines = [f"paint fitted by goniolab fit colour to run {rec.id} ({rec.sample or '-'})"]
    lines += [
        f"{p.name} = {p.value:.6g} +- {p.sigma:.3g}" if math.isfinite(p.sigma) else
        f"{p.name} = {p.value:.6g} (uncertainty: {'on a bound' if p.at_bound else 'none'})"
        for p in fit.parameters
    ]  # fmt: skip
    lines.append(f"mean dE2000 {fit.mean_dE2000:.3f}")
    try:
        for name, text in tables.items():
            (out.parent / name).write_text(text, encoding="utf-8")
        out.write_text(toml_text(doc, "\n".join(lines)), encoding="utf-8")
    except OSError as exc:
        raise UserError(f"cannot write {out}: {exc.strerror or exc}") from None
    return str(out)


def register(subparsers: Any) -> None:
    """Add ``goniolab fit`` and its sub-commands."""
    parser = subparsers.add_parser(
        "fit",
        help="fit a model to a measured run (colour: the paint's K/S, flakes, coat index)",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    sub = parser.add_subparsers(dest="fit_command", metavar="WHAT", required=True)
    p = sub.add_parser(
        "colour",
        help="fit K/S, flake area/spread and the coat index to a run's L*a*b* per angle",
        description=re.sub(r":\w+:`([^`]+)`", r"\1", (__doc__ or "").split("\n\n")[1]).replace(
            "``", "'"
        ),
    )
    p.add_argument("run", type=int, metavar="RUN", help=RUN_HELP)
    p.add_argument(
        "--store",
        help="run store: SQLite file or postgresql:// URL (default: the config's [lab] store, "
        "else goniolab.sqlite in the user data dir: goniolab --version)",
    )
    p.add_argument("--config", help="lab config TOML whose [lab] store to use")
    p.add_argument(
        "--paint", metavar="FILE.toml", help="starting paint (default: the run's sample's)"
    )
    p.add_argument(
        "--params",
        default=None,
        help="comma list of parameters to fit (default: body.ks_scale, the flakes' "
        "area_fraction and spread_deg, pearl.film_nm, coat.n; also body.s_scale)",
    )
    p.add_argument(
        "--model",
        choices=model_names(),
        default=None,
        help="coat-surface model (default: the one the run was predicted with)",
    )
    p.add_argument(
        "--no-surface", action="store_true", help="fit the paint alone (no coat-surface gloss)"
    )
    p.add_argument(
        "--min-aspecular",
        type=float,
        default=10.0,
        metavar="DEG",
        help="leave out geometries closer than this to specular, deg",
    )
    p.add_argument(
        "--metric",
        choices=("lab", "de2000"),
        default="lab",
        help="minimise dE*ab (lab: equal weights, calibrated uncertainties) or the "
        "local dE2000 metric of each measured colour",
    )
    p.add_argument("--step-nm", type=float, default=10.0, help="wavelength step, nm")
    p.add_argument("--save", metavar="FILE.toml", help="write the fitted paint (--paint format)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_fit_colour)
