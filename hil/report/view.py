"""The certificate as a person reads it: every number already rounded (GUM 7.2.6 via
:mod:`hil.gum`), every field labelled. Both the HTML and the PDF lay out this one view, so
they cannot disagree; ``certificate.json`` stays the record at full precision."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from hil.certificate.model import Certificate, ProtocolRecord, Result, as_certificate
from hil.certificate.render import (
    NOT_AUTHORISED,
    PROTOCOL_TITLES,
    certificate_fields,
    limits_text,
    protocol_messages,
    title_of,
    with_unit,
)
from hil.gum import rounded_pair, significant

#: What the banner says for each overall outcome: the word, and a line under it.
BANNER: dict[str, tuple[str, str]] = {
    "PASS": ("PASS", "every result inside its limits"),
    "MARGINAL": ("MARGINAL", "conforms; a result is marginal or its U reaches a limit"),
    "FAIL": ("FAIL", "the unit does NOT conform"),
    "ERROR": ("NOT COMPLETED", "the calibration did not complete: NO conformity statement"),
    "INCOMPLETE": ("INCOMPLETE", "required results were not measured: NO conformity statement"),
}


def certificate_view(document: Certificate | Mapping[str, Any]) -> dict[str, Any]:
    """The certificate's content for reading, in display order.

    Parameters
    ----------
    document : Certificate or mapping
        The certificate (:func:`hil.certificate.model.read_certificate`, or
        ``certificate.json`` as parsed, read here).

    Returns
    -------
    dict
        ``id``, ``title``, ``outcome``, ``banner`` (word, line), ``authorised_by`` (a name
        or "not authorised"), ``fields`` (label, text pairs: the ISO/IEC 17025 7.8 items),
        ``results``, ``not_measured`` (declared results without a value, with why),
        ``groups`` (the results by protocol, in run order), ``budgets``,
        ``protocols``, ``raw_data``, ``artifacts``, ``decision_rule``, ``conformity``,
        ``accreditation``; all text.
    """
    cert = as_certificate(document)
    outcome = cert.outcome
    word, line = BANNER.get(outcome, (outcome, ""))
    if cert.aborted:
        line = "the run was ABORTED: " + line
    results = [_result(r) for r in cert.results]
    return {
        "schema": cert.schema,  # the PDF names it beside the certificate.json it embeds
        "id": cert.certificate_id,
        "title": cert.title,
        "outcome": outcome,
        "passed": outcome in ("PASS", "MARGINAL"),
        "banner": {"word": word, "line": line},
        "authorised": bool(cert.authorised_by),
        "authorised_by": cert.authorised_by or NOT_AUTHORISED,
        "fields": [list(pair) for pair in certificate_fields(cert)],
        "results": results,
        "not_measured": not_measured(cert),
        "groups": _groups(results, cert.method.protocols),
        "budgets": [_budget(r) for r in cert.results],
        "protocols": [_protocol(name, p) for name, p in cert.method.protocols.items()],
        # where a gimbal's other axes stood, held by their drives, beside each recording
        "raw_data": [{"file": f.file + (f" (held: {f.held_axes})" if f.held_axes else ""),
                      "sha256": f.sha256} for f in cert.raw_data],
        "artifacts": [{"file": a.file, "sha256": a.sha256, "description": a.description}
                      for a in cert.artifacts],
        "decision_rule": cert.decision_rule,
        "conformity": cert.conformity,
        "accreditation": cert.accreditation,
    }


def not_measured(cert: Certificate) -> list[dict[str, str]]:
    """The declared results the run has no value of (``certificate.json``'s
    ``not_measured``; none in certificates written before it)."""
    return [{"parameter": m.parameter,
             "protocol": PROTOCOL_TITLES.get(m.protocol, m.protocol),
             "required": "required" if m.required else "optional",
             "reason": protocol_messages([m.reason])[0]}
            for m in cert.not_measured]


def _result(r: Result) -> dict[str, str]:
    value, expanded = rounded_pair(r.value, r.expanded_uncertainty)
    return {
        "parameter": r.parameter,
        "title": title_of(r),
        "description": r.description,
        "protocol": r.protocol,
        "value": value,
        "U": expanded,
        "k": f"{r.coverage_factor:.2f}",
        "unit": r.unit,
        "nominal": f"{r.nominal:.4g}" if r.nominal is not None else "—",
        "limits": limits_text(r),
        "outcome": r.outcome,
    }


def _groups(results: list[dict[str, str]], protocols: Mapping[str, ProtocolRecord]
            ) -> list[dict[str, Any]]:
    """The results by protocol, in the order the protocols ran."""
    order = list(protocols)
    names = order + sorted({r["protocol"] for r in results} - set(order))
    groups = []
    for name in names:
        rows = [r for r in results if r["protocol"] == name]
        if rows:
            record = protocols.get(name)
            groups.append({"name": name, "title": PROTOCOL_TITLES.get(name, name),
                           "outcome": record.outcome if record else "",
                           "results": rows})
    return groups


def _budget(r: Result) -> dict[str, Any]:
    u = float(r.standard_uncertainty)
    value, expanded = rounded_pair(r.value, r.expanded_uncertainty)
    lines = []
    for line in r.budget:
        share = (line.contribution / u) ** 2 if u else 0.0
        lines.append({
            "component": line.component,
            "type": line.kind,
            "u": with_unit(significant(line.standard_uncertainty), line.unit),
            "c": f"{line.sensitivity:.3g}",
            "contribution": significant(line.contribution),
            "share": f"{100 * share:.0f} %",
        })
    return {
        "parameter": r.parameter,
        "title": title_of(r),
        "description": r.description,
        "summary": f"{with_unit(f'{value} ± {expanded}', r.unit)} "
                   f"(k = {r.coverage_factor:.2f}); u = {with_unit(significant(u), r.unit)}",
        "lines": lines,
        "validated": r.validation.sentence() if r.validation else "",
    }


def _protocol(name: str, p: ProtocolRecord) -> dict[str, Any]:
    return {
        "name": name,
        "title": PROTOCOL_TITLES.get(name, name),
        "outcome": p.outcome,
        "motion": f"{p.motion_time_s:.1f} s",
        "messages": protocol_messages(p.messages),
    }
