"""A throw-away PostgreSQL server (Debian's binaries), for the store's tests and benchmark.

PostgreSQL refuses to run as root: as root its tools run as the ``postgres`` user, in a
temporary directory given to that user; the server listens on 127.0.0.1 and a free port,
its unix socket in that directory. No pytest here (the benchmark uses it too).
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path


class NoServerError(RuntimeError):
    """No PostgreSQL server can run here; the message says why."""


@dataclass
class PostgresServer:
    """A running cluster: ``url(db)`` for SQLAlchemy, stop/start for outages."""

    bin_dir: Path
    data_dir: Path
    socket_dir: Path
    port: int

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{database}"

    def _ctl(self, *args: str) -> None:
        command = [str(self.bin_dir / "pg_ctl"), "-D", str(self.data_dir), "-w", *args]
        done = subprocess.run(_as_postgres(command), capture_output=True, text=True,
                              check=False)
        if done.returncode != 0:
            log = (self.socket_dir / "server.log").read_text(errors="replace")[-2000:]
            raise RuntimeError(f"pg_ctl {args[-1]} failed: {done.stderr}\n{log}")

    def start(self) -> None:
        options = (f"-p {self.port} -k {self.socket_dir} -c listen_addresses=127.0.0.1 "
                   "-c fsync=off -c full_page_writes=off -c max_connections=60")
        self._ctl("-l", str(self.socket_dir / "server.log"), "-o", options, "start")

    def stop(self) -> None:
        self._ctl("-m", "fast", "stop")

    def create_database(self) -> str:
        """A new empty database; its URL."""
        import psycopg

        name = f"t_{uuid.uuid4().hex[:12]}"
        with psycopg.connect(host="127.0.0.1", port=self.port, user="postgres",
                             dbname="postgres", autocommit=True) as connection:
            connection.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)


@contextmanager
def temporary_server() -> Iterator[PostgresServer]:
    """Start a new cluster; stop it and delete its files on leaving.

    Raises
    ------
    NoServerError
        No server binary, or root without a ``postgres`` user / ``runuser``.
    """
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"))
    if not found:
        raise NoServerError("no PostgreSQL server binary (/usr/lib/postgresql/*/bin/pg_ctl); "
                            "apt-get install postgresql")
    if os.geteuid() == 0:
        if shutil.which("runuser") is None:
            raise NoServerError("running as root without runuser: cannot run PostgreSQL")
        try:
            pwd.getpwnam("postgres")
        except KeyError:
            raise NoServerError("running as root and no 'postgres' user to run PostgreSQL as"
                                ) from None
    bin_dir = Path(found[-1]).parent
    root = Path(tempfile.mkdtemp(prefix="gimbal-hil-pg-"))
    try:
        if os.geteuid() == 0:
            shutil.chown(root, user="postgres")
        server = PostgresServer(bin_dir, root / "data", root, _free_port())
        done = subprocess.run(
            _as_postgres([str(bin_dir / "initdb"), "-D", str(server.data_dir), "-A", "trust",
                          "-U", "postgres", "-N", "-E", "UTF8"]),
            capture_output=True, text=True, check=False,
        )
        if done.returncode != 0:
            raise RuntimeError(f"initdb failed: {done.stderr}")
        server.start()
        try:
            yield server
        finally:
            server.stop()
    finally:
        shutil.rmtree(root, ignore_errors=True)


def _as_postgres(command: list[str]) -> list[str]:
    return ["runuser", "-u", "postgres", "--", *command] if os.geteuid() == 0 else command


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])
