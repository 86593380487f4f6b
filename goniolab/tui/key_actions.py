"""The lab's commands of the goniolab app: the key actions (start, pause, abort, align,
gloss, home, views, identity) and the workers that run them off the message handlers
(opening and homing the lab, polling the arms, starting a scan or an alignment, a gloss
reading). Every device call runs in a worker; every error becomes a notification.

:class:`LabActions` is the base of :class:`goniolab.tui.app.GonioApp`; the keys are bound
there (``GonioApp.BINDINGS``).
"""

from __future__ import annotations

import asyncio
import math
import time
from typing import ClassVar

from textual import work
from textual.css.query import NoMatches
from textual.widgets import Input, Select

from drivers.base import DeviceError
from goniolab.errors import UserError
from goniolab.scan.events import RunState
from goniolab.tui.live_view import LiveView
from goniolab.tui.screens import RunIdentityScreen, RunsScreen
from goniolab.tui.view_model import ArmState, RunIdentity
from goniolab.tui.widgets import ComparisonPanel, ScanForm, StatusPanel

__all__ = ["ALIGN_CONFIRM_S", "LabActions"]

#: Seconds within which a second ``a`` confirms an alignment.
ALIGN_CONFIRM_S = 5.0


class LabActions(LiveView):
    """The key actions and the workers that talk to the lab."""

    #: The fewest terminal rows that show the side plot (residuals / log10) beside the
    #: metrics and colour tables (18 rows of the right column); under it the plot would
    #: get 4-8 rows of which 2 are its border (3 at 120 x 32, one tick label): it is
    #: hidden (``GonioApp.layout_for``) and ``l`` says why; from 40 rows it gets 9 or more.
    SIDE_PLOT_MIN_ROWS: ClassVar[int] = 40

    # the state, set by GonioApp.__init__
    autostart: bool
    poll_hz: float
    gloss_every_s: float
    _opening: bool
    _gloss_polling: bool
    _align_asked_at: float
    _pause_on_start: bool

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
            self._gloss_then_scan()  # the README's order: a gloss reading, then the scan
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
        await self._gloss_reading()

    async def _gloss_reading(self) -> None:
        """One glossmeter reading, awaited until stored (a request while one is under way
        joins the next reading: the backend coalesces, never refuses)."""
        try:
            sample = self.query_one(ScanForm).read_sample()
        except NoMatches:  # shutting down (a gloss timer may still fire)
            return
        try:
            stored = await self.backend.read_gloss(sample)
            if stored is not None:
                await stored
        except asyncio.CancelledError:
            raise
        except UserError as exc:
            self.notify(str(exc), title="Glossmeter", severity="warning")
        except (DeviceError, OSError) as exc:
            self.notify(str(exc), title="Glossmeter", severity="error", timeout=8)
        except Exception as exc:
            self.notify(f"{type(exc).__name__}: {exc}", title="Glossmeter", severity="error")

    @work(group="autostart")
    async def _gloss_then_scan(self) -> None:
        """``--autostart``: the first gloss reading, then the form's scan."""
        await self._gloss_reading()
        self.action_start_scan()

    #: Sweeps with more points than this get no live preview (a typo like step 0.0001).
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
        if self.has_class("-cramped"):  # the plot it switches is hidden: say so, and why
            rows = self.SIDE_PLOT_MIN_ROWS
            self.notify(
                f"the side plot ({'log10 of both curves' if panel.log_view else 'residuals'}) "
                f"is hidden in a window under {rows} rows: enlarge the window to see it",
                title="Side plot", timeout=4,
            )  # fmt: skip

    def action_cycle_plot(self) -> None:
        """Main plot: luminance, L* or a*/b* against angle (key ``c``)."""
        panel = self.query_one("#live", ComparisonPanel)
        mode = panel.cycle_plot_mode()
        panel.show(self.comparison)
        self.notify(f"main plot: {mode}", timeout=2)

    def action_browse_runs(self) -> None:
        """Open the stored-runs browser (key ``r``)."""
        self.push_screen(RunsScreen(self.backend))

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
