"""After a calibration: store the run, or queue it in the outbox when the store cannot take
it. Never raises for a store problem: the certificate files are already written and the
run's outcome is not the store's to change.

The store's timeouts (:mod:`hil.store.engine`) bound how long this can keep the end of
``calibrate`` waiting; past them the run goes to the outbox, the line printed says why and
which command uploads it to the store it was meant for (never a password)."""

from __future__ import annotations

import logging
import shlex
from pathlib import Path

from sqlalchemy.exc import SQLAlchemyError

from hil.errors import HilError
from hil.store.engine import (
    ENV_VAR,
    StoreUnavailableError,
    default_store_url,
    mask_password,
    open_store,
    parse_store_url,
    store_failure,
    store_target,
)
from hil.store.ingest import GIMBAL_RUN, ingest_certificate
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
        One line for the operator's console: where the run went (no password).
    """
    try:
        store = open_store(url)
        try:
            done = ingest_certificate(store, certificate)
        finally:
            store.close()
    except (HilError, SQLAlchemyError, OSError) as exc:
        failure: BaseException = exc
        if isinstance(exc, SQLAlchemyError):
            failure = store_failure(exc, _shown(url), url=url)
        said = mask_password(str(failure), url)
        log.warning("results store failed: %s", said)
        try:
            entry = to_outbox(out_dir, certificate, store=_target(url))
        except OSError as outbox_exc:
            return (f"results store FAILED ({said}) and the outbox too ({outbox_exc}); the "
                    f"certificate is kept at {certificate}: `gimbal-hil results ingest` it")
        what = failure.what if isinstance(failure, StoreUnavailableError) else "FAILED"
        return (f"results store {what} ({said}); run kept in the outbox {entry}: "
                f"{sync_hint(out_dir, url)} uploads it")
    waiting = len(pending(out_dir))
    later = (f"; {waiting} earlier run(s) wait in the outbox: {sync_hint(out_dir, url)}"
             if waiting else "")
    what = "gimbal certificate" if done.run_id == GIMBAL_RUN else f"run {done.run_id}"
    return f"results store: {what} stored in {store.url}{later}"


def sync_hint(out_dir: Path, url: str) -> str:
    """The command that uploads ``out_dir``'s waiting runs to the store at ``url``: with
    ``--store`` unless it is ``out_dir``'s own SQLite file; a URL with a password is named
    masked, the password to be given through ``$GIMBAL_HIL_STORE`` or the station file."""
    command = f"gimbal-hil results sync --out {shlex.quote(str(out_dir))}"
    target = _target(url)
    if target is None or target == _target(default_store_url(out_dir)):
        return f"`{command}`"
    if _has_password(url):
        return (f"`{command}` with ${ENV_VAR} (or the station file's [station] store, "
                f"--station-file) set to {_shown(url)}, the password in place of ***")
    return f"`{command} --store {shlex.quote(target)}`"


def _target(url: str) -> str | None:
    try:
        return store_target(url)
    except HilError:
        return None


def _shown(url: str) -> str:
    try:
        parsed = parse_store_url(url)
        return parsed.set(drivername=parsed.get_backend_name()).render_as_string(
            hide_password=True)
    except HilError:
        return mask_password(url, url)


def _has_password(url: str) -> bool:
    try:
        return bool(parse_store_url(url).password)
    except HilError:
        return False
