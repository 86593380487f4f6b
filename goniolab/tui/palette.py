"""Command-palette provider offering the same scan commands as the key bindings."""

from __future__ import annotations

from functools import partial

from textual.command import DiscoveryHit, Hit, Hits, Provider

__all__ = ["SCAN_COMMANDS", "ScanCommands"]

#: (palette text, app action, help) — the same actions the key bindings run.
SCAN_COMMANDS: tuple[tuple[str, str, str], ...] = (
    ("Start scan", "start_scan", "Start a scan with the setup form's values (key s)"),
    ("Pause / resume scan", "toggle_pause", "Pause after the current point, or resume (space)"),
    ("Abort scan", "abort_scan", "Stop after the current point; run marked aborted (x)"),
    (
        "Align arms and sample",
        "align",
        "Arm zero offsets and sample tilt from the data, saved beside the store (a, twice)",
    ),
    ("Read glossmeter", "read_gloss", "One 20/60/85 reading beside the prediction (g)"),
    ("Home the arms", "home", "Reset the arms' alarms and home them again (h)"),
    ("Toggle residual / log view", "toggle_log", "Side plot: residuals or log10 curves (l)"),
    ("Cycle colour plot", "cycle_plot", "Main plot: luminance, L* or a*/b* vs angle (c)"),
    ("Browse stored runs", "browse_runs", "Reopen a stored run's comparison (r)"),
    ("Show form / plots", "toggle_form", "Under 120 columns: the setup form or the plots (f)"),
    ("Run identity", "run_identity", "Operator, sample id, notes, tags of the next runs (i)"),
    ("Quit", "quit", "Leave goniolab (q)"),
)


class ScanCommands(Provider):
    """Start, pause/resume, abort, browse runs and quit from the command palette."""

    async def discover(self) -> Hits:
        for text, action, help_text in SCAN_COMMANDS:
            yield DiscoveryHit(text, partial(self._run, action), help=help_text)

    async def search(self, query: str) -> Hits:
        matcher = self.matcher(query)
        for text, action, help_text in SCAN_COMMANDS:
            score = matcher.match(text)
            if score > 0:
                yield Hit(
                    score, matcher.highlight(text), partial(self._run, action), help=help_text
                )

    async def _run(self, action: str) -> None:
        await self.app.run_action(action)
