"""Variants of a real certificate: a new certificate id (and run id, serial, start time),
everything else as calibrated. For load and concurrency, where distinct ids are what count."""

from __future__ import annotations

import json
import shutil
import uuid
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from hil.certificate.integrity import seal, stated_outcomes

SERIAL = "STORE-0001"  # the unit the session calibrates (conftest: calibrated)


def variant(text: str, *, serial: str, index: int, files: bool = False, **run: Any) -> str:
    """``text`` (a certificate.json) as the certificate of another run.

    ``index`` shifts the start by that many minutes; ``run`` overrides keys of the ``run``
    block (``station``, ``reference``, …); ``aborted=True`` marks the run aborted;
    ``files``: keep the recordings and derived files listed (copy them beside it,
    :func:`copy_files`), else list none.
    """
    cert = json.loads(text)
    started = datetime.fromisoformat(cert["dates"]["calibration_started"])
    moved = started + timedelta(minutes=index)
    cert["dates"]["calibration_started"] = moved.isoformat()
    cert["dates"]["issued"] = (moved + timedelta(seconds=30)).isoformat()
    cert["certificate_id"] = f"{serial}-{moved:%Y%m%dT%H%M%SZ}-{uuid.uuid4().hex[:8]}"
    cert["unit"]["serial"] = serial
    aborted = run.pop("aborted", None)
    if aborted is not None:
        cert["aborted"] = aborted
        cert["outcome"] = "ERROR" if aborted else cert["outcome"]
    cert["run"] = {**cert.get("run", {}), "id": str(uuid.uuid4()), **run}
    return json.dumps(resealed(cert, files=files), indent=2)


def with_value(text: str, *, name: str, value: float, serial: str, index: int, folder: Path,
               **unit: str) -> Path:
    """:func:`variant` of ``text`` with result ``name`` set to ``value`` (and the ``unit``
    block's keys given, e.g. ``axis``), sealed and written to ``folder/u{index}/``."""
    cert = json.loads(variant(text, serial=serial, index=index))
    cert["unit"].update(unit)
    for result in cert["results"]:
        if result["parameter"] == name:
            result["value"] = value
    path = folder / f"u{index}" / "certificate.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(resealed(cert)), encoding="utf-8")
    return path


def resealed(cert: dict[str, Any], *, files: bool = False) -> dict[str, Any]:
    """``cert`` as a certificate of its own run: outcomes as the decision rule states them,
    the recordings of the run it came from listed only with ``files`` (else not copied
    beside it), a digest of its own (``gimbal-hil verify`` would pass it; ingest refuses
    an edited one)."""
    if not files:
        cert = {**cert, "raw_data": [], "artifacts": []}
    return seal(stated_outcomes(cert))


def copy_files(certificate: Path, unit_dir: Path) -> None:
    """The recordings and derived files ``certificate`` lists, from ``unit_dir`` beside it."""
    listed = json.loads(certificate.read_text(encoding="utf-8"))
    for entry in [*listed["raw_data"], *listed["artifacts"]]:
        target = certificate.parent / entry["file"]
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(unit_dir / entry["file"], target)
