"""Hand-made certificate JSON for the compare tests (the schema the certificate writes)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

METHOD_LINE = "method: error over 50 simulated units beyond Type A (mean +0.2 % corrected)"
TAU_LINE = "current-loop time constant τ taken out (current_loop)"


def line(source: str, kind: str, u: float, *, sensitivity: float = 1.0,
         dof: float | None = None) -> dict[str, Any]:
    """One budget line as ``Measurement.as_dict`` writes it."""
    return {"component": source, "type": kind, "standard_uncertainty": u, "unit": "",
            "sensitivity": sensitivity, "contribution": abs(sensitivity) * u,
            "degrees_of_freedom": dof}


def result(name: str, value: float, *, u_a: float, u_method: float = 0.0,
           dof_a: float | None = 20.0, lower: float = 0.0, upper: float = 2.0,
           direction: str | None = None, unit: str = "N·m") -> dict[str, Any]:
    """A result with a Type A line (and a method line when ``u_method``)."""
    budget = [line("measurement noise: scatter of the data (Type A)", "A", u_a, dof=dof_a)]
    if u_method:
        budget.append(line(METHOD_LINE, "B", u_method))
    u = (u_a**2 + u_method**2) ** 0.5
    return {"parameter": name, "protocol": "p", "value": value, "unit": unit,
            "standard_uncertainty": u, "coverage_factor": 2.0, "expanded_uncertainty": 2 * u,
            "degrees_of_freedom": dof_a, "nominal": (lower + upper) / 2,
            "lower_limit": lower, "upper_limit": upper, "outcome": "PASS",
            "budget": budget, "direction": direction}


def certificate(serial: str = "U-1", results: list[dict[str, Any]] | None = None, *,
                profile_sha: str = "p" * 64, version: str = "0.1.0",
                transport: str = "in-process") -> dict[str, Any]:
    """A minimal ``gimbal-hil/certificate/v1`` document."""
    return {
        "schema": "gimbal-hil/certificate/v1",
        "unit": {"serial": serial, "type": "GMB-2 elevation axis", "axis": "elevation"},
        "method": {"profile": "x.toml", "profile_sha256": profile_sha,
                   "profile_sha256_without_firmware": "f" * 64,
                   "protocols": {"current_loop": {}, "inertia_friction": {}},
                   "method_bias": {"file": "m.toml", "sha256": "m" * 64}},
        "drive": {"kind": "sim", "vendor": "gimbal-hil", "model": "plant_sim",
                  "firmware_version": "0.1.0", "transport": transport},
        "software": {"name": "gimbal-hil", "version": version, "git_revision": "abc"},
        "results": copy.deepcopy(results if results is not None else [
            result("coulomb_nm", 1.0, u_a=0.01, u_method=0.05),
            result("bandwidth_hz", 1.0, u_a=0.01, direction="higher"),
        ]),
        "outcome": "PASS",
    }


def write(path: Path, document: dict[str, Any]) -> Path:
    """Write ``document`` as ``path`` (a ``…/SERIAL/certificate.json``); returns it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(document), encoding="utf-8")
    return path
