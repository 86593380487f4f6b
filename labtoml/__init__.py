"""The one TOML loader of the house: every config, profile, standards file, sample library,
tolerance set and paint file is read here, so every TOML problem is worded the same way.

It imports the standard library only and nothing of the house, so that every room may use
it: ``drivers`` imports nothing from ``goniolab``, and ``goniolab.colour`` and
``goniolab.surfaces`` import nothing from ``drivers`` (``tests/test_layers.py``). What goes
beyond reading (naming the key of a pydantic error) stays with the schemas, in
:mod:`drivers.toml_schema`.

* :func:`read_toml` reads and parses a file;
* :func:`parse_toml` parses text a caller has already read (a file's content handed over);

every failure is a :class:`TomlFileError` whose ``reason`` is one line: ``"<what> not
found"``, ``"cannot read <what>: ..."``, ``"TOML syntax error: ... (at line 3, column 8)"``
or ``"arrays or tables nested too deeply to be a <what>"`` (:mod:`tomllib` recurses once per
nested array or inline table, so a hostile file would otherwise end in a RecursionError).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

__all__ = ["TomlFileError", "parse_toml", "read_toml"]


class TomlFileError(ValueError):
    """A TOML file could not be read or parsed.

    Attributes
    ----------
    path
        The file (or the name the text was given under, :func:`parse_toml`).
    reason
        One line: ``"<what> not found"``, ``"cannot read <what>: ..."``,
        ``"TOML syntax error: ... (at line L, column C)"`` or ``"arrays or tables nested too
        deeply to be a <what>"``.
    not_found
        True when the file does not exist (callers add a hint, e.g. the known names).
    """

    def __init__(self, path: Path | str, reason: str, *, not_found: bool = False) -> None:
        self.path = path
        self.reason = reason
        self.not_found = not_found
        super().__init__(f"{path}: {reason}")


def parse_toml(text: str, where: Path | str, *, what: str) -> dict[str, Any]:
    """Parse TOML text.

    Parameters
    ----------
    text
        The document.
    where
        The file it came from (or a name for it), carried by the error.
    what
        How the document is named in messages (``"tolerance file"``).

    Raises
    ------
    TomlFileError
        A TOML syntax error (with line and column), or nesting too deep to parse.
    """
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TomlFileError(where, f"TOML syntax error: {exc}") from None
    except RecursionError:  # tomllib recurses once per nested array / inline table
        raise TomlFileError(where, f"arrays or tables nested too deeply to be a {what}") from None


def read_toml(path: Path, *, what: str) -> dict[str, Any]:
    """Read and parse a TOML file.

    Parameters
    ----------
    path
        The file.
    what
        How the file is named in messages (``"profile file"``, ``"config file"``).

    Raises
    ------
    TomlFileError
        Missing or unreadable file, not UTF-8, a TOML syntax error (with line and column),
        or nesting too deep to parse.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise TomlFileError(path, f"{what} not found", not_found=True) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TomlFileError(path, f"cannot read {what}: {exc}") from None
    return parse_toml(text, path, what=what)
