"""Pictures of stored runs (matplotlib, Agg: no display needed).

- A scan: measured luminance per geometry (mean of the repeats with a +-1 standard
  deviation bar, each repeat as a faint dot) beside the model's predicted curve, and under
  it the residual panel (mean measured - predicted). ``log=True`` puts the luminance on a
  log axis (the specular peak and the diffuse flanks both stay readable).
  With colour data (the spectro reported spectra, issue 11): L* and a*, b* against the
  aspecular angle in a second column.
- A gloss log: G20/G60/G85 over time with each prediction as a dashed line.

The figure is built with :class:`matplotlib.figure.Figure` (no pyplot, no global state)
and written by its Agg canvas; the file suffix (``.png``, ``.svg``, ``.pdf``) picks the
format.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover - typing only
    import xarray as xr
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from goniolab.store import RunStore

__all__ = ["PLOT_FORMATS", "plot_dataset", "plot_run"]

#: File suffixes a plot can be written to.
PLOT_FORMATS = (".png", ".svg", ".pdf")

_MEASURED = "#1f5fa8"
_PREDICTED = "#d9541e"
_GLOSS = {20: "#1f5fa8", 60: "#2a9d4a", 85: "#b8860b"}


def plot_run(
    store: RunStore, run_id: int, *, out: str | Path | None = None, log: bool = False
) -> Figure:
    """Draw run ``run_id`` of ``store`` (and write it to ``out`` when given)."""
    from goniolab.datasets import run_dataset

    return plot_dataset(run_dataset(store, run_id), out=out, log=log)


def plot_dataset(ds: xr.Dataset, *, out: str | Path | None = None, log: bool = False) -> Figure:
    """Draw a run Dataset of :func:`goniolab.datasets.run_dataset`.

    Raises
    ------
    ValueError
        ``out`` has a suffix other than :data:`PLOT_FORMATS`.
    OSError
        The file cannot be written.
    """
    if out is not None and Path(out).suffix.lower() not in PLOT_FORMATS:
        raise ValueError(
            f"{out}: a plot is written as {', '.join(PLOT_FORMATS)} (from the file suffix)"
        )
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    colour = "L_star" in ds and bool(np.isfinite(ds["L_star"].values).any())
    if ds.attrs.get("kind") == "gloss":
        fig = Figure(figsize=(8.0, 4.5), layout="constrained")
        _gloss(fig, ds)
    elif ds.attrs.get("kind") in ("align", "calibration"):
        fig = Figure(figsize=(10.0, 4.5), layout="constrained")
        _align(fig, ds)
    else:
        fig = Figure(figsize=(12.0 if colour else 8.0, 6.0), layout="constrained")
        _scan(fig, ds, log=log, colour=colour)
    FigureCanvasAgg(fig)
    if out is not None:
        fig.savefig(Path(out), dpi=120)
    return fig


def _title(ds: xr.Dataset) -> str:
    status = str(ds.attrs.get("status", ""))
    reason = str(ds.attrs.get("reason", ""))
    text = f"run {ds.attrs.get('run_id', '?')} on {ds.attrs.get('sample') or '-'}: {status}"
    if reason and status != "done":
        text += f" ({reason})"
    return text


def _predicted_label(ds: xr.Dataset) -> str:
    """``predicted (kirchhoff model)``: the model the run was predicted with (its stored
    ``model_name``; ``predicted (auto: facet, kirchhoff)`` naming the models the auto rule
    picked, from the run's ``computed_by``; a run that names none says only ``predicted``,
    not a guess)."""
    import json

    try:
        model = json.loads(str(ds.attrs.get("model_json") or "{}"))
    except ValueError:
        model = {}
    if not isinstance(model, dict):
        return "predicted"
    name = model.get("model_name") or model.get("kind")
    computed_by = model.get("computed_by")
    used = sorted(computed_by) if isinstance(computed_by, dict) else []
    if name == "auto" and used:
        # issue 27: the legend names the model auto picked, not "auto model"
        return f"predicted (auto: {', '.join(str(m) for m in used)})"
    return f"predicted ({name} model)" if name else "predicted"


def _scan(fig: Figure, ds: xr.Dataset, *, log: bool, colour: bool) -> None:
    grid = fig.add_gridspec(2, 2 if colour else 1, height_ratios=(3, 1))
    ax = fig.add_subplot(grid[0, 0])
    res = fig.add_subplot(grid[1, 0], sharex=ax)
    tr = ds["theta_r_deg"].values
    lum = ds["luminance_pct"].values
    mean = ds["luminance_mean_pct"].values
    std = np.nan_to_num(ds["luminance_std_pct"].values, nan=0.0)
    pred = ds["predicted_pct"].values
    reps = lum.shape[1] if lum.ndim == 2 else 1
    if reps > 1:
        xs = np.repeat(tr, reps)
        ax.plot(xs, lum.ravel(), ".", color=_MEASURED, alpha=0.25, ms=3, label="_repeats")
    ok = np.isfinite(mean)
    ax.errorbar(
        tr[ok],
        mean[ok],
        yerr=std[ok],
        fmt="o",
        ms=4,
        color=_MEASURED,
        ecolor=_MEASURED,
        capsize=2,
        label=f"measured (mean of {reps}, +-1 sd)" if reps > 1 else "measured",
    )
    if np.isfinite(pred).any():
        ax.plot(tr, pred, "-", color=_PREDICTED, lw=1.6, label=_predicted_label(ds))
    if log:
        ax.set_yscale("log")
    ax.set_ylabel("relative luminance (% of mirror)")
    ti = float(ds["theta_i_deg"].values) if "theta_i_deg" in ds.coords else None
    if ti is not None:
        ax.axvline(ti, color="0.6", lw=0.8, ls=":", label=f"specular ({ti:g} deg)")
    ax.set_title(_title(ds), fontsize=10)
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    ax.tick_params(labelbottom=False)
    resid = ds["residual_pct"].values
    rok = np.isfinite(resid)
    res.axhline(0.0, color="0.4", lw=0.8)
    res.plot(tr[rok], resid[rok], "o", ms=3, color=_MEASURED)
    res.set_ylabel("measured -\npredicted (%)")
    res.set_xlabel("detector angle theta_r (deg)")
    res.grid(alpha=0.3)
    if colour:
        _colour(fig, grid, ds)


def _colour(fig: Figure, grid: Any, ds: xr.Dataset) -> None:
    asp = ds["aspecular_deg"].values
    lab = fig.add_subplot(grid[0, 1])
    ab = fig.add_subplot(grid[1, 1], sharex=lab)
    _colour_series(lab, asp, ds, "L_star", "L*", "0.2")
    _colour_series(ab, asp, ds, "a_star", "a*", "#c0392b")
    _colour_series(ab, asp, ds, "b_star", "b*", "#2c7fb8")
    lab.set_ylabel("L*")
    lab.set_title("multi-angle colour (CIELAB)", fontsize=10)
    lab.tick_params(labelbottom=False)
    ab.set_ylabel("a*, b*")
    ab.set_xlabel("aspecular angle (deg)")
    for a in (lab, ab):
        a.grid(alpha=0.3)
        a.legend(fontsize=8, loc="best")


def _colour_series(ax: Axes, asp: Any, ds: xr.Dataset, name: str, label: str, c: str) -> None:
    values = ds[name].values
    mean = np.nanmean(np.where(np.isfinite(values), values, np.nan), axis=1)
    ok = np.isfinite(mean)
    ax.plot(asp[ok], mean[ok], "o", ms=3, color=c, label=f"{label} measured")
    pname = f"predicted_{name}"
    if pname in ds and np.isfinite(ds[pname].values).any():
        ax.plot(asp, ds[pname].values, "-", color=c, lw=1.2, label=f"{label} predicted")


def _gloss(fig: Figure, ds: xr.Dataset) -> None:
    ax = fig.add_subplot(1, 1, 1)
    t = ds["time"].values
    for angle, c in _GLOSS.items():
        vals = ds[f"g{angle}_gu"].values
        ok = np.isfinite(vals)
        if ok.any():
            ax.plot(t[ok], vals[ok], "o-", ms=3, lw=1, color=c, label=f"G{angle} measured")
        pred = ds[f"predicted_g{angle}_gu"].values
        if np.isfinite(pred).any():
            ax.axhline(float(np.nanmean(pred)), color=c, ls="--", lw=1, label=f"G{angle} predicted")
    ax.set_ylabel("gloss (GU, ISO 2813)")
    ax.set_xlabel("time (UTC)")
    ax.set_title(_title(ds), fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best", ncols=2)
    from matplotlib.dates import AutoDateLocator, ConciseDateFormatter

    locator = AutoDateLocator()
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(ConciseDateFormatter(locator))


def _align(fig: Figure, ds: xr.Dataset) -> None:
    """An alignment run: each specimen's detector sweeps per incidence (log scale: the
    black glass's 5 % and the sample's peaks on one axis), saturated readings marked."""
    import json

    spec = ds["specimen"].values
    names = [s for s in ("standard", "sample") if s in spec] or list(dict.fromkeys(spec))
    for k, specimen in enumerate(names):
        ax = fig.add_subplot(1, max(len(names), 1), k + 1)
        sel = spec == specimen
        ti = ds["theta_i_deg"].values[sel]
        tr = ds["theta_r_deg"].values[sel]
        lum = ds["luminance_pct"].values[sel]
        bad = ds["quality"].values[sel] == "saturated"
        for t in np.unique(ti):
            m = ti == t
            order = np.argsort(tr[m])
            ax.plot(tr[m][order], lum[m][order], ".-", ms=3, lw=0.8, label=f"theta_i {t:g} deg")
        if bad.any():
            ax.plot(tr[bad], lum[bad], "x", color="red", label="saturated")
        ax.set_yscale("log" if (lum > 0).any() else "linear")
        ax.set_xlabel("detector arm (deg)")
        ax.set_ylabel("luminance (% of a perfect mirror)")
        ax.set_title("black-glass standard" if specimen == "standard" else str(specimen),
                     fontsize=10)  # fmt: skip
        ax.grid(alpha=0.3)
        if sel.any():
            ax.legend(fontsize=8)
    result = json.loads(str(ds.attrs.get("alignment_json") or "{}"))
    extra = ""
    if result:
        extra = (
            f": lamp zero {result.get('lamp_zero_deg', float('nan')):+.3f}, detector zero "
            f"{result.get('detector_zero_deg', float('nan')):+.3f}, tilt "
            f"{result.get('sample_tilt_deg', float('nan')):+.3f} deg"
        )
    fig.suptitle(_title(ds) + extra, fontsize=10)
