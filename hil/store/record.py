"""After a calibration: store the run, or queue it in the outbox when the store cannot take
it. Never raises for a store problem: the certificate files are already written and the
run's outcome is not the store's to change."""

from __future__ import annotations

import logging
from pathlib import Path

from sqlalchemy.exc import SQLAlchemyError

from hil.errors import HilError
from hil.store.engine import StoreUnavailableError, open_store
from hil.store.ingest import ingest_certificate
from hil.store.outbox import pending, to_outbox

log = logging.getLogger(__name__)


def record_run(certificate: Path, *, out_dir: Path, url: str) -> str:
    """Ingest ``certificate`` into the store at ``url``; on failure queue it in the outbox.

    Parameters
    ----------
    certificate : Path
        The ``certificate.json`` the calibration wrote.
    out_dir : Path
        The calibration's ``--out`` (home of the outbox).
    url : str
        The store's URL (:func:`hil.store.resolve_store_url`).

    Returns
    -------
    str
        One line for the operator's console: where the run went.
    """
    try:
        store = open_store(url)
        try:
            done = ingest_certificate(store, certificate)
        finally:
            store.close()
    except (HilError, SQLAlchemyError, OSError) as exc:
        log.warning("results store failed: %s", exc)
        try:
            entry = to_outbox(out_dir, certificate)
        except OSError as outbox_exc:
            return (f"results store FAILED ({exc}) and the outbox too ({outbox_exc}); the "
                    f"certificate is kept at {certificate}: `gimbal-hil results ingest` it")
        what = "UNREACHABLE" if isinstance(exc, StoreUnavailableError) else "FAILED"
        return (f"results store {what} ({exc}); run kept in the outbox {entry}: "
                f"`gimbal-hil results sync --out {out_dir}` uploads it")
    waiting = len(pending(out_dir))
    later = f"; {waiting} earlier run(s) wait in the outbox: `gimbal-hil results sync`" \
        if waiting else ""
    return f"results store: run {done.run_id} stored in {store.url}{later}"
