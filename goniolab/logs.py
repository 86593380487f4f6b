"""The log file every command and the TUI write: rotating, in the user log dir.

``<user log dir>/goniolab.log`` (platformdirs: ``~/.local/state/goniolab/log`` on Linux;
``GONIOLAB_LOG_DIR`` overrides it), 1 MB per file, five old files kept. ``--log-level``
sets what goes in (default ``INFO``: commands, configs, stores, runs started and finished,
instrument errors). Passwords never reach the file: :class:`RedactingFilter` blanks the
password of any ``postgresql://user:password@`` URL and of any libpq ``password=`` value
in every record, tracebacks included (:func:`goniolab.redact.redact`, by parsing: an
environment variable's value is never searched for as text).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from goniolab.redact import redact

__all__ = [
    "LEVELS",
    "RedactingFilter",
    "log_dir",
    "log_path",
    "redact",
    "setup_logging",
]

LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
_MAX_BYTES = 1_000_000
_BACKUPS = 5
_MARK = "_goniolab_file_handler"


class RedactingFilter(logging.Filter):
    """Blank passwords in a record's final message (see :func:`redact`)."""

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            message = record.getMessage()
        except (TypeError, ValueError):  # a malformed record: leave it to the formatter
            return True
        clean = redact(message)
        if clean != message or record.args:
            record.msg, record.args = clean, None
        if record.exc_info and record.exc_info[1] is not None:
            record.exc_text = redact(logging.Formatter().formatException(record.exc_info))
            record.exc_info = None
        return True


class _RotatingFile(logging.FileHandler):
    """The rotation of :class:`logging.handlers.RotatingFileHandler` (the same rule and the
    same file names ``goniolab.log.1`` .. ``.5``) without importing :mod:`logging.handlers`
    (socket, pickle and queue: 4 ms of every command's start)."""

    def __init__(self, path: Path, max_bytes: int, backups: int) -> None:
        super().__init__(path, encoding="utf-8")
        self.max_bytes = max_bytes
        self.backups = backups

    def _should_roll(self, record: logging.LogRecord) -> bool:
        base = self.baseFilename
        if os.path.exists(base) and not os.path.isfile(base):  # a device, a pipe: kept
            return False
        if self.stream is None:
            self.stream = self._open()
        msg = f"{self.format(record)}\n"
        self.stream.seek(0, 2)
        return bool(self.stream.tell() + len(msg) >= self.max_bytes)

    def _roll(self) -> None:
        if self.stream is not None:
            self.stream.close()
            self.stream = None
        base = self.baseFilename
        for i in range(self.backups - 1, 0, -1):
            src, dst = f"{base}.{i}", f"{base}.{i + 1}"
            if os.path.exists(src):
                if os.path.exists(dst):
                    os.remove(dst)
                os.rename(src, dst)
        dst = f"{base}.1"
        if os.path.exists(dst):
            os.remove(dst)
        if os.path.exists(base):
            os.rename(base, dst)
        self.stream = self._open()

    def emit(self, record: logging.LogRecord) -> None:
        try:
            if self._should_roll(record):
                self._roll()
        except Exception:
            self.handleError(record)
            return
        super().emit(record)


def log_dir() -> Path:
    """The directory of the log file (``GONIOLAB_LOG_DIR`` or platformdirs' user log dir)."""
    env = os.environ.get("GONIOLAB_LOG_DIR")
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_log_dir("goniolab", appauthor=False))


def log_path() -> Path:
    """The log file ``goniolab.log`` in :func:`log_dir`."""
    return log_dir() / "goniolab.log"


def setup_logging(level: str = "INFO") -> Path | None:
    """Send log records at ``level`` and above to the rotating log file.

    Calling it again (the TUI, tests that call ``main`` many times) replaces the handler.
    A log dir that cannot be created (read-only home) leaves file logging off and returns
    ``None``; nothing else changes.
    """
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, _MARK, False):
            root.removeHandler(h)
            h.close()
    path = log_path()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handler = _RotatingFile(path, _MAX_BYTES, _BACKUPS)
    except OSError:
        return None
    setattr(handler, _MARK, True)
    handler.setLevel(getattr(logging, level.upper()))
    handler.addFilter(RedactingFilter())
    handler.setFormatter(
        logging.Formatter("%(asctime)s %(process)d %(levelname)s %(name)s: %(message)s")
    )
    root.addHandler(handler)
    if root.level > handler.level or root.level == logging.NOTSET:
        root.setLevel(handler.level)
    return path
