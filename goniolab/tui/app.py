"""The goniolab Textual app: measured beside predicted, live.

The app consumes the backend's :class:`~goniolab.scan.events.EventBus` in an async
worker, polls the arms in another, and never waits on a device in a message handler:
every device call runs in a worker, every instrument error becomes a notification
(and a banner for fatal ones), never a crash.

Its rooms: this module lays the screen out, opens and releases the lab and binds the keys;
:mod:`goniolab.tui.key_actions` holds what the keys do and the workers that talk to the lab;
:mod:`goniolab.tui.live_view` turns the bus events into the plots and the run line.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Callable
from typing import ClassVar

from textual import events, work
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.widgets import Footer, Header, Static

from drivers.base import DeviceError
from goniolab.scan.events import Event, RunState
from goniolab.tui.comparison import Comparison
from goniolab.tui.key_actions import LabActions
from goniolab.tui.live_view import alignment_note
from goniolab.tui.palette import ScanCommands
from goniolab.tui.view_model import Backend
from goniolab.tui.widgets import ComparisonPanel, GlossLog, ScanForm, StatusLine, StatusPanel

__all__ = ["GonioApp", "alignment_note"]


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


class GonioApp(LabActions):
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
    App.-medium #left { width: 41; }  /* the arm table's 39 columns inside its border */
    /* under 120 columns: the plots take the width; f swaps the form in */
    App.-narrow #left { display: none; }
    App.-narrow.-form #left { display: block; width: 1fr; }
    App.-narrow.-form #live { display: none; }
    /* under 34 rows: a shorter gloss log; under 40 the residual plot gives way: the
       metrics, the colour table and its note take 18 rows of the right column, and the
       plot would get 4-8 rows (3 at 120 x 32); from 40 rows it gets 9 or more */
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
        #: which model computes the current run's prediction (shown in the run line)
        self.prediction_note = ""
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
        self._toasts_held = 0  # warnings of the run not toasted (a device's burst)
        self._pause_on_start = False
        self._starts = 0  # scans started: a prediction preview older than a start is dropped
        self._queue: asyncio.Queue[Event | None] | None = None
        if self._backend is not None:
            self._queue = self._backend.bus.subscribe()

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
        ``-short`` under 34 rows, ``-cramped`` under :attr:`SIDE_PLOT_MIN_ROWS`, ``-tiny``
        below :attr:`MIN_SIZE`."""
        min_w, min_h = self.MIN_SIZE
        tiny = width < min_w or height < min_h
        self.set_class(width < 120, "-narrow")
        self.set_class(120 <= width < 160, "-medium")
        self.set_class(height < 34, "-short")
        self.set_class(height < self.SIDE_PLOT_MIN_ROWS, "-cramped")
        self.set_class(tiny, "-tiny")
        with contextlib.suppress(NoMatches):
            self.query_one("#too-small", Static).update(
                f"goniolab needs a terminal of at least {min_w} x {min_h} characters; "
                f"this one is {width} x {height}.\nEnlarge the window (q quits; a running "
                "scan goes on)."
                if tiny
                else ""
            )

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
