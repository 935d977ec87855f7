"""Certificate content following the structure of ISO/IEC 17025 7.8 (no accreditation claimed)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import platform
import subprocess
import uuid
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, cast

from hil import __version__
from hil.calibration import CalibrationRun
from hil.certificate.controller import controller_outputs
from hil.certificate.integrity import seal
from hil.certificate.model import (
    SCHEMA,
    Artifact,
    BudgetLine,
    Certificate,
    Conditions,
    Dates,
    Drive,
    Environment,
    Laboratory,
    MachineTime,
    Method,
    MethodBias,
    NotMeasured,
    ProtocolRecord,
    RawFile,
    Result,
    RunInfo,
    Software,
    Unit,
    Validation,
)
from hil.certificate.procedure import profile_sha256_without_firmware
from hil.certificate.render import render_text
from hil.drives.kinds import drive_kind
from hil.measurement import DECISION_RULE, Measurement
from hil.recording import write_atomic

log = logging.getLogger(__name__)
__all__ = ["SCHEMA", "build_certificate", "result_record", "write_certificate"]


def git_revision() -> str | None:
    """The source tree's commit, when running from a git checkout."""
    here = Path(__file__).resolve().parent
    try:
        done = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=here,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    if done.returncode != 0:
        return None
    dirty = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no"],
        cwd=here,
        capture_output=True,
        text=True,
        timeout=5,
        check=False,
    ).stdout.strip()
    return done.stdout.strip() + ("-dirty" if dirty else "")


def build_certificate(
    run: CalibrationRun, *, aborted: bool, issued: datetime | None = None
) -> Certificate:
    issued = issued or datetime.now(UTC)
    outcome = run.overall_outcome(aborted=aborted)
    info = run.drive_info
    identity = run.identity
    return Certificate(
        certificate_id=f"{run.unit_serial}-{issued:%Y%m%dT%H%M%SZ}-{uuid.uuid4().hex[:8]}",
        title="Calibration certificate: gimbal axis mechanical parameters",
        accreditation="none claimed; structure follows ISO/IEC 17025:2017 clause 7.8",
        # from the station file's [station] table (None: the file does not state it)
        laboratory=Laboratory(name=identity.laboratory, address=identity.laboratory_address),
        customer=identity.customer,
        authorised_by=identity.authorised_by,
        environment=Environment(temperature_c=identity.temperature_c,
                                humidity_pct=identity.humidity_pct, note=identity.conditions),
        unit=Unit(serial=run.unit_serial, unit_type=run.profile.unit_type,
                  axis=run.profile.axis),
        run=RunInfo(id=run.run_id, attempt=run.attempt(), station=run.station_id,
                    operator=run.operator, reference=run.reference),
        dates=Dates(calibration_started=run.started.isoformat(timespec="seconds"),
                    issued=issued.isoformat(timespec="seconds")),
        method=Method(
            # the file's name: its SHA-256 is the record, not where it lay on this machine
            profile=Path(run.profile.source).name,
            profile_sha256=run.profile.sha256,
            profile_sha256_without_firmware=profile_sha256_without_firmware(run.profile.raw),
            protocols={
                name: ProtocolRecord(
                    outcome=(
                        record.outcome.value
                        if record.outcome
                        else ("SKIPPED" if record.skipped else "NOT_COMPLETED")
                    ),
                    motion_time_s=round(record.motion_time_s, 3),
                    wall_time_s=round(record.wall_time_s, 3),
                    messages=tuple(record.messages),
                )
                for name, record in run.protocols.items()
            },
            method_bias=MethodBias(file=Path(run.method_bias.source).name,
                                   sha256=run.method_bias.sha256),
            details={name: found.to_json() for name, found in run.details.items()},
        ),
        machine_time=MachineTime(
            motion_time_s=round(sum(r.motion_time_s for r in run.protocols.values()), 3),
            wall_time_s=round(sum(r.wall_time_s for r in run.protocols.values()), 3),
        ),
        drive=Drive(kind=run.drive_kind, info=_drive_info(info) if info else {}),
        conditions=Conditions(drive_kind=run.drive_kind,
                              simulated=drive_kind(run.drive_kind).simulated),  # emulators too
        software=Software(name="gimbal-hil", version=__version__, git_revision=git_revision(),
                          python=platform.python_version()),
        raw_data=tuple(
            RawFile(protocol=f.protocol, excitation=f.excitation,
                    file=str(f.path.relative_to(run.unit_dir)), sha256=f.sha256,
                    samples=f.samples, complete=f.complete, held_axes=f.held_axes)
            for f in run.raw_files
        ),
        artifacts=tuple(
            Artifact(protocol=a.protocol, file=str(a.path.relative_to(run.unit_dir)),
                     sha256=a.sha256, description=a.description)
            for a in run.artifacts
        ),
        results=tuple(result_record(m) for m in run.measurements),
        # declared results without a value: a required one makes the run INCOMPLETE
        not_measured=tuple(NotMeasured(parameter=m.parameter, protocol=m.protocol,
                                       reason=m.reason, required=m.required)
                           for m in run.not_measured()),
        decision_rule=DECISION_RULE,
        outcome=outcome.value,
        aborted=aborted,
        conformity=_statement(outcome.value),
    )


def result_record(m: Measurement) -> Result:
    """A judged measurement as the certificate states it."""
    e, declared = m.estimate, m.declared
    validation = m.validation
    return Result(
        parameter=m.spec.name,
        title=declared.title if declared else m.spec.name,
        description=declared.description if declared else "",
        non_negative=declared.non_negative if declared else False,
        protocol=m.protocol,
        value=e.value,
        unit=m.spec.unit or e.unit,
        standard_uncertainty=e.standard_uncertainty,
        coverage_factor=e.coverage_factor,
        expanded_uncertainty=e.expanded_uncertainty,
        degrees_of_freedom=e.dof if math.isfinite(e.dof) else None,
        cramer_rao_std=e.cramer_rao_std,
        nominal=m.spec.nominal,
        lower_limit=m.spec.lower_limit,
        upper_limit=m.spec.upper_limit,
        marginal_fraction=m.spec.marginal_fraction,
        outcome=m.outcome.value,
        budget=tuple(
            BudgetLine(component=c.source, kind=c.kind,
                       standard_uncertainty=c.standard_uncertainty, unit=c.unit,
                       sensitivity=c.sensitivity, contribution=c.contribution,
                       degrees_of_freedom=c.dof if math.isfinite(c.dof) else None)
            for c in e.components()
        ),
        validation=None if validation is None else Validation(**cast(dict[str, Any], validation)),
        direction=m.spec.direction,
    )


def _drive_info(info: Any) -> dict[str, Any]:
    data = asdict(info)
    data["modes"] = [mode.value for mode in info.modes]
    data["capabilities"] = sorted(c.name.lower() for c in info.capabilities)
    return data


def _statement(outcome: str) -> str:
    return {
        "PASS": "The unit conforms to every specified limit.",
        "MARGINAL": "The unit conforms; at least one result lies in a marginal band or its "
        "uncertainty interval reaches a limit.",
        "FAIL": "The unit does not conform: at least one result is outside its limits or a "
        "protocol failed.",
        "ERROR": "No conformity statement: the calibration did not complete.",
        "INCOMPLETE": "No conformity statement: results the profile requires were not "
        "measured (listed under 'not measured').",
    }[outcome]


def write_certificate(run: CalibrationRun, *, aborted: bool) -> Path:
    """Write ``certificate.json`` and ``certificate.txt`` in the unit's directory."""
    run.archive_previous()
    certificate = build_certificate(run, aborted=aborted)
    run.unit_dir.mkdir(parents=True, exist_ok=True)
    outputs = controller_outputs(certificate)
    if outputs is not None:
        text = json.dumps(outputs, indent=2) + "\n"
        write_atomic(run.unit_dir / "controller.json", text.encode("utf-8"))
        certificate = dataclasses.replace(certificate, artifacts=(*certificate.artifacts, Artifact(
            protocol="certificate",
            file="controller.json",
            sha256=hashlib.sha256(text.encode("utf-8")).hexdigest(),
            description="feedforward parameters (format: hil/certificate/controller.py)",
        )))
    # the digest of its content last (integrity.py); each file whole or not at all
    document = seal(certificate.to_json())
    # read back as every reader will: what the writer wrote must read
    sealed = Certificate.from_json(document, source="the certificate being written")
    path = run.unit_dir / "certificate.json"
    write_atomic(path, (json.dumps(document, indent=2) + "\n").encode("utf-8"))
    write_atomic(run.unit_dir / "certificate.txt", render_text(sealed).encode("utf-8"))
    log.info("certificate %s written to %s", sealed.certificate_id, path)
    return path
