"""The results store: every calibration run in a database (SQLite under ``--out`` by
default, PostgreSQL for a line), its migrations, ingest with an outbox, and the queries
the fleet statistics read. Imports no pytest."""

from hil.store.engine import Store, StoreUnavailableError, open_store, resolve_store_url
from hil.store.ingest import Ingested, ingest_certificate, ingest_tree
from hil.store.outbox import sync_outbox, to_outbox
from hil.store.query import StoredResult, load_baseline, result_series, save_baseline

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
