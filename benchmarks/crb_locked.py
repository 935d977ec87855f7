"""Torque constant (locked rotor) and azimuth inertia across elevation against their
Cramér–Rao bounds (bounds explained in ``bench_crb.py``)."""

from __future__ import annotations

import math

import numpy as np

import hil.suite.inertia_elevation as elevation_protocol
import hil.suite.inertia_friction as sine
import hil.suite.torque_constant as torque_protocol
from benchmarks.crb_common import (
    FloatArray,
    MonteCarlo,
    Parameter,
    bare_plant,
    bound,
    monte_carlo,
    sim_drive,
)
from hil.characterise.truth import reported_scale
from hil.errors import IdentificationError
from hil.identify.estimate import Estimate
from hil.identify.inertia_elevation import fit_inertia_elevation
from hil.identify.inertia_friction import cramer_rao_std
from hil.identify.torque_constant import identify_torque_constant, level_means
from hil.profile import UnitProfile
from plant_sim.params import PlantParams

# ------------------------------------------------------------------------ torque constant


def locked_sweep_information(
    current_a: FloatArray,
    reported_nm: FloatArray,
    gain: float,
    *,
    used_samples: int,
    sensor_sigma: float,
    reported_sigma: float,
) -> tuple[float, float]:
    """Variance bounds of one angle's K_t slope and reported-torque gain.

    The level means are sufficient (the model is constant over a settled level).
    K_t: ``T_sensor = K·i + c`` with the measured current exact, ``var = σ_s²/(n·Sxx)``.
    Gain: errors in variables, ``T_sensor = g·x_l + c`` and ``T_reported = x_l`` with the
    true reported level ``x_l`` of every level a nuisance parameter.
    """
    n = used_samples
    sxx = float(np.sum((current_a - current_a.mean()) ** 2))
    var_slope = sensor_sigma**2 / (n * sxx)
    levels = reported_nm.size
    rows = np.zeros((2 * levels, 2 + levels))
    rows[:levels, 0] = reported_nm
    rows[:levels, 1] = 1.0
    rows[np.arange(levels), 2 + np.arange(levels)] = gain
    rows[levels + np.arange(levels), 2 + np.arange(levels)] = 1.0
    weights = np.concatenate(
        [
            np.full(levels, math.sqrt(n) / sensor_sigma),
            np.full(levels, math.sqrt(n) / reported_sigma),
        ]
    )
    weighted = rows * weights[:, None]
    var_gain = float(np.linalg.inv(weighted.T @ weighted)[0, 0])
    return var_slope, var_gain


def torque_constant(
    profile: UnitProfile,
    plant: PlantParams,
    runs: int,
    case: str,
    *,
    ripple_table: bool = False,
) -> MonteCarlo:
    """K_t and the reported-torque gain (``1 + gain error``); ``ripple_table``: the cogging
    protocol's K_t ripple table is known (here: the plant's true one)."""
    kt_scale = 1.0 + plant.torque_constant_error_rel
    result = MonteCarlo(
        estimator="torque_constant",
        case=case,
        parameters=(
            Parameter(name="K_t", truth=plant.torque_constant_nm_a * kt_scale),
            Parameter(name="gain (1 + error)", truth=kt_scale),
        ),
    )
    ripple = [(h.order, h.amplitude, h.phase_rad) for h in plant.kt_ripple] if ripple_table else []

    def one(seed: int) -> tuple[list[float], list[float]] | None:
        drive = sim_drive(plant, firmware=profile.firmware, limits=profile.limits,
                          fs_hz=profile.sample_rate_hz, seed=seed)
        spec = torque_protocol.Spec.from_profile(profile, drive.info)
        sweeps, var_k, var_g = [], [], []
        for angle in spec.angles_rad:
            position = drive.status().position_rad
            drive.run(torque_protocol.move(spec, position_rad=position, angle_rad=angle))
            with drive.locked_rotor():
                swept = torque_protocol.sweep(spec, angle_rad=angle)
                rec = drive.run(swept)
            sweep = torque_protocol.analyse_sweep(rec, spec, angle_rad=angle, excitation=swept)
            sweeps.append(sweep)
            levels = spec.torque_levels_nm
            current = level_means(
                rec.columns["current_a"],
                level_samples=spec.level_samples,
                settle_samples=spec.settle_samples,
                levels=levels.size,
            )
            gain = kt_scale * (
                1.0
                + sum(
                    a * math.sin(n * angle + p)
                    for n, a, p in ((h.order, h.amplitude, h.phase_rad) for h in plant.kt_ripple)
                )
            )
            vk, vg = locked_sweep_information(
                current,
                levels,
                gain,
                used_samples=spec.level_samples - spec.settle_samples,
                sensor_sigma=plant.load_torque_noise_nm,
                reported_sigma=plant.torque_noise_nm,
            )
            var_k.append(vk)
            var_g.append(vg)
        try:
            found = identify_torque_constant(sweeps, ripple=ripple)
        except IdentificationError:
            return None
        n = len(sweeps)
        crb = [math.sqrt(sum(var_k)) / n, math.sqrt(sum(var_g)) / n]
        values = [found.torque_constant.value, 1.0 + found.gain_error.value / 100.0]
        return values, crb

    return monte_carlo(result, runs, one)


def torque_constant_white(plant: PlantParams) -> PlantParams:
    """The K_t error (the measurand), sensor and reported-torque noise; no K_t ripple."""
    return bare_plant(plant).with_changes(torque_constant_error_rel=plant.torque_constant_error_rel)


# --------------------------------------------------------------------- inertia elevation


def elevation_crb(
    elevations_rad: tuple[float, ...], inertia_crb: FloatArray, *, zenith: float, delta: float
) -> FloatArray:
    """Bounds on (J level, J zenith, ratio): ``J(el) = J_z + ΔJ·cos²(el)`` with each
    elevation's J bound (its own B, T_c and constants free, as the estimator fits them)."""
    c2 = np.cos(np.asarray(elevations_rad)) ** 2
    design = np.column_stack([np.ones_like(c2), c2]) / inertia_crb[:, None]
    grads = np.array([[1.0, 1.0], [1.0, 0.0], [-delta / zenith**2, 1.0 / zenith]])
    return bound(design.T @ design, grads)


def inertia_elevation(profile: UnitProfile, plant: PlantParams, runs: int, case: str) -> MonteCarlo:
    scale = reported_scale(plant)
    level = plant.with_changes(elevation_rad=0.0).total_inertia_kg_m2 * scale
    zenith = plant.with_changes(elevation_rad=math.pi / 2).total_inertia_kg_m2 * scale
    result = MonteCarlo(
        estimator="inertia_elevation",
        case=case,
        parameters=(
            Parameter(name="J level", truth=level),
            Parameter(name="J zenith", truth=zenith),
            Parameter(name="ratio", truth=level / zenith),
        ),
    )
    sigma = plant.torque_noise_nm

    def one(seed: int) -> tuple[list[float], list[float]] | None:
        drive = sim_drive(plant, firmware=profile.firmware, limits=profile.limits,
                          fs_hz=profile.sample_rate_hz, seed=seed)
        spec = elevation_protocol.Spec.from_profile(profile, drive.info)
        inertias: list[Estimate] = []
        bounds = []
        for elevation in spec.elevations_rad:
            drive.set_elevation(elevation)
            recordings = [drive.run(e) for e in sine.excitation(spec.sine)]
            analysed = sine.analyse(recordings, spec.sine)
            inertias.append(analysed.inertia)
            bounds.append(float(cramer_rao_std(analysed.runs, noise_rms_nm=sigma)[0]))
        drive.set_elevation(spec.park_elevation_rad)
        try:
            found = fit_inertia_elevation(spec.elevations_rad, inertias)
        except IdentificationError:
            return None
        crb = elevation_crb(
            spec.elevations_rad, np.array(bounds), zenith=zenith, delta=level - zenith
        )
        return [found.level.value, found.zenith.value, found.ratio.value], list(crb)

    return monte_carlo(result, runs, one)


def inertia_elevation_white(plant: PlantParams) -> PlantParams:
    """Rigid axis carrying motor + load inertia, the elevation-dependent inertia, Coulomb +
    viscous friction and torque noise."""
    return bare_plant(plant).with_changes(
        inertia_kg_m2=plant.inertia_kg_m2 + plant.load_inertia_kg_m2,
        inertia_elevation_kg_m2=plant.inertia_elevation_kg_m2,
    )
