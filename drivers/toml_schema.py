"""Reading a TOML file into pydantic models, with errors that name the file, the key and the reason.

Shared by the device profiles (:mod:`drivers.profiles`) and the lab configs
(:mod:`goniolab.config`); it lives in ``drivers`` because drivers import nothing from
``goniolab``, so the config reuses it rather than the other way round.

* Reading and parsing the file is the house's one TOML loader, :mod:`labtoml`
  (:func:`~labtoml.read_toml`, :class:`~labtoml.TomlFileError`, re-exported here for the
  schemas' callers); it lives outside ``drivers`` because ``goniolab.colour`` and
  ``goniolab.surfaces`` read TOML too and may not import ``drivers``.
* :func:`first_issue` turns a pydantic :class:`~pydantic.ValidationError` into the dotted
  key of its first error (``registers.output_status``, ``replies.measure[1]``) and a reason.
  Two phrasings: :func:`pydantic_reason` keeps pydantic's words ("Input should be greater
  than 0 (got -1)"), :func:`plain_reason` says it shortly ("-1 is below the minimum 0",
  "expected an integer, got True").
* A validator that checks several keys at once raises :class:`KeyedValueError` to blame
  the one key a user would edit; :func:`first_issue` appends it to the validator's location.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from pydantic import ValidationError

from labtoml import TomlFileError, read_toml

__all__ = [
    "KeyedValueError",
    "TomlFileError",
    "dotted",
    "first_issue",
    "plain_reason",
    "pydantic_reason",
    "read_toml",
    "short_repr",
]


class KeyedValueError(ValueError):
    """Raised inside a validator to blame ``key`` (dotted, relative to the validated model).

    Parameters
    ----------
    key
        Dotted key below the model whose validator raises (``"registers.command"``).
    reason
        What is wrong, in words a user can act on.
    """

    def __init__(self, key: str, reason: str) -> None:
        self.key = key
        self.reason = reason
        super().__init__(reason)


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters, so an error stays one short line
    whatever was written (a 5000-deep array, a megabyte string)."""
    try:
        text = repr(value)
    except RecursionError:
        text = f"<{type(value).__name__} nested too deeply>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def dotted(loc: Sequence[int | str]) -> str:
    """A pydantic error location as a dotted key: ``("replies", "measure", 1)`` -> ``replies.measure[1]``."""
    parts: list[str] = []
    for item in loc:
        if isinstance(item, int):
            parts.append(f"[{item}]")
        else:
            parts.append(("." if parts else "") + item)
    return "".join(parts)


_UNKNOWN = ("extra_forbidden", "unexpected_keyword_argument")
_MISSING = ("missing", "missing_argument", "missing_keyword_only_argument")


def pydantic_reason(err: Mapping[str, Any]) -> str:
    """Pydantic's own message, plus the offending value (``"Input should be ... (got 'x')"``)."""
    kind = err.get("type", "")
    if kind in _UNKNOWN:
        return "unknown key (typo?)"
    if kind in _MISSING:
        return "required key missing"
    msg = str(err.get("msg", "invalid value")).removeprefix("Value error, ")
    value = err.get("input")
    if kind != "value_error" and not isinstance(value, dict):
        msg = f"{msg} (got {short_repr(value)})"
    return msg


def plain_reason(err: Mapping[str, Any]) -> str:
    """A short reason in the words of a datasheet (``"40 is above the maximum 31"``)."""
    kind = err.get("type", "")
    ctx: Mapping[str, Any] = err.get("ctx") or {}
    value = err.get("input")
    if kind in _UNKNOWN:
        return "unknown key (typo?)"
    if kind in _MISSING:
        return "missing"
    phrases: dict[str, Callable[[], str]] = {
        "int_type": lambda: f"expected an integer, got {short_repr(value)}",
        "float_type": lambda: f"expected a number, got {short_repr(value)}",
        "finite_number": lambda: f"must be a finite number, got {short_repr(value)}",
        "string_type": lambda: f"expected a string, got {short_repr(value)}",
        "list_type": lambda: f"expected a list, got {short_repr(value)}",
        "dict_type": lambda: f"expected a table, got {short_repr(value)}",
        "model_type": lambda: f"expected a table, got {short_repr(value)}",
        "dataclass_type": lambda: f"expected a table, got {short_repr(value)}",
        "greater_than_equal": lambda: f"{short_repr(value)} is below the minimum {ctx.get('ge')!r}",
        "less_than_equal": lambda: f"{short_repr(value)} is above the maximum {ctx.get('le')!r}",
        "greater_than": lambda: f"must be > {ctx.get('gt')!r}, got {short_repr(value)}",
        "less_than": lambda: f"must be < {ctx.get('lt')!r}, got {short_repr(value)}",
        "string_too_short": lambda: "must not be empty",
        "literal_error": lambda: f"expected {ctx.get('expected')}, got {short_repr(value)}",
    }
    if kind in phrases:
        return phrases[kind]()
    return str(err.get("msg", "invalid value")).removeprefix("Value error, ")


def first_issue(
    exc: ValidationError, reason: Callable[[Mapping[str, Any]], str] = pydantic_reason
) -> tuple[str, str]:
    """The dotted key and the reason of the first error of a validation (unknown keys first).

    Parameters
    ----------
    exc
        What ``Model.model_validate(data)`` raised.
    reason
        :func:`pydantic_reason` or :func:`plain_reason`.

    Returns
    -------
    tuple of str
        ``(key, reason)``; ``key`` is ``""`` when the whole document is at fault.
    """
    errors = exc.errors()
    # a misspelt key is also a missing one: the typo is what to fix
    unknown = [e for e in errors if e["type"] in _UNKNOWN]
    err = (unknown or errors)[0]
    loc: list[int | str] = list(err["loc"])
    cause = (err.get("ctx") or {}).get("error")
    if isinstance(cause, KeyedValueError):
        return dotted([*loc, *cause.key.split(".")]), cause.reason
    return dotted(loc), reason(err)
