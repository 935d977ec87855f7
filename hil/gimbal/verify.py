"""``gimbal-hil verify GIMBAL_FOLDER``: a gimbal certificate is verified when every axis
certificate it lists is where it says, has the SHA-256 it records, and verifies itself."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from hil.certificate.integrity import read_document, verify_document
from hil.errors import InputError
from hil.gimbal.certificate import FILE as GIMBAL_CERTIFICATE
from hil.gimbal.certificate import SCHEMA


def gimbal_certificate_path(target: Path) -> Path | None:
    """The gimbal certificate ``target`` names (the file, or a gimbal's folder); ``None``
    when it names none."""
    if target.is_dir() and (target / GIMBAL_CERTIFICATE).is_file():
        return target / GIMBAL_CERTIFICATE
    return target if target.name == GIMBAL_CERTIFICATE else None


def verify_gimbal(path: Path) -> tuple[list[str], bool]:
    """Each problem, one line, and whether the gimbal certificate is verified.

    Raises
    ------
    InputError
        The file cannot be read or is not a gimbal certificate.
    """
    try:
        document = json.loads(path.read_bytes())
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read: {exc}", source=str(path)) from None
    if not isinstance(document, dict) or document.get("schema") != SCHEMA:
        raise InputError(f"not a gimbal certificate (schema {SCHEMA!r} expected)",
                         source=str(path))
    problems = []
    for axis in document.get("axes", []):
        name = axis.get("axis")
        if axis.get("certificate") is None:
            if axis.get("outcome") != "ERROR":
                problems.append(f"axis {name}: no certificate, yet {axis.get('outcome')}")
            continue
        file = path.parent / str(axis["certificate"])
        try:
            payload = file.read_bytes()
        except OSError as exc:
            problems.append(f"axis {name}: {file}: {exc.strerror or exc}")
            continue
        if hashlib.sha256(payload).hexdigest() != axis.get("certificate_sha256"):
            problems.append(f"axis {name}: {file} is not the certificate this gimbal "
                            "certificate records (SHA-256 differs)")
            continue
        try:
            own = read_document(file)
        except InputError as exc:
            problems.append(f"axis {name}: {exc}")
            continue
        found = verify_document(own, path=file, unit_dir=file.parent)
        problems += [f"axis {name}: {line}" for line in found.problems]
        if not found.digest:
            problems.append(f"axis {name}: its certificate has no digest")
    return problems, not problems
