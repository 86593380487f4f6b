"""The runs browser (list stored runs, reopen one and show its comparison and metrics)
and the run-identity dialog (operator, physical sample id, notes, tags of the next runs)."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import ClassVar

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical
from textual.screen import ModalScreen, Screen
from textual.widgets import DataTable, Footer, Header, Input, Label, Static

from goniolab.tui.comparison import Comparison
from goniolab.tui.view_model import Backend, RunIdentity, RunSummary, StoredRun
from goniolab.tui.widgets import ComparisonPanel

__all__ = ["RunIdentityScreen", "RunsScreen"]


class RunIdentityScreen(ModalScreen[RunIdentity | None]):
    """Operator, physical sample id, notes and tags stored with the next runs (scans and
    gloss readings); Enter saves, Esc leaves them as they were. Tags: comma-separated."""

    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "Cancel")]
    DEFAULT_CSS = """
    RunIdentityScreen { align: center middle; }
    RunIdentityScreen > Vertical {
        width: 64; height: auto; border: round $primary; padding: 0 1; background: $surface;
    }
    RunIdentityScreen Input { margin: 0 0 1 0; }
    """

    def __init__(self, current: RunIdentity) -> None:
        super().__init__()
        self.current = current

    def compose(self) -> ComposeResult:
        c = self.current
        with Vertical() as box:
            box.border_title = "run identity (Enter saves, Esc cancels)"
            yield Label("operator")
            yield Input(c.operator, id="operator", placeholder="who measures")
            yield Label("physical sample id")
            yield Input(c.sample_id, id="sample_id", placeholder="label, LIMS number")
            yield Label("notes")
            yield Input(c.notes, id="notes", placeholder="free text")
            yield Label("tags (comma-separated)")
            yield Input(", ".join(c.tags), id="tags", placeholder="batch-7, wet")

    def on_input_submitted(self) -> None:
        def text(field: str) -> str:
            return self.query_one(f"#{field}", Input).value.strip()

        tags = tuple(dict.fromkeys(t.strip() for t in text("tags").split(",") if t.strip()))
        self.dismiss(
            RunIdentity(
                operator=text("operator"),
                sample_id=text("sample_id"),
                notes=text("notes"),
                tags=tags,
            )
        )

    def action_cancel(self) -> None:
        self.dismiss(None)


def run_title(loaded: RunSummary, listed: RunSummary | None) -> str:
    """The opened run's title line: its readings as the run list counts them (an
    alignment's 288 readings, a gloss log's readings; issue 27: the title said "0
    readings" for both), and where a run the plots here do not draw can be seen."""
    n = loaded.n_points if listed is None else listed.n_points
    text = f"run {loaded.run_id}: {loaded.sample}, {loaded.kind}, {loaded.status}, {n} readings"
    if loaded.kind == "align":
        text += f" (not drawn here: goniolab plot {loaded.run_id} -o align.png)"
    elif loaded.kind not in ("brdf", "gloss"):
        text += f" (not drawn here: goniolab runs show {loaded.run_id})"
    return text


class RunsScreen(Screen[None]):
    """Stored runs (newest first); Enter reopens one below the list."""

    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("escape,r", "app.pop_screen", "Back"),
        Binding("l", "toggle_log", "Residual/log"),
    ]
    DEFAULT_CSS = """
    RunsScreen #runs { height: 10; border: round $primary; }
    RunsScreen #run-title { height: 1; padding: 0 1; }
    """
    AUTO_FOCUS = "#runs"

    def __init__(self, backend: Backend) -> None:
        super().__init__()
        self.backend = backend
        self.comparison = Comparison()
        #: the run list's rows by run id (their reading counts are the store's)
        self._listed: dict[int, RunSummary] = {}
        self.loaded_run: int | None = None

    def compose(self) -> ComposeResult:
        yield Header()
        yield DataTable[str](id="runs", cursor_type="row")
        yield Static("select a run and press Enter", id="run-title")
        yield ComparisonPanel(id="run-comparison")
        yield Footer()

    def on_mount(self) -> None:
        self.query_one("#runs", DataTable).border_title = "stored runs"
        table = self.query_one("#runs", DataTable)
        for key, label in (
            ("id", "run"),
            ("started", "started (UTC)"),
            ("kind", "kind"),
            ("sample", "sample"),
            ("status", "status"),
            ("points", "points"),
        ):
            table.add_column(label, key=key)
        self.load_runs()

    @work(thread=True, exclusive=True, group="runs-list")
    def load_runs(self) -> None:
        """Read the run list from the store (blocking SQLite: a thread worker)."""
        try:
            runs = self.backend.list_runs()
        except Exception as exc:  # store errors are shown, never crash the UI
            self.app.call_from_thread(
                self.notify, f"run store: {exc}", title="Runs", severity="error"
            )
            return
        self.app.call_from_thread(self._show_runs, runs)

    def _show_runs(self, runs: list[RunSummary]) -> None:
        table = self.query_one("#runs", DataTable)
        table.clear()
        self._listed = {r.run_id: r for r in runs}
        for r in runs:
            started = datetime.fromtimestamp(r.started, tz=UTC).strftime("%Y-%m-%d %H:%M:%S")
            table.add_row(
                str(r.run_id),
                started,
                r.kind,
                r.sample,
                r.status,
                str(r.n_points),
                key=str(r.run_id),
            )

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        if event.data_table.id != "runs" or event.row_key.value is None:
            return
        self.open_run(int(event.row_key.value))

    @work(thread=True, exclusive=True, group="runs-open")
    def open_run(self, run_id: int) -> None:
        """Load one run's points and predictions (thread worker) and show them."""
        try:
            stored = self.backend.load_run(run_id)
        except Exception as exc:
            self.app.call_from_thread(
                self.notify, f"run {run_id}: {exc}", title="Runs", severity="error"
            )
            return
        self.app.call_from_thread(self._show_run, stored)

    def _show_run(self, stored: StoredRun) -> None:
        s = stored.summary
        comparison = Comparison()
        comparison.clear(run_id=s.run_id, sample=s.sample)
        comparison.prediction_record = stored.prediction
        for m in stored.measured:
            comparison.add_measured(m)
        for p in stored.predicted:
            comparison.add_predicted(p)
        for c in stored.colours:
            comparison.add_colour(c)
        for g in stored.gloss:
            comparison.add_gloss(g)
        self.comparison = comparison
        self.loaded_run = s.run_id
        self.query_one("#run-title", Static).update(run_title(s, self._listed.get(s.run_id)))
        self.query_one(ComparisonPanel).show(comparison)

    def action_toggle_log(self) -> None:
        panel = self.query_one(ComparisonPanel)
        panel.toggle_log()
        panel.show(self.comparison)
