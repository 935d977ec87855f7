"""Open the results store: which database, its engine, and its schema brought up to date.

The embedded default is a SQLite file in WAL mode under ``--out``; a production line points
every station at one PostgreSQL server (``--store postgresql://…``, the environment variable
``GIMBAL_HIL_STORE`` or ``store = "…"`` in the station file's ``[station]`` table). Opening
runs the shipped alembic migrations up to head, so an upgraded gimbal-hil keeps its data.
"""

from __future__ import annotations

import logging
import os
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError, OperationalError, ProgrammingError, SQLAlchemyError

from hil.errors import HilError, InputError

log = logging.getLogger(__name__)

ENV_VAR = "GIMBAL_HIL_STORE"
SQLITE_NAME = "results.sqlite"
HEAD_REVISION = "0003"  # the newest migration in migrations/versions (a test checks it)
SQLITE_BUSY_TIMEOUT_MS = 30_000  # a writer waits this long for another station's ingest
CONNECT_TIMEOUT_S = 5
WAL_SWITCH_POLL_S = 0.02
MIGRATIONS = Path(__file__).resolve().parent / "migrations"


class StoreUnavailableError(HilError):
    """The store cannot be reached or opened (server down, refused, unwritable file)."""


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
    """
    sources = (("--store", option), (f"${ENV_VAR}", os.environ.get(ENV_VAR)),
               ("the station file's [station] store", station_store))
    origin, chosen = next(((o, c) for o, c in sources if c), ("", None))
    if not chosen:
        return f"sqlite:///{(out_dir / SQLITE_NAME).resolve()}"
    if "://" not in chosen:
        return f"sqlite:///{Path(chosen).resolve()}"
    if chosen.startswith(("postgresql://", "postgres://")):
        chosen = "postgresql+psycopg://" + chosen.split("://", 1)[1]
    parse_store_url(chosen, source=origin)  # a bad URL is named by where it came from
    return chosen


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
    engine = _engine(parsed)
    shown = parsed.render_as_string(hide_password=True)
    try:
        if _revision(engine) != HEAD_REVISION:
            upgrade(engine)
    except OperationalError as exc:
        engine.dispose()
        reason = str(exc.orig).strip().splitlines()[0] if exc.orig else str(exc)
        raise StoreUnavailableError(f"results store {shown} unreachable: {reason}") from None
    except SQLAlchemyError as exc:
        engine.dispose()
        raise StoreUnavailableError(f"results store {shown}: {exc}") from None
    return Store(engine=engine, url=shown)


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
    """``url`` checked: SQLite or PostgreSQL (through psycopg 3); ``source`` names where it
    came from in an error.

    Raises
    ------
    InputError
        Not a URL, or another database.
    """
    try:
        parsed = make_url(url)
    except ArgumentError:
        raise InputError(f"not a database URL: {url!r}", source=source) from None
    if parsed.get_backend_name() not in ("sqlite", "postgresql"):
        raise InputError(
            f"store must be sqlite:///FILE or postgresql://…, got {parsed.drivername!r}",
            source=source,
        )
    if parsed.get_backend_name() == "postgresql" and parsed.get_driver_name() != "psycopg":
        parsed = parsed.set(drivername="postgresql+psycopg")
    return parsed


def _engine(url: URL) -> Engine:
    if url.get_backend_name() == "postgresql":
        return create_engine(
            url, pool_pre_ping=True, connect_args={"connect_timeout": CONNECT_TIMEOUT_S}
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
