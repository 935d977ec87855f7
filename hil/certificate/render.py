"""Human-readable rendering of a certificate dictionary."""

from __future__ import annotations

from typing import Any

from hil.gum import rounded_pair


def render_text(cert: dict[str, Any]) -> str:
    unit, dates = cert["unit"], cert["dates"]
    lines = [
        cert["title"],
        "=" * len(cert["title"]),
        f"Certificate id : {cert['certificate_id']}",
        f"Unit           : {unit['serial']} ({unit['type']}, {unit['axis']} axis)",
        f"Calibrated     : {dates['calibration_started']}   issued {dates['issued']}",
        f"Drive          : {cert['drive'].get('kind')} {cert['drive'].get('vendor', '')} "
        f"{cert['drive'].get('model', '')} fw {cert['drive'].get('firmware_version', '?')}",
        f"Software       : gimbal-hil {cert['software']['version']} "
        f"({cert['software']['git_revision'] or 'no git revision'})",
        f"Profile        : {cert['method']['profile']} "
        f"(sha256 {cert['method']['profile_sha256'][:12]}…)",
        f"Machine time   : {cert['machine_time']['motion_time_s']:.1f} s of motion, "
        f"{cert['machine_time']['wall_time_s']:.1f} s wall",
        "",
        "Values as GUM 7.2.6 asks: U (k ≈ 2, ~95 %) to two significant digits, the value to",
        "the same decimal place; certificate.json keeps full precision.",
        "",
        f"{'parameter':<32}{'value':>13}{'U':>11} {'(k)':<7}{'unit':<11}{'limits':<25}outcome",
    ]
    for r in cert["results"]:
        limits = f"[{r['lower_limit']:.4g}, {r['upper_limit']:.4g}]"
        value, expanded = rounded_pair(r["value"], r["expanded_uncertainty"])
        lines.append(
            f"{r['parameter']:<32}{value:>13}{expanded:>11} ({r['coverage_factor']:.2f}) "
            f"{r['unit']:<11}{limits:<25}{r['outcome']}"
        )
    lines += _budgets(cert["results"])
    lines += ["", "Protocols:"]
    for name, p in cert["method"]["protocols"].items():
        lines.append(f"  {name:<24}{p['outcome']:<14}motion {p['motion_time_s']:.1f} s")
        lines += [f"      {message}" for message in p["messages"]]
    lines += ["", "Raw data (SHA-256):"]
    lines += [f"  {f['file']}  {f['sha256']}" for f in cert["raw_data"]]
    if cert["artifacts"]:
        lines += ["", "Derived files (SHA-256):"]
        lines += [f"  {a['file']}  {a['sha256']}  {a['description']}" for a in cert["artifacts"]]
    lines += [
        "",
        f"Decision rule: {cert['decision_rule']}",
        "",
        f"OUTCOME: {cert['outcome']}. {cert['conformity']}",
        "",
    ]
    return "\n".join(lines)


def _budgets(results: list[dict[str, Any]]) -> list[str]:
    """Per result its uncertainty budget (GUM 8): each input's u(xᵢ), sensitivity cᵢ,
    contribution |cᵢ|·u(xᵢ) in the result's unit and its share of u²."""
    lines = ["", "Uncertainty budgets (standard uncertainties, k = 1; share of u²):"]
    for r in results:
        u = r["standard_uncertainty"]
        lines.append(f"  {r['parameter']} (u = {u:#.2g} {r['unit']}, "
                     f"U = {r['expanded_uncertainty']:#.2g}, k = {r['coverage_factor']:.2f})")
        for line in r.get("budget", []):
            share = (line["contribution"] / u) ** 2 if u else 0.0
            lines.append(
                f"    {line['type']}  u(x) = {line['standard_uncertainty']:<#9.2g}"
                f"{line['unit']:<11} c = {line['sensitivity']:<9.3g} "
                f"→ {line['contribution']:<#9.2g}{100 * share:>4.0f} %  {line['component']}"
            )
        validation = r.get("validation")
        if validation:
            note = f": {validation['note']}" if validation.get("note") else ""
            lines.append(f"    validated: ±U held the truth for {100 * validation['coverage']:.0f} "
                         f"% of {validation['units']} simulated units{note}")
    return lines
