"""What one protocol's plot is made from: its details, its judged results and its raw
recordings, taken from a written certificate or from a run in progress."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from hil.calibration import CalibrationRun
from hil.certificate.build import result_record
from hil.certificate.model import Certificate, Result, as_certificate
from hil.details import Details, DetailsError
from hil.recording import Recording, read_recording
from hil.suite.catalogue import CATALOGUE
from hil.suite.cogging import CoggingDetails

D = TypeVar("D", bound=Details)


@dataclass(frozen=True, slots=True, kw_only=True)
class ProtocolData:
    """One protocol of one run, as its plot needs it.

    Attributes
    ----------
    name : str
        The protocol (``inertia_friction``, ...).
    details : Details or None
        The protocol's details (:mod:`hil.details`), read back from the certificate's
        ``method.details`` entry; ``None`` when there are none or they do not read.
    details_problem : str
        Why ``details`` is ``None`` (empty when it is not).
    results : mapping
        Its judged results by parameter (:class:`hil.certificate.model.Result`).
    recordings : mapping
        Excitation name → raw recording file (complete recordings only).
    """

    name: str
    details: Details | None
    results: Mapping[str, Result]
    recordings: Mapping[str, Path]
    details_problem: str = ""

    def value(self, parameter: str) -> float | None:
        """A result's value, or ``None`` when the run did not record it."""
        found = self.results.get(parameter)
        return None if found is None else float(found.value)

    def details_as(self, kind: type[D]) -> D | None:
        """The details, as the protocol's declared type; ``None`` when the run recorded
        none (it ended before).

        Raises
        ------
        DetailsError
            They did not read (saying why), or they are of another type.
        """
        if isinstance(self.details, kind):
            return self.details
        if self.details is None and not self.details_problem:
            return None
        raise DetailsError(self.details_problem or f"{self.name}: details are "
                           f"{type(self.details).__name__}, not {kind.__name__}")

    def recording(self, excitation: str) -> Recording | None:
        """The raw recording of ``excitation``, read from its file."""
        path = self.recordings.get(excitation)
        return None if path is None else read_recording(path, log_warnings=False)

    def recordings_named(self, prefix: str) -> list[tuple[str, Recording]]:
        """Every raw recording whose excitation starts with ``prefix``, in run order."""
        return [(name, read_recording(path, log_warnings=False))
                for name, path in self.recordings.items() if name.startswith(prefix)]


def from_certificate(document: Certificate | Mapping[str, Any], unit_dir: Path
                     ) -> list[ProtocolData]:
    """The protocols of a written certificate that ran (not skipped), in run order.

    Parameters
    ----------
    document : Certificate or mapping
        The certificate (:func:`hil.certificate.model.read_certificate`; a parsed
        ``certificate.json`` is read here).
    unit_dir : Path
        The unit's directory (the recordings' paths are relative to it).

    Returns
    -------
    list of ProtocolData
    """
    cert = as_certificate(document)
    out = []
    for name, protocol in cert.method.protocols.items():
        if protocol.outcome == "SKIPPED":
            continue
        details, problem = _read_details(name, cert.method.details.get(name))
        out.append(ProtocolData(
            name=name,
            details=details,
            details_problem=problem,
            results={r.parameter: r for r in cert.results_of(name)},
            recordings={**{f.excitation: unit_dir / f.file for f in cert.raw_data
                           if f.protocol == name and f.complete},
                        **_analysed_elsewhere(details, unit_dir)},
        ))
    return out


def finite(value: float | None, default: float) -> float:
    """``value`` when it is a finite number, else ``default``."""
    return value if value is not None and math.isfinite(value) else default


def _read_details(name: str, raw: object) -> tuple[Details | None, str]:
    """A protocol's details read back as its declared type, or why they cannot be."""
    protocol = CATALOGUE.get(name)
    where = f"the certificate's details of {name}"
    if protocol is None:
        return None, f"{where}: no such protocol in this gimbal-hil"
    if raw is None:
        return None, ""  # the protocol ended before it recorded any
    if not isinstance(raw, Mapping):
        return None, f"{where}: an object expected, got {type(raw).__name__}"
    try:
        return protocol.details.from_json(raw, where=where), ""
    except DetailsError as exc:
        return None, str(exc)


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
        details=run.details.get(name),
        results={m.spec.name: result_record(m) for m in run.measurements
                 if m.protocol == name},
        recordings={**{f.excitation: f.path for f in run.raw_files
                       if f.protocol == name and f.complete},
                    **_analysed_elsewhere(run.details.get(name), run.unit_dir)},
    )


def _analysed_elsewhere(details: Details | None, unit_dir: Path) -> dict[str, Path]:
    """Recordings another protocol made that this one analysed (excitation name → file
    relative to the unit's directory): the cogging protocol's passes when they are the
    gravity sweep's."""
    if not isinstance(details, CoggingDetails):
        return {}
    return {k: unit_dir / v for k, v in details.recordings_analysed.items()}


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
