"""Sub-commands of the ``goniolab`` CLI: one module each, each exposing ``register(sub)``."""

from typing import Any

__all__ = ["apply_help"]


def apply_help(parser: Any) -> None:
    """Attach every command's examples and its options' defaults to its ``--help``
    (:mod:`goniolab.commands._help`; the package's one door to it)."""
    from goniolab.commands import _help

    _help.apply(parser)
