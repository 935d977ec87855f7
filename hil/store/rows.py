"""A certificate (``certificate.json``) as the rows of the results store.

Pure: no database. Every field comes from the certificate, read by the certificate's one
reader (:mod:`hil.certificate.model`); a certificate written before the store existed lacks
the ``run`` block (run id, station, operator, reference, attempt) and
gets a run id derived from its certificate id and "not recorded" for the rest.
"""

from __future__ import annotations

import hashlib
import json
import uuid
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from hil.certificate.model import Certificate, Result
from hil.errors import InputError

NOT_RECORDED = "(not recorded)"
_RUN_NAMESPACE = uuid.UUID("6f1d3b0e-5c55-4bd4-9a55-0c7d8b1f2e11")


@dataclass(frozen=True, slots=True)
class CertificateRows:
    """The rows one certificate becomes. ``run["attempt"]`` is ``None`` when the certificate
    does not state it (the store then counts the unit's earlier runs)."""

    run: dict[str, Any]
    protocols: list[dict[str, Any]]
    results: list[dict[str, Any]]
    recordings: list[dict[str, Any]]


def certificate_rows(text: str, *, source: str) -> CertificateRows:
    """Parse a certificate's JSON text into rows (read by
    :func:`hil.certificate.model.read_certificate`).

    Parameters
    ----------
    text : str
        The certificate file's content.
    source : str
        Where it came from (path), for messages and ``runs.certificate_path``.

    Raises
    ------
    InputError
        Not JSON, or not a certificate: another schema, a field missing, unknown or of the
        wrong type (:class:`~hil.certificate.model.CertificateError`, naming file and field),
        a time that is not ISO 8601.
    """
    try:
        document = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise InputError(f"not valid JSON: {exc}", source=source) from None
    cert = Certificate.from_json(document, source=source)
    block = cert.run
    drive = cert.drive
    run: dict[str, Any] = {
        "run_id": block.id if block is not None and block.id
        else str(uuid.uuid5(_RUN_NAMESPACE, cert.certificate_id)),
        "certificate_id": cert.certificate_id,
        "serial": cert.unit.serial,
        "unit_type": cert.unit.unit_type,
        "axis": cert.unit.axis,
        "station": (block.station if block is not None else None) or NOT_RECORDED,
        "operator": (block.operator if block is not None else None) or NOT_RECORDED,
        "is_reference": block.reference if block is not None else False,
        "attempt": block.attempt if block is not None else None,
        "profile": cert.method.profile,
        "profile_sha256": cert.method.profile_sha256,
        "software_version": cert.software.version,
        "git_revision": cert.software.git_revision,
        "drive_kind": drive.kind,
        "drive_model": drive.model,
        "firmware_version": drive.firmware_version,
        "started_at": _time(cert.dates.calibration_started, "calibration_started", source),
        "ended_at": _time(cert.dates.issued, "issued", source),
        "outcome": cert.outcome,
        "aborted": cert.aborted,
        "certificate_path": source,
        "certificate_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
    }
    run_id = str(run["run_id"])
    protocols = [
        {
            "run_id": run_id,
            "protocol": name,
            "outcome": p.outcome,
            "motion_time_s": float(p.motion_time_s),
            "wall_time_s": float(p.wall_time_s),
            "messages": json.dumps(list(p.messages)),
        }
        for name, p in cert.method.protocols.items()
    ]
    results = [_result(run_id, r) for r in cert.results]
    recordings = [
        {
            "run_id": run_id,
            "path": f.file,
            "protocol": f.protocol,
            "excitation": f.excitation,
            "sha256": f.sha256,
            "samples": f.samples,
            "complete": f.complete,
        }
        for f in cert.raw_data
    ]
    return CertificateRows(run=run, protocols=protocols, results=results, recordings=recordings)


def _result(run_id: str, r: Result) -> dict[str, Any]:
    return {
        "run_id": run_id,
        "name": r.parameter,
        "protocol": r.protocol,
        "value": float(r.value),
        "unit": r.unit,
        "standard_uncertainty": float(r.standard_uncertainty),
        "coverage_factor": float(r.coverage_factor),
        "expanded_uncertainty": float(r.expanded_uncertainty),
        "degrees_of_freedom": _optional(r.degrees_of_freedom),
        "nominal": _optional(r.nominal),
        "lower_limit": float(r.lower_limit),
        "upper_limit": float(r.upper_limit),
        "marginal_fraction": float(r.marginal_fraction),
        "outcome": r.outcome,
    }


def _optional(value: float | None) -> float | None:
    return None if value is None else float(value)


def _time(text: str, key: str, source: str) -> datetime:
    try:
        moment = datetime.fromisoformat(text)
    except ValueError:
        raise InputError(f"dates.{key}: not an ISO time", source=source) from None
    return moment.replace(tzinfo=UTC) if moment.tzinfo is None else moment.astimezone(UTC)
