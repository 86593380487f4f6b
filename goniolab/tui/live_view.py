"""The live half of the goniolab app: bus events become the comparison, the plots, the run
line and the banner; between scans the model's curve for the form's setup is previewed.

:class:`LiveView` is the base of :class:`goniolab.tui.app.GonioApp`; the state it reads
is set by ``GonioApp.__init__``.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from typing import Any

from textual import work
from textual.app import App
from textual.css.query import NoMatches
from textual.notifications import SeverityLevel
from textual.widgets import Input, Select, Static

from drivers.base import DeviceError
from goniolab.errors import UserError
from goniolab.scan.events import (
    ArmsMoved,
    ColourPredicted,
    Event,
    GlossRead,
    InstrumentError,
    PointMeasured,
    PointPredicted,
    Progress,
    RunFinished,
    RunStarted,
    RunState,
    StateChanged,
)
from goniolab.tui.comparison import Comparison
from goniolab.tui.view_model import Backend, ScanSetup
from goniolab.tui.widgets import ComparisonPanel, GlossLog, ScanForm, StatusPanel

__all__ = ["LiveView", "alignment_note"]


def alignment_note(run_id: int, summary: dict[str, object]) -> str:
    """The notification of a finished alignment: what it found, and that it is applied."""

    def deg(key: str) -> str:
        value = summary.get(key)
        return f"{value:+.3f} deg" if isinstance(value, int | float) else "?"

    where = summary.get("state_file")
    saved = (
        f"saved to {where}, later moves corrected"
        if isinstance(where, str) and where
        else "stored with the run only, this session's moves corrected"
    )
    return (
        f"run {run_id}: lamp zero {deg('lamp_zero_deg')}, detector zero "
        f"{deg('detector_zero_deg')}, sample tilt {deg('sample_tilt_deg')}; {saved}"
    )


class LiveView(App[int]):
    """Events to views: the comparison model, the live plots (redraws rate-limited), the
    run line, the error toasts and banner, and the prediction preview between scans."""

    #: Minimum time between two redraws of the live plots (wall seconds).
    REDRAW_INTERVAL_S = 0.25
    #: Minimum time between two toasts for non-fatal errors of one device (wall seconds).
    ERROR_TOAST_INTERVAL_S = 10.0

    # the state, set by GonioApp.__init__
    _backend: Backend | None
    comparison: Comparison
    run_state: RunState
    run_id: int
    #: the kind of run_id: "brdf" or "align"
    run_kind: str
    progress: tuple[int, int, float]
    #: which model computes the current run's prediction (shown in the run line)
    prediction_note: str
    events_seen: int
    ready: asyncio.Event
    _redraw_pending: bool
    _last_redraw_s: float
    _starting: bool
    _starts: int
    _error_toast_s: dict[str, float]
    _toasts_held: int

    @property
    def backend(self) -> Backend:
        """The lab; only actions allowed while it opens (:meth:`check_action`) run before."""
        if self._backend is None:
            raise RuntimeError("the lab is still opening")
        return self._backend

    PREVIEW_MAX_POINTS = 2000

    def on_select_changed(self, event: Select.Changed) -> None:
        """A new sample: show its predicted curve (the scan will measure that sample)."""
        if event.select.id == "sample":
            self.preview_prediction()

    def on_input_changed(self, event: Input.Changed) -> None:
        """A new θi or θr range: show the prediction for it, unless a finished scan is
        shown (editing the next sweep must not wipe it; a new sample pick does)."""
        if self.comparison.n_readings == 0:
            self.preview_prediction()

    def preview_prediction(self) -> None:
        """Check the form's plan as it is typed (a sweep the arms cannot reach is refused
        under the fields, in the words of ``goniolab scan``); between scans, draw the
        model's curve for the form's sample and sweep."""
        if not self.ready.is_set():
            return
        try:
            form = self.query_one(ScanForm)
            setup = form.read()
        except NoMatches:
            return
        except UserError:
            form.show_problem("")
            return  # incomplete form (typing in progress): keep what is shown
        try:
            self.backend.check_setup(setup)
        except UserError as exc:
            form.show_problem(str(exc))
            return
        form.show_problem("")
        if self.backend.running or self._starting:
            return
        if len(setup.theta_r_values_deg()) > self.PREVIEW_MAX_POINTS:
            return
        self._preview(setup)

    @work(exclusive=True, group="preview")
    async def _preview(self, setup: ScanSetup) -> None:
        starts = self._starts
        try:
            values = await self.backend.predict_curve(setup)
        except (UserError, DeviceError, OSError, ValueError) as exc:
            self.notify(str(exc), title="Prediction", severity="warning")
            return
        if self._starts != starts or self.backend.running or self._starting:
            return  # a scan started meanwhile: its own events fill the view
        self.comparison.clear(run_id=0, sample=setup.sample)
        for index, (theta_r_deg, value) in enumerate(
            zip(setup.theta_r_values_deg(), values, strict=True)
        ):
            self.comparison.add_predicted(
                PointPredicted(
                    run_id=0,
                    index=index,
                    theta_i_deg=setup.theta_i_deg,
                    theta_r_deg=theta_r_deg,
                    predicted_pct=value,
                )
            )
        self.schedule_redraw()

    # ------------------------------------------------------------------ events
    def apply_event(self, ev: Event) -> None:
        """Update the model and the widgets for one event."""
        self.events_seen += 1
        panel = self.query_one(StatusPanel)
        if isinstance(ev, RunStarted):
            if ev.kind in ("align", "brdf"):
                self._toasts_held = 0
            if ev.kind == "align":  # its readings are not a curve of the form's sweep
                self.run_id, self.run_kind = ev.run_id, ev.kind
                self.progress = (0, ev.total_points, math.nan)
                self.hide_banner()
                self.show_run_line()
                return
            if ev.kind != "brdf":
                return
            self.run_id, self.run_kind = ev.run_id, ev.kind
            self.comparison.clear(
                run_id=ev.run_id,
                sample=ev.sample,
                theta_i_deg=float(ev.plan.get("theta_i_deg", 45.0)),
            )
            self.progress = (0, ev.total_points, math.nan)
            self.prediction_note = ""
            self._load_prediction_models(ev.run_id)
            self.hide_banner()
            self.schedule_redraw()
        elif isinstance(ev, StateChanged | Progress | RunFinished) and ev.run_id != self.run_id:
            return  # another session on the bus (the gloss logger's run)
        elif isinstance(ev, StateChanged):
            self.run_state = ev.state
        elif isinstance(ev, ArmsMoved):
            panel.show_angles(ev.theta_i_deg, ev.theta_r_deg, ev.moving)
        elif isinstance(ev, PointMeasured):
            if self.run_kind == "align" and ev.run_id == self.run_id:
                return
            self.comparison.add_measured(ev)
            self.schedule_redraw()
        elif isinstance(ev, PointPredicted):
            self.comparison.add_predicted(ev)
            self.schedule_redraw()
        elif isinstance(ev, ColourPredicted):
            self.comparison.add_colour(ev)
            self.schedule_redraw()
        elif isinstance(ev, Progress):
            self.progress = (ev.done, ev.total, ev.eta_s)
        elif isinstance(ev, GlossRead):
            self.comparison.add_gloss(ev)
            log = self.query_one("#gloss-log", GlossLog)
            log.add_reading(ev)
            if ev.predicted_models:  # which model computed each predicted gloss (issue 20)
                by = ", ".join(f"G{a} {m}" for a, m in sorted(ev.predicted_models.items()))
                log.border_title = f"glossmeter log (predicted by {by})"
            if ev.predicted_gu and ev.run_id and ev.run_id not in log.checked_runs:
                log.checked_runs.add(ev.run_id)
                self._load_gloss_warnings(ev.run_id)
            self.schedule_redraw()
        elif isinstance(ev, InstrumentError):
            now_s = time.monotonic()
            last_s = self._error_toast_s.get(ev.device, -math.inf)
            # Retries of a flaky device report every failure: one toast per device per
            # ERROR_TOAST_INTERVAL_S (the fatal one always), not a stack of ten.
            if ev.fatal or now_s - last_s >= self.ERROR_TOAST_INTERVAL_S:
                self._error_toast_s[ev.device] = now_s
                self.notify(
                    ev.message,
                    title=f"{ev.device} error" + (" (fatal)" if ev.fatal else ""),
                    severity="error",
                    timeout=10,
                )
            elif ev.run_id == self.run_id:  # counted: the run's end says how many
                self._toasts_held += 1
            if ev.fatal:
                self.show_banner(f"{ev.device}: {ev.message}")
        elif isinstance(ev, RunFinished):
            self.run_state = ev.state
            text = f"run {ev.run_id} {ev.state.value}" + (f": {ev.reason}" if ev.reason else "")
            severity: SeverityLevel = "information"
            if ev.state is RunState.ABORTED:
                severity = "warning"
            elif ev.state is RunState.FAILED:
                severity = "error"
                self.show_banner(text)
            if self.run_kind == "align" and ev.state is RunState.DONE:
                text = alignment_note(ev.run_id, ev.summary)
            text += self._warnings_note(ev)
            self.notify(text, title="Align" if self.run_kind == "align" else "Scan",
                        severity=severity, timeout=15 if self.run_kind == "align" else 5)  # fmt: skip
        self.show_run_line()

    def _warnings_note(self, ev: RunFinished) -> str:
        """The run's warnings at its end: how many, that they are stored with it, and how
        many of them were not toasted (a device's burst shows one toast per
        :data:`ERROR_TOAST_INTERVAL_S`); ``""`` without any."""
        warnings = ev.summary.get("warnings") or []
        held, self._toasts_held = self._toasts_held, 0
        if not warnings:
            return ""
        text = (
            f"; {len(warnings)} warning{'s' if len(warnings) != 1 else ''} stored with the run "
            f"(goniolab runs show {ev.run_id})"
        )
        return text + (f"; {held} of its messages were not shown as they came" if held else "")

    def show_run_line(self) -> None:
        """The one-line run status under the arm table."""
        done, total, eta_s = self.progress
        kind = " (align)" if self.run_kind == "align" else ""
        text = f"run {self.run_id}{kind}: {self.run_state.value}" if self.run_id else "run: idle"
        if total:
            text += f"  {done}/{total}"
            if math.isfinite(eta_s) and self.run_state is RunState.RUNNING:
                text += f"  ETA {eta_s:.0f} s"
        if self.prediction_note and self.run_kind == "brdf":
            text += f"  (predicted by {self.prediction_note})"
        self.query_one(StatusPanel).show_run(text)

    @work(thread=True, group="provenance")
    def _load_prediction_models(self, run_id: int) -> None:
        """Read which model computes the run's prediction (its stored record) off the
        event loop, then show it in the run line (issue 20)."""
        try:
            note = self.backend.prediction_models(run_id)
            record = self.backend.prediction_record(run_id)
        except Exception as exc:  # the run line and colour table then name no model: said
            self.call_from_thread(
                self.notify,
                f"run {run_id}: which model made its prediction could not be read: {exc}",
                title="Prediction", severity="warning",
            )  # fmt: skip
            return
        self.call_from_thread(self._show_prediction_models, run_id, note, record)

    def _show_prediction_models(self, run_id: int, note: str, record: dict[str, Any]) -> None:
        if run_id == self.run_id:
            self.prediction_note = note
            # the colour table marks a colour made by a wavelength-free model from it
            self.comparison.prediction_record = record
            with contextlib.suppress(NoMatches):
                self.show_run_line()
            self.schedule_redraw()

    @work(thread=True, group="provenance")
    def _load_gloss_warnings(self, run_id: int) -> None:
        """Read the warnings stored with gloss run ``run_id``'s predicted gloss (its record)
        off the event loop, then show them (a toast each, their count under the log)."""
        try:
            record = self.backend.prediction_record(run_id)
        except Exception as exc:  # said, not dropped: the store has them
            self.call_from_thread(
                self.notify, f"run {run_id}: its prediction warnings could not be read: {exc}",
                title="Gloss prediction", severity="warning",
            )  # fmt: skip
            return
        warnings = record.get("warnings")
        said = [str(w) for w in warnings] if isinstance(warnings, list) else []
        cal = record.get("glossmeter_calibration")
        cal_said = [str(w) for w in cal.get("warnings") or []] if isinstance(cal, dict) else []
        self.call_from_thread(self._show_gloss_warnings, run_id, said, cal_said)

    def _show_gloss_warnings(
        self, run_id: int, warnings: list[str], calibration: list[str] | None = None
    ) -> None:
        with contextlib.suppress(NoMatches):
            self.query_one("#gloss-log", GlossLog).show_prediction_warnings(run_id, warnings)
        for w in warnings:
            self.notify(w, title="Gloss prediction", severity="warning")
        for w in calibration or []:  # the glossmeter calibration the run rests on
            self.notify(w, title="Glossmeter calibration", severity="warning")

    @property
    def redraw_pending(self) -> bool:
        """A redraw of the live plots is scheduled but has not run yet."""
        return self._redraw_pending

    def schedule_redraw(self) -> None:
        """Coalesce events into at most one plot redraw per ``REDRAW_INTERVAL_S``.

        Rendering both plots takes ~0.1 s; on a fast (or instant) sim clock readings
        arrive much faster than that, so redraws are rate-limited, never queued up.
        """
        if self._redraw_pending:
            return
        self._redraw_pending = True
        wait_s = self._last_redraw_s + self.REDRAW_INTERVAL_S - time.monotonic()
        if wait_s > 0:
            self.set_timer(wait_s, self.redraw)
        else:
            self.call_later(self.redraw)

    def redraw(self) -> None:
        """Redraw the live comparison from the accumulated data."""
        self._redraw_pending = False
        self._last_redraw_s = time.monotonic()
        try:
            self.query_one("#live", ComparisonPanel).show(self.comparison)
        except NoMatches:
            # a timer firing while the app shuts down: the panel, or already only some of
            # its children (the colour swatch), are gone
            return

    def show_banner(self, text: str) -> None:
        banner = self.query_one("#banner", Static)
        banner.update(text)
        banner.add_class("shown")

    def hide_banner(self) -> None:
        self.query_one("#banner", Static).remove_class("shown")
