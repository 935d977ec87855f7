"""The certificate as a person reads it: every number already rounded (GUM 7.2.6 via
:mod:`hil.gum`), every field labelled. Both the HTML and the PDF lay out this one view, so
they cannot disagree; ``certificate.json`` stays the record at full precision."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from hil.gum import rounded_pair

#: What the banner says for each overall outcome: the word, and a line under it.
BANNER: dict[str, tuple[str, str]] = {
    "PASS": ("PASS", "every result inside its limits"),
    "MARGINAL": ("MARGINAL", "conforms; a result is marginal or its U reaches a limit"),
    "FAIL": ("FAIL", "the unit does NOT conform"),
    "ERROR": ("NOT COMPLETED", "the calibration did not complete: NO conformity statement"),
}


def certificate_view(cert: Mapping[str, Any]) -> dict[str, Any]:
    """The certificate's content for reading, in display order.

    Parameters
    ----------
    cert : mapping
        ``certificate.json`` as read (or as :func:`hil.certificate.build_certificate` made it).

    Returns
    -------
    dict
        ``id``, ``title``, ``outcome``, ``banner`` (word, line), ``fields`` (label, text
        pairs: the ISO/IEC 17025 7.8 items), ``results``, ``budgets``, ``protocols``,
        ``raw_data``, ``artifacts``, ``decision_rule``, ``conformity``, ``accreditation``;
        all text.
    """
    outcome = str(cert["outcome"])
    word, line = BANNER.get(outcome, (outcome, ""))
    if cert.get("aborted"):
        line = "the run was ABORTED: " + line
    return {
        "id": cert["certificate_id"],
        "title": cert["title"],
        "outcome": outcome,
        "passed": outcome in ("PASS", "MARGINAL"),
        "banner": {"word": word, "line": line},
        "fields": _fields(cert),
        "results": [_result(r) for r in cert["results"]],
        "budgets": [_budget(r) for r in cert["results"]],
        "protocols": [_protocol(name, p) for name, p in cert["method"]["protocols"].items()],
        "raw_data": [{"file": f["file"], "sha256": f["sha256"]} for f in cert["raw_data"]],
        "artifacts": [{"file": a["file"], "sha256": a["sha256"], "description": a["description"]}
                      for a in cert["artifacts"]],
        "decision_rule": cert["decision_rule"],
        "conformity": cert["conformity"],
        "accreditation": cert["accreditation"],
    }


def _fields(cert: Mapping[str, Any]) -> list[tuple[str, str]]:
    unit, dates, drive = cert["unit"], cert["dates"], cert["drive"]
    software, method = cert["software"], cert["method"]
    ran = [n for n, p in method["protocols"].items() if p["outcome"] != "SKIPPED"]
    fields = [
        ("Certificate id", cert["certificate_id"]),
        ("Unit", f"serial {unit['serial']}, {unit['type']}, {unit['axis']} axis"),
        ("Calibration started", dates["calibration_started"]),
        ("Issued", dates["issued"]),
        ("Method", "gimbal-hil calibration suite: " + ", ".join(ran)),
        ("Unit profile", method["profile"]),
        ("Profile SHA-256", method["profile_sha256"]),
        ("Method-bias map", f"{method['method_bias']['file']} "
                            f"(SHA-256 {method['method_bias']['sha256'] or '—'})"),
        ("Software", f"gimbal-hil {software['version']}, revision "
                     f"{software.get('git_revision') or 'unknown'}, Python "
                     f"{software.get('python', '?')}"),
        ("Drive", " ".join(str(drive.get(k, "")) for k in ("kind", "vendor", "model")).strip()
         + f", firmware {drive.get('firmware_version', '?')}, serial "
           f"{drive.get('serial', '?')}, transport {drive.get('transport', '?')}"),
        ("Station and conditions", _pairs(cert.get("conditions", {}))),
    ]
    if cert.get("station"):
        fields.append(("Station", _pairs(cert["station"]) if isinstance(cert["station"], dict)
                       else str(cert["station"])))
    if cert.get("environment"):
        fields.append(("Environment", _pairs(cert["environment"])
                       if isinstance(cert["environment"], dict) else str(cert["environment"])))
    machine = cert["machine_time"]
    fields.append(("Machine time", f"{machine['motion_time_s']:.1f} s of motion, "
                                   f"{machine['wall_time_s']:.1f} s wall"))
    return fields


def _pairs(mapping: Mapping[str, Any]) -> str:
    return ", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in mapping.items())


def _result(r: Mapping[str, Any]) -> dict[str, str]:
    value, expanded = rounded_pair(r["value"], r["expanded_uncertainty"])
    return {
        "parameter": r["parameter"],
        "value": value,
        "U": expanded,
        "k": f"{r['coverage_factor']:.2f}",
        "unit": r["unit"],
        "nominal": f"{r['nominal']:.4g}" if r.get("nominal") is not None else "—",
        "limits": f"[{r['lower_limit']:.4g}, {r['upper_limit']:.4g}]",
        "outcome": r["outcome"],
    }


def _budget(r: Mapping[str, Any]) -> dict[str, Any]:
    u = float(r["standard_uncertainty"])
    value, expanded = rounded_pair(r["value"], r["expanded_uncertainty"])
    lines = []
    for line in r.get("budget", []):
        share = (line["contribution"] / u) ** 2 if u else 0.0
        lines.append({
            "component": line["component"],
            "type": line["type"],
            "u": f"{line['standard_uncertainty']:#.2g} {line['unit']}",
            "c": f"{line['sensitivity']:.3g}",
            "contribution": f"{line['contribution']:#.2g}",
            "share": f"{100 * share:.0f} %",
        })
    return {
        "parameter": r["parameter"],
        "summary": f"{value} ± {expanded} {r['unit']} (k = {r['coverage_factor']:.2f}); "
                   f"u = {u:#.2g} {r['unit']}",
        "lines": lines,
    }


def _protocol(name: str, p: Mapping[str, Any]) -> dict[str, Any]:
    return {
        "name": name,
        "outcome": p["outcome"],
        "motion": f"{p['motion_time_s']:.1f} s",
        "messages": list(p["messages"]),
    }
