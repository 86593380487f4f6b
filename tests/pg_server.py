"""A throw-away PostgreSQL server for tests: initdb + pg_ctl on a temp dir and a free port.

Password authentication (scram-sha-256) for the ``goniolab`` role, so that the tests use a
real secret the client must send (from ``PGPASSWORD``). As root, initdb and the server run
as the ``postgres`` system user (initdb refuses root). :func:`find_pg_bin` returns ``None``
with the reason when the Debian package ``postgresql`` (or psycopg) is missing.
"""

from __future__ import annotations

import contextlib
import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

#: The password the tests plant (never to be found in logs, snapshots or messages).
PLANTED_PASSWORD = "pl4nted-S3cret-xyzzy"
USER = "goniolab"


def find_pg_bin() -> tuple[Path | None, str]:
    """The directory of initdb/pg_ctl, or ``None`` and why not."""
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return None, "psycopg is not installed (pip install 'goniolab[postgres]')"
    found = shutil.which("initdb")
    candidates = [Path(found).resolve().parent] if found else []
    candidates += [Path(p) for p in sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True)]
    for d in candidates:
        if (d / "initdb").is_file() and (d / "pg_ctl").is_file():
            if os.geteuid() == 0:
                try:
                    pwd.getpwnam("postgres")
                except KeyError:
                    return None, "running as root and there is no 'postgres' user to run initdb"
                if not shutil.which("runuser"):
                    return None, "running as root and runuser is missing"
            return d, ""
    return None, "PostgreSQL server binaries not found (Debian package 'postgresql')"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class PgServer:
    """A running server: ``url(db)`` without the password (it comes from PGPASSWORD)."""

    port: int
    root: Path

    def url(self, db: str = "postgres", *, password: bool = False) -> str:
        secret = f":{PLANTED_PASSWORD}" if password else ""
        return f"postgresql://{USER}{secret}@127.0.0.1:{self.port}/{db}"

    def create_db(self, name: str) -> str:
        """Create database ``name``; return its URL."""
        import psycopg

        with psycopg.connect(self.url(), password=PLANTED_PASSWORD, autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)


def _as_server_user(cmd: list[str]) -> list[str]:
    return ["runuser", "-u", "postgres", "--", *cmd] if os.geteuid() == 0 else cmd


#: Attempts at a port: another process (an xdist worker starting its own server) may take
#: the port :func:`_free_port` found free between its check and the server's bind.
PORT_ATTEMPTS = 5


def _start(bindir: Path, data: Path, root: Path, env: dict[str, str]) -> int:
    """Start the server of ``data`` on a free port; return the port. A port taken between
    :func:`_free_port` and the server's bind (the log says "could not bind") is retried on
    another, up to :data:`PORT_ATTEMPTS` times; any other failure raises at once, with the
    server's log."""
    log = root / "server.log"
    for attempt in range(1, PORT_ATTEMPTS + 1):
        port = _free_port()
        opts = f"-p {port} -k {root} -c listen_addresses=127.0.0.1 -c fsync=off"
        log.unlink(missing_ok=True)
        proc = subprocess.run(
            _as_server_user([str(bindir / "pg_ctl"), "-D", str(data), "-o", opts,
                             "-l", str(log), "-w", "-t", "60", "start"]),
            capture_output=True, env=env, timeout=120, check=False,
        )  # fmt: skip
        if proc.returncode == 0:
            return port
        text = log.read_text(errors="replace") if log.exists() else ""
        if "could not bind" not in text or attempt == PORT_ATTEMPTS:
            raise RuntimeError(
                f"pg_ctl start on port {port} failed ({proc.returncode}): "
                f"{proc.stderr.decode(errors='replace')[-400:]} {text[-800:]}"
            )
    raise AssertionError("unreachable")


@contextlib.contextmanager
def pg_server(bindir: Path) -> Iterator[PgServer]:
    """Start a server in a temp dir; stop it and remove everything on exit."""
    root = Path(tempfile.mkdtemp(prefix="goniolab-pg-"))
    data = root / "data"
    pwfile = root / "pw"
    pwfile.write_text(PLANTED_PASSWORD + "\n")
    if os.geteuid() == 0:
        shutil.chown(root, "postgres")
        shutil.chown(pwfile, "postgres")
    env = {**os.environ, "LC_ALL": "C"}
    env.pop("PGPASSWORD", None)
    run = {"check": True, "capture_output": True, "env": env, "timeout": 120}
    subprocess.run(
        _as_server_user([str(bindir / "initdb"), "-D", str(data), "-U", USER, "-A",
                         "scram-sha-256", f"--pwfile={pwfile}", "-E", "UTF8"]),
        **run,
    )  # fmt: skip
    port = _start(bindir, data, root, env)
    try:
        yield PgServer(port=port, root=root)
    finally:
        subprocess.run(
            _as_server_user([str(bindir / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w",
                             "stop"]),
            capture_output=True, env=env, timeout=120, check=False,
        )  # fmt: skip
        shutil.rmtree(root, ignore_errors=True)
