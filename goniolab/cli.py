"""The ``goniolab`` command.

Sub-commands live in :mod:`goniolab.commands`, one module each, discovered at start-up:
every module there exposes ``register(subparsers)`` which adds its parser and sets
``func`` (a callable taking the parsed namespace and returning the exit code).

Errors a user can act on (bad file, bad config, unreachable instrument) are printed as one
line on stderr, ``goniolab: error: ...``, with exit code 2 for bad input and 1 for
instrument or run failures; a traceback is shown only with ``--debug``. A reader that
goes away early (``goniolab runs export 1 | head``) ends the command quietly with exit
status 141 (128 + SIGPIPE, as a C tool killed by SIGPIPE reports it).
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
from collections.abc import Sequence
from typing import Any

from goniolab.errors import UserError

__all__ = ["EXIT_BROKEN_PIPE", "build_parser", "main"]

#: Exit status when stdout's reader went away (128 + SIGPIPE).
EXIT_BROKEN_PIPE = 141


class _VersionAction(argparse.Action):
    """``--version``: looks the version up only when asked (see :mod:`goniolab`)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        kwargs.setdefault("nargs", 0)
        kwargs.setdefault("default", argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *_: Any) -> None:
        from goniolab import __version__

        parser.exit(message=f"goniolab {__version__}\n")


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every sub-command found in ``goniolab.commands``."""
    import goniolab.commands as commands_pkg

    parser = argparse.ArgumentParser(
        prog="goniolab",
        description="Goniospectrophotometer and glossmeter control, with BRDF and gloss "
        "predicted from surface roughness (Wittmann et al. 2021).",
    )
    parser.add_argument("--version", action=_VersionAction, help="show the version and exit")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands_pkg.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"goniolab.commands.{info.name}")
        module.register(sub)
    return parser


def _quiet_library_logs(debug: bool) -> None:
    """Keep library log lines (pymodbus prints "Failed to connect ..." at ERROR) off the
    terminal: the drivers turn those failures into one clear error of their own."""
    if not debug:
        import logging

        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def _silence_stdout() -> None:
    """Point stdout at /dev/null: the interpreter flushes it again at exit, and that flush
    must not raise a second BrokenPipeError (Python docs, "Note on SIGPIPE")."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # stdout replaced by a non-file (tests)
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``goniolab`` console script; returns the process exit code."""
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        _quiet_library_logs(args.debug)
        code: int = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except UserError as exc:
        if "args" in locals() and args.debug:
            raise
        print(f"goniolab: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("goniolab: interrupted", file=sys.stderr)
        return 130
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
