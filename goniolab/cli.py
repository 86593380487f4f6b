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
import contextlib
import importlib
import os
import re
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from goniolab.errors import UserError

__all__ = ["EXIT_BROKEN_PIPE", "build_parser", "console", "main", "version_text"]

#: Exit status when stdout's reader went away (128 + SIGPIPE).
EXIT_BROKEN_PIPE = 141


def _log() -> Any:
    """The ``goniolab`` logger (logging is imported once a command runs, not for --help)."""
    import logging

    return logging.getLogger("goniolab")


class _VersionAction(argparse.Action):
    """``--version``: the version (looked up only when asked, see :mod:`goniolab`), then
    where goniolab keeps things: the default store, the config, the log file."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        kwargs.setdefault("nargs", 0)
        kwargs.setdefault("default", argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *_: Any) -> None:
        print(version_text())  # on stdout, as argparse's own version action
        parser.exit()


#: A negative number, or an angle range/list starting with one ("-40:-30:5", "-10,0,10"): a
#: value, not an option, so ``--theta-r -20:20:1`` needs no ``=``.
_NEGATIVE_ARG = re.compile(r"^-\d+$|^-\d*\.\d+$|^-[\d.]+[:,][\d.:,\-]*$")


class _Parser(argparse.ArgumentParser):
    """argparse with goniolab's one-line errors (``goniolab: error: ...``, exit 2) and
    negative angle ranges taken as values; sub-command parsers are of the same class."""

    #: The command line the top-level parser is parsing, for the hints of :meth:`error`
    #: (the sub-command parsers report errors without the whole line).
    argv: Sequence[str] = ()
    #: Set on the top-level parser (:func:`build_parser`): its parse records the line.
    top_level = False

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        if self.top_level:
            _Parser.argv = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # a private attribute (stable since Python 3.2): widen "looks like a negative number"
        self._negative_number_matcher = _NEGATIVE_ARG

    def error(self, message: str) -> NoReturn:
        # one prefix: "goniolab: error: scan: ..." (the top level names no command)
        where = self.prog.removeprefix("goniolab").strip()
        if "invalid choice" in message:
            # an unknown option before a sub-command's positional makes argparse blame the
            # positional ("argument resume: invalid choice: '0:70:1'"): name the option
            unknown = [
                tok.split("=", 1)[0]
                for tok in _Parser.argv
                if tok.startswith("--") and tok.split("=", 1)[0] not in self._options()
            ]
            if unknown:
                message = "unrecognized arguments: " + " ".join(unknown)
        prog = self.prog
        words = [t for t in _Parser.argv if not t.startswith("-")][:2]
        if not where and words and message.startswith("unrecognized arguments"):
            # the top-level parser reports a command's leftovers: name that command (and
            # its action, "predict brdf", when it has one)
            sub = self._subcommand(words)
            where, prog = sub, f"{self.prog} {sub}"
        hint = self._did_you_mean(message)
        raise UserError(f"{where + ': ' if where else ''}{message}{hint} (see {prog} --help)")

    def _subcommand(self, words: list[str]) -> str:
        """The command (and its action) among the first positional ``words``."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction) and words[0] in action.choices:
                child = action.choices[words[0]]
                for inner in child._actions:
                    if (
                        isinstance(inner, argparse._SubParsersAction)
                        and len(words) > 1
                        and words[1] in inner.choices
                    ):
                        return f"{words[0]} {words[1]}"
                return words[0]
        return words[0]

    def _options(self) -> set[str]:
        """Every option string of this parser and of its sub-commands' parsers."""
        found: set[str] = set()
        todo: list[argparse.ArgumentParser] = [self]
        while todo:
            parser = todo.pop()
            for action in parser._actions:
                found.update(action.option_strings)
                if isinstance(action, argparse._SubParsersAction):
                    todo.extend(action.choices.values())
        return found

    def _did_you_mean(self, message: str) -> str:
        """``" (did you mean --theta-r?)"`` for a mistyped option or command, else ""."""
        import difflib

        m = re.match(r"unrecognized arguments: (.*)", message)
        if m:
            options = sorted(self._options())
            guesses = []
            for token in m.group(1).split():
                if not token.startswith("--"):
                    continue
                name = token.split("=", 1)[0]
                close = difflib.get_close_matches(name.replace("_", "-"), options, n=1)
                if close and close[0] != name:
                    guesses.append(close[0])
            return f" (did you mean {', '.join(guesses)}?)" if guesses else ""
        m = re.match(r"argument \S+: invalid choice: '(.*?)' \(choose from (.*)\)", message)
        if m:
            choices = [c.strip(" '") for c in m.group(2).split(",")]
            close = difflib.get_close_matches(m.group(1), choices, n=1)
            return f" (did you mean {close[0]!r}?)" if close else ""
        return ""


#: Top-level options that take a value (the token after them is not the command).
_VALUE_OPTIONS = frozenset({"--log-level"})


def _command_in(argv: Sequence[str]) -> str | None:
    """The sub-command named in ``argv`` (its first positional token), if any."""
    skip = False
    for tok in argv:
        if skip:
            skip = False
        elif tok in _VALUE_OPTIONS:
            skip = True
        elif tok == "--":
            return None
        elif not tok.startswith("-"):
            return tok
    return None


def _is_command(path: Sequence[str], name: str) -> bool:
    """Whether ``name`` is a command module of the package at ``path`` (a file
    ``name.py`` there; ``_``-prefixed modules are helpers), as ``pkgutil.iter_modules``
    would list it."""
    if not name.isidentifier() or name.startswith("_"):
        return False
    return any(os.path.isfile(os.path.join(d, name + ".py")) for d in path)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Build the top-level parser with every sub-command found in ``goniolab.commands``, or
    with ``only`` that one when it names a command (a command's run imports only its own
    module: ``predict`` need not import the scan plans, the fit, the TUI's entry...)."""
    import goniolab.commands as commands_pkg

    parser = _Parser(
        prog="goniolab",
        description="Goniospectrophotometer and glossmeter control, with BRDF and gloss "
        "predicted from surface roughness (Wittmann et al. 2021).",
    )
    parser.top_level = True
    parser.add_argument(
        "--version",
        action=_VersionAction,
        help="show the version, the store and config in use and the log file, then exit",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    parser.add_argument(
        "--log-level",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        default="INFO",
        type=str.upper,
        help="what goes into the log file (the file: goniolab --version)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    names = [only] if only is not None and _is_command(commands_pkg.__path__, only) else None
    if names is None:
        import pkgutil  # here: listing the commands (pkgutil imports inspect, 5 ms)

        names = sorted(
            info.name
            for info in pkgutil.iter_modules(commands_pkg.__path__)
            if not info.name.startswith("_")
        )
    for name in names:
        module = importlib.import_module(f"goniolab.commands.{name}")
        module.register(sub)
    from goniolab.commands import apply_help

    apply_help(parser)  # examples and "(default: X)" in every command's --help
    return parser


def version_text() -> str:
    """``goniolab X.Y.Z`` and the default store, config and log file, one per line."""
    from pathlib import Path

    import platformdirs

    from goniolab import __version__
    from goniolab.logs import log_path

    # goniolab.store.default_store_path, without importing the store (and sqlite3) here
    store = Path(platformdirs.user_data_dir("goniolab", appauthor=False)) / "goniolab.sqlite"
    return "\n".join(
        [
            f"goniolab {__version__}",
            f"store:  {store} (default; --store or a config's [lab] store chooses another)",
            "config: none by default; commands that drive instruments take --config FILE "
            "(configs/lab-sim.toml is the simulated lab)",
            f"log:    {log_path()}",
        ]
    )


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


def _own_warning(category: type[Warning], filename: str) -> bool:
    """A warning goniolab itself issues: its class is goniolab's (or the drivers'), or it
    was raised from goniolab's or the drivers' code."""
    module = getattr(category, "__module__", "")
    if module.split(".")[0] in ("goniolab", "drivers"):
        return True
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    path = os.path.abspath(filename)
    return any(path.startswith(os.path.join(here, pkg) + os.sep) for pkg in ("goniolab", "drivers"))


def _one_line_warnings(debug: bool = False) -> None:
    """Show goniolab's own warnings (e.g. heights that look like nm read as um) as one line,
    like errors. A library's warning (numpy, pandas, colour-science ...) is not goniolab's
    to say: it goes to the log file with its origin, and to stderr only under ``--debug``
    (issue 23, Low: they leaked as ``goniolab: warning: ...``)."""
    import warnings

    def show(
        message: Warning | str,
        category: type[Warning],
        filename: str = "",
        lineno: int = 0,
        *_: object,
        **__: object,
    ) -> None:
        if _own_warning(category, filename):
            print(f"goniolab: warning: {message}", file=sys.stderr)
            _log().warning("%s", message)
            return
        origin = f"{category.__name__} from {filename}:{lineno}"
        _log().warning("library warning (%s): %s", origin, message)
        if debug:
            print(f"goniolab: library warning ({origin}): {message}", file=sys.stderr)

    warnings.showwarning = show


#: Refractive indices of dielectric coats (paints, plastics, glasses) lie in this range; a
#: value outside it is most likely a typo (``--n 155`` for 1.55) and is said, not refused.
DIELECTRIC_N_RANGE = (1.0, 3.0)


def _warn_implausible(args: argparse.Namespace) -> None:
    """Warn about an option that parses but is physically implausible (issue 27: ``--n 155``
    gave G20 = 1166 GU without a word): a dielectric index (no k) outside 1.0-3.0."""
    n = getattr(args, "n", None)
    if isinstance(n, bool) or not isinstance(n, int | float | complex):
        return
    lo, hi = DIELECTRIC_N_RANGE
    value = complex(n)
    if value.imag == 0 and not lo <= value.real <= hi:
        import warnings

        warnings.warn(
            f"--n {value.real:g} lies outside {lo:.1f}-{hi:.1f}, the refractive indices of "
            "dielectric coats (a PU clear coat: 1.55; a metal takes n+kj): the prediction "
            "uses it as given",
            stacklevel=1,
        )


def _start_log(args: argparse.Namespace, argv: Sequence[str] | None) -> None:
    """Open the log file and record the command (passwords blanked by the log filter)."""
    from goniolab import __version__
    from goniolab.logs import setup_logging

    setup_logging(getattr(args, "log_level", "INFO"))
    words = list(sys.argv[1:] if argv is None else argv)
    _log().info("goniolab %s: %s", __version__, " ".join(words))
    for name in ("config", "store"):
        value = getattr(args, name, None)
        if value:
            _log().info("%s: %s", name, value)


def _stack_dump_on_sigusr1() -> None:
    """``kill -USR1 <pid>`` prints every thread's stack to stderr and the process goes on.

    For a scan or a TUI that seems stuck: where it waits shows without stopping it. A
    Python-level handler (run by the main thread between bytecodes, also when it waits in
    ``select`` or on a lock) reading :func:`sys._current_frames`; :mod:`faulthandler`'s
    all-thread dump reads other threads' frames from a signal handler and can crash the
    process it was asked to inspect.
    """
    import signal

    if not hasattr(signal, "SIGUSR1"):  # Windows
        return

    def dump(signum: int, frame: Any) -> None:
        import threading
        import traceback

        names = {t.ident: t.name for t in threading.enumerate()}
        parts = [f"goniolab: stacks of pid {os.getpid()} (SIGUSR1)\n"]
        for ident, top in sys._current_frames().items():
            parts.append(f"\nThread {names.get(ident, '?')} ({ident}), most recent call last:\n")
            parts.extend(traceback.format_stack(top))
        text = "".join(parts)
        # the process's own stderr (the TUI captures sys.stderr while it runs), and the log
        err = sys.__stderr__
        if err is not None:
            with contextlib.suppress(OSError, ValueError):  # closed: nothing to show there
                err.write(text)
                err.flush()
        if "logging" in sys.modules:
            sys.modules["logging"].getLogger("goniolab").warning("%s", text)

    with contextlib.suppress(ValueError):  # not the main thread (an embedding host)
        signal.signal(signal.SIGUSR1, dump)


#: BLAS thread pools capped at one thread unless the user sets them (see :func:`_one_blas_thread`).
_BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _one_blas_thread() -> None:
    """Cap numpy's BLAS at one thread, unless the environment already chooses.

    goniolab's array work is element-wise, FFTs and small matrix products (plane fits,
    aperture frames): BLAS threads gain nothing there, but after any product OpenBLAS's
    workers spin, and a ``predict`` process burned twice its wall time in CPU (batch
    workers competed with each other's spinning threads: two workers were no faster than
    one). Set before numpy is imported (the CLI imports it lazily); worker processes
    inherit it. numba's own threads are not affected.
    """
    if "numpy" in sys.modules:
        return
    for var in _BLAS_THREAD_VARS:
        os.environ.setdefault(var, "1")


#: Commands that never run the models' threaded walks: no thread setting to check (the
#: check imports goniolab.optics, and numpy with it: 45 ms of a 80 ms ``runs list``).
_NO_THREAD_COMMANDS = frozenset({"samples", "runs", "lab"})


def _check_thread_env(command: str | None) -> None:
    """A ``GONIOLAB_THREADS`` or ``OMP_NUM_THREADS`` that is not a positive integer is the
    user's error, said before any work (the models read it deep inside a computation,
    where it surfaced as a traceback); not for :data:`_NO_THREAD_COMMANDS`."""
    if command in _NO_THREAD_COMMANDS:
        return
    if not (os.environ.get("GONIOLAB_THREADS") or os.environ.get("OMP_NUM_THREADS")):
        return
    from goniolab.optics.facet_threads import walk_threads

    try:
        walk_threads()
    except ValueError as exc:
        raise UserError(str(exc)) from None


def _freeze_imports() -> None:
    """In a one-shot ``predict`` process: import what every ``predict`` command imports
    (numpy, the models' front end) and freeze the objects made so far out of the cyclic
    garbage collector (:func:`gc.freeze`), so that the interpreter's collections, the final
    ones at exit above all, no longer walk them: the exit of a rough 2048^2 ``predict brdf``
    took 24.2 ms, 7.8 ms frozen (``bench/bench_process.py --before BASE``, bench/README.md,
    issue 26). The collector, paused by :func:`main` while the modules were imported (the
    process's collections 59 -> 18, 6.3 -> 1.7 ms: the same bench), runs again from here.

    The objects the command makes are not frozen: the collector still finds their cycles,
    at exit too, and runs their finalizers (a file left open in a cycle is flushed). What
    goes without finalizer is a module-level object that ends in a reference cycle at exit;
    logging's files are closed by logging's own exit hook.
    """
    import gc

    import goniolab.app.predictions  # noqa: F401  (the command imports it next)

    gc.freeze()
    gc.enable()


#: Set by :func:`main` when a one-shot ``predict`` command has run to its end (its status).
_one_shot_ended: list[int] = []


def _end_one_shot(code: int) -> NoReturn:
    """End a one-shot ``predict`` process as the interpreter would, less the modules'
    teardown: the exit handlers (:mod:`atexit`: logging closes its file, temporary
    directories go), a collection (the command's cyclic garbage, with its finalizers), the
    standard streams flushed, then :func:`os._exit`. The teardown left out deallocates
    every object of numpy and goniolab's modules one by one: a rough 2048^2 ``predict
    brdf``'s exit took 3.2 ms this way, 7.8 ms by the interpreter's
    (``bench/bench_process.py``, bench/README.md, issue 26)."""
    import atexit
    import gc

    atexit._run_exitfuncs()
    gc.collect()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a reader gone, a closed stream
            stream.flush()
    os._exit(code & 0xFF)  # as the shell sees sys.exit(code): the low 8 bits


def console() -> NoReturn:
    """The ``goniolab`` console script and ``python -m goniolab``: :func:`main` on the
    process's command line, then the process's exit: :func:`_end_one_shot` after a
    one-shot ``predict`` command, else the interpreter's own, which is also taken when
    another thread the interpreter would wait for still runs, or a profiler or tracer
    watches the process (``python -m cProfile -o FILE -m goniolab ...`` writes its file
    after the command returns)."""
    import threading

    code = main()
    waited_for = any(not t.daemon and t is not threading.main_thread() and t.is_alive()
                     for t in threading.enumerate())  # fmt: skip
    if _one_shot_ended and not waited_for and sys.getprofile() is None and sys.gettrace() is None:
        _end_one_shot(code)
    sys.exit(code)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``goniolab`` console script; returns the process exit code.

    ``argv`` None: the process's own command line (``sys.argv``)."""
    _stack_dump_on_sigusr1()
    _one_blas_thread()
    paused = False  # the cyclic collector, while a one-shot predict imports
    try:
        command = _command_in(sys.argv[1:] if argv is None else argv)
        one_shot = command == "predict" and argv is None  # a process of its own
        if one_shot:
            import gc

            gc.disable()  # until the imports are frozen (_freeze_imports)
            paused = True
            from goniolab.process_heap import tune_predict_heap

            tune_predict_heap()
        parser = build_parser(command)
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        _quiet_library_logs(args.debug)
        _one_line_warnings(args.debug)
        _start_log(args, argv)
        _warn_implausible(args)
        _check_thread_env(command)
        if one_shot:
            _freeze_imports()
            paused = False
        code: int = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
        if one_shot:
            _one_shot_ended.append(code)
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except UserError as exc:
        if "args" in locals() and args.debug:
            raise
        from goniolab.logs import redact

        message = redact(str(exc))
        if "logging" in sys.modules and sys.modules["logging"].getLogger().handlers:
            # the log file is open (it is not before the arguments are parsed)
            _log().error("error: %s", message)
        print(f"goniolab: error: {message}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("goniolab: interrupted", file=sys.stderr)
        return 130
    except Exception:
        # a bug or an unforeseen failure: the traceback goes to the log file too (the
        # README promises it), passwords redacted by the file's filter
        if "logging" in sys.modules and sys.modules["logging"].getLogger().handlers:
            _log().exception("unexpected error")
        raise
    finally:
        if paused:
            # a one-shot predict that ended before its imports were frozen (bad options,
            # --help): the collector runs again for whoever goes on in this process
            import gc

            gc.enable()
    return code


if __name__ == "__main__":  # pragma: no cover
    console()
