"""The store against careless and hostile input (issue 26, items 6, 8, 16 and the store's
tracebacks): a waiting run goes only to the store it was meant for; a URL that is not
``sqlite:///FILE`` or ``postgresql://…`` is one line and never shows its password; a store
locked by another client sends the run to the outbox within the stated timeout; a missing
table, a corrupt file, a refused password, two syncs at once and an unwritable export are
each one line of their own, exit 2, no traceback."""

from __future__ import annotations

import fcntl
import json
import multiprocessing
import os
import re
import shlex
import sqlite3
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from multiprocessing.synchronize import Barrier
from pathlib import Path

# loaded before pytester's in-process runs snapshot sys.modules (numpy's fft loads once)
import gimbal_hil_protocols.test_inertia_friction  # noqa: F401
import psycopg
import pytest
import sqlalchemy.dialects.postgresql  # noqa: F401  (and the store's dialect, once)
from pg_server import PostgresServer
from store_variants import SERIAL, variant

import hil.calibration_session
from hil.cli import main
from hil.store import open_store
from hil.store.engine import (
    ENV_VAR,
    PG_LOCK_TIMEOUT_MS,
    SQLITE_BUSY_TIMEOUT_MS,
    resolve_store_url,
    store_target,
)
from hil.store.outbox import SYNC_LOCK_NAME, outbox_dir, pending, to_outbox
from hil.store.query import history
from hil.store.record import record_run
from tests.helpers import subset_profile

pytestmark = pytest.mark.slow(seconds=30)  # scheduled early (conftest.py)

pytest_plugins = ["pytester"]

PASSWORD = "Sekrit-Pw-42"
RELEASE_S = 45.0  # the lock holder gives up after this (the old code waited for it)
MARGIN_S = 8.0  # a loaded CI machine: calibrate's store step may take this much longer


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["results", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _one_line_error(code: int, err: str) -> str:
    assert code == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    return err


def _pg(server: PostgresServer, database: str = "postgres") -> psycopg.Connection:
    return psycopg.connect(host="127.0.0.1", port=server.port, user="postgres",
                           dbname=database, autocommit=True)


# -- item 6: a waiting run goes to the store it was meant for ------------------------------


@pytest.mark.parametrize("with_password", [False, True], ids=["no-password", "password"])
def test_a_waiting_run_is_uploaded_only_to_the_store_it_was_meant_for(
    with_password: bool, postgres: PostgresServer, calibrated: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    name = f"late_{uuid.uuid4().hex[:10]}"  # not created yet: the store cannot take the run
    user = f"postgres:{PASSWORD}" if with_password else "postgres"
    given = f"postgresql://{user}@127.0.0.1:{postgres.port}/{name}"
    out = tmp_path / "certs"
    message = record_run(calibrated / SERIAL / "certificate.json", out_dir=out,
                         url=resolve_store_url(given, out_dir=out))
    assert PASSWORD not in message
    assert message.startswith("results store UNREACHABLE (")
    (entry,) = pending(out)
    assert PASSWORD not in entry.read_text(encoding="utf-8")
    meant = f"postgresql://postgres@127.0.0.1:{postgres.port}/{name}"
    assert json.loads(entry.read_text(encoding="utf-8"))["store"] == meant

    # the sync the old hint printed (no --store): refused, the run stays, no local store
    code, _, err = _run(capsys, "sync", "--out", str(out))
    assert f"meant for {meant}" in _one_line_error(code, err)
    assert pending(out) == [entry]
    assert not (out / "results.sqlite").exists()
    # another store named: refused too
    other = f"sqlite:///{tmp_path / 'other.sqlite'}"
    code, _, err = _run(capsys, "sync", "--out", str(out), "--store", other)
    assert f"meant for {meant}" in _one_line_error(code, err)
    assert pending(out) == [entry]

    # the server gets its database; the hint's command, as printed, uploads the run
    with _pg(postgres) as connection:
        connection.execute(f'CREATE DATABASE "{name}"')
    hint = re.search(r"`(gimbal-hil results sync [^`]*)`", message)
    assert hint is not None, message
    argv = shlex.split(hint[1])[1:]
    if with_password:  # a password is never printed: it goes through the environment
        assert f"${ENV_VAR}" in message
        assert "--store" not in argv
        monkeypatch.setenv(ENV_VAR, given)
    else:
        assert argv[-2:] == ["--store", meant]
    capsys.readouterr()
    assert main([*argv, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["new"] == 1
    assert pending(out) == []
    store = open_store(resolve_store_url(given, out_dir=out))
    try:
        assert [r.serial for r in history(store, SERIAL)] == [SERIAL]
    finally:
        store.close()


def test_an_entry_from_before_the_store_field_is_still_synced(
    calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    out = tmp_path / "certs"
    path = to_outbox(out, calibrated / SERIAL / "certificate.json")
    payload = json.loads(path.read_text(encoding="utf-8"))
    payload.pop("store")  # as an older gimbal-hil wrote it
    path.write_text(json.dumps(payload), encoding="utf-8")
    # and a half-written entry of a calibration finishing now is not one yet
    (outbox_dir(out) / ".incoming-x.json").write_text("{", encoding="utf-8")
    code, stdout, err = _run(capsys, "sync", "--out", str(out))
    assert (code, err) == (0, "")
    assert "sync: 1 run(s) stored" in stdout


# -- item 8: a URL that is not a store URL; no password anywhere ---------------------------


BAD_URLS = [
    ("postgresql:/postgres:secret-pw@127.0.0.1:5432/gimbal", "store must be sqlite:///FILE"),
    ("postgresql://u@[::1", "not a readable store URL"),
    ("postgresql://postgres:secret-pw@[::1:5432/gimbal", "not a readable store URL"),
    ("postgresql://postgres:secret-pw@db:99999/gimbal", "is not a TCP port"),
    ("sqlite://relative.sqlite", "three slashes"),
    ("postgresql+psycopg2://postgres:secret-pw@db/gimbal", "store must be sqlite:///FILE"),
]


@pytest.mark.parametrize(("url", "words"), BAD_URLS, ids=[u for u, _ in BAD_URLS])
@pytest.mark.parametrize("given_by", ["--store", "env", "station file"])
@pytest.mark.parametrize("command", ["units", "sync"])
def test_a_url_that_is_not_a_store_url_is_one_line_without_its_password(
    url: str, words: str, given_by: str, command: str, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    here = tmp_path / "cwd"
    here.mkdir()
    monkeypatch.chdir(here)
    monkeypatch.delenv(ENV_VAR, raising=False)
    args = ["--out", str(tmp_path / "out")]
    if given_by == "--store":
        args += ["--store", url]
    elif given_by == "env":
        monkeypatch.setenv(ENV_VAR, url)
    else:
        station = tmp_path / "station.toml"
        station.write_text(f'[station]\nid = "ST-1"\nstore = "{url}"\n', encoding="utf-8")
        args += ["--station-file", str(station)]
    code, out, err = _run(capsys, command, *args)
    assert words in _one_line_error(code, err)
    assert "secret-pw" not in out + err
    assert list(here.iterdir()) == []  # no folder named after the URL (or its password)
    assert not (tmp_path / "out").exists()


def test_calibrate_refuses_a_one_slash_url_before_motion_without_its_password(
    pytester: pytest.Pytester, tmp_path: Path
) -> None:
    here = tmp_path / "cwd"
    here.mkdir()
    os.chdir(here)  # pytester restores the directory
    result = pytester.runpytest_inprocess(
        "--profile", str(subset_profile(tmp_path, "inertia_friction")),
        "--pyargs", "gimbal_hil_protocols.test_inertia_friction", "-p", "no:cacheprovider",
        "--out", str(tmp_path / "out"), "--store", "postgresql:/postgres:secret-pw@db/gimbal",
    )
    said = "\n".join(result.outlines + result.errlines)
    assert result.ret == pytest.ExitCode.USAGE_ERROR, said
    assert "store must be sqlite:///FILE" in said
    assert "secret-pw" not in said
    assert list(here.iterdir()) == []


# -- item 16: a locked store ---------------------------------------------------------------


@contextmanager
def _locked(url: str, postgres: PostgresServer | None) -> Iterator[None]:
    """Another client holds the store: PostgreSQL, ACCESS EXCLUSIVE on ``runs`` in an open
    transaction; SQLite, an open write transaction. Released on leaving, or after
    :data:`RELEASE_S` (so that code without timeouts finishes, late)."""
    open_store(url).close()  # the store exists, at head
    release: Callable[[], object]
    if postgres is not None:
        pg = psycopg.connect(host="127.0.0.1", port=postgres.port, user="postgres",
                             dbname=url.rsplit("/", 1)[1])
        pg.execute("LOCK TABLE runs IN ACCESS EXCLUSIVE MODE")
        release = pg.rollback
    else:
        lite = sqlite3.connect(url.removeprefix("sqlite:///"), isolation_level=None,
                               check_same_thread=False)
        lite.execute("BEGIN IMMEDIATE")

        def release() -> None:
            lite.execute("ROLLBACK")

    done = threading.Lock()

    def once() -> None:
        with done:
            if getattr(once, "ran", False):
                return
            once.ran = True  # type: ignore[attr-defined]
            release()

    timer = threading.Timer(RELEASE_S, once)
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        once()
        (pg if postgres is not None else lite).close()


def test_a_locked_store_sends_calibrates_run_to_the_outbox_within_the_timeout(
    store_url: str, pytester: pytest.Pytester, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest,
) -> None:
    postgres = (request.getfixturevalue("postgres") if store_url.startswith("postgresql")
                else None)
    timeout_s = (PG_LOCK_TIMEOUT_MS if postgres else SQLITE_BUSY_TIMEOUT_MS) / 1000
    took: list[float] = []
    real = hil.calibration_session.record_run

    def timed(certificate: Path, *, out_dir: Path, url: str) -> str:
        start = time.monotonic()
        try:
            return real(certificate, out_dir=out_dir, url=url)
        finally:
            took.append(time.monotonic() - start)

    monkeypatch.setattr(hil.calibration_session, "record_run", timed)
    out = tmp_path / "certs"
    with _locked(store_url, postgres):
        result = pytester.runpytest_inprocess(
            "--profile", str(subset_profile(pytester.path, "inertia_friction")),
            "--pyargs", "gimbal_hil_protocols.test_inertia_friction", "-p",
            "no:cacheprovider", "--out", str(out), "--unit-serial", "LOCK-1",
            "--store", store_url,
        )
    assert result.ret == 0
    (line,) = [x for x in result.outlines if x.startswith("results store")]
    assert line.startswith("results store TIMED OUT ("), line
    assert f"held a lock for more than {timeout_s:g} s" in line
    assert "run kept in the outbox" in line
    (seconds,) = took
    assert 0.8 * timeout_s <= seconds <= timeout_s + MARGIN_S, seconds
    (entry,) = pending(out)
    certificate = json.loads((out / "LOCK-1" / "certificate.json").read_text(encoding="utf-8"))
    assert entry.name == f"{certificate['certificate_id']}.json"
    assert certificate["outcome"] == "PASS"


# -- each failure its own words ------------------------------------------------------------


def test_a_corrupt_file_is_named_corrupt(calibrated: Path, tmp_path: Path) -> None:
    store = tmp_path / "results.sqlite"
    store.write_bytes(b"this is no database\n" * 200)
    message = record_run(calibrated / SERIAL / "certificate.json", out_dir=tmp_path,
                         url=f"sqlite:///{store}")
    assert message.startswith("results store CORRUPT (")
    assert "corrupt or not a database" in message
    assert len(pending(tmp_path)) == 1


def _drop_table(url: str, table: str, postgres: PostgresServer | None) -> None:
    open_store(url).close()
    if postgres is None:
        with sqlite3.connect(url.removeprefix("sqlite:///")) as lite:
            lite.execute(f"DROP TABLE {table}")
        return
    with _pg(postgres, url.rsplit("/", 1)[1]) as connection:
        connection.execute(f"DROP TABLE {table} CASCADE")


def test_a_missing_table_is_named_and_the_run_waits(
    store_url: str, calibrated: Path, tmp_path: Path, request: pytest.FixtureRequest,
) -> None:
    postgres = (request.getfixturevalue("postgres") if store_url.startswith("postgresql")
                else None)
    _drop_table(store_url, "recordings", postgres)
    message = record_run(calibrated / SERIAL / "certificate.json", out_dir=tmp_path,
                         url=store_url)
    assert message.startswith("results store MISSING TABLE ("), message
    assert "recordings" in message
    assert len(pending(tmp_path)) == 1


@pytest.mark.parametrize("command", [
    ("history", SERIAL), ("trend", "inertia_kg_m2"), ("spc", "inertia_kg_m2"),
    ("export", "inertia_kg_m2", "--output", "{tmp}/x.csv"), ("units",),
])
def test_reading_a_store_missing_a_table_is_one_line(
    command: tuple[str, ...], store_url: str, calibrated: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], request: pytest.FixtureRequest,
) -> None:
    postgres = (request.getfixturevalue("postgres") if store_url.startswith("postgresql")
                else None)
    assert _run(capsys, "ingest", str(calibrated), "--store", store_url)[0] == 0
    _drop_table(store_url, "results", postgres)
    args = [a.replace("{tmp}", str(tmp_path)) for a in command]
    code, out, err = _run(capsys, *args, "--store", store_url)
    assert "missing table(s) results" in _one_line_error(code, err)
    assert out == ""


def test_a_refused_password_is_named_and_never_shown(
    postgres: PostgresServer, calibrated: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    role = "gimbal_pw"
    hba = postgres.data_dir / "pg_hba.conf"
    before = hba.read_text(encoding="utf-8")
    # this one role must give a password (the test server trusts everyone else)
    hba.write_text(f"host all {role} 127.0.0.1/32 scram-sha-256\n{before}", encoding="utf-8")
    try:
        with _pg(postgres) as connection:
            connection.execute(f"DROP ROLE IF EXISTS {role}")
            connection.execute(f"CREATE ROLE {role} LOGIN PASSWORD 'the-right-one'")
            connection.execute("SELECT pg_reload_conf()")
        time.sleep(0.5)  # the postmaster rereads pg_hba.conf on SIGHUP
        url = f"postgresql://{role}:{PASSWORD}@127.0.0.1:{postgres.port}/postgres"
        message = record_run(calibrated / SERIAL / "certificate.json", out_dir=tmp_path,
                             url=resolve_store_url(url, out_dir=tmp_path))
        assert message.startswith("results store AUTHENTICATION FAILED ("), message
        assert "refused the user or password" in message
        assert PASSWORD not in message
        assert len(pending(tmp_path)) == 1
        code, out, err = _run(capsys, "units", "--store", url)
        assert "refused the user or password" in _one_line_error(code, err)
        assert PASSWORD not in out + err
    finally:
        hba.write_text(before, encoding="utf-8")
        with _pg(postgres) as connection:
            connection.execute("SELECT pg_reload_conf()")


# -- two syncs at once; an unwritable export -----------------------------------------------


def _sync(argv: list[str], log: Path, barrier: Barrier) -> None:
    with log.open("w", encoding="utf-8") as stream:
        sys.stdout = sys.stderr = stream
        barrier.wait()
        try:
            code = main(argv)
        except BaseException:  # a traceback reaching the user: written, exit 1
            import traceback

            traceback.print_exc()
            code = 1
        stream.flush()
    os._exit(code)


def test_two_syncs_at_once_upload_each_run_once_and_the_loser_says_so(
    store_url: str, calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "certs"
    text = (calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8")
    ids = set()
    for k in range(24):
        path = tmp_path / "made" / f"S-{k}" / "certificate.json"
        path.parent.mkdir(parents=True)
        path.write_text(variant(text, serial=f"S-{k}", index=k), encoding="utf-8")
        to_outbox(out, path, store=store_target(store_url))
        ids.add(json.loads(path.read_text(encoding="utf-8"))["certificate_id"])
    open_store(store_url).close()

    # a sync in progress (it holds the outbox's lock): a second one is refused, one line
    with (outbox_dir(out) / SYNC_LOCK_NAME).open("a") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)
        code, _, err = _run(capsys, "sync", "--out", str(out), "--store", store_url)
    assert "another 'gimbal-hil results sync'" in _one_line_error(code, err)
    assert len(pending(out)) == 24

    # and two real ones released together
    context = multiprocessing.get_context("fork")
    barrier = context.Barrier(2)
    argv = ["results", "sync", "--out", str(out), "--store", store_url]
    logs = [tmp_path / f"sync{i}.log" for i in range(2)]
    workers = [context.Process(target=_sync, args=(argv, log, barrier)) for log in logs]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    said = [log.read_text(encoding="utf-8") for log in logs]
    for worker, text_said in zip(workers, said, strict=True):
        assert "Traceback" not in text_said, text_said
        assert worker.exitcode in (0, 2), text_said
        if worker.exitcode == 2:
            assert len(text_said.strip().splitlines()) == 1, text_said
    assert pending(out) == []
    store = open_store(store_url)
    try:
        from sqlalchemy import select

        from hil.store.schema import runs

        with store.engine.connect() as connection:
            stored = list(connection.execute(select(runs.c.certificate_id)).scalars())
    finally:
        store.close()
    assert sorted(stored) == sorted(ids)


def test_an_export_to_an_unwritable_path_is_one_line(
    calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    store = ["--out", str(tmp_path)]
    assert _run(capsys, "ingest", str(calibrated), *store)[0] == 0
    folder = tmp_path / "a-folder"
    folder.mkdir()
    code, _, err = _run(capsys, "export", "inertia_kg_m2", "--output", str(folder), *store)
    assert f"{folder}: cannot write" in _one_line_error(code, err)
    code, _, err = _run(capsys, "report", "--html", str(folder), *store)
    assert f"{folder}: cannot write" in _one_line_error(code, err)
