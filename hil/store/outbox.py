"""The local outbox: a run the store could not take waits here, as its certificate's exact
text, until ``gimbal-hil results sync`` uploads it. Files are written atomically and removed
only after the store holds the run."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from hil.errors import InputError
from hil.store.engine import Store
from hil.store.ingest import Ingested, ingest_text

OUTBOX_NAME = "outbox"


def outbox_dir(out_dir: Path) -> Path:
    """``<out>/outbox``: where runs wait for the store."""
    return out_dir / OUTBOX_NAME


def to_outbox(out_dir: Path, certificate: Path) -> Path:
    """Queue ``certificate`` for a later sync.

    Parameters
    ----------
    out_dir : Path
        The calibration's ``--out`` directory.
    certificate : Path
        The ``certificate.json`` just written.

    Returns
    -------
    Path
        The outbox entry (``<out>/outbox/<certificate id>.json``).
    """
    text = certificate.read_text(encoding="utf-8")
    certificate_id = str(json.loads(text)["certificate_id"])
    entry = {"certificate_path": str(certificate.resolve()), "certificate_text": text}
    folder = outbox_dir(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / f"{certificate_id}.json"
    handle, temporary = tempfile.mkstemp(dir=folder, prefix=".incoming-", suffix=".json")
    with os.fdopen(handle, "w", encoding="utf-8") as stream:
        json.dump(entry, stream)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(temporary, target)
    return target


def pending(out_dir: Path) -> list[Path]:
    """The runs waiting in ``out_dir``'s outbox, oldest name first."""
    folder = outbox_dir(out_dir)
    return sorted(folder.glob("*.json")) if folder.is_dir() else []


def sync_outbox(store: Store, out_dir: Path) -> list[Ingested]:
    """Upload every waiting run; each entry is removed once the store holds its run.

    Raises
    ------
    InputError
        An entry that is not an outbox entry (naming it; the others are still synced first).
    StoreUnavailableError
        The store went away (entries not yet uploaded stay).
    """
    done: list[Ingested] = []
    bad: list[str] = []
    for entry in pending(out_dir):
        try:
            payload = json.loads(entry.read_text(encoding="utf-8"))
            text, source = str(payload["certificate_text"]), str(payload["certificate_path"])
        except (OSError, ValueError, KeyError, TypeError):
            bad.append(str(entry))
            continue
        try:
            done.append(ingest_text(store, text, source=source))
        except InputError:  # not a valid certificate: kept for a person to look at
            bad.append(str(entry))
            continue
        entry.unlink()
    if bad:
        raise InputError(f"not an outbox entry or not a valid certificate, left in place "
                         f"({len(done)} synced)", source=", ".join(bad))
    return done
