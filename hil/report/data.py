"""What one protocol's plot is made from: its details, its judged results and its raw
recordings, taken from a written certificate or from a run in progress."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hil.calibration import CalibrationRun
from hil.recording import Recording, read_recording


@dataclass(frozen=True, slots=True, kw_only=True)
class ProtocolData:
    """One protocol of one run, as its plot needs it.

    Attributes
    ----------
    name : str
        The protocol (``inertia_friction``, ...).
    details : mapping
        The protocol's ``method.details`` entry of the certificate.
    results : mapping
        Its judged results by parameter, as the certificate writes them.
    recordings : mapping
        Excitation name → raw recording file (complete recordings only).
    """

    name: str
    details: Mapping[str, Any]
    results: Mapping[str, Mapping[str, Any]]
    recordings: Mapping[str, Path]

    def value(self, parameter: str) -> float | None:
        """A result's value, or ``None`` when the run did not record it."""
        found = self.results.get(parameter)
        return None if found is None else float(found["value"])

    def number(self, key: str, default: float | None = None) -> float | None:
        """A finite number from the details, else ``default``."""
        raw = self.details.get(key)
        if isinstance(raw, int | float) and math.isfinite(raw):
            return float(raw)
        return default

    def recording(self, excitation: str) -> Recording | None:
        """The raw recording of ``excitation``, read from its file."""
        path = self.recordings.get(excitation)
        return None if path is None else read_recording(path, log_warnings=False)

    def recordings_named(self, prefix: str) -> list[tuple[str, Recording]]:
        """Every raw recording whose excitation starts with ``prefix``, in run order."""
        return [(name, read_recording(path, log_warnings=False))
                for name, path in self.recordings.items() if name.startswith(prefix)]


def from_certificate(cert: Mapping[str, Any], unit_dir: Path) -> list[ProtocolData]:
    """The protocols of a written certificate that ran (not skipped), in run order.

    Parameters
    ----------
    cert : mapping
        ``certificate.json`` as read.
    unit_dir : Path
        The unit's directory (the recordings' paths are relative to it).

    Returns
    -------
    list of ProtocolData
    """
    out = []
    for name, protocol in cert["method"]["protocols"].items():
        if protocol["outcome"] == "SKIPPED":
            continue
        out.append(ProtocolData(
            name=name,
            details=cert["method"]["details"].get(name, {}),
            results={r["parameter"]: r for r in cert["results"] if r["protocol"] == name},
            recordings={**{f["excitation"]: unit_dir / f["file"] for f in cert["raw_data"]
                           if f["protocol"] == name and f["complete"]},
                        **_analysed_elsewhere(cert["method"]["details"].get(name, {}),
                                              unit_dir)},
        ))
    return out


def from_run(run: CalibrationRun, name: str) -> ProtocolData:
    """One protocol of a run in progress (for attachments while the suite runs).

    Parameters
    ----------
    run : CalibrationRun
        The calibration in progress.
    name : str
        The protocol.

    Returns
    -------
    ProtocolData
    """
    return ProtocolData(
        name=name,
        details=run.details.get(name, {}),
        results={m.spec.name: m.as_dict() for m in run.measurements if m.protocol == name},
        recordings={**{f.excitation: f.path for f in run.raw_files
                       if f.protocol == name and f.complete},
                    **_analysed_elsewhere(run.details.get(name, {}), run.unit_dir)},
    )


def _analysed_elsewhere(details: Mapping[str, Any], unit_dir: Path) -> dict[str, Path]:
    """Recordings another protocol made that this one analysed (its details'
    ``recordings_analysed``: excitation name → file relative to the unit's directory), e.g.
    the cogging protocol's passes when they are the gravity sweep's."""
    found = details.get("recordings_analysed")
    if not isinstance(found, Mapping):
        return {}
    return {str(k): unit_dir / str(v) for k, v in found.items()}


def sample_rate_hz(recording: Recording) -> float:
    """The recording's median sample rate.

    Parameters
    ----------
    recording : Recording
        A recording.

    Returns
    -------
    float
        ``1 / median(Δt)`` (Hz).
    """
    return float(1.0 / np.median(np.diff(recording.time_s)))
