"""Human-readable rendering of a certificate (:class:`hil.certificate.model.Certificate`),
and the wording every reading of it shares (``certificate.txt`` here, the HTML and PDF
through :mod:`hil.report.view`): every line labelled, no Python literals, no paths of the
machine that ran it, limits one-sided where the quantity is, each skipped protocol once
with its reason."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from datetime import datetime
from pathlib import PureWindowsPath
from typing import Any

from hil.certificate.model import Certificate, Result, as_certificate
from hil.gum import rounded_pair, significant

NOT_AUTHORISED = "not authorised"
NOT_STATED = "not stated"
#: What each protocol is, for a reader (the code name stays beside it).
PROTOCOL_TITLES: dict[str, str] = {
    "current_loop": "Current loop",
    "gravity_cable": "Gravity unbalance and cable",
    "inertia_friction": "Inertia and friction",
    "cogging": "Cogging and torque-constant ripple",
    "stribeck": "Low-speed (Stribeck) friction",
    "torque_constant": "Torque constant",
    "resonance": "Resonance",
    "inertia_elevation": "Azimuth inertia across elevation",
    "cross_coupling": "Cross-coupling between the axes",
    "velocity_loop_frf": "Velocity-loop frequency response",
    "velocity_step": "Velocity steps",
    "tracking": "Tracking a standard move",
    "standstill": "Standstill",
    "cogging_compensation": "Cogging compensation",
}
# "skipped: test_x[param]: Skipped: reason" (pytest's words) → "reason"
_SKIP_PREFIX = re.compile(r"^skipped: (?:[\w.]+(?:\[[^\]]*\])?: )?(?:Skipped: )?")


def file_name(path: str) -> str:
    """The base name of a path as a certificate stores it (an old certificate kept the
    absolute path of the machine that ran it: POSIX or Windows)."""
    return PureWindowsPath(path).name if path else ""


def yes_no(flag: object) -> str:
    """A flag as words, never ``True``/``False``."""
    return "yes" if flag else "no"


def when(stamp: str) -> str:
    """``2026-11-27T08:55:29+00:00`` → ``2026-11-27 08:55:29 UTC`` (else as written)."""
    try:
        moment = datetime.fromisoformat(stamp)
    except (TypeError, ValueError):
        return str(stamp)
    offset = moment.utcoffset()
    zone = "UTC" if offset is not None and not offset else moment.strftime("%z") or ""
    return f"{moment:%Y-%m-%d %H:%M:%S} {zone}".strip()


def title_of(result: Result) -> str:
    """A result's title; a certificate written before titles existed has its code name."""
    return result.shown_title


def limits_text(result: Result) -> str:
    """The acceptance limits as a reader expects them: ``0.21 to 0.39``; one-sided
    (``≤ 20``) for a size by nature (``non_negative``) with a lower limit at or below zero,
    or when one limit is infinite."""
    lower, upper = float(result.lower_limit), float(result.upper_limit)
    if result.non_negative and lower <= 0:
        lower = -math.inf
    if not math.isfinite(lower) and not math.isfinite(upper):
        return "none"
    if not math.isfinite(lower):
        return f"≤ {upper:.4g}"
    if not math.isfinite(upper):
        return f"≥ {lower:.4g}"
    return f"{lower:.4g} to {upper:.4g}"


def protocol_messages(messages: Sequence[str]) -> list[str]:
    """A protocol's messages, each once: a skip says its reason once, not once per result
    with pytest's test id."""
    seen: list[str] = []
    for message in messages:
        text = str(message)
        if text.startswith("skipped: "):
            text = "skipped: " + _SKIP_PREFIX.sub("", text)
        if text not in seen:
            seen.append(text)
    return seen


def environment_text(cert: Certificate) -> str:
    """The environmental conditions the station declares, or that it records none."""
    env = cert.environment
    parts = []
    if env.temperature_c is not None:
        parts.append(f"temperature {env.temperature_c:g} °C")
    if env.humidity_pct is not None:
        parts.append(f"relative humidity {env.humidity_pct:g} %")
    if env.note:
        parts.append(env.note)
    if not parts:
        return "not recorded by the station"
    return ", ".join(parts) + " (declared by the station, not measured in this run)"


def certificate_fields(document: Certificate | Mapping[str, Any]) -> list[tuple[str, str]]:
    """The ISO/IEC 17025 7.8 items of a certificate as (label, text) pairs, in reading order.

    Parameters
    ----------
    document : Certificate or mapping
        The certificate (``certificate.json`` as read: old ones without the laboratory
        fields too).

    Returns
    -------
    list of (str, str)
    """
    cert = as_certificate(document)
    unit, dates, drive, software, method = (cert.unit, cert.dates, cert.drive, cert.software,
                                            cert.method)
    run, lab = cert.run, cert.laboratory
    ran = method.ran()
    unit_type = unit.unit_type
    axis = unit.axis
    kind = "" if not axis or axis in unit_type.lower() else f", {axis} axis"
    simulated = cert.conditions.simulated if cert.conditions else None
    drive_text = (" ".join(v or "" for v in (drive.kind, drive.vendor, drive.model)).strip()
                  + f", firmware {drive.firmware_version or NOT_STATED}")
    for key, value in (("serial", drive.serial), ("transport", drive.transport)):
        if value:
            drive_text += f", {key} {value}"
    if simulated is not None:
        drive_text += f"; simulated: {yes_no(simulated)}"
    bias = method.method_bias
    station = (run.station if run else None) or NOT_STATED
    operator = (run.operator if run else None) or NOT_STATED
    fields = [
        ("Certificate id", cert.certificate_id),
        ("Laboratory", ", ".join(v for v in (lab.name, lab.address) if v) or NOT_STATED),
        ("Customer", cert.customer or NOT_STATED),
        ("Unit", f"serial {unit.serial}, type {unit_type}{kind}"),
        ("Calibration started", when(dates.calibration_started)),
        ("Issued", when(dates.issued)),
        ("Authorised by", cert.authorised_by or NOT_AUTHORISED),
        ("Station and operator", f"station {station}, operator {operator}"
         + ("; a reference (golden) unit" if run and run.reference else "")),
        ("Environment", environment_text(cert)),
        ("Method", "gimbal-hil calibration suite: "
                   + (", ".join(PROTOCOL_TITLES.get(n, n).lower() for n in ran)
                      or "no protocol ran")),
        ("Unit profile", f"{file_name(method.profile)} (SHA-256 {method.profile_sha256})"),
        ("Method-bias map", f"{file_name(bias.file if bias else '')} "
                            f"(SHA-256 {(bias.sha256 if bias else '') or NOT_STATED})"),
        ("Software", f"gimbal-hil {software.version}, revision "
                     f"{software.git_revision or 'unknown'}, Python "
                     f"{software.python or 'unknown'}"),
        ("Drive", drive_text),
        ("Machine time", f"{cert.machine_time.motion_time_s:.1f} s of motion, "
                         f"{cert.machine_time.wall_time_s:.1f} s wall"),
        ("Accreditation", cert.accreditation),
    ]
    return fields


def render_text(document: Certificate | Mapping[str, Any]) -> str:
    """``certificate.txt``: the certificate as plain text."""
    cert = as_certificate(document)
    fields = certificate_fields(cert)
    width = max(len(label) for label, _ in fields)
    authorised = cert.authorised_by
    lines = [
        cert.title,
        "=" * len(cert.title),
        f"OUTCOME: {cert.outcome}" + ("" if authorised else f" ({NOT_AUTHORISED})"),
        "",
        *(f"{label:<{width}} : {text}" for label, text in fields),
        "",
        "Values as GUM 7.2.6 asks: U (k ≈ 2, ~95 %) to two significant digits, the value to",
        "the same decimal place; certificate.json keeps full precision.",
        "",
        f"{'result':<40}{'value':>13}{'U':>11} {'(k)':<7}{'unit':<11}{'limits':<22}"
        f"{'outcome':<10}code name",
    ]
    for r in cert.results:
        value, expanded = rounded_pair(r.value, r.expanded_uncertainty)
        lines.append(
            f"{title_of(r):<40}{value:>13}{expanded:>11} ({r.coverage_factor:.2f}) "
            f"{r.unit:<11}{limits_text(r):<22}{r.outcome:<10}{r.parameter}"
        )
    missing = cert.not_measured
    if missing:
        lines += ["", "Not measured (declared by the profile):"]
        lines += [f"  {m.parameter:<38}{'required' if m.required else 'optional':<10}"
                  f"{m.protocol}: {protocol_messages([m.reason])[0]}" for m in missing]
    lines += _budgets(cert.results)
    lines += ["", "Protocols:"]
    for name, p in cert.method.protocols.items():
        lines.append(f"  {name:<24}{p.outcome:<14}motion {p.motion_time_s:.1f} s")
        lines += [f"      {message}" for message in protocol_messages(p.messages)]
    lines += ["", "Raw data (SHA-256):"]
    lines += [f"  {f.file}  {f.sha256}" + (f"  (held: {f.held_axes})" if f.held_axes else "")
              for f in cert.raw_data]
    if cert.artifacts:
        lines += ["", "Derived files (SHA-256):"]
        lines += [f"  {a.file}  {a.sha256}  {a.description}" for a in cert.artifacts]
    lines += [
        "",
        f"Decision rule: {cert.decision_rule}",
        "",
        f"OUTCOME: {cert.outcome}. {cert.conformity}",
        f"Authorised by: {authorised or NOT_AUTHORISED}",
        "",
    ]
    return "\n".join(lines)


def with_unit(text: str, unit: str) -> str:
    """``text unit``, without a dangling space for a result with no unit (a ratio)."""
    return f"{text} {unit}" if unit else text


def _budgets(results: Sequence[Result]) -> list[str]:
    """Per result its uncertainty budget (GUM 8): each input's u(xᵢ), sensitivity cᵢ,
    contribution |cᵢ|·u(xᵢ) in the result's unit and its share of u²."""
    lines = ["", "Uncertainty budgets (standard uncertainties, k = 1; share of u²):"]
    for r in results:
        u = r.standard_uncertainty
        value, expanded = rounded_pair(r.value, r.expanded_uncertainty)
        lines.append(f"  {title_of(r)} ({r.parameter}): "
                     f"{with_unit(f'{value} ± {expanded}', r.unit)} "
                     f"(k = {r.coverage_factor:.2f}), "
                     f"u = {with_unit(significant(u), r.unit)}")
        if r.description:
            lines.append(f"    {r.description}")
        for line in r.budget:
            share = (line.contribution / u) ** 2 if u else 0.0
            lines.append(
                f"    {line.kind}  u(x) = {significant(line.standard_uncertainty):<9}"
                f"{line.unit:<11} c = {line.sensitivity:<9.3g} "
                f"→ {significant(line.contribution):<9}{100 * share:>4.0f} %  "
                f"{line.component}"
            )
        if r.validation:
            lines.append(f"    {r.validation.sentence()}")
    return lines
