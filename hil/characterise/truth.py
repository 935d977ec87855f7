"""What each result claims to measure, from the drawn plant's parameters.

Truth map (``truths``): what each result claims to measure, from the plant parameters.
The drive converts current with the nominal K_t, so a torque the shaft feels as ``T`` is
reported as ``T / g`` with ``g = 1 + torque_constant_error_rel``; results identified from
the reported torque are in those units.

=================================  ==========================================================
result                             truth
=================================  ==========================================================
current_loop_time_constant_ms      ``1000·current_loop_time_constant_s`` (``[firmware]``)
gravity_mge_nm                     ``gravity_mge_nm / g``
gravity_phase_rad                  ``gravity_phase_rad``
eccentricity_mm                    ``1000·gravity_mge_nm / (g·mass_kg·9.80665)`` (reported)
cable_stiffness_nm_rad             ``cable_stiffness_nm_rad / g``
cable_hysteresis_nm                ``cable_hysteresis_nm / g``
inertia_kg_m2                      ``(J_motor + J_load + J_elevation·cos²(el)) / g``
viscous_nm_s_rad                   ``viscous_nm_s_rad / g``
coulomb_nm                         ``coulomb_nm / g``
static_friction_nm                 ``static_friction_nm / g`` (the cable loop taken out)
stribeck_velocity_rad_s            ``stribeck_velocity_rad_s``
cogging_peak_nm                    largest cogging amplitude ``/ g``
kt_ripple_peak_pct                 ``100·`` largest K_t ripple amplitude (a ratio: no ``g``)
torque_constant_nm_a               ``torque_constant_nm_a·g`` (the shaft sensor sees true K_t)
reported_torque_gain_error_pct     ``100·(g − 1)``
torque_constant_vs_datasheet_pct   ``100·(torque_constant_nm_a·g / (9.5493/kv) − 1)``
resonance_frequency_hz             two-mass resonance of the drawn shaft (``crb_frf``)
antiresonance_frequency_hz         two-mass anti-resonance
resonance_damping_ratio            two-mass resonance damping
azimuth_inertia_level_kg_m2        ``J_motor + J_load + J_elevation`` (shaft-torque units)
azimuth_inertia_zenith_kg_m2       ``J_motor + J_load``
azimuth_inertia_product_kg_m2      ``inertia_product_kg_m2``
azimuth_inertia_ratio              largest / smallest J on the protocol's travel
=================================  ==========================================================

Results with no truth of the plant's (``inertia_amplitude_spread_pct``,
``torque_linearity_pct``, ``resonance_to_bandwidth_ratio``) are checked by repeatability:
the same unit calibrated with two noise seeds, ``(x₁ − x₂)/√(u₁² + u₂²)``.
"""

from __future__ import annotations

import math

from hil.characterise.draw import Unit
from hil.identify.inertia_elevation import inertia_extremes_rad
from hil.identify.resonance import TwoMassModel
from hil.profile import load_profile
from hil.suite.inertia_elevation import travel_of
from plant_sim.params import PlantParams

STANDARD_GRAVITY_M_S2 = 9.80665
NO_TRUTH = ("inertia_amplitude_spread_pct", "torque_linearity_pct",
            "resonance_to_bandwidth_ratio")


def truths(unit: Unit) -> dict[str, float]:
    """What each result claims to measure, for the drawn plant (module docstring's map)."""
    profile = load_profile(unit.profile_path)
    plant = profile.plant
    assert plant is not None
    g = 1.0 + plant.torque_constant_error_rel
    truth: dict[str, float] = {
        "current_loop_time_constant_ms": 1000 * profile.firmware.current_loop_time_constant_s,
        "gravity_mge_nm": plant.gravity_mge_nm / g,
        "gravity_phase_rad": plant.gravity_phase_rad,
        "cable_stiffness_nm_rad": plant.cable_stiffness_nm_rad / g,
        "cable_hysteresis_nm": plant.cable_hysteresis_nm / g,
        "inertia_kg_m2": _total_inertia(plant, plant.elevation_rad) / g,
        "viscous_nm_s_rad": plant.viscous_nm_s_rad / g,
        "coulomb_nm": plant.coulomb_nm / g,
        "static_friction_nm": plant.static_friction_nm / g,
        "stribeck_velocity_rad_s": plant.stribeck_velocity_rad_s,
        "cogging_peak_nm": max((h.amplitude for h in plant.cogging), default=0.0) / g,
        "kt_ripple_peak_pct": 100 * max((h.amplitude for h in plant.kt_ripple), default=0.0),
        "torque_constant_nm_a": plant.torque_constant_nm_a * g,
        "reported_torque_gain_error_pct": 100 * (g - 1),
    }
    mass_kg = profile.unit.get("mass_kg")
    if isinstance(mass_kg, int | float):
        weight_n = mass_kg * STANDARD_GRAVITY_M_S2
        truth["eccentricity_mm"] = 1000 * truth["gravity_mge_nm"] / weight_n
    kv = profile.unit.get("kv_rpm_per_v")
    if isinstance(kv, int | float):
        datasheet = 60 / (2 * math.pi) / kv
        truth["torque_constant_vs_datasheet_pct"] = 100 * (plant.torque_constant_nm_a * g
                                                           / datasheet - 1)
    if plant.load_inertia_kg_m2 > 0:
        model = two_mass_truth(
            plant, time_constant_s=profile.firmware.current_loop_time_constant_s)
        truth["resonance_frequency_hz"] = model.resonance_hz
        truth["antiresonance_frequency_hz"] = model.antiresonance_hz
        truth["resonance_damping_ratio"] = model.resonance_damping
    if plant.inertia_elevation_kg_m2 > 0 and "inertia_elevation" in profile.protocols:
        zenith = _total_inertia(plant, math.pi / 2)
        coefficients = (zenith, plant.inertia_elevation_kg_m2, plant.inertia_product_kg_m2)
        travel = travel_of(profile)
        largest, smallest = (_total_inertia(plant, el)
                             for el in inertia_extremes_rad(coefficients, travel))
        truth["azimuth_inertia_level_kg_m2"] = _total_inertia(plant, 0.0)
        truth["azimuth_inertia_zenith_kg_m2"] = zenith
        truth["azimuth_inertia_product_kg_m2"] = plant.inertia_product_kg_m2
        truth["azimuth_inertia_ratio"] = largest / smallest
    return {k: v for k, v in truth.items() if k in profile.measurements}


def _total_inertia(plant: PlantParams, elevation_rad: float) -> float:
    return (plant.inertia_kg_m2 + plant.load_inertia_kg_m2
            + plant.inertia_elevation_kg_m2 * math.cos(elevation_rad) ** 2
            + plant.inertia_product_kg_m2 * math.sin(2.0 * elevation_rad))


def reported_scale(plant: PlantParams) -> float:
    """Reported torque units per true N·m: the drive converts current with the nominal K_t,
    so a physical torque ``T`` is reported as ``T / (1 + torque_constant_error_rel)``."""
    return 1.0 / (1.0 + plant.torque_constant_error_rel)


def two_mass_truth(plant: PlantParams, *, time_constant_s: float) -> TwoMassModel:
    """The resonance protocol's fitted model's parameters for the simulated plant (torque
    in reported units: the K_t error scales J)."""
    j_total = plant.total_inertia_kg_m2
    j_load = plant.load_at_elevation_kg_m2
    k, c = plant.shaft_stiffness_nm_rad, plant.shaft_damping_nm_s_rad
    reduced = plant.motor_inertia_kg_m2 * j_load / j_total
    wa, wr = math.sqrt(k / j_load), math.sqrt(k / reduced)
    return TwoMassModel(
        inertia_kg_m2=j_total * reported_scale(plant),
        antiresonance_hz=wa / (2 * math.pi),
        antiresonance_damping=c / (2 * math.sqrt(k * j_load)),
        resonance_hz=wr / (2 * math.pi),
        resonance_damping=c / (2 * math.sqrt(k * reduced))
        + plant.viscous_nm_s_rad / (2 * plant.motor_inertia_kg_m2 * wr) * j_load / j_total,
        viscous_over_inertia_1_s=plant.viscous_nm_s_rad / j_total,
        time_constant_s=time_constant_s,
    )
