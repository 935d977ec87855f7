"""A gimbal certificate (``gimbal-certificate.json``) as a row of the ``gimbals`` table:
its identity, its verdict and its axes' certificates, each checked against the file the
gimbal certificate names (SHA-256) when the folder is at hand."""

from __future__ import annotations

import hashlib
import json
from datetime import datetime
from pathlib import Path
from typing import Any

from hil.certificate.gimbal_file import GIMBAL_SCHEMA
from hil.errors import InputError


def is_gimbal_certificate(text: str) -> bool:
    """Whether ``text`` is a gimbal certificate (else: an axis's, or not a certificate)."""
    try:
        document = json.loads(text)
    except ValueError:
        return False
    return isinstance(document, dict) and document.get("schema") == GIMBAL_SCHEMA


def gimbal_row(text: str, *, source: str, folder: Path | None) -> dict[str, Any]:
    """The ``gimbals`` row of a gimbal certificate (``ingested_at`` left to the writer).

    Parameters
    ----------
    text : str
        The certificate's JSON.
    source : str
        Where it was read (its path), for the messages and the row.
    folder : Path or None
        The gimbal's folder: each axis's certificate there must have the SHA-256 the gimbal
        certificate states (``None``: from the outbox, checked when it was written).

    Raises
    ------
    InputError
        A field missing or of the wrong type, or an axis's certificate changed or missing.
    """
    document = json.loads(text)
    gimbal = _field(document, "gimbal", dict, source)
    axes = _field(document, "axes", list, source)
    for index, axis in enumerate(axes):
        if not isinstance(axis, dict) or not isinstance(axis.get("axis"), str):
            raise InputError(f"axes[{index}] is not an axis section", source=source)
        named, sha = axis.get("certificate"), axis.get("certificate_sha256")
        if folder is not None and isinstance(named, str):
            found = folder / named
            if not found.is_file():
                raise InputError(f"axis {axis['axis']}: its certificate {named} is missing",
                                 source=source)
            if hashlib.sha256(found.read_bytes()).hexdigest() != sha:
                raise InputError(f"axis {axis['axis']}: its certificate {named} is not the one "
                                 "this gimbal certificate records (SHA-256 differs)",
                                 source=source)
    try:
        issued = datetime.fromisoformat(_field(document, "issued", str, source))
    except ValueError as exc:
        raise InputError(f"'issued' is no ISO 8601 time: {exc}", source=source) from None
    return {
        "certificate_id": _field(document, "certificate_id", str, source),
        "serial": _field(gimbal, "serial", str, source),
        "part_number": _field(gimbal, "part_number", str, source),
        "revision": str(gimbal.get("revision") or ""),
        "outcome": _field(document, "outcome", str, source),
        "issued_at": issued,
        "axes": json.dumps([{"axis": a["axis"], "certificate_id": a.get("certificate_id"),
                             "outcome": a.get("outcome")} for a in axes]),
        "certificate_path": source,
        "certificate_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
    }


def _field(document: dict[str, Any], key: str, kind: type, source: str) -> Any:
    value = document.get(key)
    if not isinstance(value, kind):
        raise InputError(f"gimbal certificate field '{key}' missing or not a "
                         f"{kind.__name__}", source=source)
    return value
