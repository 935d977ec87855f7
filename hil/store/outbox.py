"""The local outbox: a run the store could not take waits here, as its certificate's exact
text, until ``gimbal-hil results sync`` uploads it. Files are written atomically and removed
only after the store holds the run.

Each entry records the store it was meant for (``store``: its URL without the password,
:func:`hil.store.engine.store_target`); ``results sync`` uploads only the entries meant for
the store it was given and names the others, which stay. An entry written before that field
existed names no store and is uploaded to whichever store ``results sync`` uses. One sync at
a time per outbox (a lock file, ``.sync.lock``): a second one is refused in one line.
"""

from __future__ import annotations

import fcntl
import json
import os
import shlex
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from hil.errors import InputError
from hil.store.engine import Store, same_store
from hil.store.ingest import Ingested, ingest_text

OUTBOX_NAME = "outbox"
SYNC_LOCK_NAME = ".sync.lock"


def outbox_dir(out_dir: Path) -> Path:
    """``<out>/outbox``: where runs wait for the store."""
    return out_dir / OUTBOX_NAME


def to_outbox(out_dir: Path, certificate: Path, *, store: str | None = None) -> Path:
    """Queue ``certificate`` for a later sync.

    Parameters
    ----------
    out_dir : Path
        The calibration's ``--out`` directory.
    certificate : Path
        The ``certificate.json`` just written.
    store : str or None
        The store the run was meant for, without its password
        (:func:`hil.store.engine.store_target`); ``None``: any store.

    Returns
    -------
    Path
        The outbox entry (``<out>/outbox/<certificate id>.json``).
    """
    text = certificate.read_text(encoding="utf-8")
    certificate_id = str(json.loads(text)["certificate_id"])
    entry = {"certificate_path": str(certificate.resolve()), "certificate_text": text,
             "store": store}
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
    """The runs waiting in ``out_dir``'s outbox, oldest name first (an entry still being
    written, ``.incoming-*``, is not one yet)."""
    folder = outbox_dir(out_dir)
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.glob("*.json") if not p.name.startswith("."))


def meant_for(entry: Path) -> str | None:
    """The store an entry was meant for (``None``: any store, or unreadable)."""
    try:
        payload = json.loads(entry.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    found = payload.get("store") if isinstance(payload, dict) else None
    return found if isinstance(found, str) and found else None


def foreign_entries(out_dir: Path, target: str) -> dict[str, list[Path]]:
    """The waiting entries meant for another store than ``target``, by that store."""
    found: dict[str, list[Path]] = {}
    for entry in pending(out_dir):
        meant = meant_for(entry)
        if meant is not None and not same_store(meant, target):
            found.setdefault(meant, []).append(entry)
    return found


def refusal(out_dir: Path, foreign: dict[str, list[Path]], shown: str) -> str:
    """One line: which waiting runs are meant for another store, and the command for it."""
    count = sum(len(entries) for entries in foreign.values())
    first = next(iter(foreign))
    also = f" (and {len(foreign) - 1} other store(s))" if len(foreign) > 1 else ""
    return (f"{count} run(s) in {outbox_dir(out_dir)} are meant for {first}{also}, not "
            f"{shown}: left in the outbox; `gimbal-hil results sync --out "
            f"{shlex.quote(str(out_dir))} --store {shlex.quote(first)}` uploads them (a "
            "password goes in $GIMBAL_HIL_STORE or the station file's store, not --store)")


@contextmanager
def sync_lock(out_dir: Path) -> Iterator[None]:
    """Hold the outbox's sync lock (none needed when there is no outbox).

    Raises
    ------
    InputError
        Another ``results sync`` holds it.
    """
    folder = outbox_dir(out_dir)
    if not folder.is_dir():
        yield
        return
    path = folder / SYNC_LOCK_NAME
    try:
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise InputError(f"cannot lock the outbox: {exc.strerror}", source=str(path)) from None
    try:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"another 'gimbal-hil results sync' is uploading {folder}; run "
                             "it again once that one is done") from None
        yield
    finally:
        os.close(descriptor)  # closing drops the flock


def sync_outbox(store: Store, out_dir: Path) -> list[Ingested]:
    """Upload every waiting run meant for ``store`` (or for no store in particular); each
    entry is removed once the store holds its run.

    Raises
    ------
    InputError
        Another sync is running; or entries meant for another store, or that are not outbox
        entries (naming them; the others are still synced first; they stay).
    StoreUnavailableError
        The store went away (entries not yet uploaded stay).
    """
    done: list[Ingested] = []
    bad: list[str] = []
    foreign: dict[str, list[Path]] = {}
    with sync_lock(out_dir):
        for entry in pending(out_dir):
            try:
                payload = json.loads(entry.read_text(encoding="utf-8"))
                text, source = str(payload["certificate_text"]), str(payload["certificate_path"])
                meant = payload.get("store")
            except FileNotFoundError:  # taken meanwhile (an older gimbal-hil's sync)
                continue
            except (OSError, ValueError, KeyError, TypeError, AttributeError):
                bad.append(str(entry))
                continue
            if isinstance(meant, str) and meant and store.target and not same_store(
                    meant, store.target):
                foreign.setdefault(meant, []).append(entry)
                continue
            try:
                done.append(ingest_text(store, text, source=source))
            except InputError:  # not a valid certificate: kept for a person to look at
                bad.append(str(entry))
                continue
            entry.unlink(missing_ok=True)
    if foreign:
        more = (f"; also not outbox entries or not valid certificates: {', '.join(bad)}"
                if bad else "")
        raise InputError(refusal(out_dir, foreign, store.url) + f" ({len(done)} synced)"
                         + more)
    if bad:
        raise InputError(f"not an outbox entry or not a valid certificate, left in place "
                         f"({len(done)} synced)", source=", ".join(bad))
    return done
