"""The gimbal certificate: the gimbal's identity, a section per axis (its certificate's id,
file and SHA-256, its verdict and results) and one verdict, the worst of its axes'. Written
as ``gimbal-certificate.json`` and ``.txt`` beside the axes' folders; each axis keeps its
full certificate (budgets, plots, recordings) in its own folder."""

from __future__ import annotations

import hashlib
import json
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from hil.certificate.gimbal_file import GIMBAL_FILE, GIMBAL_SCHEMA
from hil.certificate.integrity import OUTCOME_RANK
from hil.certificate.model import Certificate, CertificateError
from hil.gimbal.profile import GimbalProfile
from hil.gum import rounded_pair

SCHEMA, FILE = GIMBAL_SCHEMA, GIMBAL_FILE
NOT_STARTED = -1  # an axis's exit code when an earlier axis stopped the gimbal


@dataclass(frozen=True, slots=True, kw_only=True)
class AxisOutcome:
    """What one axis's calibration left: its certificate (``None``: none was written) and
    the calibration's exit code."""

    name: str
    certificate: Path | None
    exit_code: int


def verdict(outcomes: Sequence[str]) -> str:
    """The gimbal's verdict: the worst of its axes' (the certificate's order; unknown
    outcomes count as ERROR, an axis without a certificate is one)."""
    return max(outcomes, key=lambda o: OUTCOME_RANK.get(o, OUTCOME_RANK["ERROR"]),
               default="ERROR")


def build(gimbal: GimbalProfile, *, serial: str, folder: Path,
          axes: Sequence[AxisOutcome],
          together: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The gimbal certificate as a JSON-ready dict (paths relative to ``folder``);
    ``together``: the shared gimbal's clock when the axes ran at the same time
    (:func:`together_time`)."""
    issued = datetime.now(UTC)
    sections = [_section(axis, folder) for axis in axes]
    return {
        "schema": SCHEMA,
        "certificate_id": f"{serial}-{issued:%Y%m%dT%H%M%SZ}-{uuid.uuid4().hex[:8]}",
        "gimbal": {"serial": serial, "part_number": gimbal.part_number,
                   "revision": gimbal.revision, "description": gimbal.description,
                   "profile": Path(gimbal.source).name, "profile_sha256": gimbal.sha256},
        "issued": issued.isoformat(timespec="seconds"),
        "axes": sections,
        "cycle_time": cycle_time(sections, together),
        "outcome": verdict([s["outcome"] for s in sections]),
    }


def cycle_time(sections: Sequence[Mapping[str, Any]],
               together: Mapping[str, Any] | None = None) -> dict[str, Any] | None:
    """The gimbal's motion time: each axis's (its certificate's), their sum (the axes run
    one after the other) and that sum over the slowest axis's (1.0 would be every axis at
    once); with ``together``, the gimbal's own clock over the slowest axis's instead, and
    which protocols ran beside which. ``None`` when an axis has no certificate."""
    found = {s["axis"]: s.get("motion_time_s") for s in sections}
    times = {axis: float(t) for axis, t in found.items() if isinstance(t, int | float) and t > 0}
    if not times or len(times) != len(found):
        return None
    total, slowest = sum(times.values()), max(times.values())
    if together is None:
        return {"motion_time_s": times, "one_after_the_other_s": total,
                "slowest_axis_s": slowest, "ratio_to_slowest": total / slowest}
    own = together["own_motion_s"]
    slowest_own = max(own.values())
    return {"motion_time_s": times, "together_s": together["gimbal_s"],
            "own_motion_s": own, "one_after_the_other_s": sum(own.values()),
            "beside": together["beside"],
            "declared_beside": together.get("declared_beside", {}),
            "slowest_axis_s": slowest_own,
            "ratio_to_slowest": together["gimbal_s"] / slowest_own}


def together_time(gimbal_s: float, own_motion_s: Mapping[str, float],
                  intervals: Sequence[tuple[str, str, float, float]],
                  declared: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The shared gimbal's clock, each axis's own motion on it (its runs, and the other
    axis's moves it commanded: more than its certificate's protocol motion, which leaves
    out the moves between excitations) and the protocols that overlapped: ``intervals``
    are (axis, protocol, start, end) in seconds; ``declared``: the pairs the gimbal profile
    lets run together (``azimuth X beside elevation Y``) and why."""
    beside = []
    for axis, protocol, start, end in intervals:
        for other, theirs, their_start, their_end in intervals:
            overlap = min(end, their_end) - max(start, their_start)
            if axis < other and overlap > 0:
                beside.append({axis: protocol, other: theirs, "overlap_s": round(overlap, 3)})
    return {"gimbal_s": round(gimbal_s, 3),
            "own_motion_s": {axis: round(t, 3) for axis, t in own_motion_s.items()},
            "beside": beside, "declared_beside": dict(declared or {})}


def cycle_time_text(cycle: Mapping[str, Any] | None) -> str:
    """``azimuth 127.2 s, elevation 98.0 s; one after the other 225.2 s, 1.77 × the
    slowest axis``, or why there is no figure."""
    if cycle is None:
        return "not stated: an axis has no certificate"
    each = ", ".join(f"{axis} {t:.1f} s" for axis, t in cycle["motion_time_s"].items())
    if "together_s" in cycle:
        own = ", ".join(f"{axis} {t:.1f} s" for axis, t in cycle["own_motion_s"].items())
        pairs = "; ".join(" beside ".join(f"{axis} {name}" for axis, name in pair.items()
                                           if axis != "overlap_s")
                          + f" ({pair['overlap_s']:.1f} s)" for pair in cycle["beside"])
        declared = "".join(f". Declared by the gimbal profile: {pair} ({why})"
                           for pair, why in cycle.get("declared_beside", {}).items())
        return (f"protocols {each}. With the moves between them {own}, one after the "
                f"other {cycle['one_after_the_other_s']:.1f} s. At the same time "
                f"{cycle['together_s']:.1f} s, {cycle['ratio_to_slowest']:.2f} × the "
                f"slowest axis ({pairs or 'no protocols beside each other'}){declared}")
    return (f"{each}; one after the other {cycle['one_after_the_other_s']:.1f} s, "
            f"{cycle['ratio_to_slowest']:.2f} × the slowest axis")


def _section(axis: AxisOutcome, folder: Path) -> dict[str, Any]:
    if axis.certificate is None or not axis.certificate.is_file():
        note = ("not started: an earlier axis stopped the gimbal"
                if axis.exit_code == NOT_STARTED else
                "no certificate was written (the calibration was refused or stopped before "
                "it; see its console output)")
        return {"axis": axis.name, "outcome": "ERROR", "certificate": None,
                "exit_code": axis.exit_code, "note": note, "results": []}
    payload = axis.certificate.read_bytes()
    try:
        cert = Certificate.from_json(json.loads(payload), source=str(axis.certificate))
    except (ValueError, CertificateError) as exc:  # not JSON, or not an axis certificate
        return {"axis": axis.name, "outcome": "ERROR", "certificate": None,
                "exit_code": axis.exit_code, "note": f"its certificate does not read: {exc}",
                "results": []}
    outcome = "ERROR" if cert.aborted else cert.outcome
    return {
        "axis": axis.name,
        "outcome": outcome,
        "certificate": axis.certificate.relative_to(folder).as_posix(),
        "certificate_id": cert.certificate_id,
        "certificate_sha256": hashlib.sha256(payload).hexdigest(),
        "unit_type": cert.unit.unit_type,
        "exit_code": axis.exit_code,
        "motion_time_s": cert.machine_time.motion_time_s,
        # null title: an axis certificate written before titles
        "results": [{"parameter": r.parameter, "title": r.title or None, "value": r.value,
                     "expanded_uncertainty": r.expanded_uncertainty, "unit": r.unit,
                     "outcome": r.outcome}
                    for r in cert.results],
    }


def rounded_results(axis: Mapping[str, Any]) -> list[dict[str, str]]:
    """An axis section's results as a person reads them: title, code name, value and U as
    GUM asks (U to two significant digits, the value to the same decimal), unit, outcome."""
    rows = []
    for r in axis["results"]:
        if r["value"] is None or r["expanded_uncertainty"] is None:
            continue
        value, u = rounded_pair(r["value"], r["expanded_uncertainty"])
        rows.append({"title": r["title"] or r["parameter"], "name": r["parameter"],
                     "value": value, "u": u, "unit": r["unit"], "outcome": r["outcome"]})
    return rows


def text(certificate: dict[str, Any]) -> str:
    """The certificate for a person: identity, verdict, then each axis's results (values
    and U as GUM asks: U to two significant digits, the value to the same decimal)."""
    g = certificate["gimbal"]
    lines = [f"Gimbal calibration certificate {certificate['certificate_id']}",
             f"Gimbal {g['serial']}: part number {g['part_number']}"
             + (f" revision {g['revision']}" if g["revision"] else "")
             + (f" ({g['description']})" if g["description"] else ""),
             f"Gimbal profile {g['profile']} (SHA-256 {g['profile_sha256']})",
             f"Issued {certificate['issued']}",
             f"Verdict: {certificate['outcome']} (the worst of its "
             f"{len(certificate['axes'])} axes)",
             f"Motion time: {cycle_time_text(certificate.get('cycle_time'))}", ""]
    for axis in certificate["axes"]:
        lines.append(f"Axis {axis['axis']}: {axis['outcome']}")
        if axis["certificate"] is None:
            lines += [f"  {axis['note']}", ""]
            continue
        lines.append(f"  certificate {axis['certificate_id']} ({axis['certificate']}, "
                     f"SHA-256 {axis['certificate_sha256']})")
        rows = [(r["title"], f"{r['value']} ± {r['u']}", r["unit"], r["outcome"])
                for r in rounded_results(axis)]
        widths = [max((len(row[i]) for row in rows), default=0) for i in range(3)]
        lines += [f"  {t:<{widths[0]}}  {v:>{widths[1]}}  {u:<{widths[2]}}  {o}"
                  for t, v, u, o in rows]
        lines.append("")
    return "\n".join(lines)


def write(certificate: dict[str, Any], folder: Path) -> tuple[Path, Path]:
    """``gimbal-certificate.json`` and ``.txt`` in ``folder``; an earlier gimbal
    certificate there (its four files) moves to ``history/ITS_ID/`` first."""
    json_path = folder / FILE
    if json_path.is_file():
        try:
            earlier = str(json.loads(json_path.read_bytes())["certificate_id"])
        except (ValueError, KeyError, TypeError):
            earlier = f"unreadable-{uuid.uuid4().hex[:8]}"
        target = folder / "history" / earlier
        target.mkdir(parents=True, exist_ok=True)
        for old in folder.glob(f"{Path(FILE).stem}.*"):
            old.rename(target / old.name)
    json_path.write_text(json.dumps(certificate, indent=2) + "\n", encoding="utf-8")
    text_path = json_path.with_suffix(".txt")
    text_path.write_text(text(certificate) + "\n", encoding="utf-8")
    return json_path, text_path
