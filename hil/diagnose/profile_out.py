"""The extended model as a unit profile (TOML) that ``gimbal-hil simulate`` accepts.

The ``[plant]`` table follows :mod:`plant_sim.params`: the base parameters, every named
cause mapped onto its simulator fields, and the data effects the diagnosis measured
(encoder resolution, effort noise, velocity filter, effort limit, and the velocity PI
gains when the recording carries a velocity command). The profile round-trips through
:func:`hil.profile.load_profile`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import tomli_w

from hil.diagnose import interpret
from hil.diagnose.model import Fit
from hil.errors import ProfileError
from hil.profile import profile_from_mapping
from plant_sim.firmware import FIRMWARE_KEYS, firmware_from_mapping, firmware_to_mapping
from plant_sim.params import plant_from_mapping, plant_to_mapping

if TYPE_CHECKING:
    from hil.diagnose.core import Diagnosis
    from hil.recording import Recording


def _positive(value: float) -> float:
    return max(float(value), 0.0)


def model_fields(fit: Fit) -> dict[str, Any]:
    """``PlantParams`` fields of a fitted model (mechanics only).

    Parameters
    ----------
    fit : Fit

    Returns
    -------
    dict of str to Any
        The base fields and those of every effect in ``fit``. Friction, stiffness and
        hysteresis are clipped at 0; with a ``two_mass`` term ``inertia_kg_m2`` is the
        motor's; an inertia that is not positive is replaced by ``|J|`` (or 1e-9) to keep
        the profile loadable.
    """
    values = fit.as_dict()
    inertia = values["inertia"]
    fields: dict[str, Any] = {
        "inertia_kg_m2": inertia,
        "viscous_nm_s_rad": _positive(values["viscous"]),
        "coulomb_nm": _positive(values["coulomb"]),
    }
    effects = fit.model.effects
    if "offset" in effects:
        fields["torque_offset_nm"] = values["offset"]
    if "asymmetric_friction" in effects:
        fields["viscous_neg_nm_s_rad"] = _positive(values["viscous"]
                                                   + values["viscous_neg_delta"])
        half = 0.5 * values.get("coulomb_neg_delta", 0.0)  # the model: T_c·sgn ω − 2·half
        fields["coulomb_nm"] = _positive(values["coulomb"] - half)
        fields["coulomb_neg_nm"] = _positive(values["coulomb"] + half)
    if "stribeck" in effects:
        term = fit.model.term("stribeck")
        fields["static_friction_nm"] = _positive(values["coulomb"] + values["stribeck_delta"])
        if term is not None:
            fields["stribeck_velocity_rad_s"] = term.nonlinear["stribeck_velocity"]
    for effect, key in (("cogging", "cogging"), ("kt_ripple", "kt_ripple")):
        if effect in effects:
            rows = interpret.effect_parameters(effect, fit)["parameters"]["orders"]
            name = "amplitude_nm" if effect == "cogging" else "relative_amplitude"
            fields[key] = [
                {"order": int(r["periods_per_rev"]), "amplitude": float(r[name]),
                 "phase_rad": float(r["phase_rad"])}
                for r in rows
            ]
    if "gravity" in effects:
        named = interpret.effect_parameters("gravity", fit)["parameters"]
        fields["gravity_mge_nm"] = named["mge_nm"]
        fields["gravity_phase_rad"] = named["phase_rad"]
    if "cable_spring" in effects:
        named = interpret.effect_parameters("cable_spring", fit)["parameters"]
        fields["cable_stiffness_nm_rad"] = _positive(named["stiffness_nm_per_rad"])
        fields["cable_zero_rad"] = named["zero_rad"]
        fields["cable_hysteresis_nm"] = _positive(named.get("hysteresis_nm", 0.0))
        if "hysteresis_angle_rad" in named:
            fields["cable_hysteresis_angle_rad"] = named["hysteresis_angle_rad"]
    if "current_lag" in effects:
        fields["current_loop_time_constant_s"] = fit.model.lag_s
    if "two_mass" in effects:
        two = interpret.two_mass_parameters(fit)
        fields["inertia_kg_m2"] = two["motor_inertia_kg_m2"]
        fields["load_inertia_kg_m2"] = values["load_inertia"]
        fields["shaft_stiffness_nm_rad"] = two["shaft_stiffness_nm_rad"]
        fields["shaft_damping_nm_s_rad"] = two["shaft_damping_nm_s_rad"]
    if not fields["inertia_kg_m2"] > 0:
        fields["inertia_kg_m2"] = abs(inertia) or 1e-9  # keep the profile loadable
    return fields


def velocity_pi_gains(recording: Recording) -> tuple[float, float] | None:
    """``(kp, ki)`` of ``T = kp·e + ki·∫e dt``, ``e = v_cmd − v``, when that explains T.

    Parameters
    ----------
    recording : Recording
        Its velocity command, reported velocity, effort and timestamps.

    Returns
    -------
    (float, float) or None
        ``kp``, ``ki`` by least squares; ``None`` without a velocity command, when they
        explain less than 90 % of the effort's variance (or the effort is constant), or
        when ``kp ≤ 0`` or ``ki < 0``.
    """
    command = recording.velocity_cmd
    if command is None:
        return None
    error = command - recording.velocity
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (error[1:] + error[:-1])
                                                 * np.diff(recording.time_s))))
    matrix = np.column_stack((error, integral))
    effort = recording.effort
    coef, *_ = np.linalg.lstsq(matrix, effort, rcond=None)
    residual = effort - matrix @ coef
    spread = float(np.sum((effort - effort.mean()) ** 2))
    if spread == 0.0:  # a constant effort: nothing for the gains to explain
        return None
    explained = 1.0 - float(residual @ residual) / spread
    if explained < 0.9 or coef[0] <= 0 or coef[1] < 0:
        return None
    return float(coef[0]), float(coef[1])


def data_fields(diagnosis: Diagnosis) -> dict[str, Any]:
    """Simulator fields for the data effects measured in the recording.

    Parameters
    ----------
    diagnosis : Diagnosis

    Returns
    -------
    dict of str to Any
        From the data issues, when found: ``encoder_counts_per_rev``,
        ``torque_noise_nm``, ``velocity_filter_hz`` (when finite), ``torque_limit_nm``;
        from :func:`velocity_pi_gains`: ``velocity_kp_nm_s_rad``, ``velocity_ki_nm_rad``.
    """
    fields: dict[str, Any] = {}
    for issue in diagnosis.issues:
        values = issue.values
        if issue.kind == "quantisation" and isinstance(values.get("counts_per_rev"), int):
            fields["encoder_counts_per_rev"] = values["counts_per_rev"]
        elif issue.kind == "effort_noise":
            fields["torque_noise_nm"] = float(values["std"])
        elif issue.kind == "velocity_filter_lag" and math.isfinite(
                values["equivalent_cutoff_hz"]):
            fields["velocity_filter_hz"] = float(values["equivalent_cutoff_hz"])
        elif issue.kind == "saturation":
            fields["torque_limit_nm"] = abs(float(values["level"]))
    gains = velocity_pi_gains(diagnosis.recording)
    if gains is not None:
        fields["velocity_kp_nm_s_rad"], fields["velocity_ki_nm_rad"] = gains
    return fields


def extended_plant(diagnosis: Diagnosis) -> dict[str, Any]:
    """The ``[plant]`` table of the extended model (validated by ``plant_sim``).

    Parameters
    ----------
    diagnosis : Diagnosis

    Returns
    -------
    dict of str to Any
        :func:`model_fields` of :attr:`Diagnosis.final` and :func:`data_fields`, as
        ``plant_sim`` writes them.

    Raises
    ------
    ProfileError
        They do not make a valid plant.
    """
    fields = model_fields(diagnosis.final)
    fields.update(data_fields(diagnosis))
    plant, _ = split_firmware(fields)
    try:
        return plant_to_mapping(plant_from_mapping(plant, source="extended model"))
    except ProfileError as exc:
        raise ProfileError(f"extended model is not a valid plant: {exc}") from exc


def split_firmware(fields: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Simulator fields split into the ``[plant]`` table's and the ``[firmware]`` table's
    (the drive's velocity loop, filter and current-loop lag).

    Parameters
    ----------
    fields : dict of str to Any
        From :func:`model_fields` and :func:`data_fields`.

    Returns
    -------
    plant, firmware : dict of str to Any
    """
    firmware = {k: v for k, v in fields.items() if k in FIRMWARE_KEYS}
    plant = {k: v for k, v in fields.items() if k not in FIRMWARE_KEYS}
    return plant, firmware


def extended_firmware(diagnosis: Diagnosis) -> dict[str, Any]:
    """The ``[firmware]`` table of the extended model: what the recording shows of the
    drive's controller (velocity PI, filter, current-loop lag), the rest at its defaults.

    Raises
    ------
    ProfileError
        The values do not make a valid firmware.
    """
    fields = model_fields(diagnosis.final)
    fields.update(data_fields(diagnosis))
    _, firmware = split_firmware(fields)
    firmware.setdefault("version", "diagnosed")
    return firmware_to_mapping(firmware_from_mapping(firmware, source="extended model"))


def extended_profile(diagnosis: Diagnosis) -> dict[str, Any]:
    """A complete unit profile around :func:`extended_plant`.

    Parameters
    ----------
    diagnosis : Diagnosis

    Returns
    -------
    dict of str to Any
        ``unit``, ``limits`` (1.5 × the largest recorded speed, the plant's torque limit
        or 1.5 × the largest effort, the recorded travel widened by 5 % of its span on
        each side), ``drive``, ``firmware``, ``plant`` and an empty ``measurements``.

    Raises
    ------
    ProfileError
        The extended model is not a valid plant.
    """
    recording = diagnosis.recording
    position = np.asarray(recording.position)
    margin = 0.05 * float(np.ptp(position)) + 1e-6
    effort_max = float(np.max(np.abs(recording.effort)))
    plant = extended_plant(diagnosis)
    torque_limit = plant.get("torque_limit_nm", 1.5 * effort_max)
    return {
        "unit": {
            "type": f"diagnosed from {Path(recording.source).name}",
            "axis": recording.metadata.get("axis", "unknown"),
            "axis_kind": recording.axis_kind,
            "description": ("extended model written by gimbal-hil diagnose; effects: "
                            + (", ".join(diagnosis.cause_names) or "none")),
        },
        "limits": {
            "velocity_rad_s": 1.5 * float(np.max(np.abs(recording.velocity))) + 1e-6,
            "torque_nm": max(float(torque_limit), 1e-6),
            "travel_min_rad": float(np.min(position)) - margin,
            "travel_max_rad": float(np.max(position)) + margin,
        },
        "drive": {"sample_rate_hz": diagnosis.signals.fs_hz},
        "firmware": extended_firmware(diagnosis),
        "plant": plant,
        "measurements": {},
    }


def write_profile(diagnosis: Diagnosis, path: str | Path) -> Path:
    """Write the extended profile as TOML; it is checked by the profile loader first.

    Parameters
    ----------
    diagnosis : Diagnosis
    path : str or Path
        Its directory is created when missing.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ProfileError
        The profile does not load.
    """
    data = extended_profile(diagnosis)
    path = Path(path)
    profile_from_mapping(data, source=str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    header = ("# Extended model written by `gimbal-hil diagnose` (see docs/diagnose.md).\n"
              "# On a linear axis the rotary field names hold linear units (kg, N, m).\n")
    path.write_text(header + tomli_w.dumps(data), encoding="utf-8")
    return path
