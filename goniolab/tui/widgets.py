"""The widgets of the goniolab TUI: comparison plots, metrics, instrument status, gloss log."""

from __future__ import annotations

import math
import re
from datetime import UTC, datetime
from typing import Any

import numpy as np
from textual import events
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.widget import Widget
from textual.widgets import DataTable, Input, Label, Select, Static
from textual_plot import HiResMode, LegendLocation, PlotWidget

from goniolab.errors import UserError
from goniolab.scan.events import GlossRead
from goniolab.tui.comparison import Comparison, ComparisonMetrics
from goniolab.tui.view_model import ArmState, ScanSetup

FloatArray = np.typing.NDArray[np.float64]

__all__ = [
    "PLOT_MODES",
    "ColourNote",
    "ColourSwatch",
    "ColourTable",
    "ComparisonPanel",
    "FormInput",
    "GlossLog",
    "MetricsTable",
    "ScanForm",
    "StatusLine",
    "StatusPanel",
    "fmt_num",
]

GLOSS_ANGLES_DEG = (20, 60, 85)

#: Main-plot modes cycled by ``c``: the luminance curve, L* against angle, a* and b* against angle.
PLOT_MODES: tuple[str, ...] = ("luminance", "L*", "a*b*")


class ColourSwatch(Static):
    """The colour of the current point (display sRGB of its L*a*b*) with its numbers."""

    DEFAULT_CSS = "ColourSwatch { height: 1; }"

    def show_lab(self, lab: tuple[float, float, float] | None) -> None:
        """Paint the swatch (blank without a colour)."""
        if lab is None:
            self.update("colour: -")
            return
        from goniolab.colour.spectra import lab_to_srgb  # colour-science: already imported
        # by the runner, which converted this reading's spectrum before publishing it

        r, g, b = (round(255 * float(v)) for v in lab_to_srgb(lab))
        self.update(
            f"[on rgb({r},{g},{b})]        [/] L* {lab[0]:.1f}  a* {lab[1]:.1f}  b* {lab[2]:.1f}"
        )


class SyncedTable(DataTable[str]):
    """A :class:`DataTable` whose vertical scrollbar shows where it is scrolled when the
    bar appears.

    Textual moves a scrollbar's thumb only while the bar is shown
    (``Widget.watch_scroll_y``). A table that scrolls to its new last row in the same
    refresh that makes it overflow (the gloss log's third reading at 80 x 24) scrolled
    first and showed its bar after, its thumb at the top beside the bottom rows until
    the next scroll."""

    def watch_show_vertical_scrollbar(self, shown: bool) -> None:
        if shown:
            self.vertical_scrollbar.position = self.scroll_y


class ColourTable(SyncedTable):
    """Per point: theta_r, the E2194 aspecular angle, measured L*a*b*, predicted L*, the
    signed dL*, dC*, dH* and dE00 (predicted - measured) and the verdict of the tolerance
    set at that aspecular angle (:data:`goniolab.colour.tolerance.BUILTIN_SETS`
    ``din6175-2`` by default); a last row gives the overall verdict, with ``prov.`` beside
    it for a provisional set (``din6175-2``'s limits are goniolab's, not the standard's).
    A predicted L* made by a wavelength-free model (the facet model) carries
    :data:`FREE_MARK`; :class:`ColourNote` under the table says what that means, in the app
    layer's words (:func:`goniolab.app.colour_notes.predicted_colour_models`, as ``runs colour``)."""

    #: The mark beside a predicted colour whose model has no wavelength in it.
    FREE_MARK = "†"
    #: The tolerance set judged per angle (a :class:`goniolab.colour.tolerance.ToleranceSet`).
    tolerance_name = "din6175-2"

    def on_mount(self) -> None:
        self.cursor_type = "none"
        self.zebra_stripes = True
        for label, key, width in (
            ("θr °", "theta", 7),
            ("asp °", "asp", 6),
            ("L*", "L", 6),
            ("a*", "a", 6),
            ("b*", "b", 6),
            ("pred L*", "pL", 7),
            ("ΔL*", "dL", 6),
            ("ΔC*", "dC", 6),
            ("ΔH*", "dH", 6),
            ("ΔE00", "dE", 6),
            ("tol", "tol", 5),
        ):
            self.add_column(label, key=key, width=width)

    def show(self, comparison: Comparison) -> None:
        """Refill from ``comparison`` (one row per point, then the overall verdict)."""
        from goniolab.colour.tolerance import BUILTIN_SETS, evaluate

        c = comparison.colour_arrays()
        self.clear()
        d = c.differences()
        tol = BUILTIN_SETS[self.tolerance_name]
        verdicts, overall = evaluate(tol, c.aspecular_deg, c.measured_lab, c.predicted_lab)
        for k, t in enumerate(c.theta_r_deg):
            m, p = c.measured_lab[k], c.predicted_lab[k]
            passed = verdicts[k].passed if np.all(np.isfinite(d["dE00"][k])) else None
            self.add_row(
                fmt_num(float(t), 1),
                fmt_num(float(c.aspecular_deg[k]), 0),
                *(fmt_num(float(v), 1) for v in m),
                fmt_num(float(p[0]), 1)
                + (f" {self.FREE_MARK}" if c.predicted_colour_note[k] is not None else ""),
                *(fmt_num(float(d[key][k]), 2) for key in ("dL", "dC", "dH", "dE00")),
                {True: "pass", False: "FAIL", None: "-"}[passed],
            )
        if overall["checked_angles"] and np.all(np.isfinite(d["dE00"])):
            verdict = "PASS" if overall["passed"] else "FAIL"
            # a set whose limits are not confirmed says so beside its verdict
            prov = "prov." if tol.provisional else ""
            self.add_row("overall", "", "", "", "", "", "", "", prov, tol.name[:6], verdict)


class ColourNote(Static):
    """The colour table's legend: what its :attr:`ColourTable.FREE_MARK` means (the notes of
    :func:`goniolab.app.colour_notes.predicted_colour_models`) and where repeats were
    averaged as L*a*b* instead of as spectra; hidden when there is nothing to say."""

    #: at most two lines under the table (of fixed height, :class:`ComparisonPanel`): the
    #: rows' own notes, whose first words say what the mark means; the whole notes, with
    #: the angles each covers, in the tooltip
    DEFAULT_CSS = "ColourNote { height: auto; max-height: 2; color: $warning; }"

    def show(self, comparison: Comparison) -> None:
        """Say the notes of ``comparison``'s predicted colours (hide without any)."""
        c = comparison.colour_arrays()
        row_notes = dict.fromkeys(n for n in c.predicted_colour_note if n is not None)
        lines = [f"{ColourTable.FREE_MARK} {n}" for n in row_notes]
        lines += [f"note: {n}" for n in c.averaging_notes]
        self.update("\n".join(lines))
        whole = [f"{ColourTable.FREE_MARK} {n}" for n in c.predicted_colour_notes]
        whole += [f"note: {n}" for n in c.averaging_notes]
        self.tooltip = "\n".join(whole) or None
        self.display = bool(lines)


def fmt_num(value: float | None, digits: int = 2) -> str:
    """Format a number for a table cell; ``-`` for missing or NaN."""
    if value is None or not math.isfinite(value):
        return "-"
    if abs(value) < 0.5 * 10.0**-digits:
        value = 0.0  # no "-0.00"
    return f"{value:.{digits}f}"


class MetricsTable(DataTable[str]):
    """Measured vs predicted: amplitude, peak position, FWHM, RMSE and gloss."""

    ROWS = (
        ("amplitude", "peak %"),
        ("position", "peak θr °"),
        ("fwhm", "FWHM °"),
        ("rmse", "RMSE %"),
        ("g20", "G20 GU"),
        ("g60", "G60 GU"),
        ("g85", "G85 GU"),
    )

    def on_mount(self) -> None:
        self.cursor_type = "none"
        self.zebra_stripes = True
        self.add_column("metric", key="metric")
        self.add_column("meas.", key="measured", width=6)
        self.add_column("pred.", key="predicted", width=6)
        self.add_column("Δ", key="delta", width=6)
        for key, label in self.ROWS:
            self.add_row(label, "-", "-", "-", key=key)

    def show(self, m: ComparisonMetrics) -> None:
        """Fill the table from ``m``."""
        pairs: dict[str, tuple[float | None, float | None, int]] = {
            "amplitude": (m.measured.amplitude, m.predicted.amplitude, 2),
            "position": (m.measured.position_deg, m.predicted.position_deg, 1),
            "fwhm": (m.measured.fwhm_deg, m.predicted.fwhm_deg, 2),
            "rmse": (m.rmse_pct, None, 3),
        }
        for angle in GLOSS_ANGLES_DEG:
            pairs[f"g{angle}"] = (
                m.gloss_measured_gu.get(angle),
                m.gloss_predicted_gu.get(angle),
                1,
            )
        for key, (meas, pred, digits) in pairs.items():
            delta = meas - pred if meas is not None and pred is not None else None
            self.update_cell(key, "measured", fmt_num(meas, digits))
            self.update_cell(key, "predicted", fmt_num(pred, digits))
            self.update_cell(key, "delta", fmt_num(delta, digits))


class ComparisonPanel(Horizontal):
    """Measured points (mean with min/max bars of the repeats) over the predicted curve,
    and beside it the residuals (or a log10 view) and the metrics table."""

    DEFAULT_CSS = """
    ComparisonPanel { height: 1fr; }
    ComparisonPanel > .main-plot { width: 3fr; border: round $primary; }
    ComparisonPanel > Vertical { width: 2fr; min-width: 36; }
    ComparisonPanel .side-plot { height: 1fr; min-height: 5; border: round $secondary; }
    ComparisonPanel MetricsTable { height: 9; }
    ComparisonPanel ColourTable { height: 7; }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.log_view = False
        self.plot_mode = PLOT_MODES[0]

    def compose(self) -> ComposeResult:
        main = PlotWidget(classes="main-plot", allow_pan_and_zoom=True)
        main.border_title = "luminance % vs θr °"
        yield main
        with Vertical():
            side = PlotWidget(classes="side-plot", allow_pan_and_zoom=True)
            side.border_title = "residual (meas. − pred.) %"
            yield side
            yield MetricsTable()
            yield ColourSwatch("colour: -")
            yield ColourTable()
            note = ColourNote("")
            note.display = False  # until a predicted colour needs it
            yield note

    @property
    def main_plot(self) -> PlotWidget:
        return self.query_one(".main-plot", PlotWidget)

    @property
    def side_plot(self) -> PlotWidget:
        return self.query_one(".side-plot", PlotWidget)

    def toggle_log(self) -> None:
        """Switch the side plot between residuals and log10 of both curves."""
        self.log_view = not self.log_view

    def cycle_plot_mode(self) -> str:
        """Main plot: luminance -> L* vs angle -> a*, b* vs angle -> luminance."""
        k = PLOT_MODES.index(self.plot_mode)
        self.plot_mode = PLOT_MODES[(k + 1) % len(PLOT_MODES)]
        return self.plot_mode

    def _show_colour_plot(self, comparison: Comparison) -> None:
        c = comparison.colour_arrays()
        main = self.main_plot
        main.border_subtitle = comparison.sample.removeprefix("sample:")
        main.clear()
        main.set_xlabel("θr (deg)")
        axes = ((0, "L*", "cyan", "yellow"),) if self.plot_mode == "L*" else (
            (1, "a*", "red", "bold red"),
            (2, "b*", "blue", "bold blue"),
        )  # fmt: skip
        main.border_title = f"{self.plot_mode} vs θr °"
        ys: list[FloatArray] = []
        for col, name, line, marker in axes:
            pred, meas = c.predicted_lab[:, col], c.measured_lab[:, col]
            hp, hm = np.isfinite(pred), np.isfinite(meas)
            if hp.any():
                main.plot(
                    c.theta_r_deg[hp], pred[hp], line_style=line, hires_mode=HiResMode.BRAILLE,
                    label=f"predicted {name}",
                )  # fmt: skip
                ys.append(pred[hp])
            if hm.any():
                main.scatter(
                    c.theta_r_deg[hm], meas[hm], marker="●", marker_style=marker,
                    label=f"measured {name}",
                )  # fmt: skip
                ys.append(meas[hm])
        main.show_legend(LegendLocation.TOPRIGHT, is_visible=bool(ys))
        if ys:
            v = np.concatenate(ys)
            lo, hi = float(v.min()), float(v.max())
            pad = 0.08 * (hi - lo) if hi > lo else 1.0
            main.set_ylimits(lo - pad, hi + pad)
        else:
            main.set_ylimits(None, None)

    def show(self, comparison: Comparison) -> None:
        """Redraw both plots and the metrics table from ``comparison``."""
        self.query_one(ColourSwatch).show_lab(comparison.current_lab())
        self.query_one(ColourTable).show(comparison)
        self.query_one(ColourNote).show(comparison)
        if self.plot_mode != "luminance":
            self._show_colour_plot(comparison)
        else:
            self._show_luminance_plot(comparison)
        self._show_side(comparison)

    def _show_luminance_plot(self, comparison: Comparison) -> None:
        a = comparison.arrays()
        main = self.main_plot
        main.border_title = "luminance % vs θr °"
        main.border_subtitle = comparison.sample.removeprefix("sample:")
        main.clear()
        main.set_xlabel("θr (deg)")
        has_pred = np.isfinite(a.predicted_pct)
        has_meas = np.isfinite(a.mean_pct)
        if has_pred.any():
            main.plot(
                a.theta_r_deg[has_pred],
                a.predicted_pct[has_pred],
                line_style="bold cyan",
                hires_mode=HiResMode.BRAILLE,
                label="predicted",
            )
        if has_meas.any():
            x = a.theta_r_deg[has_meas]
            mean = a.mean_pct[has_meas]
            # Asymmetric min/max bars drawn as symmetric bars around the midpoint.
            mid = (a.min_pct[has_meas] + a.max_pct[has_meas]) / 2.0
            half = (a.max_pct[has_meas] - a.min_pct[has_meas]) / 2.0
            if np.any(half > 0):
                main.errorbar(x, mid, yerr=half, marker_style="yellow", label="min/max")
            main.scatter(x, mean, marker="●", marker_style="bold yellow", label="measured")
        # top left: an in-plane curve is low there (its peak sits near theta_r = theta_i)
        main.show_legend(LegendLocation.TOPLEFT, is_visible=bool(has_pred.any() or has_meas.any()))
        # Head-room above the peak so the top point is not drawn on the frame.
        ys = np.concatenate([a.predicted_pct[has_pred], a.max_pct[has_meas]])
        if ys.size:
            top = float(ys.max())
            bottom = min(0.0, float(np.concatenate([a.min_pct[has_meas], ys]).min()))
            main.set_ylimits(bottom, top + 0.08 * (top - bottom) if top > bottom else top + 1.0)
        else:
            main.set_ylimits(None, None)

    def _show_side(self, comparison: Comparison) -> None:
        a = comparison.arrays()
        has_pred = np.isfinite(a.predicted_pct)
        has_meas = np.isfinite(a.mean_pct)
        side = self.side_plot
        side.clear()
        side.set_xlabel("θr (deg)")
        if self.log_view:
            side.border_title = "log10 luminance %"
            pos_p = has_pred & (a.predicted_pct > 0)
            pos_m = has_meas & (a.mean_pct > 0)
            if pos_p.any():
                side.plot(
                    a.theta_r_deg[pos_p],
                    np.log10(a.predicted_pct[pos_p]),
                    line_style="bold cyan",
                    hires_mode=HiResMode.BRAILLE,
                )
            if pos_m.any():
                side.scatter(
                    a.theta_r_deg[pos_m],
                    np.log10(a.mean_pct[pos_m]),
                    marker="●",
                    marker_style="bold yellow",
                )
        else:
            side.border_title = "residual (meas. − pred.) %"
            res = a.residual_pct
            ok = np.isfinite(res)
            if ok.any():
                side.bar(
                    a.theta_r_deg[ok],
                    res[ok],
                    bar_style=["green" if r >= 0 else "red" for r in res[ok]],
                )
        self.query_one(MetricsTable).show(comparison.metrics())


class StatusPanel(Vertical):
    """Arm angles, moving/idle, homed, connection and alarm state, plus the run state."""

    DEFAULT_CSS = """
    StatusPanel { height: auto; border: round $primary; }
    StatusPanel DataTable { height: 3; }
    StatusPanel #arm-note { height: auto; color: $warning; }
    StatusPanel #run-state { height: auto; margin: 1 0 0 0; }
    """

    def __init__(self) -> None:
        super().__init__()
        self._notes: dict[str, str] = {}

    def compose(self) -> ComposeResult:
        yield DataTable[str](id="arms", cursor_type="none", show_cursor=False)
        yield Static("", id="arm-note")
        yield Static("run: idle", id="run-state")

    def on_mount(self) -> None:
        self.border_title = "instrument"
        table = self.query_one("#arms", DataTable)
        table.cell_padding = 0  # fits a 41-column panel: each width leaves its own gap
        for key, label, width in (
            # "-89.99" .. "89.99" (the sample plane) leave a gap: with the labels' 9
            # columns the table is 39 wide (the -medium layout's panel gives 39 inside)
            ("angle", "angle°", 7),
            ("motion", "motion", 7),
            ("homed", "homed", 6),
            ("link", "link", 5),
            ("alarm", "alarm", 5),
        ):
            table.add_column(label, key=key, width=width)
        # the labels' trailing space is the gap before the angle ("detector58.00" was
        # read as one word: the label column is as wide as its longest label)
        table.add_row("-", "-", "-", "…", "-", key="lamp", label="lamp ")
        table.add_row("-", "-", "-", "…", "-", key="detector", label="detector ")

    def _set(self, row: str, col: str, text: str) -> None:
        """Update one cell, skipping unchanged values (polling must not repaint idly)."""
        table = self.query_one("#arms", DataTable)
        if str(table.get_cell(row, col)) != text:
            table.update_cell(row, col, text)

    def show_arm(self, arm: ArmState) -> None:
        """Update one arm's row (``arm.name`` is ``lamp`` or ``detector``)."""
        self._set(arm.name, "angle", fmt_num(arm.position_deg, 2))
        self._set(arm.name, "motion", "moving" if arm.moving else "idle")
        self._set(arm.name, "homed", "yes" if arm.homed else "no")
        self._set(arm.name, "link", "ok" if arm.connected else "lost")
        self._set(arm.name, "alarm", "-" if arm.alarm_code is None else f"{arm.alarm_code:#x}")
        # The reason (alarm text, lost link) in full on its own line under the table.
        self._notes[arm.name] = f"{arm.name}: {arm.message}" if arm.message else ""
        note = "\n".join(n for n in (self._notes.get("lamp"), self._notes.get("detector")) if n)
        self.query_one("#arm-note", Static).update(note)
        line = _status_line(self)
        if line is not None:
            state = "moving" if arm.moving else "idle"
            if not arm.connected:
                state = "link lost"
            elif arm.alarm_code is not None:
                state = f"alarm {arm.alarm_code:#x}"
            elif not arm.homed:
                state += ", not homed"
            line.set_arm(arm.name, fmt_num(arm.position_deg, 2), state)

    def show_angles(self, theta_i_deg: float, theta_r_deg: float, moving: bool) -> None:
        """Update both arms from an ArmsMoved event (angles in degrees)."""
        motion = "moving" if moving else "idle"
        self._set("lamp", "angle", fmt_num(theta_i_deg, 2))
        self._set("detector", "angle", fmt_num(theta_r_deg, 2))
        self._set("lamp", "motion", motion)
        self._set("detector", "motion", motion)
        line = _status_line(self)
        if line is not None:
            line.set_arm("lamp", fmt_num(theta_i_deg, 2), motion)
            line.set_arm("detector", fmt_num(theta_r_deg, 2), motion)

    def show_run(self, text: str) -> None:
        """Replace the run-state line (and the status line's run part)."""
        self.query_one("#run-state", Static).update(text)
        line = _status_line(self)
        if line is not None:
            line.set_run(text)


def _arms_text(arms: dict[str, tuple[str, str]], short: bool) -> str:
    """Both arms' angle and state: ``lamp 45.00 idle  detector 30.00 moving``, or short
    ``θi 45.00 θr 30.00 idle`` (one state when both share it)."""
    labels = (("θi", "lamp"), ("θr", "detector")) if short else (("lamp", "lamp"), ("detector", "detector"))  # fmt: skip
    parts = [(label, *arms[name]) for label, name in labels if name in arms]
    if short and len(parts) == 2 and parts[0][2] == parts[1][2]:
        return f"{parts[0][0]} {parts[0][1]} {parts[1][0]} {parts[1][1]} {parts[0][2]}"
    return "  ".join(f"{label} {angle} {state}" for label, angle, state in parts)


def status_text(run: str, arms: dict[str, tuple[str, str]], width: int) -> str:
    """The status line for ``width`` columns (0: unknown, in full): the run part (state,
    points, ETA, model) and each arm's (angle, state) as long as it fits, else shorter:
    the arms as θi/θr, then the model's name alone, then no model (the instrument panel's
    run line names it), so that the run's state, its points and both arms stay on an
    80-column line (issue 27: the detector's part was cut off there)."""
    runs = [run]
    model = re.search(r"\s*\(predicted by ([^)]*)\)", run)
    if model is not None:
        runs.append(run.replace(model.group(0), f"  ({model.group(1)})"))
        runs.append(run.replace(model.group(0), ""))
    candidates = []
    for r in runs:
        for short in (False, True):
            a = _arms_text(arms, short)
            candidates.append(f"{r}  |  {a}" if a else r)
    for text in candidates:
        if width <= 0 or len(text) <= width:
            return text
    return candidates[-1][: max(0, width - 1)] + "…"


class StatusLine(Static):
    """One line that stays on screen at any terminal size: the run (state, points, ETA) and
    the lab (each arm's angle and motion, homed, link, alarm), shortened to fit
    (:func:`status_text`)."""

    DEFAULT_CSS = """
    StatusLine { height: 1; background: $boost; padding: 0 1; }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__("run: idle", id=id)
        self._run = "run: idle"
        self._arms: dict[str, tuple[str, str]] = {}

    def set_run(self, text: str) -> None:
        """The run part (what the instrument panel's run line says)."""
        self._run = text
        self._show()

    def set_arm(self, name: str, angle: str, state: str) -> None:
        """One arm's part: its angle (``45.00``) and state (``idle``, ``alarm 0x10``)."""
        self._arms[name] = (angle, state)
        self._show()

    def on_resize(self, event: events.Resize) -> None:
        self._show()

    def _show(self) -> None:
        self.update(status_text(self._run, self._arms, self.content_region.width))


def _status_line(widget: Widget) -> StatusLine | None:
    """The app's status line, if it is mounted."""
    try:
        return widget.app.query_one(StatusLine)
    except NoMatches:
        return None


class GlossLog(SyncedTable):
    """Glossmeter readings as they come: time, measured and predicted G20/G60/G85; the
    border's subtitle counts the warnings stored with the predicted gloss of the run."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        #: the gloss runs whose stored prediction warnings were asked for
        self.checked_runs: set[int] = set()

    def show_prediction_warnings(self, run_id: int, warnings: list[str]) -> None:
        """Say under the log how many warnings run ``run_id``'s predicted gloss carries
        (the stored run's, :func:`goniolab.optics.provenance.gloss_provenance_of`'s notes)
        and where to read them."""
        n = len(warnings)
        self.border_subtitle = (
            f"{n} prediction warning{'s' if n != 1 else ''} (goniolab runs show {run_id})"
            if warnings
            else ""
        )

    def on_mount(self) -> None:
        self.cursor_type = "row"
        self.zebra_stripes = True
        self.add_column("time (UTC)", key="time")
        for angle in GLOSS_ANGLES_DEG:
            self.add_column(f"G{angle}", key=f"g{angle}")
        for angle in GLOSS_ANGLES_DEG:
            self.add_column(f"pred G{angle}", key=f"p{angle}")

    def add_reading(self, ev: GlossRead) -> None:
        """Append one reading (newest at the bottom, scrolled into view)."""
        when = datetime.fromtimestamp(ev.timestamp, tz=UTC).strftime("%H:%M:%S")
        pred = ev.predicted_gu or {}
        cells = [when]
        cells += [fmt_num(ev.values_gu.get(a), 1) for a in GLOSS_ANGLES_DEG]
        cells += [fmt_num(pred.get(a), 1) for a in GLOSS_ANGLES_DEG]
        self.add_row(*cells)
        self.move_cursor(row=self.row_count - 1)


class FormInput(Input):
    """A number field that takes only what a number can contain, so that the app's
    single-letter commands (s, x, g, h, l, r, q) still work while it has focus.

    Textual drops an app binding whose key the focused widget may consume
    (:meth:`check_consume_key`); a plain :class:`Input` claims every printable key.
    """

    def _accepts(self, character: str | None) -> bool:
        allowed = "0123456789+-" if self.type == "integer" else "0123456789+-.eE"
        return character is not None and len(character) == 1 and character in allowed

    def check_consume_key(self, key: str, character: str | None) -> bool:
        return self._accepts(character)

    async def _on_key(self, event: events.Key) -> None:
        if event.is_printable and not self._accepts(event.character):
            event.prevent_default()  # not for the field: let it reach the app's bindings
            return
        await super()._on_key(event)


class ScanForm(Vertical):
    """Sample, theta_i, theta_r range and repeats of the next scan."""

    DEFAULT_CSS = """
    ScanForm { height: auto; border: round $primary; }
    ScanForm .field { height: 1; }
    ScanForm .field Label { width: 11; }
    ScanForm .field Input { width: 1fr; }
    ScanForm #sample-note { height: auto; color: $text-muted; margin: 0 0 1 0; }
    ScanForm #form-problem { height: auto; color: $error; display: none; }
    ScanForm #form-problem.shown { display: block; }
    """

    FIELDS = (
        ("theta_i_deg", "θi °"),
        ("theta_r_start_deg", "θr from °"),
        ("theta_r_stop_deg", "θr to °"),
        ("theta_r_step_deg", "θr step °"),
        ("repeats", "repeats"),
    )

    def __init__(self, samples: list[str], setup: ScanSetup, *, sample_note: str = "") -> None:
        super().__init__()
        self._samples = samples
        self._setup = setup
        self._sample_note = sample_note

    def compose(self) -> ComposeResult:
        name = self._setup.sample.removeprefix("sample:")
        options = [(s, s) for s in self._samples]
        if name not in self._samples:
            options.insert(0, (name, name))
        yield Select(options, value=name, allow_blank=False, id="sample")
        if self._sample_note:
            yield Static(self._sample_note, id="sample-note")
        for key, label in self.FIELDS:
            with Horizontal(classes="field"):
                yield Label(label)
                value = getattr(self._setup, key)
                yield FormInput(
                    f"{value:g}" if isinstance(value, float) else str(value),
                    id=key,
                    type="integer" if key == "repeats" else "number",
                    compact=True,
                )
        yield Static("", id="form-problem")

    def on_mount(self) -> None:
        self.border_title = "scan setup"

    def show_problem(self, text: str) -> None:
        """Why the plan as typed cannot run (the lab's words, :meth:`Backend.check_setup`),
        under the fields; ``""`` hides the line."""
        line = self.query_one("#form-problem", Static)
        line.update(text)
        line.set_class(bool(text), "shown")

    @property
    def problem(self) -> str:
        """The refusal shown under the fields (``""``: none)."""
        line = self.query_one("#form-problem", Static)
        return str(line.render()) if line.has_class("shown") else ""

    def read_sample(self) -> str:
        """The selected sample as a spec (``sample:NAME`` or a path)."""
        sample = self.query_one("#sample", Select).value
        if not isinstance(sample, str):
            raise UserError("scan setup: sample: choose a sample")
        return sample if ":" in sample or "/" in sample or "." in sample else f"sample:{sample}"

    def read(self) -> ScanSetup:
        """The setup as typed; raises :class:`~goniolab.errors.UserError` when invalid."""
        values: dict[str, float] = {}
        for key, _label in self.FIELDS:
            text = self.query_one(f"#{key}", Input).value.strip()
            try:
                values[key] = float(text)
            except ValueError:
                raise UserError(f"scan setup: {key}: not a number: {text!r}") from None
        spec = self.read_sample()
        if values["repeats"] != int(values["repeats"]):
            raise UserError(f"scan setup: repeats: must be an integer, got {values['repeats']}")
        setup = ScanSetup(
            sample=spec,
            theta_i_deg=values["theta_i_deg"],
            theta_r_start_deg=values["theta_r_start_deg"],
            theta_r_stop_deg=values["theta_r_stop_deg"],
            theta_r_step_deg=values["theta_r_step_deg"],
            repeats=int(values["repeats"]),
        )
        setup.validate()
        return setup
