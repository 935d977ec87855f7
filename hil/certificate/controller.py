"""Controller outputs derived from the judged measurements (the source article's use of them).

``controller.json`` (schema ``gimbal-hil/controller/v1``)::

    {
      "schema": "gimbal-hil/controller/v1",
      "certificate_id": "...", "certificate_outcome": "PASS|MARGINAL|FAIL|ERROR",
      "friction_feedforward": {            # T_ff = B·ω* + T_c·sgn(ω*)   [N·m]
        "viscous_nm_s_rad": B, "coulomb_nm": T_c,
        "static_friction_nm": T_s, "stribeck_velocity_rad_s": v_s   # when measured
      },
      "gravity_feedforward": {             # T_ff = m·g·e·cos(θ + φ)    [N·m]
        "mge_nm": ..., "phase_rad": ...
      },
      "cable_feedforward": {               # T_ff = k·θ + h·sgn(ω*) once past the loop's
        "stiffness_nm_rad": k,             # travel s₀ (Dahl); T_c above excludes h
        "hysteresis_nm": h
      },
      "inertia_kg_m2": J,                  # for acceleration feedforward J·α*
      "cogging_table": "cogging_compensation.json"   # when the cogging protocol ran
    }

Use only parameters from a certificate whose outcome is PASS or MARGINAL.
"""

from __future__ import annotations

from typing import Any

from hil.certificate.model import Certificate

SCHEMA = "gimbal-hil/controller/v1"

_FRICTION = ("viscous_nm_s_rad", "coulomb_nm", "static_friction_nm", "stribeck_velocity_rad_s")
_GRAVITY = {"gravity_mge_nm": "mge_nm", "gravity_phase_rad": "phase_rad"}
_CABLE = {"cable_stiffness_nm_rad": "stiffness_nm_rad", "cable_hysteresis_nm": "hysteresis_nm"}


def controller_outputs(certificate: Certificate) -> dict[str, Any] | None:
    """Feedforward parameters from a certificate's results; None when there are none."""
    values = {r.parameter: r.value for r in certificate.results}
    friction = {name: values[name] for name in _FRICTION if name in values}
    gravity = {key: values[name] for name, key in _GRAVITY.items() if name in values}
    cable = {key: values[name] for name, key in _CABLE.items() if name in values}
    if not friction and not gravity and "inertia_kg_m2" not in values:
        return None
    outputs: dict[str, Any] = {
        "schema": SCHEMA,
        "certificate_id": certificate.certificate_id,
        "certificate_outcome": certificate.outcome,
    }
    if friction:
        outputs["friction_feedforward"] = friction
    if gravity:
        outputs["gravity_feedforward"] = gravity
    if cable:
        outputs["cable_feedforward"] = cable
    if "inertia_kg_m2" in values:
        outputs["inertia_kg_m2"] = values["inertia_kg_m2"]
    tables = [a.file for a in certificate.artifacts if "cogging" in a.file]
    if tables:
        outputs["cogging_table"] = tables[0]
    return outputs
