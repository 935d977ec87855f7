"""The results store: every calibration run in a database (SQLite under ``--out`` by
default, PostgreSQL for a line), its migrations, ingest with an outbox, and the queries
the fleet statistics read. Imports no pytest.

The names below load on first use (PEP 562), so that importing :mod:`hil.store.cli` for its
arguments (``gimbal-hil --help``) does not load SQLAlchemy."""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from hil.store.engine import Store, StoreUnavailableError, open_store, resolve_store_url
    from hil.store.ingest import Ingested, ingest_certificate, ingest_tree
    from hil.store.outbox import sync_outbox, to_outbox
    from hil.store.query import StoredResult, load_baseline, result_series, save_baseline

_HOME = {"Store": "engine", "StoreUnavailableError": "engine", "open_store": "engine",
         "resolve_store_url": "engine", "Ingested": "ingest",
         "ingest_certificate": "ingest", "ingest_tree": "ingest", "sync_outbox": "outbox",
         "to_outbox": "outbox", "StoredResult": "query", "load_baseline": "query",
         "result_series": "query", "save_baseline": "query"}

__all__ = [
    "Ingested",
    "Store",
    "StoreUnavailableError",
    "StoredResult",
    "ingest_certificate",
    "ingest_tree",
    "load_baseline",
    "open_store",
    "resolve_store_url",
    "result_series",
    "save_baseline",
    "sync_outbox",
    "to_outbox",
]


def __getattr__(name: str) -> Any:
    if name not in _HOME:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{_HOME[name]}"), name)
