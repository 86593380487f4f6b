"""A ``goniolab`` command on a shell's PATH that starts in milliseconds: a fork server.

The doc examples (tests/test_readme_examples.py) run the README's and the tutorial's shell
blocks as written: each ``goniolab`` in them is a process of its own, with the block's
working directory, environment, standard streams and exit status. Each such process paid
0.5-1.5 s of CPU importing numpy, pandas, colour-science, scipy and matplotlib before it
did anything, about two thirds of the examples' CPU.

Here one server process imports those libraries once (:data:`PRELOAD`) and forks a child
per command. The ``goniolab`` on the PATH (:func:`install`) is a small stdlib-only client:
it hands the server its argv, working directory, environment and its stdin/stdout/stderr
(the file descriptors themselves, over a Unix socket), and exits with the child's status.
The child takes those descriptors, that directory and that environment, and runs
:func:`goniolab.cli.main` as the console script does; everything else about the command
(argument parsing, lazy imports of goniolab's own modules, the store, the log file, what
it prints where) is a fresh process's. The server waits for each child, so their CPU time
counts in the server's children and, once the server is stopped, in the test's.

Not a replacement for the console script: ``tests/test_store_pg.py`` and
``tests/test_cli_pipes.py`` run the installed ``goniolab`` / ``python -m goniolab.cli``.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

#: What the server imports before it forks: the libraries the commands import lazily.
PRELOAD = (
    "numpy",
    "pandas",
    "colour",
    "scipy.fft",
    "scipy.ndimage",
    "scipy.optimize",
    "scipy.special",
    "scipy.interpolate",
    "matplotlib",
    "matplotlib.pyplot",
    "xarray",
    "sqlite3",
    "pydantic",
    "pymodbus.client",
    "serial",
    "goniolab.cli",
    "goniolab.config",
    "dask",
    "platformdirs",
    "filelock",
    "sim",
)

#: The client: stdlib only, started with ``-IS`` (no site-packages to scan).
_CLIENT = """\
import json, os, socket, sys
s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
s.connect(os.environ["GONIOLAB_TEST_ZYGOTE"])
req = json.dumps({"argv": sys.argv[1:], "cwd": os.getcwd(), "env": dict(os.environ)}).encode()
socket.send_fds(s, [len(req).to_bytes(8, "big")], [0, 1, 2])
s.sendall(req)
got = b""
while len(got) < 4:
    part = s.recv(4 - len(got))
    if not part:
        sys.exit(1)  # the child died without a status (a signal): as a shell would see it
    got += part
sys.exit(int.from_bytes(got, "big", signed=True))
"""


def _recv_exact(conn: socket.socket, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        part = conn.recv(n - len(buf))
        if not part:
            raise EOFError
        buf += part
    return buf


def _child(conn: socket.socket, fds: list[int], req: dict[str, object]) -> None:
    """In the forked child: become the command's process, run it, report its status."""
    code = 1
    try:
        for target, fd in enumerate(fds):
            os.dup2(fd, target)
            os.close(fd)
        os.chdir(str(req["cwd"]))
        env = req["env"]
        assert isinstance(env, dict)
        os.environ.clear()
        os.environ.update(env)
        argv = req["argv"]
        assert isinstance(argv, list)
        sys.argv = ["goniolab", *argv]
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        from goniolab.cli import main

        try:
            code = main()
        except SystemExit as exc:
            if isinstance(exc.code, int) or exc.code is None:
                code = exc.code or 0
            else:
                print(exc.code, file=sys.stderr)
                code = 1
        except BaseException:
            import traceback

            traceback.print_exc()
            code = 1
        import atexit

        atexit._run_exitfuncs()  # what the interpreter's exit would run (the log's close)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
    finally:
        with contextlib.suppress(Exception):
            conn.sendall(int(code).to_bytes(4, "big", signed=True))
        os._exit(int(code) & 0xFF)


def serve(path: str) -> None:
    """Import :data:`PRELOAD`, listen on ``path``, fork a child per request until SIGTERM."""
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")  # as goniolab.cli does before numpy: no BLAS threads
    import importlib

    import matplotlib

    matplotlib.use("Agg")
    for name in PRELOAD:
        importlib.import_module(name)
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(path)
    srv.listen(8)
    children: set[int] = set()

    def stop(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)
    print("ready", flush=True)
    try:
        while True:
            conn, _ = srv.accept()
            head, fds, _flags, _addr = socket.recv_fds(conn, 8, 3)
            req = json.loads(_recv_exact(conn, int.from_bytes(head, "big")))
            pid = os.fork()
            if pid == 0:
                srv.close()
                _child(conn, fds, req)
            conn.close()
            for fd in fds:
                os.close(fd)
            children.add(pid)
            for done in [p for p in children if os.waitpid(p, os.WNOHANG)[0]]:
                children.discard(done)
    except KeyboardInterrupt:
        pass
    finally:
        for pid in children:  # every child waited for: its CPU counts in ours
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)


@contextlib.contextmanager
def zygote(workdir: Path) -> Iterator[dict[str, str]]:
    """Start the server (with this process's environment); yield the variables that put
    its ``goniolab`` client first on a PATH (:func:`client_env`); stop the server and wait
    for it on exit."""
    bindir = workdir / ".zygote-bin"
    bindir.mkdir()
    client = bindir / "goniolab"
    client.write_text(f"#!{sys.executable} -IS\n{_CLIENT}")
    client.chmod(0o755)
    sock = os.path.join(tempfile.mkdtemp(prefix="gz-"), "s")  # a Unix socket path is short
    root = str(Path(__file__).resolve().parents[1])
    path = os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))
    proc = subprocess.Popen(
        [sys.executable, "-m", "tests._zygote", sock],
        env={**os.environ, "PYTHONPATH": path}, cwd=root, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "ready", "the goniolab fork server did not start"
        yield {"bin": str(bindir), "GONIOLAB_TEST_ZYGOTE": sock}
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:  # pragma: no cover - a stuck server
            proc.kill()
            proc.wait()
        with contextlib.suppress(OSError):
            os.unlink(sock)
            os.rmdir(os.path.dirname(sock))


def client_env(env: dict[str, str], server: dict[str, str]) -> dict[str, str]:
    """``env`` with the server's ``goniolab`` client first on its PATH."""
    return {
        **env,
        "PATH": f"{server['bin']}{os.pathsep}{env.get('PATH', '')}",
        "GONIOLAB_TEST_ZYGOTE": server["GONIOLAB_TEST_ZYGOTE"],
    }


if __name__ == "__main__":
    serve(sys.argv[1])
