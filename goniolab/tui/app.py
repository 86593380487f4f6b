"""The goniolab Textual app: measured beside predicted, live.

The app consumes the backend's :class:`~goniolab.scan.events.EventBus` in an async
worker, polls the arms in another, and never waits on a device in a message handler:
every device call runs in a worker, every instrument error becomes a notification
(and a banner for fatal ones), never a crash.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable
from typing import ClassVar

from textual import events, work
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.notifications import SeverityLevel
from textual.widgets import Footer, Header, Input, Select, Static

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
from goniolab.tui.palette import ScanCommands
from goniolab.tui.screens import RunIdentityScreen, RunsScreen
from goniolab.tui.view_model import ArmState, Backend, RunIdentity, ScanSetup
from goniolab.tui.widgets import ComparisonPanel, GlossLog, ScanForm, StatusLine, StatusPanel

__all__ = ["GonioApp", "alignment_note"]


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


#: Seconds within which a second ``a`` confirms an alignment.
ALIGN_CONFIRM_S = 5.0


#: After a hangup, once the lab is released, the process ends within this many seconds even
#: if textual's shutdown does not: restoring a terminal that is gone can block it for good
#: (its output thread's queue, after the SIGCONT the kernel sends with the SIGHUP).
HANGUP_EXIT_S = 5.0


def _exit_soon(delay_s: float) -> None:
    """End the process ``delay_s`` from now unless it has ended by itself (logs flushed)."""
    import logging
    import os
    import threading

    def end() -> None:
        logging.shutdown()
        os._exit(0)

    timer = threading.Timer(delay_s, end)
    timer.daemon = True
    timer.start()


#: Actions that need the lab (refused by :meth:`GonioApp.check_action` while it opens).
_LAB_ACTIONS = frozenset(
    {
        "start_scan",
        "toggle_pause",
        "abort_scan",
        "align",
        "read_gloss",
        "home",
        "toggle_log",
        "cycle_plot",
        "browse_runs",
        "toggle_form",
        "run_identity",
        "blur",
    }
)


class GonioApp(App[int]):
    """Scan setup, instrument status, live comparison plots, metrics and gloss log.

    Parameters
    ----------
    backend
        The lab (real, simulated, or scripted in tests), or a function that builds it. The
        function (the CLI's: it imports the lab's modules and reads the config, about 0.4 s)
        runs in a thread after the first frame, which shows the title and "opening the
        lab..." until the lab's widgets replace it; an error it raises (a bad config)
        ends the app, kept in :attr:`boot_error` for the caller to report.
    autostart
        Start a scan with the form's values as soon as the goniometer is homed.
    poll_hz
        Arm status polling rate in Hz (0 disables polling; ArmsMoved events still update).
    gloss_every_s
        Take a glossmeter reading every this many seconds once the lab is ready (0: only on
        ``g``), so the gloss log fills while a scan runs.
    """

    TITLE = "goniolab"
    #: Minimum time between two redraws of the live plots (wall seconds).
    REDRAW_INTERVAL_S = 0.25
    #: Minimum time between two toasts for non-fatal errors of one device (wall seconds).
    ERROR_TOAST_INTERVAL_S = 10.0
    AUTO_FOCUS = None
    COMMANDS: ClassVar = App.COMMANDS | {ScanCommands}
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("s", "start_scan", "Start"),
        Binding("space", "toggle_pause", "Pause/Resume", key_display="space", priority=True),
        Binding("x", "abort_scan", "Abort"),
        Binding("a", "align", "Align"),
        Binding("g", "read_gloss", "Gloss"),
        Binding("h", "home", "Home"),
        Binding("l", "toggle_log", "Residual/log"),
        Binding("c", "cycle_plot", "Colour plot"),
        Binding("r", "browse_runs", "Runs"),
        Binding("f", "toggle_form", "Form/plot"),
        Binding("i", "run_identity", "Identity"),
        Binding("q", "quit", "Quit"),
        Binding("escape", "blur", "Leave field", show=False),
    ]
    #: The smallest terminal the app is laid out for (columns, rows).
    MIN_SIZE: ClassVar[tuple[int, int]] = (80, 24)
    CSS = """
    #top { height: 1fr; }
    #left { width: 50; overflow-y: auto; }
    #gloss-log { height: 9; border: round $primary; }
    #banner { display: none; background: $error; color: $text; height: auto; padding: 0 1; }
    #banner.shown { display: block; }
    #too-small { display: none; }
    /* 120 to 159 columns: a narrower form beside the plots */
    App.-medium #left { width: 40; }
    /* under 120 columns: the plots take the width; f swaps the form in */
    App.-narrow #left { display: none; }
    App.-narrow.-form #left { display: block; width: 1fr; }
    App.-narrow.-form #live { display: none; }
    /* under 34 rows: a shorter gloss log; under 30 the residual plot gives way */
    App.-short #gloss-log { height: 5; }
    App.-cramped ComparisonPanel .side-plot { display: none; }
    /* below the minimum: only a message saying so */
    App.-tiny #top, App.-tiny #gloss-log, App.-tiny #banner { display: none; }
    App.-tiny #too-small {
        display: block; height: 1fr; content-align: center middle; text-align: center;
        color: $warning;
    }
    """

    def __init__(
        self,
        backend: Backend | Callable[[], Backend],
        *,
        autostart: bool = False,
        poll_hz: float = 4.0,
        gloss_every_s: float = 0.0,
    ) -> None:
        super().__init__()
        self._backend: Backend | None = None
        self._factory: Callable[[], Backend] | None = None
        if callable(backend) and not hasattr(backend, "bus"):
            self._factory = backend
        else:
            self._backend = backend  # type: ignore[assignment]
        #: What building the backend raised (the app then exits with code 2).
        self.boot_error: BaseException | None = None
        self.autostart = autostart
        self.poll_hz = poll_hz
        self.gloss_every_s = gloss_every_s
        self.comparison = Comparison()
        self.run_state = RunState.IDLE
        self.run_id = 0
        self.run_kind = "brdf"  # of run_id: "brdf" or "align"
        self.progress: tuple[int, int, float] = (0, 0, math.nan)
        self.events_seen = 0
        self.ready = asyncio.Event()
        self._redraw_pending = False
        self._last_redraw_s = -math.inf
        self._hung_up = False  # SIGHUP: the terminal is gone
        self._lab_released = False
        self._starting = False
        self._align_asked_at = -math.inf  # when `a` last asked for its confirmation
        self._opening = False  # backend.open() or home() in progress
        self._gloss_polling = False
        self._error_toast_s: dict[str, float] = {}  # device -> time of its last error toast
        self._pause_on_start = False
        self._starts = 0  # scans started: a prediction preview older than a start is dropped
        self._queue: asyncio.Queue[Event | None] | None = None
        if self._backend is not None:
            self._queue = self._backend.bus.subscribe()

    @property
    def backend(self) -> Backend:
        """The lab; only actions allowed while it opens (:meth:`check_action`) run before."""
        if self._backend is None:
            raise RuntimeError("the lab is still opening")
        return self._backend

    # ------------------------------------------------------------------ layout
    def compose(self) -> ComposeResult:
        yield Header()
        if self._backend is None:
            yield Static("opening the lab...", id="boot")
        else:
            yield from self._layout()
        yield Footer()

    def _layout(self) -> list[Static | Horizontal | GlossLog]:
        """The lab's widgets between the header and the footer."""
        form = ScanForm(
            self.backend.sample_names(),
            self.backend.default_setup(),
            sample_note=self.backend.sample_note,
        )
        left = Vertical(form, StatusPanel(), id="left")
        return [
            Static("", id="banner"),
            Static("", id="too-small"),
            Horizontal(left, ComparisonPanel(id="live"), id="top"),
            GlossLog(id="gloss-log"),
            StatusLine(id="statusline"),
        ]

    def on_resize(self, event: events.Resize) -> None:
        """Lay the screen out for the terminal's size (see :attr:`CSS`)."""
        self.layout_for(event.size.width, event.size.height)

    def layout_for(self, width: int, height: int) -> None:
        """Set the size classes: ``-narrow`` under 120 columns, ``-medium`` under 160,
        ``-short`` under 34 rows, ``-cramped`` under 30, ``-tiny`` below :attr:`MIN_SIZE`."""
        min_w, min_h = self.MIN_SIZE
        tiny = width < min_w or height < min_h
        self.set_class(width < 120, "-narrow")
        self.set_class(120 <= width < 160, "-medium")
        self.set_class(height < 34, "-short")
        self.set_class(height < 30, "-cramped")
        self.set_class(tiny, "-tiny")
        with contextlib.suppress(NoMatches):
            self.query_one("#too-small", Static).update(
                f"goniolab needs a terminal of at least {min_w} x {min_h} characters; "
                f"this one is {width} x {height}.\nEnlarge the window (q quits; a running "
                "scan goes on)."
                if tiny
                else ""
            )

    def action_run_identity(self) -> None:
        """Ask for the operator, physical sample id, notes and tags of the next runs."""

        def chosen(identity: RunIdentity | None) -> None:
            if identity is None:
                return
            self.backend.run_identity = identity
            said = identity.describe() or "cleared (the config's [run] table applies)"
            self.notify(f"next runs: {said}", title="Run identity", timeout=5)

        self.push_screen(RunIdentityScreen(self.backend.run_identity), chosen)

    def action_toggle_form(self) -> None:
        """Under 120 columns: show the setup form and instrument panel instead of the
        plots, or the plots again (wider terminals show both)."""
        self.toggle_class("-form")
        if self.has_class("-narrow"):
            shown = "form" if self.has_class("-form") else "plots"
            self.notify(f"showing the {shown} (f swaps)", timeout=2)

    def on_mount(self) -> None:
        self._watch_hangup()
        if self._backend is None:
            self.sub_title = "opening the lab..."
            self.call_after_refresh(self._build_backend)
            return
        self._lab_mounted()

    def _lab_mounted(self) -> None:
        self.layout_for(self.size.width, self.size.height)
        # the footer listed the bindings while the lab opened (only q then): list them again
        self.refresh_bindings()
        self.sub_title = self.backend.title
        self.query_one("#gloss-log", GlossLog).border_title = "glossmeter log"
        self.consume_events()
        self.startup()

    @work(thread=True, exclusive=True, group="boot")
    def _build_backend(self) -> None:
        """Build the lab's backend off the event loop, after the first frame (its modules
        and the config's validation take ~0.4 s), then show the lab's widgets."""
        assert self._factory is not None
        try:
            backend = self._factory()
        except BaseException as exc:  # a bad config: the caller reports it, exit code 2
            self.call_from_thread(self._boot_failed, exc)
            return
        self.call_from_thread(self._attach_lab, backend)  # type: ignore[arg-type]  # awaited

    def _boot_failed(self, exc: BaseException) -> None:
        self.boot_error = exc
        self.exit(2, return_code=2)

    async def _attach_lab(self, backend: Backend) -> None:
        if self._lab_released:  # quit while the lab was opening
            return
        self._backend = backend
        self._queue = backend.bus.subscribe()
        await self.mount_all(self._layout(), before=self.query_one(Footer))
        await self.query_one("#boot", Static).remove()
        self._lab_mounted()

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        """While the lab opens only quitting (and textual's own actions) can run."""
        return not (self._backend is None and action in _LAB_ACTIONS)

    def _watch_hangup(self) -> None:
        """Quit as ``q`` does (abort a scan, park, release the lab) when the terminal goes
        away (SIGHUP: the window closed, the ssh link or the tmux session ended); without
        it the app kept running with no terminal, polling the arms, until killed."""
        import signal

        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError, AttributeError):
            asyncio.get_running_loop().add_signal_handler(signal.SIGHUP, self._on_hangup)

    def _on_hangup(self) -> None:
        self._hung_up = True
        if self._lab_released:  # already closing (the app saw the terminal go first)
            _exit_soon(HANGUP_EXIT_S)
        self._quit()

    # ------------------------------------------------------------------ workers
    @work(exclusive=True, group="startup")
    async def startup(self, rehome: bool = False) -> None:
        """Connect and home the lab (``rehome``: reset alarms and home again), then poll
        the arms and (optionally) start a scan."""
        self.query_one(StatusPanel).show_run("run: idle (homing...)")
        self._opening = True
        if self.poll_hz > 0:
            self.poll_arms()  # already while homing: the arms move
        try:
            await (self.backend.home() if rehome else self.backend.open())
        except (DeviceError, UserError, OSError, ValueError, RuntimeError) as exc:
            # Unreachable instrument, bad map/profile, port busy: shown, the UI stays up.
            self._opening = False
            self.show_banner(f"lab not ready: {exc}")
            self.notify(str(exc), title="Lab", severity="error", timeout=10)
            self.query_one(StatusPanel).show_run("run: idle (lab not ready)")
            await self.poll_once()  # connected but not homed: the arms' alarm shows
            return
        self._opening = False
        self.hide_banner()
        self.query_one(StatusPanel).show_run("run: idle (homed)")
        await self.poll_once()
        self.ready.set()
        if self.gloss_every_s > 0 and not self._gloss_polling:
            self._gloss_polling = True
            self.set_interval(self.gloss_every_s, self.action_read_gloss)
        if self.autostart and not rehome:
            self.action_read_gloss()
            self.action_start_scan()
        else:
            self.preview_prediction()

    async def poll_once(self) -> None:
        """Read both arms once and show them (errors shown as link lost)."""
        try:
            panel = self.query_one(StatusPanel)
        except NoMatches:  # shutting down
            return
        try:
            for arm in await self.backend.arm_states():
                panel.show_arm(arm)
        except NoMatches:  # the app shut down while the arms were read
            return
        except UserError as exc:
            if self._opening:
                return  # the lab is still connecting: the rows keep "…"
            for name in ("lamp", "detector"):
                panel.show_arm(ArmState(name, None, False, False, None, False, str(exc)))
        except (DeviceError, OSError) as exc:
            for name in ("lamp", "detector"):
                panel.show_arm(ArmState(name, None, False, False, None, False, str(exc)))

    @work(exclusive=True, group="poll")
    async def poll_arms(self) -> None:
        """Poll the arm status at ``poll_hz`` while the app runs."""
        while True:
            await asyncio.sleep(1.0 / self.poll_hz)
            await self.poll_once()

    @work(exclusive=True, group="events")
    async def consume_events(self) -> None:
        """Apply every bus event to the views (runs on the app's event loop)."""
        assert self._queue is not None
        while (ev := await self._queue.get()) is not None:
            try:
                self.apply_event(ev)
            except NoMatches:  # the screen is being torn down: nothing left to show
                return
            except Exception as exc:  # a bad event must not kill the consumer
                self.notify(f"{type(ev).__name__}: {exc}", title="Display", severity="error")

    @work(exclusive=True, group="start")
    async def _start(self) -> None:
        try:
            setup = self.query_one(ScanForm).read()
            self.run_id = await self.backend.start(setup)
            if self._pause_on_start:
                # space pressed while the run was being set up (model, store): the
                # runner honours it before its first reading.
                self.backend.pause()
        except UserError as exc:
            self.notify(str(exc), title="Scan setup", severity="error", timeout=8)
        except (DeviceError, OSError) as exc:
            self.show_banner(f"scan could not start: {exc}")
            self.notify(str(exc), title="Scan", severity="error", timeout=8)
        finally:
            self._starting = False
            self._pause_on_start = False

    @work(exclusive=True, group="start")
    async def _align(self) -> None:
        try:
            sample = self.query_one(ScanForm).read_sample()
            await self.backend.align(sample)
            self.notify("aligning: black-glass standard, then the sample (x aborts)", title="Align")
        except UserError as exc:
            self.notify(str(exc), title="Align", severity="error", timeout=8)
        except (DeviceError, OSError) as exc:
            self.show_banner(f"alignment could not start: {exc}")
            self.notify(str(exc), title="Align", severity="error", timeout=8)
        finally:
            self._starting = False

    @work(group="gloss")
    async def _read_gloss(self) -> None:
        try:
            sample = self.query_one(ScanForm).read_sample()
        except NoMatches:  # shutting down (a gloss timer may still fire)
            return
        try:
            await self.backend.read_gloss(sample)
        except UserError as exc:
            self.notify(str(exc), title="Glossmeter", severity="warning")
        except (DeviceError, OSError) as exc:
            self.notify(str(exc), title="Glossmeter", severity="error", timeout=8)

    #: Sweeps with more points than this get no live preview (a typo like step 0.0001).
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
        """Between scans, draw the model's curve for the form's sample and sweep."""
        if not self.ready.is_set() or self.backend.running or self._starting:
            return
        try:
            setup = self.query_one(ScanForm).read()
        except (UserError, NoMatches):
            return  # incomplete form (typing in progress): keep what is shown
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
            self.notify(text, title="Align" if self.run_kind == "align" else "Scan",
                        severity=severity, timeout=15 if self.run_kind == "align" else 5)  # fmt: skip
        self.show_run_line()

    def show_run_line(self) -> None:
        """The one-line run status under the arm table."""
        done, total, eta_s = self.progress
        kind = " (align)" if self.run_kind == "align" else ""
        text = f"run {self.run_id}{kind}: {self.run_state.value}" if self.run_id else "run: idle"
        if total:
            text += f"  {done}/{total}"
            if math.isfinite(eta_s) and self.run_state is RunState.RUNNING:
                text += f"  ETA {eta_s:.0f} s"
        self.query_one(StatusPanel).show_run(text)

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

    # ------------------------------------------------------------------ actions
    def action_start_scan(self) -> None:
        """Start a scan from the form (key ``s``)."""
        if not self.ready.is_set():
            self.notify("the lab is not ready (not homed)", title="Scan", severity="warning")
            return
        if self.backend.running or self._starting:
            self.notify("a scan is already running", title="Scan", severity="warning")
            return
        self._starting = True
        self._starts += 1
        self._start()

    def action_align(self) -> None:
        """Align the arms and the sample from the data (key ``a``, pressed twice within
        :data:`ALIGN_CONFIRM_S`; ``scan --plan align``): the black-glass standard, then the
        form's sample; the result is saved to the lab's alignment state file (never the
        config) and corrects every later move. Refused while a form field is being edited."""
        if isinstance(self.focused, Input | Select):
            self.notify(
                "a form field is being edited: leave it (Esc) before aligning",
                title="Align", severity="warning",
            )  # fmt: skip
            return
        now = time.monotonic()
        if now - self._align_asked_at > ALIGN_CONFIRM_S:
            self._align_asked_at = now
            self.notify(
                "align the arms? It needs the black-glass standard on the reference seat, "
                "then the sample, and replaces the lab's alignment: press a again to start",
                title="Align", timeout=ALIGN_CONFIRM_S,
            )  # fmt: skip
            return
        self._align_asked_at = -math.inf
        if not self.ready.is_set():
            self.notify("the lab is not ready (not homed)", title="Align", severity="warning")
            return
        if self.backend.running or self._starting:
            self.notify("a run is already in progress", title="Align", severity="warning")
            return
        self._starting = True
        self._starts += 1
        self._align()

    def action_toggle_pause(self) -> None:
        """Pause a running scan or resume a paused one (key ``space``)."""
        if self.backend.running and self.run_kind == "align":
            self.notify(
                "an alignment cannot pause (x aborts it)", title="Align", severity="warning"
            )
        elif self._starting:
            self._pause_on_start = not self._pause_on_start
            what = "will pause before the first reading" if self._pause_on_start else "will run"
            self.notify(f"the scan {what}", title="Scan")
        elif not self.backend.running:
            self.notify("no scan running", title="Scan", severity="warning")
        elif self.run_state is RunState.PAUSED:
            self.backend.resume()
            self.notify("resuming", title="Scan")
        else:
            # Also when the runner has not reported RUNNING yet: it honours the
            # request before its first reading.
            self.backend.pause()
            self.notify("pausing after the current point", title="Scan")

    def action_abort_scan(self) -> None:
        """Abort the scan after the current point (key ``x``)."""
        if self.backend.running:
            self.backend.abort()
            self.notify("aborting after the current point", title="Scan", severity="warning")
        else:
            self.notify("no scan running", title="Scan", severity="warning")

    def action_home(self) -> None:
        """Reset the arms' alarms and home them again, e.g. after an alarm (key ``h``)."""
        if self.backend.running or self._starting:
            self.notify("a scan is running: abort it first (x)", title="Home", severity="warning")
            return
        if self._opening:
            self.notify("already connecting / homing", title="Home", severity="warning")
            return
        self.ready.clear()
        self.startup(rehome=True)

    def action_blur(self) -> None:
        """Leave a form field so that the single-key commands work again (``escape``)."""
        self.screen.set_focus(None)

    def action_read_gloss(self) -> None:
        """Take one glossmeter reading, shown in the log beside its prediction (key ``g``)."""
        if not self.ready.is_set():
            self.notify("the lab is not ready", title="Glossmeter", severity="warning")
            return
        self._read_gloss()

    def action_toggle_log(self) -> None:
        """Side plot: residuals or log10 of both curves (key ``l``)."""
        panel = self.query_one("#live", ComparisonPanel)
        panel.toggle_log()
        panel.show(self.comparison)

    def action_cycle_plot(self) -> None:
        """Main plot: luminance, L* or a*/b* against angle (key ``c``)."""
        panel = self.query_one("#live", ComparisonPanel)
        mode = panel.cycle_plot_mode()
        panel.show(self.comparison)
        self.notify(f"main plot: {mode}", timeout=2)

    def action_browse_runs(self) -> None:
        """Open the stored-runs browser (key ``r``)."""
        self.push_screen(RunsScreen(self.backend))

    async def close_backend(self) -> None:
        """Abort any scan (the runner parks the arms) and release the instruments, once."""
        if self._lab_released:
            return
        self._lab_released = True
        if self._backend is None:  # still opening: nothing to release
            if self._hung_up:
                _exit_soon(HANGUP_EXIT_S)
            return
        # Stop polling first: a status read on an instrument being closed may never answer.
        self.workers.cancel_group(self, "poll")
        try:
            if self.backend.running:
                self.backend.abort()
            await self.backend.close()
        except (DeviceError, OSError) as exc:
            self.log.error(f"closing the lab: {exc}")
        if self._hung_up:
            _exit_soon(HANGUP_EXIT_S)

    async def action_quit(self) -> None:
        """Abort any scan, release the instruments and leave (key ``q``).

        The closing (the runner parks the arms) runs in a worker so the screen stays live.
        """
        if self._backend is not None and self._backend.running:
            self.notify("aborting the scan and parking the arms...", title="Quit")
        self._quit()

    @work(exclusive=True, group="quit")
    async def _quit(self) -> None:
        await self.close_backend()
        self.exit(0)

    async def on_unmount(self) -> None:
        """Also release the lab when the app ends another way (ctrl+c, a test's end)."""
        import signal

        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError, AttributeError):
            asyncio.get_running_loop().remove_signal_handler(signal.SIGHUP)
        await self.close_backend()
