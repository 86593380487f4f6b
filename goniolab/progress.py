"""One progress abstraction for every face (issue 24): a reporter the use cases call, and
its renderers.

A use case (:mod:`goniolab.app.lab_scan`, a batch) calls a :class:`Reporter`:
``start(total, label)``, ``advance(done, eta_s=..., detail=...)`` as the work goes on,
``message(text)`` for a line that must scroll above the bar, ``finish()`` at the end. The
faces choose the renderer:

- :func:`terminal_progress`: a rich bar redrawn in place on a terminal (messages scroll
  above it); to a pipe or a file one plain line per 10 % (``[####......] 12/30 ETA 4s
  detail``), stable for scripts and logs. Never on stdout unless asked: the summaries and
  ``--json`` go there (issue 22.3).
- :func:`notebook_progress`: the same rich bar rendered by Jupyter (rich draws it as an
  output widget in a kernel, :func:`auto_progress` picks it there).
- :class:`CallbackProgress`: each update handed to a function as a
  :class:`ProgressUpdate` (a UI that draws its own bar, a test).

A library that reports ``(done, total, what)`` (the physical-optics model's set-up,
:data:`goniolab.app.predictions.Progress`) is drawn by a reporter through
:class:`StepsProgress` (:func:`model_progress`: only on a terminal, once the work has taken
2 s). ``terminal_progress(..., piped_lines=False)`` draws nothing to a pipe or a file but
still writes the messages (the batch of ``predict gloss``).

The ETA shown is the caller's (``eta_s``, wall seconds) when it has one; without it
(``eta_s=None``: a simulated clock at scale 0 takes no wall time, so a motion model cannot
predict the wait) it is the measured wall time per step times the steps left, "?" until
one step was timed, 0 at the end.

rich is imported when a renderer draws, not with this module (``goniolab --help`` stays
light, tests/test_startup.py).

>>> with terminal_progress(3, "maps") as p:   # doctest: +SKIP
...     for spec in specs:
...         p.advance(detail=spec)
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, TextIO

__all__ = [
    "CallbackProgress",
    "NullProgress",
    "ProgressUpdate",
    "Reporter",
    "StepsProgress",
    "TerminalProgress",
    "auto_progress",
    "format_eta",
    "in_jupyter",
    "model_progress",
    "notebook_progress",
    "terminal_progress",
]


def format_eta(seconds: float) -> str:
    """``1h02m03s`` / ``2m03s`` / ``7s`` for a non-negative duration, ``?`` when unknown."""
    if not math.isfinite(seconds):
        return "?"
    s = max(0, round(seconds))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    if h:
        return f"{h}h{m:02d}m{sec:02d}s"
    if m:
        return f"{m}m{sec:02d}s"
    return f"{sec}s"


class Reporter(Protocol):
    """What a use case reports its progress to (a renderer, or nothing)."""

    def start(self, total: int, label: str = "") -> None:
        """``total`` steps are to come (it may change with a later :meth:`advance`)."""

    def advance(
        self,
        done: int | None = None,
        *,
        total: int | None = None,
        eta_s: float | None = None,
        detail: str = "",
    ) -> None:
        """``done`` steps are done (``None``: one more than before); ``eta_s`` wall seconds
        are left (``None``: from the measured rate); ``detail`` describes the last step."""

    def message(self, text: str) -> None:
        """A line to show above the bar (a warning, a fault, a notice)."""

    def finish(self) -> None:
        """The work ended (the bar is drawn a last time and released)."""


class _Base:
    """Counting, the measured-rate ETA and the context manager shared by the renderers."""

    def __init__(self, total: int = 0, label: str = "") -> None:
        self.total = total
        self.label = label
        self.done = 0
        self._first: tuple[float, int] | None = None  # (monotonic s, done) of the first step

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.finish()

    def start(self, total: int, label: str = "") -> None:
        self.total, self.label = total, label or self.label

    def eta_s(self, done: int, total: int, eta_s: float | None, now_s: float) -> float:
        """Wall seconds left: ``eta_s`` when given, 0 at the end, else the measured rate
        since the first update times the steps left (NaN until a step was timed)."""
        if self._first is None:
            self._first = (now_s, done)
        if total and done >= total:
            return 0.0
        if eta_s is not None:
            return eta_s
        t0, done0 = self._first
        if done <= done0:
            return math.nan
        return (now_s - t0) / (done - done0) * (total - done)

    def advance(
        self,
        done: int | None = None,
        *,
        total: int | None = None,
        eta_s: float | None = None,
        detail: str = "",
    ) -> None:
        self.done = self.done + 1 if done is None else done
        if total is not None:
            self.total = total
        eta = self.eta_s(self.done, self.total, eta_s, time.monotonic())
        self._draw(eta, detail)

    def _draw(self, eta_s: float, detail: str) -> None:
        raise NotImplementedError

    def message(self, text: str) -> None:
        raise NotImplementedError

    def finish(self) -> None:
        raise NotImplementedError


class NullProgress(_Base):
    """Shows nothing (``progress=False``); messages are dropped too."""

    def _draw(self, eta_s: float, detail: str) -> None:
        return None

    def message(self, text: str) -> None:
        return None

    def finish(self) -> None:
        return None


@dataclass(frozen=True, slots=True)
class ProgressUpdate:
    """One update handed to a :class:`CallbackProgress` function.

    ``kind`` is ``"start"``, ``"advance"``, ``"message"`` or ``"finish"``; ``eta_s`` is in
    wall seconds (NaN: not known yet); ``text`` is a message's text.
    """

    kind: str
    done: int
    total: int
    eta_s: float = math.nan
    detail: str = ""
    text: str = ""
    label: str = ""


class CallbackProgress(_Base):
    """Every start, step, message and finish handed to ``callback`` as a
    :class:`ProgressUpdate` (a UI that draws its own bar: the TUI's status line)."""

    def __init__(self, callback: Callable[[ProgressUpdate], None], label: str = "") -> None:
        super().__init__(0, label)
        self.callback = callback

    def start(self, total: int, label: str = "") -> None:
        super().start(total, label)
        self.callback(ProgressUpdate("start", self.done, self.total, label=self.label))

    def _draw(self, eta_s: float, detail: str) -> None:
        self.callback(
            ProgressUpdate("advance", self.done, self.total, eta_s, detail, label=self.label)
        )

    def message(self, text: str) -> None:
        self.callback(ProgressUpdate("message", self.done, self.total, text=text))

    def finish(self) -> None:
        self.callback(ProgressUpdate("finish", self.done, self.total, 0.0, label=self.label))


class TerminalProgress(_Base):
    """A rich bar on a terminal, one plain line per 10 % elsewhere (see the module's doc).

    Parameters
    ----------
    stream
        Where to draw (default ``sys.stderr``).
    jupyter
        Draw the rich bar for a Jupyter kernel (an output widget) instead of a stream.
    """

    def __init__(
        self,
        stream: TextIO | None = None,
        *,
        total: int = 0,
        label: str = "",
        width: int = 30,
        jupyter: bool = False,
        piped_lines: bool = True,
    ) -> None:
        super().__init__(total, label)
        self.stream = sys.stderr if stream is None else stream
        self.width = width
        self.jupyter = jupyter
        self.rich_bar = jupyter or self.stream.isatty()
        #: Off: nothing drawn to a pipe or a file (the messages are still written).
        self.piped_lines = piped_lines
        self._last_pct = -1
        self._rich: Any = None
        self._task: Any = None

    def _start_rich(self) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

        console = (
            Console(force_jupyter=True, highlight=False)
            if self.jupyter
            else Console(file=self.stream, highlight=False)
        )
        columns: list[Any] = [TextColumn("{task.description}")] if self.label else []
        self._rich = Progress(
            *columns,
            BarColumn(bar_width=self.width),
            MofNCompleteColumn(),
            TextColumn("ETA {task.fields[eta]}"),
            TextColumn("{task.fields[detail]}"),
            console=console,
            # never wrap sys.stdout: the summary and --json go there (issue 22.3)
            redirect_stdout=False,
            redirect_stderr=False,
            # In a kernel the bar is an ipywidgets Output, and rich's refresh thread draws
            # into it inside ``with widget:``; a cell's result printed while that thread is
            # in there was captured into the widget (the cell showed no result, now and
            # then). There it is drawn only here, on the reporting thread, before finish().
            auto_refresh=not self.jupyter,
        )
        self._rich.start()
        self._task = self._rich.add_task(self.label, total=self.total, eta="?", detail="")

    def _draw(self, eta_s: float, detail: str) -> None:
        eta = format_eta(eta_s)
        if self.rich_bar:
            if self._rich is None:
                self._start_rich()
            self._rich.update(self._task, completed=self.done, total=self.total, eta=eta,
                              detail=detail)  # fmt: skip
            if self.jupyter:
                self._rich.refresh()
            return
        if not self.piped_lines:
            return
        total = self.total
        frac = self.done / total if total else 1.0
        n = round(frac * self.width)
        pct = int(frac * 100)
        if pct // 10 != self._last_pct // 10 or self.done == total:
            line = f"[{'#' * n}{'.' * (self.width - n)}] {self.done}/{total} ETA {eta} {detail}"
            self.stream.write(line + "\n")
            self.stream.flush()
        self._last_pct = pct

    def message(self, text: str) -> None:
        if self._rich is not None:
            self._rich.console.print(text, markup=False, highlight=False, soft_wrap=True)
            return
        self.stream.write(text + "\n")
        self.stream.flush()

    def finish(self) -> None:
        if self._rich is not None:
            self._rich.stop()
            self._rich = None


def terminal_progress(
    total: int = 0, label: str = "", *, stream: TextIO | None = None, piped_lines: bool = True
) -> TerminalProgress:
    """A :class:`TerminalProgress` on ``stream`` (default stderr); a context manager:
    ``with terminal_progress(n, "maps") as p: p.advance()``. ``piped_lines=False``: no
    10 % lines to a pipe or a file (the messages still are)."""
    return TerminalProgress(stream, total=total, label=label, piped_lines=piped_lines)


class StepsProgress:
    """A ``(done, total, what)`` progress callback drawn by ``reporter``, from the first
    call made ``after_s`` seconds or more after this was made (short work shows nothing);
    the reporter is finished when ``done`` reaches ``total``."""

    def __init__(self, reporter: Reporter, *, after_s: float = 0.0) -> None:
        self.reporter = reporter
        self.after_s = after_s
        self.t0 = time.monotonic()
        #: The reporter was started (something was shown).
        self.shown = False

    def __call__(self, done: int, total: int, what: str) -> None:
        if not self.shown:
            if time.monotonic() - self.t0 < self.after_s:
                return
            self.shown = True
            self.reporter.start(total, what)
        self.reporter.advance(done, total=total)
        if done >= total:
            self.reporter.finish()


def model_progress(*, after_s: float = 2.0, stream: TextIO | None = None) -> StepsProgress:
    """The CLI's progress of long model work: a :func:`terminal_progress` bar on ``stream``
    (default stderr) when a terminal watches and the work has taken ``after_s`` s; nothing
    to a pipe or a file."""
    out = sys.stderr if stream is None else stream
    reporter: Reporter = TerminalProgress(out, label="model") if out.isatty() else NullProgress()
    return StepsProgress(reporter, after_s=after_s)


def notebook_progress(total: int = 0, label: str = "") -> TerminalProgress:
    """The rich bar drawn in a Jupyter kernel's output (a widget), never on stdout."""
    return TerminalProgress(sys.stderr, total=total, label=label, jupyter=True)


def in_jupyter() -> bool:
    """Running in a Jupyter kernel (IPython's ZMQ shell), where rich draws widgets."""
    shell = sys.modules.get("IPython")
    if shell is None:
        return False
    try:
        ip = shell.get_ipython()
    except AttributeError:
        return False
    return ip is not None and type(ip).__name__ == "ZMQInteractiveShell"


def auto_progress(total: int = 0, label: str = "") -> TerminalProgress:
    """:func:`notebook_progress` in a Jupyter kernel, else :func:`terminal_progress` on stderr."""
    if in_jupyter():
        return notebook_progress(total, label)
    return terminal_progress(total, label)
