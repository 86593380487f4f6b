"""JSON that every reader accepts: no ``NaN``, ``Infinity`` or ``-Infinity``.

Python's :func:`json.dumps` writes non-finite floats as those bare words by default, which
RFC 8259 does not allow (``jq``, JavaScript's ``JSON.parse``, Go and Rust decoders refuse
the whole document). A missing or undefined number is ``null`` in goniolab's JSON; with
``allow_nan=False`` any value this missed raises instead of writing invalid JSON
(issue 23.13: ``runs show --json`` printed ``Infinity`` for an RMSE).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

__all__ = ["dumps", "finite"]


def finite(obj: Any) -> Any:
    """``obj`` with every non-finite float (numpy's too) replaced by ``None``, through
    dicts, lists and tuples; anything else as it is."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    kind = getattr(obj, "dtype", None)
    if kind is not None and getattr(obj, "ndim", None) == 0 and kind.kind == "f":
        value = float(obj)
        return value if math.isfinite(value) else None
    return obj


def dumps(obj: Any, **kwargs: Any) -> str:
    """:func:`json.dumps` of :func:`finite` ``(obj)``, never writing NaN or Infinity."""
    return json.dumps(finite(obj), allow_nan=False, **kwargs)
