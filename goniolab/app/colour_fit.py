"""``fit colour``: fit a paint to a measured multi-angle run (issue 24: the use case of
``goniolab fit colour``).

The run's measured L*a*b* per geometry (mean over repeats; geometries closer than
``min_aspecular_deg`` to the specular direction are left out: there the gloss of the coat
surface, not the paint, sets the colour) are fitted with the model the run was predicted
with -- its sample's coat surface model (or another, or none) over the sample's paint (or a
given starting paint) -- through :func:`goniolab.colour.paint_fit.fit_paint`: K/S of the
body, the flake populations' area and spread (and a pearl's film), and the coat index,
each with its 1-sigma uncertainty, and the residual dE2000 per geometry. The fitted paint
can be saved in the format ``--paint`` reads.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from goniolab.errors import UserError, a_run_of_kind

if TYPE_CHECKING:
    from goniolab.store import RunRecord

__all__ = ["ColourFit", "FitOptions", "fit_colour", "toml_text"]


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


@dataclass(frozen=True)
class FitOptions:
    """How to fit: a starting ``paint`` file (``None``: the run's sample's), the
    ``params`` to fit (a comma list; ``None``: the default set), the coat-surface ``model``
    (``None``: the one the run was predicted with), ``no_surface`` (the paint alone), the
    geometries left out near specular, the ``metric`` minimised (``lab``: dE*ab,
    ``de2000``), the wavelength step and a ``save`` file for the fitted paint."""

    paint: str | None = None
    params: str | None = None
    model: str | None = None
    no_surface: bool = False
    min_aspecular_deg: float = 10.0
    metric: Literal["lab", "de2000"] = "lab"
    step_nm: float = 10.0
    save: str | None = None


@dataclass(frozen=True)
class ColourFit:
    """The fit: the run, the ``fit colour --json`` document, the fit itself
    (:class:`goniolab.colour.paint_fit.PaintFit`: parameters, dE2000), the geometries
    used and left out, and the warnings (e.g. dE2000 rose while dE*ab fell)."""

    record: RunRecord
    doc: dict[str, Any]
    fit: Any
    used: list[dict[str, Any]]
    skipped: list[dict[str, Any]]
    warnings: list[str] = field(default_factory=list)


def fit_colour(
    run_id: int,
    opts: FitOptions,
    *,
    store: str | Path | None = None,
    config: str | Path | None = None,
    say: Callable[[str], None] | None = None,
) -> ColourFit:
    """Fit a paint to scan ``run_id``'s measured colour; ``say`` is told what is being
    done (building the surface model, fitting)."""
    import numpy as np

    from goniolab.app.colours import load_paint_file
    from goniolab.app.stored_runs import get_run, open_store, run_colour
    from goniolab.colour.paint import Paint
    from goniolab.colour.paint_fit import FitError, fit_paint

    def _say(text: str) -> None:
        if say is not None:
            say(text)

    if not (math.isfinite(opts.min_aspecular_deg) and opts.min_aspecular_deg >= 0):
        raise UserError(f"--min-aspecular {opts.min_aspecular_deg:g}: must be >= 0 deg")
    with open_store(store, config) as s:
        rec = get_run(s, run_id)
        if rec.kind != "brdf":
            raise UserError(
                f"run {rec.id} is {a_run_of_kind(rec.kind)}: a colour fit needs a scan run"
            )
        rows = run_colour(s, rec)
    coloured = [r for r in rows if "L" in r]
    if not coloured:
        raise UserError(
            f"run {rec.id} has no measured colour (no readings, or no usable spectra): "
            "nothing to fit"
        )
    used = [r for r in coloured if abs(float(r["aspecular_deg"])) >= opts.min_aspecular_deg]
    skipped = [r for r in coloured if r not in used]
    theta_i = float(rec.plan.get("theta_i_deg", 45.0))
    settings, scale, src_deg, det_deg = _settings_of(rec)
    if scale not in ("diffuser", "mirror"):
        raise UserError(f"run {rec.id}: colour scale {scale!r} is neither diffuser nor mirror")

    # the starting paint: --paint, else the run's sample's
    if opts.paint:
        paint: Paint = load_paint_file(opts.paint)
    else:
        from goniolab.model_cache import paint_for

        paint = paint_for(rec.sample or None)
    if paint.body is None and not paint.has_flakes and not opts.params:
        raise UserError(
            f"run {rec.id}: its sample {rec.sample or '-'} has no paint (no body, no flakes) "
            "to fit; give a starting paint with --paint FILE.toml"
        )
    names = [p.strip() for p in opts.params.split(",") if p.strip()] if opts.params else None

    # the model: the coat surface of the run's sample (or none) + the paint
    from goniolab.colour.spectra import ColourError, standard_grid_nm
    from goniolab.colour.spectral import SpectralPredictor
    from goniolab.optics.apertures import Cone

    try:
        wl = standard_grid_nm(opts.step_nm)
        surface = None
        if not opts.no_surface:
            if not rec.sample:
                raise UserError(
                    f"run {rec.id} names no sample: its coat surface is unknown (use --no-surface)"
                )
            from goniolab.model_cache import model_for, surface_factory

            _say(f"building the coat-surface model of {rec.sample} ...")
            model_name = opts.model or str(rec.model.get("model_name") or "auto")
            n = complex(paint.coat.index(589.3))
            surface = surface_factory(model_for(rec.sample, n=n, model=model_name))
        predictor = SpectralPredictor(
            surface, paint, source=Cone(src_deg), detector=Cone(det_deg), wavelengths_nm=wl
        )
        tr = np.array([float(r["theta_r_deg"]) for r in used])
        lab = np.array([[r["L"], r["a"], r["b"]] for r in used])
        _say(f"fitting {len(used)} geometries ...")
        fit = fit_paint(
            predictor,
            theta_i,
            tr,
            lab,
            parameters=names,
            settings=settings,
            scale=scale,  # type: ignore[arg-type]
            metric=opts.metric,
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
    if opts.save:
        saved = _save(opts.save, fit, rec)
    doc: dict[str, Any] = {
        "run": rec.id,
        "sample": rec.sample,
        "theta_i_deg": theta_i,
        "illuminant": settings.illuminant,
        "observer": settings.observer,
        "scale": scale,
        "metric": opts.metric,
        "surface": None if predictor.surface is None else predictor.surface.name,
        "parameters": [p.as_dict() for p in fit.parameters],
        "correlation": corr,
        "geometries": geometries,
        "skipped_aspecular_deg": [float(r["aspecular_deg"]) for r in skipped],
        "minimised": (
            "sum of squared dE2000 (local metric of each measured colour)"
            if opts.metric == "de2000"
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
    warnings: list[str] = []
    if doc["dE2000_worse_after_fit"]:
        warnings.append(
            f"the fit minimised {doc['minimised']}; its mean dE2000 rose "
            f"from {fit.start_mean_dE2000:.2f} to {fit.mean_dE2000:.2f} "
            "(--metric de2000 minimises dE2000 itself)"
        )
    return ColourFit(rec, doc, fit, used, skipped, warnings)


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
