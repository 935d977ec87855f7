"""One calibration run of one unit: raw recordings kept, measurements judged, outcome derived.

Independent of pytest: the plugin creates one per session and hands it to protocols.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import logging
import os
import re
import shutil
import socket
import time
import uuid
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from hil.budget import StorageError, storage_error
from hil.details import Details
from hil.drives.base import Capability, Drive, DriveInfo, Interrupted
from hil.drives.station import StationIdentity
from hil.errors import DriveError, DriveStateError, InputError
from hil.identify.estimate import Estimate
from hil.measurement import (
    Declared,
    Measurement,
    MethodBias,
    MethodBiasMap,
    Outcome,
    judge,
    load_method_bias,
    with_method_terms,
)
from hil.motion import Excitation
from hil.profile import UnitProfile
from hil.recording import Recording, write_atomic, write_recording
from hil.stop_request import StopRequest

log = logging.getLogger(__name__)
SERIAL_PATTERN = r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}"
LOCK_NAME = ".gimbal-hil.lock"  # in the unit folder; never archived, never removed



def check_serial(serial: str) -> None:
    """Refuse ``serial`` unless it is a unit serial (:data:`SERIAL_PATTERN`: a folder name).

    Raises
    ------
    InputError
        Naming the serial and ``--unit-serial``.
    """
    if not re.fullmatch(SERIAL_PATTERN, serial):
        raise InputError(f"{serial!r} is not a unit serial: 1-64 letters, digits, '.', '_' "
                         "or '-', starting with a letter or digit", source="--unit-serial")

class UnitLock:
    """One writer per unit folder: ``fcntl.flock`` on ``SERIAL/.gimbal-hil.lock``, held by
    the calibration from before its first write to its end (the system drops it when the
    process dies, however it dies). The file names its holder: pid, host, start."""

    def __init__(self, path: Path, descriptor: int) -> None:
        self.path, self._descriptor = path, descriptor

    @classmethod
    def acquire(cls, unit_dir: Path) -> UnitLock:
        """Take the unit folder's lock, or refuse at once.

        Raises
        ------
        InputError
            Another process holds it (naming its pid, host and start), or the folder cannot
            be made.
        """
        path = unit_dir / LOCK_NAME
        try:
            unit_dir.mkdir(parents=True, exist_ok=True)
            descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as exc:
            raise InputError(f"cannot lock the unit folder: {exc.strerror or exc}",
                             source=str(unit_dir)) from None
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = _holder(descriptor)
            os.close(descriptor)
            raise InputError(f"another calibration is writing this unit folder ({holder}; "
                             f"lock {LOCK_NAME}): wait for it to end or choose another --out",
                             source=str(unit_dir)) from None
        stamp = {"pid": os.getpid(), "host": socket.gethostname(),
                 "started": datetime.now(UTC).isoformat(timespec="seconds")}
        os.ftruncate(descriptor, 0)
        os.pwrite(descriptor, (json.dumps(stamp) + "\n").encode("utf-8"), 0)
        return cls(path, descriptor)

    def release(self) -> None:
        """Let the next calibration of this unit write (idempotent)."""
        if self._descriptor >= 0:
            os.close(self._descriptor)  # closing drops the flock
            self._descriptor = -1


def _holder(descriptor: int) -> str:
    """Who holds a lock, as its file says."""
    try:
        stamp = json.loads(os.pread(descriptor, 4096, 0) or b"{}")
        return (f"pid {stamp['pid']} on {stamp['host']}, started {stamp['started']}")
    except (OSError, ValueError, KeyError, TypeError):
        return "holder not yet named"


@dataclass(frozen=True, slots=True, kw_only=True)
class RawFile:
    protocol: str
    excitation: str
    path: Path
    sha256: str
    samples: int
    motion_time_s: float
    complete: bool
    held_axes: str = ""  # where a gimbal's other axes stood, held by their drives


@dataclass(frozen=True, slots=True, kw_only=True)
class Artifact:
    """A file derived from the calibration (compensation table, controller parameters)."""

    protocol: str
    path: Path
    sha256: str
    description: str


@dataclass(slots=True)
class ProtocolRecord:
    name: str
    outcome: Outcome | None = None  # None until the protocol test reports
    skipped: bool = False
    motion_time_s: float = 0.0
    wall_time_s: float = 0.0
    messages: list[str] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class NotMeasured:
    """A result the profile declares and the run did not measure."""

    parameter: str
    protocol: str
    reason: str
    required: bool


class CalibrationRun:
    """Collects everything the certificate needs while protocols run."""

    def __init__(
        self,
        *,
        profile: UnitProfile,
        unit_serial: str,
        out_dir: Path,
        drive_kind: str,
        method_bias: MethodBiasMap | None = None,
        station_id: str = "",
        operator: str = "",
        reference: bool = False,
        identity: StationIdentity | None = None,
        stop: StopRequest | None = None,
    ) -> None:
        if not re.fullmatch(SERIAL_PATTERN, unit_serial):
            raise ValueError(
                f"unit serial {unit_serial!r} must be 1-64 letters, digits, '.', '_' or '-'"
            )
        self.profile = profile
        self.unit_serial = unit_serial
        self.drive_kind = drive_kind
        self.method_bias = (load_method_bias(axis=profile.axis) if method_bias is None
                            else method_bias)
        self.unit_dir = out_dir / unit_serial
        self.run_id = str(uuid.uuid4())
        self.station_id, self.operator, self.reference = station_id, operator, reference
        # the station file's [station] table: laboratory, customer, authoriser, conditions
        self.identity = identity or StationIdentity()
        self.started = datetime.now(UTC)
        self.drive_info: DriveInfo | None = None
        self.raw_files: list[RawFile] = []
        self.artifacts: list[Artifact] = []
        self.measurements: list[Measurement] = []
        self.protocols: dict[str, ProtocolRecord] = {}
        self.details: dict[str, Details] = {}  # by protocol (hil.details)
        # every result the profile declares → the protocol that measures it (the suite's
        # catalogue): what is missing at the end makes the run INCOMPLETE
        self.expected: dict[str, str] = {}
        # results measured but not judged, each with why (a share too uncertain to decide
        # on: its protocol judges another result instead); never make the run INCOMPLETE
        self.unresolved: dict[str, str] = {}
        self._archived = False
        self.stop = stop or StopRequest()  # a stop signal's request: no motion after it

    # -- used by protocols ----------------------------------------------------------------
    def protocol(self, name: str) -> ProtocolRecord:
        return self.protocols.setdefault(name, ProtocolRecord(name=name))

    def run(self, drive: Drive, excitation: Excitation, *, protocol: str) -> Recording:
        """Execute ``excitation`` and keep its raw recording, even a partial one on error."""
        self.drive_info = drive.info
        if excitation.elevation_path_rad is not None and (
                lacking := drive.info.lacking((Capability.ELEVATION_MOTION,))) is not None:
            raise DriveStateError(f"'{excitation.name}' moves the elevation axis: {lacking}")
        self.stop.honour(f"'{excitation.name}'")
        record = self.protocol(protocol)
        started = time.perf_counter()
        try:
            recording = drive.run(excitation)
        except DriveError as exc:
            partial = exc.partial_recording
            if isinstance(partial, Recording):
                self._keep(partial, protocol, excitation, complete=False)
            raise
        except Interrupted as stop:  # a stop signal mid-excitation: keep what was acquired
            if isinstance(stop.partial_recording, Recording):
                try:
                    self._keep(stop.partial_recording, protocol, excitation, complete=False)
                except (OSError, StorageError) as exc:  # the stop matters more
                    log.error("the interrupted recording of %s was not kept: %s",
                              excitation.name, exc)
            raise
        finally:
            record.wall_time_s += time.perf_counter() - started
        record.motion_time_s += excitation.duration_s
        self._keep(recording, protocol, excitation, complete=True)
        return recording

    def result(self, name: str) -> Estimate | None:
        """The judged estimate of an earlier protocol's declared measurement ``name``.

        Parameters
        ----------
        name : str
            A declared measurement, e.g. ``"reported_torque_gain_error_pct"``.

        Returns
        -------
        Estimate or None
            The estimate as recorded (method bias corrected, budget complete), or ``None`` when no
            protocol has measured it in this run.
        """
        for measurement in self.measurements:
            if measurement.spec.name == name:
                return measurement.estimate
        return None

    def results(self, *names: str) -> tuple[Estimate, ...] | None:
        """Several earlier results at once.

        Parameters
        ----------
        *names : str
            Declared measurements.

        Returns
        -------
        tuple of Estimate or None
            The estimates in the order of ``names`` (see :meth:`result`), or ``None``
            unless every one was measured.
        """
        found = [self.result(name) for name in names]
        return None if any(e is None for e in found) else tuple(e for e in found if e)

    def method_line(self, name: str, *, method_of: str | None = None,
                    acquisition: str | None = None,
                    variant: str | None = None) -> MethodBias | None:
        """The method line :meth:`record` adds to result ``name`` (the stop rule judges
        each run's U with the same, :func:`hil.suite.stop_rule.run_repeated`), at this
        unit's earlier results where the line follows one (:meth:`MethodBias.at`)."""
        bias = self.method_bias.line(method_of or name, path=acquisition, variant=variant)
        if bias is None or (method_of is not None and not bias.relative):
            return None
        return bias.at({m.spec.name: m.estimate.value for m in self.measurements})

    def record(self, protocol: str, estimate: Estimate, *, method_of: str | None = None,
               declared: Declared | None = None, acquisition: str | None = None,
               variant: str | None = None) -> Measurement:
        """Judge ``estimate`` against the profile's declared measurement of the same name,
        after the method's known bias is corrected and its budget completed
        (:func:`hil.measurement.with_method_terms`); ``method_of``: take the method terms
        of that (relative) result, which this one is proportional to; ``declared``: the
        protocol's title and description of it, for the certificate; ``acquisition``: the
        path its recording came over, when the method's error depends on it (the method
        line of that path, or none: :meth:`hil.measurement.MethodBiasMap.line`);
        ``variant``: the method ran without an input its main line assumes."""
        spec = self.profile.measurement(estimate.name)
        bias = self.method_line(spec.name, method_of=method_of, acquisition=acquisition,
                                variant=variant)
        estimate = with_method_terms(estimate, spec, bias)
        measurement = Measurement(
            protocol=protocol, spec=spec, estimate=estimate,
            outcome=judge(estimate, spec, non_negative=declared is not None and
                          declared.non_negative),
            validation=None if bias is None or method_of else bias.validation(),
            declared=declared,
        )
        self.measurements = [m for m in self.measurements if m.spec.name != spec.name]
        self.measurements.append(measurement)
        log.info(
            "%s = %.6g ± %.2g %s → %s",
            spec.name,
            estimate.value,
            estimate.expanded_uncertainty,
            spec.unit,
            measurement.outcome.value,
        )
        return measurement

    def write_artifact(self, protocol: str, name: str, text: str, *, description: str) -> Path:
        """Write a derived file next to the certificate; the certificate lists its SHA-256."""
        self.archive_previous()
        path = self.unit_dir / name
        path.parent.mkdir(parents=True, exist_ok=True)
        payload = text.encode("utf-8")
        try:
            write_atomic(path, payload)
        except OSError as exc:
            raise storage_error(exc, path) from None
        self.artifacts = [a for a in self.artifacts if a.path != path]
        self.artifacts.append(
            Artifact(
                protocol=protocol,
                path=path,
                sha256=hashlib.sha256(payload).hexdigest(),
                description=description,
            )
        )
        return path

    # -- used by the plugin ---------------------------------------------------------------
    def report_protocol(self, name: str, outcome: Outcome, message: str = "") -> None:
        record = self.protocol(name)
        worse = {Outcome.PASS: 0, Outcome.MARGINAL: 1, Outcome.FAIL: 2, Outcome.ERROR: 3}
        if record.outcome is None or worse[outcome] > worse[record.outcome]:
            record.outcome = outcome
        if message:
            record.messages.append(message)

    def state_unresolved(self, protocol: str, name: str, reason: str) -> None:
        """``name`` was measured but cannot be judged (``reason`` says why and what its
        protocol judged instead): the certificate lists it, with the reason, under the
        results not measured, and it does not make the run INCOMPLETE."""
        self.protocol(protocol)  # the protocol ran
        self.unresolved[name] = reason

    def report_skip(self, name: str, reason: str) -> None:
        record = self.protocol(name)
        record.skipped = True
        record.messages.append(f"skipped: {reason}")

    def overall_outcome(self, *, aborted: bool) -> Outcome:
        """Never PASS when aborted, when a protocol failed or errored, with no results, or
        with a required declared result not measured (INCOMPLETE: deselected, skipped or
        not collected); the worst of ERROR, FAIL, INCOMPLETE, MARGINAL, PASS."""
        if aborted or not self.measurements:
            return Outcome.ERROR
        outcomes = [m.outcome for m in self.measurements]
        outcomes += [p.outcome for p in self.protocols.values() if p.outcome is not None]
        if any(p.outcome is None and not p.skipped for p in self.protocols.values()):
            outcomes.append(Outcome.ERROR)
        if any(missing.required for missing in self.not_measured()):
            outcomes.append(Outcome.INCOMPLETE)
        for worst in (Outcome.ERROR, Outcome.FAIL, Outcome.INCOMPLETE, Outcome.MARGINAL):
            if worst in outcomes:
                return worst
        return Outcome.PASS

    def not_measured(self) -> list[NotMeasured]:
        """The declared results this run has no value of, each with why."""
        measured = {m.spec.name for m in self.measurements}
        missing = []
        for name, protocol in self.expected.items():
            if name in measured:
                continue
            if name in self.unresolved:
                missing.append(NotMeasured(parameter=name, protocol=protocol,
                                           reason=self.unresolved[name], required=False))
                continue
            record = self.protocols.get(protocol)
            if record is None:
                reason = "its protocol did not run (deselected or not collected)"
            elif record.skipped:
                reason = next((m for m in record.messages if m.startswith("skipped:")),
                              "its protocol was skipped")
            elif record.outcome == Outcome.ERROR:
                reason = "its protocol stopped with an error"
            else:
                reason = "its protocol gave no value"
            missing.append(NotMeasured(parameter=name, protocol=protocol, reason=reason,
                                       required=self.profile.measurement(name).required))
        return missing

    def attempt(self) -> int:
        """This run's number for the unit's axis: 1 + the calibrations of this axis kept in
        ``history/`` (one without a readable axis counts)."""
        return 1 + sum(certificate_axis(path) in (None, self.profile.axis)
                       for path in self.unit_dir.glob("history/*/certificate.json"))

    @property
    def active(self) -> bool:
        return bool(self.protocols)

    # -- raw data -------------------------------------------------------------------------
    def _keep(
        self, recording: Recording, protocol: str, excitation: Excitation, *, complete: bool
    ) -> None:
        self.archive_previous()
        suffix = "" if complete else "_PARTIAL"
        name = re.sub(r"[^A-Za-z0-9._-]+", "_", f"{protocol}__{excitation.name}{suffix}")
        path = self.unit_dir / "recordings" / f"{name}.csv.gz"
        # an excitation run twice in one calibration keeps both recordings
        taken = {raw.path for raw in self.raw_files}
        repeat = 2
        while path in taken:
            path = self.unit_dir / "recordings" / f"{name}__{repeat}.csv.gz"
            repeat += 1
        metadata = {
            "unit_serial": self.unit_serial,
            "unit_type": self.profile.unit_type,
            "axis": self.profile.axis,
            "protocol": protocol,
            **recording.metadata,
        }
        kept = Recording(columns=recording.columns, metadata=metadata, source=str(path))
        try:
            sha = write_recording(kept, path)
        except OSError as exc:  # a full or read-only disk: the run stops (written whole or not)
            raise storage_error(exc, path) from None
        self.raw_files.append(
            RawFile(
                protocol=protocol,
                excitation=excitation.name,
                path=path,
                sha256=sha,
                samples=len(recording),
                motion_time_s=recording.duration_s,
                complete=complete,
                held_axes=recording.metadata.get("held_axes", ""),
            )
        )

    def archive_previous(self) -> None:
        """Move an earlier run of this unit to ``history/`` before writing anything."""
        if self._archived:
            return
        self._archived = True
        previous = [
            p
            for p in (self.unit_dir / "certificate.json", self.unit_dir / "recordings")
            if p.exists()
        ]
        if not previous:
            return
        stamp = datetime.fromtimestamp(previous[0].stat().st_mtime, UTC).strftime("%Y%m%dT%H%M%SZ")
        # the second alone collides (two runs in one second, a clock stepped back): the
        # earlier run's id (or a random one) makes the name unique; never an existing one
        suffix = _run_id(self.unit_dir / "certificate.json") or uuid.uuid4().hex
        target = self.unit_dir / "history" / f"{stamp}-{suffix[:8]}"
        while target.exists():
            target = self.unit_dir / "history" / f"{stamp}-{uuid.uuid4().hex[:8]}"
        target.mkdir(parents=True)
        for item in self.unit_dir.iterdir():
            if item.name not in ("history", LOCK_NAME):
                shutil.move(str(item), target / item.name)
        log.info("previous calibration of %s moved to %s", self.unit_serial, target)


def certificate_axis(certificate: Path) -> str | None:
    """The axis an earlier certificate states (``None``: none, or none readable)."""
    try:
        found = json.loads(certificate.read_bytes())["unit"]["axis"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return found if isinstance(found, str) else None


def _run_id(certificate: Path) -> str | None:
    """The run id an earlier certificate states (``None``: none readable)."""
    try:
        found = json.loads(certificate.read_bytes())["run"]["id"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return re.sub(r"[^A-Za-z0-9]", "", str(found)) or None
