"""A certificate's integrity: the digest of its content, its files' SHA-256, its outcome.

``certificate.json`` carries ``integrity.content_sha256``: SHA-256 over the canonical JSON
(sorted keys, no whitespace, ASCII) of every field but ``integrity`` itself. It already
lists each recording and derived file with its SHA-256. :func:`verify_certificate`
recomputes both, and each result's outcome and the overall outcome with the project's
decision rule (:func:`hil.measurement.judge`): an edited value, outcome, recording or a
deleted file is a problem, one line each. No signature: a digest shows an edit by someone
who did not recompute it, not who wrote the certificate (``docs/integrity.md``).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hil.errors import InputError
from hil.identify.estimate import Estimate
from hil.measurement import Outcome, judge
from hil.profile import MeasurementSpec

INTEGRITY_KEY = "integrity"
CERTIFICATE_NAME = "certificate.json"
CANONICAL = ("SHA-256 of the certificate's JSON without 'integrity': keys sorted, no "
             "whitespace, ASCII")
NO_DIGEST = ("no digest (written before gimbal-hil certificates carried one, issue 26): "
             "its content cannot be verified")
# worst last, as CalibrationRun.overall_outcome orders them (INCOMPLETE: a required
# declared result not measured, listed under "not_measured")
OUTCOME_RANK = {"PASS": 0, "MARGINAL": 1, "INCOMPLETE": 2, "FAIL": 3, "ERROR": 4}


@dataclass(frozen=True, slots=True, kw_only=True)
class Verification:
    """What :func:`verify_certificate` found, one line per problem.

    Attributes
    ----------
    path : Path
        The ``certificate.json``.
    certificate_id : str or None
        Its id, as stated.
    digest : bool
        It carries a digest (certificates written before issue 26 do not).
    content : tuple of str
        The digest does not match (or is malformed).
    files : tuple of str
        A listed recording or derived file missing, changed, outside its folder.
    outcomes : tuple of str
        A stated outcome the decision rule does not give.
    """

    path: Path
    certificate_id: str | None
    digest: bool
    content: tuple[str, ...] = ()
    files: tuple[str, ...] = ()
    outcomes: tuple[str, ...] = ()

    @property
    def problems(self) -> tuple[str, ...]:
        """Everything found, in the order checked."""
        return (*self.content, *self.files, *self.outcomes)

    @property
    def verified(self) -> bool:
        """A digest that matched, every file as listed, every outcome as the rule gives."""
        return self.digest and not self.problems

    @property
    def refusals(self) -> tuple[str, ...]:
        """What makes a reading command (compare, ingest, render) refuse it. A certificate
        without a digest cannot be shown edited or not: only its files are held to it (their
        SHA-256 were always listed); its outcome findings are warnings."""
        return self.problems if self.digest else self.files

    @property
    def warnings(self) -> tuple[str, ...]:
        """What a reading command says and still reads it."""
        return () if self.digest else (NO_DIGEST, *self.outcomes)

    def refusal(self) -> str:
        """One line for a command that refuses the certificate."""
        return "not verified: " + "; ".join(self.refusals)


def canonical_bytes(document: Mapping[str, Any]) -> bytes:
    """The canonical JSON the digest covers: every field but ``integrity``."""
    content = {key: value for key, value in document.items() if key != INTEGRITY_KEY}
    return json.dumps(content, sort_keys=True, separators=(",", ":"),
                      ensure_ascii=True).encode("ascii")


def content_digest(document: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of :func:`canonical_bytes`."""
    return hashlib.sha256(canonical_bytes(document)).hexdigest()


def seal(certificate: Mapping[str, Any]) -> dict[str, Any]:
    """The certificate as it will be read back (JSON types only) with its digest added."""
    # round trip first: the digest covers what a reader parses (tuples, paths → JSON)
    document: dict[str, Any] = json.loads(json.dumps(certificate, default=str))
    document.pop(INTEGRITY_KEY, None)
    document[INTEGRITY_KEY] = {"content_sha256": content_digest(document),
                               "canonicalization": CANONICAL}
    return document


def certificate_path(target: Path) -> Path:
    """``target`` itself, or the ``certificate.json`` in the unit directory it names."""
    return target / CERTIFICATE_NAME if target.is_dir() else target


def read_document(path: Path) -> dict[str, Any]:
    """Read a certificate as a JSON object.

    Raises
    ------
    InputError
        Missing, unreadable, empty, not JSON or not an object (naming the file).
    """
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", source=str(path)) from None
    if not data.strip():
        raise InputError(f"empty file ({len(data)} bytes): not a certificate",
                         source=str(path))
    try:
        document = json.loads(data)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InputError(f"not JSON: {exc}", source=str(path)) from None
    if not isinstance(document, dict):
        raise InputError("not a JSON object: not a certificate", source=str(path))
    return document


def verify_certificate(target: Path, *, files: bool = True) -> Verification:
    """Check a written certificate: digest, recordings' SHA-256, outcomes.

    Parameters
    ----------
    target : Path
        A ``certificate.json`` or the unit directory holding one.
    files : bool
        Also hash the recordings and derived files it lists (beside it).

    Returns
    -------
    Verification

    Raises
    ------
    InputError
        The file cannot be read as a JSON object (unreadable input, not a verdict).
    """
    path = certificate_path(target)
    document = read_document(path)
    return verify_document(document, path=path, unit_dir=path.parent if files else None)


def verify_document(document: Mapping[str, Any], *, path: Path,
                    unit_dir: Path | None) -> Verification:
    """:func:`verify_certificate` of an already parsed certificate (files in ``unit_dir``,
    not hashed when ``None``)."""
    content: list[str] = []
    files: list[str] = []
    outcomes: list[str] = []
    digest = _check_digest(document, content)
    if unit_dir is not None:
        _check_files(document, unit_dir, files)
    _check_outcomes(document, outcomes)
    certificate_id = document.get("certificate_id")
    return Verification(path=path,
                        certificate_id=certificate_id if isinstance(certificate_id, str)
                        else None,
                        digest=digest, content=tuple(content), files=tuple(files),
                        outcomes=tuple(outcomes))


def _check_digest(document: Mapping[str, Any], problems: list[str]) -> bool:
    """The stated digest against the content's; ``False`` when there is none."""
    block = document.get(INTEGRITY_KEY)
    if block is None:
        return False
    stated = block.get("content_sha256") if isinstance(block, dict) else None
    if not isinstance(stated, str):
        problems.append("integrity.content_sha256 is missing or not a string")
        return True
    found = content_digest(document)
    if found != stated:
        problems.append(f"content changed after it was written (digest {found[:12]}… ≠ "
                        f"stated {stated[:12]}…)")
    return True


def _check_files(document: Mapping[str, Any], unit_dir: Path, problems: list[str]) -> None:
    """Every listed recording and derived file: there, inside the folder, same SHA-256."""
    root = unit_dir.resolve()
    for key, what in (("raw_data", "recording"), ("artifacts", "file")):
        entries = document.get(key, [])
        if not isinstance(entries, list):
            problems.append(f"{key} is not a list")
            continue
        for i, entry in enumerate(entries):
            name = entry.get("file") if isinstance(entry, dict) else None
            stated = entry.get("sha256") if isinstance(entry, dict) else None
            if not isinstance(name, str) or not isinstance(stated, str):
                problems.append(f"{key}[{i}] has no file and sha256")
                continue
            file = (unit_dir / name).resolve()
            if not file.is_relative_to(root):
                problems.append(f"{what} {name} lies outside the certificate's folder")
                continue
            try:
                found = _sha256(file)
            except FileNotFoundError:
                problems.append(f"{what} {name} is missing")
                continue
            except OSError as exc:
                problems.append(f"{what} {name} cannot be read: {exc.strerror or exc}")
                continue
            if found != stated:
                problems.append(f"{what} {name} changed (SHA-256 {found[:12]}… ≠ "
                                f"listed {stated[:12]}…)")


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _check_outcomes(document: Mapping[str, Any], problems: list[str]) -> None:
    """Each result's outcome by the decision rule; the overall outcome from them and the
    protocols (as :meth:`hil.calibration.CalibrationRun.overall_outcome` derives it)."""
    results = document.get("results", [])
    if not isinstance(results, list):
        problems.append("results is not a list")
        return
    judged: list[str] = []
    for i, entry in enumerate(results):
        outcome = _judged(entry, i, problems, bounded=_bounded_rule(document))
        if outcome is not None:
            judged.append(outcome)
    stated = document.get("outcome")
    if not isinstance(stated, str):
        problems.append("outcome is missing")
        return
    if stated not in OUTCOME_RANK:
        problems.append(f"outcome {stated!r} is not one of {', '.join(OUTCOME_RANK)}")
        return
    implied = _implied(document, judged)
    if implied != stated:
        problems.append(f"outcome {stated} contradicts its results and protocols "
                        f"({implied} by the decision rule)")


def stated_outcomes(document: Mapping[str, Any]) -> dict[str, Any]:
    """``document`` with each result's outcome and the overall outcome set as the decision
    rule gives them (a tool that writes a certificate of its own, a test that derives one
    run from another); seal it afterwards (:func:`seal`)."""
    restated: dict[str, Any] = json.loads(json.dumps(document))
    bounded = _bounded_rule(restated)
    judged = [_judged(entry, i, [], bounded=bounded)
              for i, entry in enumerate(restated.get("results", []))]
    for entry, outcome in zip(restated.get("results", []), judged, strict=True):
        if outcome is not None:
            entry["outcome"] = outcome
    restated["outcome"] = _implied(restated, [j for j in judged if j is not None])
    return restated


def _bounded_rule(document: Mapping[str, Any]) -> bool:
    """Whether the certificate's decision rule exempts a quantity that cannot be negative
    from a lower limit at or below zero (certificates issued before it do not)."""
    return "cannot be negative" in str(document.get("decision_rule", ""))


def _judged(entry: Any, i: int, problems: list[str], *, bounded: bool) -> str | None:
    """Result ``i``'s outcome by :func:`hil.measurement.judge` under the certificate's own
    rule (``bounded``: :func:`_bounded_rule`), checked against the stated one; ``None``
    when it cannot be judged (a problem is noted)."""
    if not isinstance(entry, dict):
        problems.append(f"results[{i}] is not an object")
        return None
    name = str(entry.get("parameter", f"results[{i}]"))
    numbers: dict[str, float] = {}
    for key in ("value", "expanded_uncertainty", "lower_limit", "upper_limit"):
        value = entry.get(key)
        if isinstance(value, bool) or not isinstance(value, int | float):
            problems.append(f"result {name}: {key} is not a number")
            return None
        numbers[key] = float(value)
    fraction = entry.get("marginal_fraction", 0.1)
    nominal = entry.get("nominal")
    if isinstance(fraction, bool) or not isinstance(fraction, int | float):
        fraction = 0.1
    if isinstance(nominal, bool) or not isinstance(nominal, int | float):
        nominal = (numbers["lower_limit"] + numbers["upper_limit"]) / 2
    spec = MeasurementSpec(name=name, unit=str(entry.get("unit", "")), nominal=float(nominal),
                           lower_limit=numbers["lower_limit"],
                           upper_limit=numbers["upper_limit"],
                           marginal_fraction=float(fraction))
    expanded = numbers["expanded_uncertainty"]
    if not math.isfinite(expanded) or expanded < 0:
        problems.append(f"result {name}: expanded_uncertainty {expanded} is not a size")
        return None
    # k = 2 at infinite degrees of freedom: judge() sees exactly the stated U
    estimate = Estimate(name=name, value=numbers["value"], standard_uncertainty=expanded / 2,
                        unit=spec.unit)
    outcome = judge(estimate, spec,
                    non_negative=bounded and entry.get("non_negative") is True).value
    stated = entry.get("outcome")
    if stated != outcome:
        problems.append(f"result {name}: outcome {stated} contradicts its value and limits "
                        f"({outcome} by the decision rule)")
    return outcome


def _implied(document: Mapping[str, Any], judged: list[str]) -> str:
    """The overall outcome the results and protocols give."""
    if document.get("aborted") is True or not judged:
        return Outcome.ERROR.value
    outcomes = list(judged)
    method = document.get("method")
    protocols = method.get("protocols") if isinstance(method, dict) else None
    for record in (protocols or {}).values() if isinstance(protocols, dict) else ():
        outcome = record.get("outcome") if isinstance(record, dict) else None
        if outcome in OUTCOME_RANK:
            outcomes.append(outcome)
        elif outcome == "NOT_COMPLETED":
            outcomes.append(Outcome.ERROR.value)
    missing = document.get("not_measured", [])
    if isinstance(missing, list) and any(isinstance(m, dict) and m.get("required")
                                         for m in missing):
        outcomes.append("INCOMPLETE")
    return max(outcomes, key=OUTCOME_RANK.__getitem__)
