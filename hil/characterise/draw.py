"""Drawing a population of units of one unit type: every ``[plant]`` parameter (and the
``[firmware]`` current-loop lag, gains and filter) across its measurement's tolerance range
(parameters without a declared measurement: ±20 %; ``T_s`` as ``T_c·(1.1 … 1.5)``, so that
every unit has the Stribeck peak ``v_s`` describes), every effect on, a noise seed each.
The friction law is drawn too (issue 30: a map no single simulator's habits shape): the
static Stribeck map with sticking or LuGre at the same T_c/T_s/v_s, its pre-sliding and
bristle damping drawn (:data:`LUGRE_SHARE`, :data:`PRESLIDING_LOG10_RAD`).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from hil.profile import resolve_profile_path

PROFILES = ("demo_gimbal_elevation", "demo_gimbal_azimuth")
NUISANCE_SPREAD = 0.2  # ± relative spread of plant parameters with no declared measurement
STRIBECK_RISE = (1.1, 1.5)  # T_s / T_c: a peak of 10–50 % (below ~10 % v_s is not defined)
LUGRE_SHARE = 0.5  # of the units whose friction is LuGre's
PRESLIDING_LOG10_RAD = (-5.0, -3.7)  # LuGre: the bristles' deflection at T_s, 10 … 200 µrad
BRISTLE_DAMPING = (0.3, 1.0)  # LuGre: σ1 = 2ζ·√(σ0·J), ζ drawn in this range

# plant parameter → the measurement whose tolerance sets its spread
MEASURED_BY = {
    "inertia_kg_m2": "inertia_kg_m2",
    "load_inertia_kg_m2": "inertia_kg_m2",
    "viscous_nm_s_rad": "viscous_nm_s_rad",
    "coulomb_nm": "coulomb_nm",
    "static_friction_nm": "static_friction_nm",
    "stribeck_velocity_rad_s": "stribeck_velocity_rad_s",
    "gravity_mge_nm": "gravity_mge_nm",
    "cable_stiffness_nm_rad": "cable_stiffness_nm_rad",
    "current_loop_time_constant_s": "current_loop_time_constant_ms",
    "shaft_stiffness_nm_rad": "antiresonance_frequency_hz",
}
# not varied: they define the station or the experiment, not the unit
FIXED = {"torque_limit_nm", "encoder_counts_per_rev", "elevation_rad", "substeps",
         "exact_torque_hold", "locked_rotor", "position_kp_1_s", "cable_zero_rad",
         "coulomb_neg_nm", "viscous_neg_nm_s_rad", "torque_offset_nm"}


def _relative_spread(profile_raw: Mapping[str, Any], measurement: str) -> float:
    spec = profile_raw.get("measurements", {}).get(measurement, {})
    return 0.9 * float(spec.get("tolerance_pct", 100 * NUISANCE_SPREAD)) / 100


def draw_plant(profile_raw: Mapping[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    """The ``[plant]`` table of a new unit: every scalar drawn across its range."""
    plant = dict(profile_raw["plant"])
    drawn: dict[str, Any] = {}
    for key, value in plant.items():
        if key in FIXED or isinstance(value, bool):
            drawn[key] = value
        elif key in ("cogging", "kt_ripple"):
            drawn[key] = [
                {**h, "amplitude": h["amplitude"] * rng.uniform(0.4, 1.8),
                 "phase_rad": rng.uniform(-math.pi, math.pi)}
                for h in value
            ]
        elif key == "torque_constant_error_rel":
            drawn[key] = rng.uniform(-0.04, 0.04)
        elif key == "gravity_phase_rad":
            drawn[key] = rng.uniform(-0.08, 0.08)
        elif key == "cable_hysteresis_nm":
            drawn[key] = value * rng.uniform(0.4, 1.8)
        elif isinstance(value, int | float):
            spread = _relative_spread(profile_raw, MEASURED_BY.get(key, ""))
            drawn[key] = value * rng.uniform(1 - spread, 1 + spread)
        else:
            drawn[key] = value
    if "gravity_mge_nm" in drawn and "gravity_phase_rad" not in drawn:
        drawn["gravity_phase_rad"] = rng.uniform(-0.08, 0.08)
    if "static_friction_nm" in drawn:  # v_s exists only with a Stribeck peak above T_c
        drawn["static_friction_nm"] = drawn["coulomb_nm"] * rng.uniform(*STRIBECK_RISE)
    return drawn


# The [firmware] numbers are drawn where the [plant] table held them before they moved
# (after the key named here), so a seed draws the same population as it did then.
DRAWN_AFTER = {"current_loop_time_constant_s": "cable_hysteresis_nm",
               "velocity_filter_hz": "torque_noise_nm",
               "velocity_kp_nm_s_rad": "velocity_filter_hz",
               "velocity_ki_nm_rad": "velocity_kp_nm_s_rad"}


def draw_unit(profile_raw: Mapping[str, Any], rng: np.random.Generator
              ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The ``[plant]`` and ``[firmware]`` tables of a new unit: the plant as
    :func:`draw_plant`, the firmware's current-loop lag across its measurement's tolerance
    and its velocity gains and filter ±20 % (the tuning each drive ships with), its version
    and switches kept."""
    firmware = dict(profile_raw.get("firmware", {}))
    merged: dict[str, Any] = {}
    for key, value in profile_raw["plant"].items():
        merged[key] = value
        for moved, after in DRAWN_AFTER.items():
            if after in merged and moved in firmware and moved not in merged:
                merged[moved] = firmware[moved]
    merged.update({k: v for k, v in firmware.items()
                   if isinstance(v, float) and k not in merged})
    drawn = draw_plant({**profile_raw, "plant": merged}, rng)
    drawn_firmware = {k: drawn.pop(k) if k in drawn else v for k, v in firmware.items()}
    lugre = rng.uniform() < LUGRE_SHARE
    presliding, damping = 10 ** rng.uniform(*PRESLIDING_LOG10_RAD), rng.uniform(*BRISTLE_DAMPING)
    if lugre:
        drawn.update(presliding_rad=float(presliding), bristle_damping_ratio=float(damping))
    return drawn, drawn_firmware


def write_population(
    directory: Path, *, units_per_profile: int, seed: int, profiles: Sequence[str] = PROFILES
) -> list[Unit]:
    """Draw ``units_per_profile`` units of each profile (a built-in name or a file); one
    TOML file each, serials from the profile's name (``demo_gimbal_`` dropped)."""
    rng = np.random.default_rng(seed)
    directory.mkdir(parents=True, exist_ok=True)
    units = []
    for name in profiles:
        path = resolve_profile_path(name)
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
        prefix = path.stem.removeprefix("demo_gimbal_")[:3].upper()
        for i in range(units_per_profile):
            serial = f"{prefix}-{i:04d}"
            unit_path = directory / f"{serial}.toml"
            plant, firmware = draw_unit(raw, rng)
            drawn = {**raw, "plant": plant, "firmware": firmware}
            unit_path.write_text(tomli_w.dumps(drawn), encoding="utf-8")
            units.append(Unit(profile_path=unit_path, serial=serial, axis=raw["unit"]["axis"],
                              seed=int(rng.integers(1, 2**31 - 1)),
                              variant=friction_law(plant)))
    return units


@dataclass(frozen=True, slots=True, kw_only=True)
class Unit:
    """One drawn unit: its profile file, seed and serial."""

    profile_path: Path
    serial: str
    seed: int
    axis: str
    variant: str = ""  # the simulator's drawn choices (friction_law)


def friction_law(plant: Mapping[str, Any]) -> str:
    """The drawn unit's friction law, as its validation groups units."""
    return "LuGre friction" if plant.get("presliding_rad", 0.0) > 0 else "static friction"
