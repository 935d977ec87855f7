"""Stores the tests use: a SQLite file, and a real PostgreSQL server the tests start
themselves (Debian's binaries, run as the ``postgres`` user when the tests run as root, on
127.0.0.1 and a free port, unix socket in its own directory). Where no server binary exists
the PostgreSQL tests skip, saying why. Also: real certificates from one simulated
calibration (first run and a recalibration of the same unit), produced once a session."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from pg_server import NoServerError, PostgresServer, temporary_server
from store_variants import SERIAL

from tests.helpers import subset_profile


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    """One PostgreSQL server for the session (skips, with the reason, where none exists)."""
    try:
        with temporary_server() as server:
            yield server
    except NoServerError as exc:
        pytest.skip(str(exc))


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
    seeds 0 and 1): ``SERIAL/certificate.json`` and ``SERIAL/history/*/certificate.json``.
    The first went to the default store (``results.sqlite`` there), the second to none."""
    out = tmp_path_factory.mktemp("calibrated")
    profile = subset_profile(tmp_path_factory.mktemp("profiles"), "inertia_friction")
    script = (
        "import sys; from hil.cli import main\n"
        "for seed, store in (('0', []), ('1', ['--store', 'off'])):\n"
        f"    code = main(['calibrate', '--drive', 'sim', '--unit-serial', '{SERIAL}',\n"
        f"                 '--out', r'{out}', '--seed', seed, *store,\n"
        f"                 '--operator', 'tester', '--profile', r'{profile}'])\n"
        "    assert code == 0, code\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          check=False, env={**os.environ, "PYTHONHASHSEED": "0"})
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return out
