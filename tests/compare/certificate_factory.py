"""Certificate JSON for the compare tests, complete and written by the certificate's own
writer (:meth:`hil.certificate.model.Certificate.to_json`): what the compare reads is what a
calibration writes, and a field the model renames or adds is renamed or added here too."""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

from hil.certificate.model import (
    SCHEMA,
    BudgetLine,
    Certificate,
    Dates,
    Drive,
    MachineTime,
    Method,
    MethodBias,
    ProtocolRecord,
    Result,
    Software,
    Unit,
)

__all__ = ["SCHEMA", "certificate", "line", "result", "write"]

METHOD_LINE = "method: error over 50 simulated units beyond Type A (mean +0.2 % corrected)"
TAU_LINE = "current-loop time constant τ taken out (current_loop)"
_RUNS = itertools.count(1)  # each certificate its own id, as each run has


def line(source: str, kind: str, u: float, *, sensitivity: float = 1.0,
         dof: float | None = None) -> BudgetLine:
    """One budget line as the certificate states it."""
    return BudgetLine(component=source, kind=kind, standard_uncertainty=u, unit="",
                      sensitivity=sensitivity, contribution=abs(sensitivity) * u,
                      degrees_of_freedom=dof)


def result(name: str, value: float, *, u_a: float, u_method: float = 0.0,
           dof_a: float | None = 20.0, lower: float = 0.0, upper: float = 2.0,
           direction: str | None = None, unit: str = "N·m") -> Result:
    """A result with a Type A line (and a method line when ``u_method``)."""
    budget = [line("measurement noise: scatter of the data (Type A)", "A", u_a, dof=dof_a)]
    if u_method:
        budget.append(line(METHOD_LINE, "B", u_method))
    u = (u_a**2 + u_method**2) ** 0.5
    return Result(parameter=name, protocol="p", value=value, unit=unit,
                  standard_uncertainty=u, coverage_factor=2.0, expanded_uncertainty=2 * u,
                  degrees_of_freedom=dof_a, nominal=(lower + upper) / 2,
                  lower_limit=lower, upper_limit=upper, outcome="PASS",
                  budget=tuple(budget), direction=direction)


def certificate(serial: str = "U-1", results: list[Result] | None = None, *,
                profile_sha: str = "p" * 64, version: str = "0.1.0",
                transport: str = "in-process") -> dict[str, Any]:
    """A complete certificate (schema :data:`~hil.certificate.model.SCHEMA`) as JSON values,
    without a digest (a certificate written before digests: read with a warning), its id
    new at each call."""
    ran = ProtocolRecord(outcome="PASS", motion_time_s=1.0, wall_time_s=1.0)
    return Certificate(
        certificate_id=f"{serial}-20260101T000000Z-{next(_RUNS):08x}",
        title="Calibration certificate: gimbal axis mechanical parameters",
        accreditation="none claimed",
        unit=Unit(serial=serial, unit_type="GMB-2 elevation axis", axis="elevation"),
        dates=Dates(calibration_started="2026-01-01T00:00:00+00:00",
                    issued="2026-01-01T00:00:00+00:00"),
        method=Method(profile="x.toml", profile_sha256=profile_sha,
                      profile_sha256_without_firmware="f" * 64,
                      protocols={"current_loop": ran, "inertia_friction": ran},
                      method_bias=MethodBias(file="m.toml", sha256="m" * 64)),
        machine_time=MachineTime(motion_time_s=2.0, wall_time_s=2.0),
        drive=Drive(kind="sim", info={"vendor": "gimbal-hil", "model": "plant_sim",
                                      "firmware_version": "0.1.0", "transport": transport}),
        software=Software(name="gimbal-hil", version=version, git_revision="abc"),
        raw_data=(),
        results=tuple(results if results is not None else [
            result("coulomb_nm", 1.0, u_a=0.01, u_method=0.05),
            result("bandwidth_hz", 1.0, u_a=0.01, direction="higher"),
        ]),
        decision_rule="simple acceptance",
        outcome="PASS",
        aborted=False,
        conformity="The unit conforms to every specified limit.",
    ).to_json()


def write(path: Path, document: dict[str, Any]) -> Path:
    """Write ``document`` as ``path`` (a ``…/SERIAL/certificate.json``); returns it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(document), encoding="utf-8")
    return path
