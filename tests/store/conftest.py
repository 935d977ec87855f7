"""Stores the tests use: a SQLite file, and a real PostgreSQL server the tests start
themselves (Debian's binaries, run as the ``postgres`` user when the tests run as root, on
127.0.0.1 and a free port, unix socket in its own directory). Where no server binary exists
the PostgreSQL tests skip, saying why. Also: real certificates from one simulated
calibration (first run and a recalibration of the same unit), produced once a session."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import sys
import tempfile
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from store_variants import SERIAL


@dataclass
class PostgresServer:
    """A throw-away PostgreSQL cluster: ``url(db)`` for SQLAlchemy, stop/start for outages."""

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
            raise RuntimeError(f"pg_ctl {args[0]} failed: {done.stderr}\n{log}")

    def start(self) -> None:
        options = (f"-p {self.port} -k {self.socket_dir} -c listen_addresses=127.0.0.1 "
                   "-c fsync=off -c full_page_writes=off -c max_connections=60")
        self._ctl("-l", str(self.socket_dir / "server.log"), "-o", options, "start")

    def stop(self) -> None:
        self._ctl("-m", "fast", "stop")

    def create_database(self) -> str:
        import psycopg

        name = f"t_{uuid.uuid4().hex[:12]}"
        with psycopg.connect(host="127.0.0.1", port=self.port, user="postgres",
                             dbname="postgres", autocommit=True) as connection:
            connection.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)


def _as_postgres(command: list[str]) -> list[str]:
    """PostgreSQL refuses to run as root: run its tools as the ``postgres`` user then."""
    return ["runuser", "-u", "postgres", "--", *command] if os.geteuid() == 0 else command


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _server_binaries() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"))
    return Path(found[-1]).parent if found else None


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    """One PostgreSQL server for the session (skips, with the reason, where none exists)."""
    bin_dir = _server_binaries()
    if bin_dir is None:
        pytest.skip("no PostgreSQL server binary (/usr/lib/postgresql/*/bin/pg_ctl): "
                    "apt-get install postgresql")
    if os.geteuid() == 0:
        if shutil.which("runuser") is None:
            pytest.skip("running as root without runuser: cannot start PostgreSQL as postgres")
        try:
            pwd.getpwnam("postgres")
        except KeyError:
            pytest.skip("running as root and no 'postgres' user to run PostgreSQL as")
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


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A fresh, empty store of each kind."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'store' / 'results.sqlite'}"
    server: PostgresServer = request.getfixturevalue("postgres")
    return server.create_database()


@pytest.fixture(scope="session")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``--out`` of two real simulated calibrations of one unit (the J/B/T_c protocol only,
    seeds 0 and 1): ``SERIAL/certificate.json`` and ``SERIAL/history/*/certificate.json``."""
    out = tmp_path_factory.mktemp("calibrated")
    script = (
        "import sys; from hil.cli import main\n"
        "for seed in ('0', '1'):\n"
        f"    code = main(['calibrate', '--drive', 'sim', '--unit-serial', '{SERIAL}',\n"
        f"                 '--out', r'{out}', '--seed', seed, '--store', 'off',\n"
        "                 '--operator', 'tester', '--', '-k', 'inertia_friction'])\n"
        "    assert code == 0, code\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          check=False, env={**os.environ, "PYTHONHASHSEED": "0"})
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return out
