"""The axis certificate, typed: ``certificate.json`` (schema :data:`SCHEMA`) as frozen
dataclasses, with one writer (:meth:`Certificate.to_json`) and one reader
(:func:`read_certificate`).

The JSON keeps the field names (a field may name its key in ``metadata["json"]`` when the
key is a Python word: ``unit.type``); tuples become lists and come back as tuples; a nested
dataclass becomes an object, in field order, so the writer's bytes are the ones
:mod:`hil.certificate.build` always wrote. A number is kept as JSON gave it (an integer
stays an integer), so write → read → write gives the same document.

A field with a default may be absent from what is read: the certificate was written
before the field existed (old certificates still read). A key marked ``omit`` in its
metadata is left out when its value is ``None`` or empty, as the writer always did (a
recording's ``held_axes``, the environment's undeclared conditions, the digest of a
certificate written before digests). Any other absent key, a mistyped or an unknown one,
or another schema, is refused in one line naming the file and the key
(:class:`CertificateError`).

What stays untyped here, on purpose: a protocol's ``method.details`` (typed per protocol
by :mod:`hil.details`, read with the suite's catalogue by :mod:`hil.report.data`) and the
drive's own description beside its kind (:class:`hil.drives.base.DriveInfo` as the drive
stated it; drives of other versions state other fields).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from hil.errors import InputError

#: The schema string of an axis certificate, declared once.
SCHEMA = "gimbal-hil/certificate/v1"
#: Every overall outcome a certificate states, best first.
OUTCOMES = ("PASS", "MARGINAL", "INCOMPLETE", "FAIL", "ERROR")

T = TypeVar("T")


class CertificateError(InputError):
    """A certificate that does not read as :class:`Certificate` (naming file and key)."""


def _omit() -> dict[str, object]:
    return {"omit": True}


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Laboratory:
    """The station file's laboratory (``None``: the file does not state it)."""

    name: str | None = None
    address: str | None = None


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Environment:
    """The environmental conditions the station file declares (not measured by the run);
    an undeclared one is not written."""

    temperature_c: float | None = dataclasses.field(default=None, metadata=_omit())
    humidity_pct: float | None = dataclasses.field(default=None, metadata=_omit())
    note: str | None = dataclasses.field(default=None, metadata=_omit())


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Unit:
    """The unit calibrated: serial, type, axis."""

    serial: str
    unit_type: str = dataclasses.field(metadata={"json": "type"})
    axis: str = ""


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class RunInfo:
    """The run: its id, which attempt of this serial, station, operator, reference unit."""

    id: str
    attempt: int
    station: str | None
    operator: str | None
    reference: bool


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Dates:
    """ISO 8601 time stamps (seconds)."""

    calibration_started: str
    issued: str


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class ProtocolRecord:
    """One protocol's outcome (``PASS`` … ``SKIPPED``, ``NOT_COMPLETED``), times, messages."""

    outcome: str
    motion_time_s: float
    wall_time_s: float
    messages: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class MethodBias:
    """The method-bias map applied, by file name and SHA-256."""

    file: str
    sha256: str


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Method:
    """The profile, the protocols as they ran, the method-bias map, each protocol's details."""

    profile: str
    profile_sha256: str
    profile_sha256_without_firmware: str | None = dataclasses.field(default=None,
                                                                    metadata=_omit())
    protocols: Mapping[str, ProtocolRecord]
    method_bias: MethodBias | None = dataclasses.field(default=None, metadata=_omit())
    #: per protocol its details as JSON (typed by :mod:`hil.details`, read by the report)
    details: Mapping[str, Mapping[str, Any]] = dataclasses.field(default_factory=dict)

    def ran(self) -> list[str]:
        """The protocols that ran (not skipped), in run order."""
        return [name for name, p in self.protocols.items() if p.outcome != "SKIPPED"]


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class MachineTime:
    """Motion and wall time over every protocol (s)."""

    motion_time_s: float
    wall_time_s: float


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Drive:
    """The drive: its kind, and what it stated of itself (``DriveInfo`` as written)."""

    kind: str
    #: every other key, as the drive stated it (written after ``kind``)
    info: Mapping[str, Any] = dataclasses.field(default_factory=dict,
                                                metadata={"rest": True})

    def _text(self, key: str) -> str | None:
        value = self.info.get(key)
        return None if value is None else str(value)

    @property
    def vendor(self) -> str | None:
        return self._text("vendor")

    @property
    def model(self) -> str | None:
        return self._text("model")

    @property
    def firmware_version(self) -> str | None:
        return self._text("firmware_version")

    @property
    def serial(self) -> str | None:
        return self._text("serial")

    @property
    def transport(self) -> str | None:
        return self._text("transport")


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Conditions:
    """The drive kind, and whether the plant was simulated (emulators too)."""

    drive_kind: str
    simulated: bool


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Software:
    """The software that ran the calibration."""

    name: str
    version: str
    git_revision: str | None = None
    python: str | None = None


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class RawFile:
    """A raw recording, relative to the certificate's folder, with its SHA-256."""

    protocol: str
    excitation: str
    file: str
    sha256: str
    samples: int
    complete: bool
    #: where a gimbal's other axes stood, held by their drives ("" : none, not written)
    held_axes: str = dataclasses.field(default="", metadata=_omit())


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Artifact:
    """A derived file (compensation table, controller parameters) with its SHA-256."""

    protocol: str
    file: str
    sha256: str
    description: str


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class BudgetLine:
    """One line of a result's uncertainty budget (GUM 8)."""

    component: str
    kind: str = dataclasses.field(metadata={"json": "type"})  # "A" or "B"
    standard_uncertainty: float
    unit: str
    sensitivity: float
    contribution: float
    degrees_of_freedom: float | None  # None: infinitely many (Type B)


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Validation:
    """The method-bias map's out-of-sample check of a result's ±U."""

    coverage: float
    units: int | None
    note: str = ""

    def sentence(self) -> str:
        """What a reader is told under the result's budget."""
        note = f": {self.note}" if self.note else ""
        return (f"validated: ±U held the truth for {100 * self.coverage:.0f} % of "
                f"{self.units} simulated units{note}")


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Result:
    """One judged result: value, U (k), limits, outcome, budget."""

    parameter: str
    title: str = ""  # "" : written before titles (the code name is shown)
    description: str = ""
    non_negative: bool = False
    protocol: str
    value: float
    unit: str
    standard_uncertainty: float
    coverage_factor: float
    expanded_uncertainty: float
    degrees_of_freedom: float | None
    cramer_rao_std: float | None = None
    nominal: float | None = None
    lower_limit: float
    upper_limit: float
    marginal_fraction: float = 0.1
    outcome: str
    budget: tuple[BudgetLine, ...] = ()
    validation: Validation | None = None
    direction: str | None = None  # "higher", "lower" is better; None: neither

    @property
    def shown_title(self) -> str:
        """Its title; its code name for a certificate written before titles."""
        return self.title or self.parameter

    def to_json(self) -> dict[str, Any]:
        """The result as JSON values, as the certificate's ``results`` holds it."""
        return typing.cast(dict[str, Any], _to_json(self))


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class NotMeasured:
    """A result the profile declares and the run did not measure, with why."""

    parameter: str
    protocol: str
    reason: str
    required: bool


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Integrity:
    """The digest of the certificate's content (:mod:`hil.certificate.integrity`)."""

    content_sha256: str
    canonicalization: str


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Certificate:
    """An axis certificate (ISO/IEC 17025 7.8 structure), as ``certificate.json`` holds it.

    Fields in the order they are written; the JSON key is the field's name (``unit.type``,
    a budget line's ``type``: ``metadata["json"]``).
    """

    schema: str = SCHEMA
    certificate_id: str
    title: str
    accreditation: str
    laboratory: Laboratory = Laboratory()
    customer: str | None = None
    authorised_by: str | None = None
    environment: Environment = Environment()
    unit: Unit
    run: RunInfo | None = None
    dates: Dates
    method: Method
    machine_time: MachineTime
    drive: Drive
    conditions: Conditions | None = None
    software: Software
    raw_data: tuple[RawFile, ...]
    artifacts: tuple[Artifact, ...] = ()
    results: tuple[Result, ...]
    not_measured: tuple[NotMeasured, ...] = ()
    decision_rule: str
    outcome: str
    aborted: bool
    conformity: str
    integrity: Integrity | None = dataclasses.field(default=None, metadata=_omit())

    def to_json(self) -> dict[str, Any]:
        """The certificate as JSON values (the one writer): ``json.dumps(…, indent=2)``
        gives ``certificate.json`` as :mod:`hil.certificate.build` writes it."""
        return typing.cast(dict[str, Any], _to_json(self))

    @classmethod
    def from_json(cls, document: object, *, source: str = "certificate") -> Certificate:
        """:func:`read_certificate` of an already parsed document (``source`` names it)."""
        if not isinstance(document, Mapping):
            raise CertificateError(f"not a JSON object but {type(document).__name__}: "
                                   "not a certificate", source=source)
        schema = document.get("schema")
        if schema != SCHEMA:
            raise CertificateError(
                f"schema {schema!r} is not {SCHEMA!r} (another version of gimbal-hil)"
                if str(schema).startswith(SCHEMA.rsplit("/", 1)[0] + "/")
                else f"not a gimbal-hil certificate (schema {schema!r})", source=source)
        certificate = _read(cls, document, "", source)
        if certificate.outcome not in OUTCOMES:
            raise CertificateError(f"outcome is {certificate.outcome!r}, expected one of "
                                   f"{', '.join(OUTCOMES)}", source=source)
        return certificate

    def results_of(self, protocol: str) -> tuple[Result, ...]:
        """The results a protocol measured, in certificate order."""
        return tuple(r for r in self.results if r.protocol == protocol)

    def result(self, parameter: str) -> Result | None:
        """The result of ``parameter``, or ``None`` when the run has none."""
        return next((r for r in self.results if r.parameter == parameter), None)


def read_certificate(source: Path | str | Mapping[str, Any]) -> Certificate:
    """Read an axis certificate (the one reader).

    Parameters
    ----------
    source : Path, str or mapping
        A ``certificate.json`` (or the unit directory holding one), or the document already
        parsed.

    Returns
    -------
    Certificate

    Raises
    ------
    CertificateError
        Unreadable, not JSON, another schema, a key missing, unknown or of another type:
        one line naming the file and the key (``results[2].value``).
    """
    if isinstance(source, Mapping):
        return Certificate.from_json(source)
    path = Path(source)
    if path.is_dir():
        path = path / "certificate.json"
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CertificateError(f"cannot read: {exc.strerror or exc}",
                               source=str(path)) from None
    try:
        document = json.loads(data)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise CertificateError(f"not JSON: {exc}", source=str(path)) from None
    return Certificate.from_json(document, source=str(path))


def as_certificate(cert: Certificate | Mapping[str, Any]) -> Certificate:
    """``cert`` itself, or the document read as one (:meth:`Certificate.from_json`)."""
    return cert if isinstance(cert, Certificate) else Certificate.from_json(cert)


# the writer and reader: field by field, by the dataclasses' declared types


def _key(field: dataclasses.Field[Any]) -> str:
    return str(field.metadata.get("json", field.name))


def _to_json(value: object) -> object:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out: dict[str, object] = {}
        for f in dataclasses.fields(value):
            item = getattr(value, f.name)
            if f.metadata.get("rest"):
                out.update({str(k): _to_json(v) for k, v in item.items()})
            elif not (f.metadata.get("omit") and (item is None or item in ("", (), {}))):
                out[_key(f)] = _to_json(item)
        return out
    if isinstance(value, list | tuple):
        return [_to_json(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _to_json(v) for k, v in value.items()}
    return value


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _path(where: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{where}[{key}]"
    return f"{where}.{key}" if where else key


def _read(cls: type[T], raw: object, where: str, source: str) -> T:
    if not isinstance(raw, Mapping):
        raise CertificateError(f"{where or 'the document'} must be an object, not "
                               f"{_kind(raw)}", source=source)
    fields = dataclasses.fields(typing.cast(Any, cls))
    rest = next((f for f in fields if f.metadata.get("rest")), None)
    keys = {_key(f): f for f in fields if not f.metadata.get("rest")}
    unknown = [str(k) for k in raw if k not in keys]
    if unknown and rest is None:
        raise CertificateError(f"{_path(where, unknown[0])} is not a key of a certificate "
                               f"of {SCHEMA}", source=source)
    hints = _hints(typing.cast(type, cls))
    values: dict[str, object] = {}
    for key, field in keys.items():
        if key in raw:
            values[field.name] = _value(hints[field.name], raw[key], _path(where, key), source)
        elif (field.default is dataclasses.MISSING
              and field.default_factory is dataclasses.MISSING):
            raise CertificateError(f"{_path(where, key)} is missing", source=source)
    if rest is not None:
        values[rest.name] = {str(k): raw[k] for k in unknown}
    return cls(**values)


def _kind(raw: object) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean",
            int: "a number", float: "a number", type(None): "null"}.get(
        type(raw), type(raw).__name__)


def _value(hint: Any, raw: object, where: str, source: str) -> object:
    origin = typing.get_origin(hint)
    arguments = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if raw is None and type(None) in arguments:
            return None
        options = [a for a in arguments if a is not type(None)]
        if len(options) == 1:
            return _value(options[0], raw, where, source)
        raise CertificateError(f"{where}: a field type this reader lacks", source=source)
    if hint is Any or hint is object:
        return raw
    if dataclasses.is_dataclass(hint):
        return _read(typing.cast(type, hint), raw, where, source)
    if origin is tuple:
        if not isinstance(raw, list):
            raise CertificateError(f"{where} must be a list, not {_kind(raw)}", source=source)
        item = arguments[0] if arguments else Any
        return tuple(_value(item, v, _path(where, i), source) for i, v in enumerate(raw))
    if origin in (Mapping, dict) or hint is dict:
        if not isinstance(raw, Mapping):
            raise CertificateError(f"{where} must be an object, not {_kind(raw)}",
                                   source=source)
        item = arguments[1] if len(arguments) == 2 else Any
        return {str(k): _value(item, v, _path(where, str(k)), source) for k, v in raw.items()}
    if hint is float:  # an integer stays one: the same bytes written back
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise CertificateError(f"{where} must be a number, not {_kind(raw)}",
                                   source=source)
        return raw
    if hint is int:
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise CertificateError(f"{where} must be an integer, not {_kind(raw)}",
                                   source=source)
        return raw
    if hint in (str, bool):
        if not isinstance(raw, hint):
            raise CertificateError(f"{where} must be a {'string' if hint is str else 'boolean'}"
                                   f", not {_kind(raw)}", source=source)
        return raw
    raise CertificateError(f"{where}: a field type this reader lacks ({hint})", source=source)
