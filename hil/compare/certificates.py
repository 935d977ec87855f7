"""Reading the two sides of a comparison: certificate JSON, checked against its schema.

Each side is one ``certificate.json`` or a directory holding one per serial
(``DIR/SERIAL/certificate.json``), read by the certificate's one reader
(:func:`hil.certificate.model.read_certificate`). Anything missing or mistyped is an
:class:`~hil.errors.InputError` naming the file and the place in it.
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from hil.certificate import model
from hil.certificate.gimbal_file import GIMBAL_FILE
from hil.certificate.integrity import verify_document
from hil.errors import InputError

log = logging.getLogger(__name__)
CERTIFICATE_FILE = "certificate.json"
DIRECTIONS = ("higher", "lower")
# an emulator's endpoint is new in every run (a virtual CAN channel, a loopback port)
_EPHEMERAL = ((re.compile(r"virtual:[\w-]+"), "virtual"),
              (re.compile(r"127\.0\.0\.1:\d+"), "127.0.0.1"))


@dataclass(frozen=True, slots=True, kw_only=True)
class BudgetLine:
    """One line of a result's uncertainty budget as the certificate states it."""

    source: str
    kind: Literal["A", "B"]
    standard_uncertainty: float
    sensitivity: float
    dof: float  # inf when the certificate gives none

    @property
    def signed_contribution(self) -> float:
        """``cᵢ·u(xᵢ)``, in the result's unit."""
        return self.sensitivity * self.standard_uncertainty


@dataclass(frozen=True, slots=True, kw_only=True)
class Result:
    """One certificate result: value, uncertainty, limits, direction, budget."""

    parameter: str
    value: float
    unit: str
    standard_uncertainty: float
    expanded_uncertainty: float
    dof: float
    lower_limit: float
    upper_limit: float
    outcome: str
    direction: str | None
    budget: tuple[BudgetLine, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class Certificate:
    """What a comparison needs from one certificate."""

    path: Path
    serial: str
    unit_type: str
    axis: str
    profile_sha256: str
    profile_sha256_without_firmware: str | None
    protocols: tuple[str, ...]
    station: Mapping[str, Any]
    software_version: str
    git_revision: str | None
    firmware_version: str | None
    method_bias_sha256: str | None
    outcome: str
    results: Mapping[str, Result]
    certificate_id: str | None = None
    warnings: tuple[str, ...] = ()  # believed with these (no digest: written before one)
    in_gimbal: bool = False  # an axis of a gimbal folder: paired by serial and axis

    @property
    def label(self) -> str:
        """How it pairs and is shown: the serial, with the axis for a gimbal's axis."""
        return f"{self.serial}/{self.axis}" if self.in_gimbal else self.serial


def load_side(path: Path) -> dict[str, Certificate]:
    """One side of a comparison, by serial.

    Parameters
    ----------
    path : Path
        A ``certificate.json``, a unit directory holding one, a gimbal's folder (its
        ``gimbal-certificate.json`` names each axis's certificate), or a directory of unit
        or gimbal directories (``DIR/SERIAL/``; ``history/`` is not read).

    Returns
    -------
    dict of str to Certificate
        By :attr:`Certificate.label`: the serial, ``SERIAL/AXIS`` for a gimbal's axis.

    Raises
    ------
    InputError
        Missing path, no certificate found, unreadable JSON, schema mismatch, the same
        serial twice.
    """
    if not path.exists():
        raise InputError("no such file or directory", source=str(path))
    files = _files(path)
    if not files:
        raise InputError(f"no {CERTIFICATE_FILE} here nor in DIR/SERIAL/{CERTIFICATE_FILE}",
                         source=str(path))
    side: dict[str, Certificate] = {}
    for file, in_gimbal in files:
        certificate = replace(read_certificate(file), in_gimbal=in_gimbal)
        if certificate.label in side:
            raise InputError(f"serial {certificate.label} also in {side[certificate.label].path}",
                             source=str(file))
        side[certificate.label] = certificate
    return side


def read_certificate(path: Path) -> Certificate:
    """Read one ``certificate.json`` with the certificate's own reader
    (:func:`hil.certificate.model.read_certificate`), then check what a comparison
    relies on beyond its types: each parameter once, finite numbers, non-negative
    uncertainties, a known direction, a budget of Type A and B lines."""
    cert = model.read_certificate(path)
    at = _Reader(path)
    by_name: dict[str, Result] = {}
    for i, entry in enumerate(cert.results):
        result = _result(at, entry, f"results[{i}]")
        if result.parameter in by_name:
            raise at.error(f"results[{i}].parameter", f"{result.parameter!r} appears twice")
        by_name[result.parameter] = result
    drive = cert.drive
    station: dict[str, Any] = {"kind": drive.kind,
                               **{key: drive.info.get(key)
                                  for key in ("vendor", "model", "transport")}}
    station["transport"] = _stable_transport(station["transport"])
    # verified before believed: digest, recordings' SHA-256, outcomes (integrity.py, which
    # reads the raw JSON: the digest covers its bytes)
    document = json.loads(path.read_bytes())
    verification = verify_document(document, path=path, unit_dir=path.parent)
    if verification.refusals:
        raise InputError(verification.refusal(), source=str(path))
    for warning in verification.warnings:
        log.warning("%s: %s", path, warning)
    bias = cert.method.method_bias
    return Certificate(
        path=path,
        serial=cert.unit.serial,
        unit_type=cert.unit.unit_type,
        axis=cert.unit.axis,
        profile_sha256=cert.method.profile_sha256,
        profile_sha256_without_firmware=cert.method.profile_sha256_without_firmware,
        protocols=tuple(cert.method.protocols),
        station=station,
        software_version=cert.software.version,
        git_revision=cert.software.git_revision,
        firmware_version=drive.firmware_version,
        method_bias_sha256=bias.sha256 if bias is not None else None,
        outcome=cert.outcome,
        results=by_name,
        certificate_id=verification.certificate_id,
        warnings=verification.warnings,
    )


def same_certificates(baseline: Path, candidate: Path) -> list[str]:
    """One line per certificate that is on both sides (the same certificate id): a
    comparison of a run with itself shows nothing, whatever changed since.

    Parameters
    ----------
    baseline, candidate : Path
        The two sides as :func:`load_side` takes them.

    Returns
    -------
    list of str
        Empty when no id is on both sides, or a side cannot be read or verified
        (:func:`load_side` says why, in one line).
    """
    try:
        ids = [_ids(side) for side in (baseline, candidate)]
    except (OSError, ValueError, RecursionError):
        return []
    return [f"{ids[0][same]} and {ids[1][same]} are the same certificate ({same}): the "
            "run is compared with itself" for same in sorted(set(ids[0]) & set(ids[1]))]


def _files(path: Path) -> list[tuple[Path, bool]]:
    """The certificates a side names (each with whether it is a gimbal's axis): the file,
    the unit directory's, a gimbal's axes, or those of each serial's directory."""
    if path.is_file():
        return [(path, False)]
    if (path / CERTIFICATE_FILE).is_file():
        return [(path / CERTIFICATE_FILE, False)]
    if (path / GIMBAL_FILE).is_file():
        return [(file, True) for file in _gimbal_axes(path)]
    found: list[tuple[Path, bool]] = []
    for folder in sorted(path.iterdir()):
        if (folder / CERTIFICATE_FILE).is_file():
            found.append((folder / CERTIFICATE_FILE, False))
        elif (folder / GIMBAL_FILE).is_file():
            found += [(file, True) for file in _gimbal_axes(folder)]
    return found


def _gimbal_axes(folder: Path) -> list[Path]:
    """Each axis's certificate a gimbal certificate names (an axis never certified is not
    there: the comparison says MISSING or NEW for its results)."""
    try:
        document = json.loads((folder / GIMBAL_FILE).read_text(encoding="utf-8"))
        axes = document["axes"]
        files = [folder / axis["certificate"] for axis in axes if axis.get("certificate")]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"not a gimbal certificate: {exc}",
                         source=str(folder / GIMBAL_FILE)) from exc
    return files


def _ids(path: Path) -> dict[str, Path]:
    """Certificate id → file, for the certificates :func:`load_side` would read."""
    found: dict[str, Path] = {}
    for file, _ in _files(path):
        document = json.loads(file.read_bytes())
        if not isinstance(document, dict):
            raise ValueError(f"{file}: not a certificate")
        if verify_document(document, path=file, unit_dir=file.parent).refusals:
            raise ValueError(f"{file}: not verified")
        certificate_id = document.get("certificate_id")
        if isinstance(certificate_id, str):
            found[certificate_id] = file
    return found


def _stable_transport(transport: object) -> object:
    """The transport without an emulator's per-run endpoint (channel name, loopback port)."""
    if not isinstance(transport, str):
        return transport
    for pattern, stable in _EPHEMERAL:
        transport = pattern.sub(stable, transport)
    return transport


def _result(at: _Reader, entry: model.Result, where: str) -> Result:
    if entry.direction is not None and entry.direction not in DIRECTIONS:
        raise at.error(f"{where}.direction",
                       f"is {entry.direction!r}, expected 'higher' or 'lower'")
    if not entry.budget:
        raise at.error(f"{where}.budget", "is empty (every result has at least one line)")
    return Result(
        parameter=entry.parameter,
        value=at.number(entry.value, f"{where}.value"),
        unit=entry.unit,
        standard_uncertainty=at.number(entry.standard_uncertainty,
                                       f"{where}.standard_uncertainty", non_negative=True),
        expanded_uncertainty=at.number(entry.expanded_uncertainty,
                                       f"{where}.expanded_uncertainty", non_negative=True),
        dof=at.dof(entry.degrees_of_freedom, f"{where}.degrees_of_freedom"),
        lower_limit=at.number(entry.lower_limit, f"{where}.lower_limit"),
        upper_limit=at.number(entry.upper_limit, f"{where}.upper_limit"),
        outcome=entry.outcome,
        direction=entry.direction,
        budget=tuple(_line(at, line, f"{where}.budget[{j}]")
                     for j, line in enumerate(entry.budget)),
    )


def _line(at: _Reader, line: model.BudgetLine, where: str) -> BudgetLine:
    if line.kind not in ("A", "B"):
        raise at.error(f"{where}.type", f"is {line.kind!r}, expected 'A' or 'B'")
    return BudgetLine(
        source=line.component,
        kind="A" if line.kind == "A" else "B",
        standard_uncertainty=at.number(line.standard_uncertainty,
                                       f"{where}.standard_uncertainty", non_negative=True),
        sensitivity=at.number(line.sensitivity, f"{where}.sensitivity"),
        dof=at.dof(line.degrees_of_freedom, f"{where}.degrees_of_freedom"),
    )


class _Reader:
    """The checks beyond the certificate's types; errors name the file and the JSON path."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def error(self, where: str, message: str) -> InputError:
        return InputError(f"{where} {message}" if where else message, source=str(self.path))

    def number(self, value: float, where: str, *, non_negative: bool = False) -> float:
        if not math.isfinite(value) or (non_negative and value < 0):
            raise self.error(where, f"is {value}, expected a finite"
                             + (" non-negative" if non_negative else "") + " number")
        return float(value)

    def dof(self, value: float | None, where: str) -> float:
        """Degrees of freedom: ``null`` means infinitely many (Type B)."""
        if value is None:
            return math.inf
        value = self.number(value, where, non_negative=True)
        if value <= 0:
            raise self.error(where, f"is {value}, expected a positive number or null")
        return value
