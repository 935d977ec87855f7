"""Ingest certificates into the store: atomic (one transaction per run) and idempotent (keyed
by certificate id: the same certificate twice is one run, also when two stations race)."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy import Connection, func, insert, select
from sqlalchemy.exc import DBAPIError, IntegrityError

from hil.certificate.gimbal_file import GIMBAL_FILE
from hil.certificate.integrity import verify_document
from hil.errors import InputError
from hil.store.engine import Store, store_failure
from hil.store.gimbal_rows import gimbal_row, is_gimbal_certificate
from hil.store.rows import CertificateRows, certificate_rows
from hil.store.schema import gimbals, protocol_outcomes, recordings, results, runs

log = logging.getLogger(__name__)
CERTIFICATE_NAME = "certificate.json"
GIMBAL_RUN = "gimbal"  # the run id an ingested gimbal certificate reports (it has none)


@dataclass(frozen=True, slots=True)
class Ingested:
    """What one ingest did: ``new`` is False when the certificate was already stored."""

    certificate_id: str
    run_id: str
    serial: str
    new: bool


def ingest_certificate(store: Store, path: Path) -> Ingested:
    """Store the run of one ``certificate.json`` (nothing happens if it is stored already).

    Parameters
    ----------
    store : Store
        An open store (:func:`hil.store.open_store`).
    path : Path
        The certificate file.

    Returns
    -------
    Ingested

    Raises
    ------
    InputError
        The file is missing or not a valid certificate.
    StoreUnavailableError
        The database went away.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=str(path)) from None
    except UnicodeDecodeError as exc:
        raise InputError(f"not valid JSON: {exc}", source=str(path)) from None
    if is_gimbal_certificate(text):
        return _ingest_gimbal(store, text, source=str(path.resolve()), folder=path.parent)
    certificate_rows(text, source=str(path))  # its fields first: errors name the field
    _verify(text, path)
    return ingest_text(store, text, source=str(path.resolve()))


def _verify(text: str, path: Path) -> None:
    """Believe a certificate only once verified (digest, recordings' SHA-256, outcomes);
    one written before digests is stored with a warning.

    Raises
    ------
    InputError
        Naming the file and what is wrong.
    """
    verification = verify_document(json.loads(text), path=path, unit_dir=path.parent)
    if verification.refusals:
        raise InputError(verification.refusal(), source=str(path))
    for warning in verification.warnings:
        log.warning("%s: %s", path, warning)


def ingest_text(store: Store, text: str, *, source: str) -> Ingested:
    """Store a certificate given as its JSON text (see :func:`ingest_certificate`)."""
    if is_gimbal_certificate(text):
        return _ingest_gimbal(store, text, source=source, folder=None)
    rows = certificate_rows(text, source=source)
    run = rows.run
    done = Ingested(run["certificate_id"], run["run_id"], run["serial"], new=False)
    try:
        with store.engine.begin() as connection:
            if _stored(connection, run["certificate_id"]):
                return done
            _insert(connection, rows)
    except IntegrityError:  # another station stored the same certificate meanwhile
        with store.engine.connect() as connection:
            if _stored(connection, run["certificate_id"]):
                return done
        raise
    except DBAPIError as exc:  # down, locked past the timeout, a table gone, …
        raise store_failure(exc, store.url) from None
    log.info("stored run %s (%s)", run["run_id"], run["certificate_id"])
    return Ingested(run["certificate_id"], run["run_id"], run["serial"], new=True)


def ingest_tree(store: Store, directory: Path) -> list[Ingested]:
    """Ingest every certificate under ``directory``: a folder of serials, one serial's
    folder, with its ``history/`` (older runs first, so attempts count up in time order),
    or one ``certificate.json``.

    A certificate that cannot be read or verified (empty, edited, a recording changed or
    missing) is not stored and is named in a warning, one line; the others are stored.

    Raises
    ------
    InputError
        ``directory`` holds no certificate, or none that could be stored.
    """
    if directory.is_file():  # one certificate.json named directly
        return [ingest_certificate(store, directory)]
    if not directory.is_dir():
        raise InputError("not a directory", source=str(directory))
    paths = sorted(directory.rglob(CERTIFICATE_NAME))
    if not paths:
        raise InputError(f"no {CERTIFICATE_NAME} found under it", source=str(directory))
    texts, refused = [], []
    for path in paths:
        try:
            text = path.read_text(encoding="utf-8")
            started = certificate_rows(text, source=str(path)).run["started_at"]
            _verify(text, path)
        except (OSError, UnicodeDecodeError) as exc:
            refused.append(f"{path}: cannot read: {exc}")
        except InputError as exc:
            refused.append(str(exc))
        else:
            texts.append((started, str(path.resolve()), text))
            continue
        log.warning("not stored: %s", refused[-1])
    if not texts:
        more = f" (and {len(refused) - 1} more)" if len(refused) > 1 else ""
        raise InputError(f"no certificate under it could be stored: {refused[0]}{more}",
                         source=str(directory))
    texts.sort(key=lambda item: (item[0], item[1]))
    done = [ingest_text(store, text, source=source) for _, source, text in texts]
    for path in sorted(directory.rglob(GIMBAL_FILE)):  # a gimbal's verdict over its axes
        try:
            done.append(ingest_certificate(store, path))
        except InputError as exc:
            log.warning("not stored: %s", exc)
    return done


def _ingest_gimbal(store: Store, text: str, *, source: str, folder: Path | None) -> Ingested:
    """Store a gimbal certificate's row (nothing happens if it is stored already)."""
    row = gimbal_row(text, source=source, folder=folder)
    done = Ingested(row["certificate_id"], GIMBAL_RUN, row["serial"], new=False)
    try:
        with store.engine.begin() as connection:
            if connection.execute(select(gimbals.c.serial).where(
                    gimbals.c.certificate_id == row["certificate_id"])).first() is not None:
                return done
            connection.execute(insert(gimbals), [dict(row, ingested_at=datetime.now(UTC))])
    except IntegrityError:  # another station stored the same certificate meanwhile
        return done
    except DBAPIError as exc:
        raise store_failure(exc, store.url) from None
    log.info("stored gimbal %s (%s)", row["serial"], row["certificate_id"])
    return Ingested(row["certificate_id"], GIMBAL_RUN, row["serial"], new=True)


def _stored(connection: Connection, certificate_id: str) -> bool:
    found = connection.execute(
        select(runs.c.run_id).where(runs.c.certificate_id == certificate_id)
    ).first()
    return found is not None


def _insert(connection: Connection, rows: CertificateRows) -> None:
    run = dict(rows.run, ingested_at=datetime.now(UTC))
    if run["attempt"] is None:  # an old certificate: count this unit's axis's earlier runs
        earlier = connection.execute(
            select(func.count())
            .select_from(runs)
            .where(runs.c.serial == run["serial"], runs.c.axis == run["axis"],
                   runs.c.started_at < run["started_at"])
        ).scalar_one()
        run["attempt"] = int(earlier) + 1
    connection.execute(insert(runs), [run])
    for table, table_rows in (
        (protocol_outcomes, rows.protocols),
        (results, rows.results),
        (recordings, rows.recordings),
    ):
        if table_rows:
            connection.execute(insert(table), table_rows)
