"""Open the results store: which database, its engine, and its schema brought up to date.

The embedded default is a SQLite file in WAL mode under ``--out``; a production line points
every station at one PostgreSQL server (``--store postgresql://…``, the environment variable
``GIMBAL_HIL_STORE`` or ``store = "…"`` in the station file's ``[station]`` table). Opening
runs the shipped alembic migrations up to head, so an upgraded gimbal-hil keeps its data.
"""

from __future__ import annotations

import logging
import os
import re
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import quote

from sqlalchemy import Engine, create_engine, event, inspect, text
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError, OperationalError, ProgrammingError, SQLAlchemyError

from hil.errors import HilError, InputError

log = logging.getLogger(__name__)

ENV_VAR = "GIMBAL_HIL_STORE"
SQLITE_NAME = "results.sqlite"
HEAD_REVISION = "0004"  # the newest migration in migrations/versions (a test checks it)
# How long a store may keep a calibration waiting (docs/store.md): past these, the run goes
# to the outbox with one line saying why, instead of hanging the end of `calibrate`.
SQLITE_BUSY_TIMEOUT_MS = 10_000  # a writer waits this long for another client's write lock
PG_LOCK_TIMEOUT_MS = 10_000  # a statement waits this long for a lock another client holds
PG_STATEMENT_TIMEOUT_MS = 60_000  # and runs this long at most (migrations: no limit)
CONNECT_TIMEOUT_S = 5
WAL_SWITCH_POLL_S = 0.02
MIGRATIONS = Path(__file__).resolve().parent / "migrations"
STORE_FORMS = "sqlite:///FILE or postgresql://USER@HOST[:PORT]/DB"
MASK = "***"
# "scheme:" at the start of a --store value: a URL, not a file path (a drive letter is)
_SCHEME = re.compile(r"^(?P<scheme>[A-Za-z][A-Za-z0-9+.\-]+):")
# "scheme:[//]user:PASSWORD@" anywhere in a text, however few slashes
_USERINFO = re.compile(r"(?P<head>[A-Za-z][A-Za-z0-9+.\-]*:/*[^\s/:@'\"]*):[^\s@'\"]*@")
_POSTGRES_SCHEMES = ("postgresql", "postgresql+psycopg", "postgres")
MIN_MASKED_PASSWORD = 4  # a shorter password is masked only inside URLs (not every "a")


class StoreUnavailableError(HilError):
    """The store cannot be reached or opened (server down, refused, unwritable file).

    ``what`` is the word ``calibrate`` prints for it; the subclasses below say more.
    """

    what = "UNREACHABLE"


class StoreAuthenticationError(StoreUnavailableError):
    """The server refused the user or password."""

    what = "AUTHENTICATION FAILED"


class StoreCorruptError(StoreUnavailableError):
    """The SQLite file is not a database or is damaged."""

    what = "CORRUPT"


class StoreSchemaError(StoreUnavailableError):
    """A table of the store is missing (damaged, or not gimbal-hil's database)."""

    what = "MISSING TABLE"


class StoreTimeoutError(StoreUnavailableError):
    """Another client held a lock past the lock/busy timeout, or a statement ran too long."""

    what = "TIMED OUT"


@dataclass(frozen=True, slots=True)
class Store:
    """An open results store.

    Attributes
    ----------
    engine : Engine
        SQLAlchemy engine (SQLite or PostgreSQL).
    url : str
        The URL it was opened with, password hidden (for messages).
    """

    engine: Engine
    url: str
    target: str = ""  # :func:`store_target`: which store this is (outbox entries name it)

    @property
    def dialect(self) -> str:
        """``"sqlite"`` or ``"postgresql"``."""
        return self.engine.dialect.name

    def close(self) -> None:
        """Release the engine's connections."""
        self.engine.dispose()


def resolve_store_url(
    option: str | None, *, out_dir: Path, station_store: str | None = None
) -> str:
    """The store a command uses: ``--store``, else ``$GIMBAL_HIL_STORE``, else the station
    file's ``store``, else ``sqlite:///<out_dir>/results.sqlite``.

    Parameters
    ----------
    option : str or None
        The ``--store`` value: a URL, or a path to a SQLite file.
    out_dir : Path
        The ``--out`` directory (home of the embedded SQLite file).
    station_store : str or None
        The station file's ``[station] store`` key.

    Returns
    -------
    str
        A SQLAlchemy URL (``postgresql://`` becomes ``postgresql+psycopg://``).

    Raises
    ------
    InputError
        A URL other than ``sqlite:///FILE`` or ``postgresql://…`` (one line, password
        masked, naming where it came from).
    """
    sources = (("--store", option), (f"${ENV_VAR}", os.environ.get(ENV_VAR)),
               ("the station file's [station] store", station_store))
    origin, chosen = next(((o, c) for o, c in sources if c), ("", None))
    if not chosen:
        return default_store_url(out_dir)
    scheme = _SCHEME.match(chosen)
    if scheme is None:  # a plain path (a one-letter "C:" is a drive, not a scheme)
        return f"sqlite:///{Path(chosen).resolve()}"
    parse_store_url(chosen, source=origin)  # a bad URL is named by where it came from
    if scheme["scheme"].lower() in _POSTGRES_SCHEMES:
        chosen = "postgresql+psycopg://" + chosen.split("://", 1)[1]
    return chosen


def default_store_url(out_dir: Path) -> str:
    """The embedded store of ``out_dir``: ``sqlite:///<out_dir>/results.sqlite``."""
    return f"sqlite:///{(out_dir / SQLITE_NAME).resolve()}"


def mask_password(message: str, url: str | None = None) -> str:
    """``message`` with every ``user:password@`` of a URL in it, and ``url``'s password
    wherever it appears, shown as ``***``."""
    masked = _USERINFO.sub(lambda m: f"{m['head']}:{MASK}@", message)
    password = _password(url) if url else None
    if password and len(password) >= MIN_MASKED_PASSWORD:
        for form in {password, quote(password, safe="")}:
            masked = masked.replace(form, MASK)
    return masked


def _password(url: str) -> str | None:
    try:
        found = make_url(url).password
    except (ArgumentError, ValueError):
        return None
    return None if found is None else str(found)


def store_target(url: str) -> str:
    """Which store ``url`` is, without its password: ``postgresql://user@host:port/db`` or
    ``sqlite:///ABSOLUTE-PATH`` (what an outbox entry records and ``results sync``
    compares)."""
    parsed = parse_store_url(url)
    if parsed.get_backend_name() == "sqlite":
        return f"sqlite:///{Path(str(parsed.database)).resolve()}"
    bare = URL.create("postgresql", username=parsed.username, host=parsed.host,
                      port=parsed.port, database=parsed.database, query=parsed.query)
    return bare.render_as_string(hide_password=False)


def same_store(a: str, b: str) -> bool:
    """Whether two targets (:func:`store_target`) name one store (port 5432 is the
    default, host names compared without case)."""
    try:
        first, second = make_url(a), make_url(b)
    except (ArgumentError, ValueError):
        return a == b

    def key(u: URL) -> tuple[object, ...]:
        if u.get_backend_name() == "sqlite":
            return ("sqlite", u.database)
        return ("postgresql", u.username, (u.host or "").lower(), u.port or 5432, u.database,
                tuple(sorted(u.query.items())))

    return key(first) == key(second)


def open_store(url: str) -> Store:
    """Open the store at ``url`` and migrate its schema to head.

    Parameters
    ----------
    url : str
        ``sqlite:///PATH`` or ``postgresql+psycopg://user@host:port/db`` (see
        :func:`resolve_store_url`).

    Returns
    -------
    Store

    Raises
    ------
    InputError
        The URL is not one gimbal-hil can use.
    StoreUnavailableError
        The database cannot be reached or opened.
    """
    parsed = parse_store_url(url)
    shown = parsed.render_as_string(hide_password=True)
    try:
        engine = _engine(parsed)
    except OSError as exc:  # the SQLite file's folder cannot be made
        raise StoreUnavailableError(
            f"results store {shown}: cannot create its folder: {exc.strerror}") from None
    try:
        if _revision(engine) != HEAD_REVISION:
            upgrade(engine)
        _check_tables(engine, shown)
    except SQLAlchemyError as exc:
        engine.dispose()
        raise store_failure(exc, shown, url=url) from None
    except StoreUnavailableError:
        engine.dispose()
        raise
    return Store(engine=engine, url=shown, target=store_target(url))


def store_failure(exc: BaseException, shown: str, *, url: str | None = None
                  ) -> StoreUnavailableError:
    """The error to raise for a database error ``exc`` of the store ``shown``: one line,
    password masked, its class saying what went wrong (refused login, corrupt file, missing
    table, a lock or statement timeout, else unreachable)."""
    orig = getattr(exc, "orig", None) or exc
    lines = str(orig).strip().splitlines()
    reason = mask_password(lines[0] if lines else type(orig).__name__, url)
    state = str(getattr(orig, "sqlstate", "") or "")
    low = reason.lower()
    if state.startswith("28") or "authentication failed" in low or "no password" in low:
        return StoreAuthenticationError(
            f"results store {shown}: the server refused the user or password ({reason})")
    if "not a database" in low or "malformed" in low or state in ("XX001", "XX002"):
        return StoreCorruptError(
            f"results store {shown} is corrupt or not a database ({reason}); restore it "
            "from a backup")
    if state == "42P01" or "no such table" in low or (
            "does not exist" in low and ("relation" in low or "table" in low)):
        return StoreSchemaError(
            f"results store {shown} is missing a table ({reason}): damaged or not "
            "gimbal-hil's store; restore it from a backup")
    if state == "55P03" or "lock timeout" in low or "database is locked" in low:
        wait = (SQLITE_BUSY_TIMEOUT_MS if "database is locked" in low else
                PG_LOCK_TIMEOUT_MS) / 1000
        return StoreTimeoutError(
            f"results store {shown} timed out: another client held a lock for more than "
            f"{wait:g} s ({reason})")
    if state == "57014" or "statement timeout" in low:
        return StoreTimeoutError(
            f"results store {shown} timed out: a statement ran longer than "
            f"{PG_STATEMENT_TIMEOUT_MS / 1000:g} s ({reason})")
    return StoreUnavailableError(f"results store {shown} unreachable: {reason}")


def _check_tables(engine: Engine, shown: str) -> None:
    """Every table of the schema is there (a store at head may have lost one)."""
    from hil.store.schema import metadata

    with engine.connect() as connection:
        try:
            present = set(inspect(connection).get_table_names())
        finally:
            connection.rollback()
    missing = sorted(set(metadata.tables) - present)
    if missing:
        raise StoreSchemaError(
            f"results store {shown} is missing table(s) {', '.join(missing)}: damaged or "
            "not gimbal-hil's store; restore it from a backup")


def upgrade(engine: Engine, revision: str = "head") -> None:
    """Run the shipped migrations up to ``revision`` (one migrator at a time)."""
    from alembic import command
    from alembic.config import Config

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    # one transaction around all of it (SQLite: BEGIN IMMEDIATE), the version read included:
    # alembic's own per-migration transactions on SQLite would let two stations both
    # start from an empty database
    with engine.connect() as connection, connection.begin():
        if engine.dialect.name == "postgresql":  # a migration must finish; locks still time out
            connection.exec_driver_sql("SET LOCAL statement_timeout = 0")
        config.attributes["connection"] = connection
        command.upgrade(config, revision)


def _revision(engine: Engine) -> str | None:
    """The schema revision stamped in the database, ``None`` for a new one."""
    with engine.connect() as connection:
        try:
            row = connection.execute(text("SELECT version_num FROM alembic_version")).first()
        except (OperationalError, ProgrammingError) as exc:
            if "alembic_version" not in str(exc):  # not "no such table": unreachable
                raise
            return None
        finally:
            connection.rollback()
    return None if row is None else str(row[0])


def parse_store_url(url: str, *, source: str = "--store") -> URL:
    """``url`` checked: exactly ``sqlite:///FILE`` or ``postgresql://…`` (also
    ``postgresql+psycopg://`` and ``postgres://``), for psycopg 3; ``source`` names where it
    came from in an error.

    Raises
    ------
    InputError
        Anything else, one line, its password masked.
    """
    shown = mask_password(url, url)
    scheme = _SCHEME.match(url)
    name = scheme["scheme"].lower() if scheme else ""
    rest = url[scheme.end():] if scheme else ""
    if name not in ("sqlite", *_POSTGRES_SCHEMES) or not rest.startswith("//"):
        raise InputError(f"store must be {STORE_FORMS}, got {shown!r}", source=source)
    try:
        parsed = make_url(url)
        port = parsed.port  # a bad port or "[::1" without "]" fails here
    except (ArgumentError, ValueError):
        raise InputError(f"not a readable store URL (host, port or brackets): {shown!r}; "
                         f"a store is {STORE_FORMS}", source=source) from None
    if name == "sqlite":
        if not rest.startswith("///") or parsed.database in (None, "", ":memory:"):
            raise InputError(f"store must be {STORE_FORMS} (a file: three slashes, then its "
                             f"path), got {shown!r}", source=source)
        return parsed
    if port is not None and not 0 < port < 2**16:
        raise InputError(f"store port {port} is not a TCP port (1-65535): {shown!r}",
                         source=source)
    return parsed.set(drivername="postgresql+psycopg")


def _engine(url: URL) -> Engine:
    if url.get_backend_name() == "postgresql":
        # the URL's own ?options=… kept, the timeouts added (the later -c wins)
        options = " ".join(filter(None, (
            str(url.query.get("options", "")),
            f"-c lock_timeout={PG_LOCK_TIMEOUT_MS}",
            f"-c statement_timeout={PG_STATEMENT_TIMEOUT_MS}")))
        return create_engine(
            url.difference_update_query(["options"]), pool_pre_ping=True,
            connect_args={"connect_timeout": CONNECT_TIMEOUT_S, "options": options},
        )
    if url.database:
        Path(url.database).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url, connect_args={"timeout": SQLITE_BUSY_TIMEOUT_MS / 1000})
    event.listen(engine, "connect", _sqlite_connect)
    event.listen(engine, "begin", _sqlite_begin)
    return engine


def _sqlite_connect(dbapi_connection: Any, _record: Any) -> None:
    # transactions are ours (BEGIN IMMEDIATE below), not the driver's deferred ones: a
    # deferred reader upgrading to writer under WAL gets SQLITE_BUSY without waiting
    dbapi_connection.isolation_level = None
    cursor = dbapi_connection.cursor()
    cursor.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
    _switch_to_wal(cursor)
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.close()


def _switch_to_wal(cursor: Any) -> None:
    """Put the database in WAL mode (it stays so, in the file). SQLite answers the switch
    with SQLITE_BUSY at once, without its busy handler, while another connection holds the
    file (stations opening a new store together), so the wait is ours, as long as the
    busy timeout."""
    if str(cursor.execute("PRAGMA journal_mode").fetchone()[0]).lower() == "wal":
        return
    deadline = time.monotonic() + SQLITE_BUSY_TIMEOUT_MS / 1000
    while True:
        try:
            cursor.execute("PRAGMA journal_mode=WAL")
            return
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() > deadline:
                raise
        time.sleep(WAL_SWITCH_POLL_S)


def _sqlite_begin(connection: Any) -> None:
    connection.exec_driver_sql("BEGIN IMMEDIATE")
