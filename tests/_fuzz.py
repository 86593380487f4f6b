"""What the hypothesis fuzz tests of configs, device profiles and paints share: their
settings, a small TOML writer for the hostile documents they write, and key-path edits."""

from __future__ import annotations

import math
from datetime import timedelta
from typing import Any

from hypothesis import HealthCheck, settings

#: Drawn as a value: the key is removed instead.
DELETE = object()


def fuzz_settings(max_examples: int) -> Any:
    """``max_examples`` cases, 3 s each at most (a hang or a slow path is a finding)."""
    return settings(
        max_examples=max_examples,
        deadline=timedelta(seconds=3),
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
        database=None,
    )


def toml_value(value: Any, *, escape_controls: bool = False) -> str:
    """``value`` as a TOML value: nan/inf literals, inline arrays and tables. Strings escape
    only ``\\`` and ``"`` (a control character stays raw, which TOML refuses), or with
    ``escape_controls`` every unprintable character as ``\\uXXXX`` (lone surrogates,
    which TOML cannot hold, dropped)."""

    def text(v: Any) -> str:
        return toml_value(v, escape_controls=escape_controls)

    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        if not escape_controls:
            return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
        escaped = "".join(
            c if c.isprintable() and c not in '"\\' else f"\\u{ord(c):04x}"
            for c in value
            if not 0xD800 <= ord(c) <= 0xDFFF
        )
        return f'"{escaped}"'
    if isinstance(value, list):
        return "[" + ", ".join(text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f'"{k}" = {text(v)}' for k, v in value.items()) + "}"
    raise TypeError(value)


def toml_document(data: dict[str, Any], *, escape_controls: bool = False) -> str:
    """A TOML document of top-level ``"key" = value`` lines."""
    return "".join(
        f'"{k}" = {toml_value(v, escape_controls=escape_controls)}\n' for k, v in data.items()
    )


def leaves(data: dict[str, Any], prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every key path of a nested table, tables included."""
    out: list[tuple[str, ...]] = []
    for key, value in data.items():
        path = (*prefix, key)
        out.append(path)
        if isinstance(value, dict):
            out.extend(leaves(value, path))
    return out


def set_path(data: dict[str, Any], path: tuple[str, ...], value: Any) -> None:
    """Set (or, for :data:`DELETE`, remove) the key at ``path``, making tables on the way
    (a non-table in the way is replaced)."""
    node = data
    for part in path[:-1]:
        child = node.get(part)
        if not isinstance(child, dict):
            child = node[part] = {}
        node = child
    if value is DELETE:
        node.pop(path[-1], None)
    else:
        node[path[-1]] = value
