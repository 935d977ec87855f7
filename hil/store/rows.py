"""A certificate (``certificate.json``) as the rows of the results store.

Pure: no database. Every field comes from the certificate; a certificate written before the
store existed lacks the ``run`` block (run id, station, operator, reference, attempt) and
gets a run id derived from its certificate id and "not recorded" for the rest.
"""

from __future__ import annotations

import hashlib
import json
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

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
    """Parse a certificate's JSON text into rows.

    Parameters
    ----------
    text : str
        The certificate file's content.
    source : str
        Where it came from (path), for messages and ``runs.certificate_path``.

    Raises
    ------
    InputError
        Not JSON, or a required field missing or of the wrong type (naming file and field).
    """
    try:
        cert = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc}", source=source) from None
    if not isinstance(cert, dict) or "certificate_id" not in cert:
        raise InputError("not a gimbal-hil certificate (no certificate_id)", source=source)
    get = _Reader(cert, source)
    certificate_id = get.text("certificate_id")
    block: dict[str, Any] = cert["run"] if isinstance(cert.get("run"), dict) else {}
    dates = get.mapping("dates")
    drive = get.mapping("drive")
    started = _time(dates, "calibration_started", source)
    run: dict[str, Any] = {
        "run_id": str(block.get("id") or uuid.uuid5(_RUN_NAMESPACE, certificate_id)),
        "certificate_id": certificate_id,
        "serial": get.text("unit", "serial"),
        "unit_type": get.text("unit", "type"),
        "axis": get.text("unit", "axis"),
        "station": str(block.get("station") or NOT_RECORDED),
        "operator": str(block.get("operator") or NOT_RECORDED),
        "is_reference": bool(block.get("reference", False)),
        "attempt": int(block["attempt"]) if block.get("attempt") is not None else None,
        "profile": get.text("method", "profile"),
        "profile_sha256": get.text("method", "profile_sha256"),
        "software_version": get.text("software", "version"),
        "git_revision": get.mapping("software").get("git_revision"),
        "drive_kind": get.text("drive", "kind"),
        "drive_model": drive.get("model"),
        "firmware_version": drive.get("firmware_version"),
        "started_at": started,
        "ended_at": _time(dates, "calibration_finished", source)
        if "calibration_finished" in dates else _time(dates, "issued", source),
        "outcome": get.text("outcome"),
        "aborted": bool(cert.get("aborted", False)),
        "certificate_path": source,
        "certificate_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
    }
    run_id = str(run["run_id"])
    protocols = [
        {
            "run_id": run_id,
            "protocol": name,
            "outcome": str(p.get("outcome", "NOT_COMPLETED")),
            "motion_time_s": float(p.get("motion_time_s", 0.0)),
            "wall_time_s": float(p.get("wall_time_s", 0.0)),
            "messages": json.dumps(p.get("messages", [])),
        }
        for name, p in get.mapping("method", "protocols").items()
    ]
    results = [_result(run_id, r, source) for r in get.sequence("results")]
    recordings = [
        {
            "run_id": run_id,
            "path": str(f["file"]),
            "protocol": str(f.get("protocol", "")),
            "excitation": str(f.get("excitation", "")),
            "sha256": str(f["sha256"]),
            "samples": f.get("samples"),
            "complete": bool(f.get("complete", True)),
        }
        for f in get.sequence("raw_data")
    ]
    return CertificateRows(run=run, protocols=protocols, results=results, recordings=recordings)


def _result(run_id: str, r: Mapping[str, Any], source: str) -> dict[str, Any]:
    try:
        return {
            "run_id": run_id,
            "name": str(r["parameter"]),
            "protocol": str(r.get("protocol", "")),
            "value": float(r["value"]),
            "unit": str(r.get("unit", "")),
            "standard_uncertainty": float(r["standard_uncertainty"]),
            "coverage_factor": float(r["coverage_factor"]),
            "expanded_uncertainty": float(r["expanded_uncertainty"]),
            "degrees_of_freedom": _optional(r.get("degrees_of_freedom")),
            "nominal": _optional(r.get("nominal")),
            "lower_limit": _optional(r.get("lower_limit")),
            "upper_limit": _optional(r.get("upper_limit")),
            "marginal_fraction": _optional(r.get("marginal_fraction")),
            "outcome": str(r["outcome"]),
        }
    except (KeyError, TypeError, ValueError) as exc:
        name = r.get("parameter", "?") if isinstance(r, Mapping) else "?"
        raise InputError(f"results[{name}]: missing or invalid {exc}", source=source) from None


def _optional(value: Any) -> float | None:
    return None if value is None else float(value)


def _time(dates: Mapping[str, Any], key: str, source: str) -> datetime:
    try:
        moment = datetime.fromisoformat(str(dates[key]))
    except (KeyError, ValueError):
        raise InputError(f"dates.{key}: missing or not an ISO time", source=source) from None
    return moment.replace(tzinfo=UTC) if moment.tzinfo is None else moment.astimezone(UTC)


class _Reader:
    """Required fields of a certificate, each missing one an error naming its path."""

    def __init__(self, cert: Mapping[str, Any], source: str) -> None:
        self.cert = cert
        self.source = source

    def _at(self, keys: tuple[str, ...]) -> Any:
        node: Any = self.cert
        for key in keys:
            if not isinstance(node, Mapping) or key not in node:
                raise InputError(f"certificate lacks '{'.'.join(keys)}'", source=self.source)
            node = node[key]
        return node

    def text(self, *keys: str) -> str:
        value = self._at(keys)
        if not isinstance(value, str):
            raise InputError(f"'{'.'.join(keys)}' must be text", source=self.source)
        return value

    def mapping(self, *keys: str) -> Mapping[str, Any]:
        value = self._at(keys)
        if not isinstance(value, Mapping):
            raise InputError(f"'{'.'.join(keys)}' must be a table", source=self.source)
        return value

    def sequence(self, *keys: str) -> list[Any]:
        value = self._at(keys)
        if not isinstance(value, list):
            raise InputError(f"'{'.'.join(keys)}' must be a list", source=self.source)
        return value
