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
