"""Variants of a real certificate: a new certificate id (and run id, serial, start time),
everything else as calibrated. For load and concurrency, where distinct ids are what count."""

from __future__ import annotations

import json
import uuid
from datetime import datetime, timedelta
from typing import Any

SERIAL = "STORE-0001"  # the unit the session calibrates (conftest: calibrated)


def variant(text: str, *, serial: str, index: int, **run: Any) -> str:
    """``text`` (a certificate.json) as the certificate of another run.

    ``index`` shifts the start by that many minutes; ``run`` overrides keys of the ``run``
    block (``station``, ``reference``, …); ``aborted=True`` marks the run aborted.
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
    return json.dumps(cert, indent=2)
