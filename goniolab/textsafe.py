"""Text from the store shown on a terminal without its control characters.

A sample name, a reason or a note is whatever a user, a config or a file name put there;
``sample = "x\\x1b]0;owned\\x07\\x1b[2J"`` cleared the screen and retitled the terminal
when ``runs list`` printed it (issue 23, Low). :func:`printable` shows every control
character (C0 but newline and tab, DEL, C1) and the bidirectional overrides (which reorder
what follows on screen, CVE-2021-42574's "Trojan Source") as a visible escape
(``\\x1b``, ``\\u202e``). JSON output needs none of this: ``json.dumps`` escapes them.
"""

from __future__ import annotations

import functools
import re
import sys
from collections.abc import Callable
from typing import Any, TextIO, TypeVar

__all__ = ["EscapingWriter", "escaped_stdout", "printable"]

_UNSAFE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u200e\u200f\u202a-\u202e\u2066-\u2069]")

_F = TypeVar("_F", bound=Callable[..., Any])


def _escape(m: re.Match[str]) -> str:
    c = ord(m.group(0))
    return f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}"


def printable(text: str) -> str:
    """``text`` with control characters and bidi overrides as visible escapes."""
    return _UNSAFE.sub(_escape, text)


class EscapingWriter:
    """A text stream that writes :func:`printable` of everything to ``inner``."""

    def __init__(self, inner: TextIO) -> None:
        self._inner = inner

    def write(self, text: str) -> int:
        self._inner.write(printable(text))
        return len(text)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


def escaped_stdout(func: _F) -> _F:
    """Run ``func`` with ``sys.stdout`` escaping control characters (a command's text
    output of stored strings)."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        saved = sys.stdout
        sys.stdout = EscapingWriter(saved)
        try:
            return func(*args, **kwargs)
        finally:
            sys.stdout = saved

    return wrapper  # type: ignore[return-value]
