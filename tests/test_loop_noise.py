"""Noise inside the loops (issue 24, defect 3): a real axis' shaft disturbance, current-sensor
noise and encoder jitter feed back through its loops, so two runs of one unit move
differently while the same seed moves the same. Before, the noise was on the recorded
torque only and every closed-loop result was the same under every seed."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from hil.config import ConfigTable
from hil.drives.sim import SimDrive
from hil.motion import Mode
from hil.profile import load_profile
from hil.suite import velocity_loop_frf
from plant_sim.firmware import Firmware
from plant_sim.model import Plant
from plant_sim.params import (
    LOOP_NOISE_DEFAULTS,
    PlantParams,
    plant_from_table,
    plant_to_mapping,
)

FS = 4000.0
LOOP_NOISE_KEYS = tuple(LOOP_NOISE_DEFAULTS)


def _demo_velocity_run(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The demo unit (its profile's plant and firmware) following a speed step: the
    encoder's position and the drive's velocity estimate."""
    profile = load_profile()
    plant = Plant(_demo_plant(), firmware=profile.firmware, fs_hz=FS, seed=seed)
    command = np.concatenate([np.zeros(400), np.full(2000, 0.3)])
    trace = plant.run(Mode.VELOCITY, command)
    return trace.position_rad, trace.velocity_rad_s


def test_the_demo_unit_moves_differently_under_two_seeds_and_the_same_under_one() -> None:
    position_a, velocity_a = _demo_velocity_run(seed=1)
    position_b, velocity_b = _demo_velocity_run(seed=2)
    position_again, velocity_again = _demo_velocity_run(seed=1)
    np.testing.assert_array_equal(position_a, position_again)
    np.testing.assert_array_equal(velocity_a, velocity_again)
    assert not np.array_equal(position_a, position_b)  # the motion itself, not the record
    assert np.std(velocity_a[600:] - velocity_b[600:]) > 1e-3  # rad/s: the loop feels it


def test_the_velocity_bandwidth_differs_between_seeds_and_repeats_under_one() -> None:
    profile = load_profile()

    def bandwidth_hz(seed: int) -> float:
        with SimDrive(_demo_plant(), firmware=profile.firmware, limits=profile.limits,
                      fs_hz=profile.sample_rate_hz, seed=seed) as drive:
            drive.enable()
            spec = velocity_loop_frf.Spec.from_profile(profile, drive.info)
            *moves, lines = velocity_loop_frf.excitation(
                spec, position_rad=drive.status().position_rad)
            for move in moves:
                drive.run(move)
            found = velocity_loop_frf.analyse(drive.run(lines), spec)
        return found.estimates["bandwidth_hz"].value

    first, second, again = bandwidth_hz(1), bandwidth_hz(2), bandwidth_hz(1)
    assert first == again
    assert first != second
    assert abs(first - second) < 0.05 * first  # noise, not a different loop


def _demo_plant() -> PlantParams:
    """The demo unit with a real unit's noise inside its loops (the documented sizes)."""
    plant = load_profile().plant
    assert plant is not None
    return replace(plant, **LOOP_NOISE_DEFAULTS)


def test_a_profile_names_its_loop_noise_and_none_is_applied_unnamed() -> None:
    ideal = PlantParams(inertia_kg_m2=0.003)
    assert all(getattr(ideal, key) == 0.0 for key in LOOP_NOISE_KEYS)
    unnamed = plant_from_table(ConfigTable({"inertia_kg_m2": 0.003}, table="[plant]",
                                           source="test"))
    assert all(getattr(unnamed, key) == 0.0 for key in LOOP_NOISE_KEYS)
    named = plant_from_table(ConfigTable({"inertia_kg_m2": 0.003, **LOOP_NOISE_DEFAULTS},
                                         table="[plant]", source="test"))
    for key, size in LOOP_NOISE_DEFAULTS.items():
        assert getattr(named, key) == size, key


def test_writing_a_plant_and_reading_it_back_keeps_its_loop_noise() -> None:
    for params in (PlantParams(inertia_kg_m2=0.003), _demo_plant()):
        mapping = plant_to_mapping(params)
        back = plant_from_table(ConfigTable(mapping, table="[plant]", source="test"))
        for key in LOOP_NOISE_KEYS:
            assert getattr(back, key) == getattr(params, key), key


def test_without_loop_noise_the_seed_changes_only_the_recorded_noise() -> None:
    params = PlantParams(inertia_kg_m2=0.003, coulomb_nm=0.02, torque_noise_nm=0.002,
                         encoder_counts_per_rev=1 << 19)
    firmware = Firmware(velocity_kp_nm_s_rad=0.45, velocity_ki_nm_rad=12.0)
    command = 0.5 * np.sin(np.linspace(0, 20, 8000))
    a = Plant(params, firmware=firmware, fs_hz=FS, seed=1).run(Mode.VELOCITY, command)
    b = Plant(params, firmware=firmware, fs_hz=FS, seed=2).run(Mode.VELOCITY, command)
    np.testing.assert_array_equal(a.position_rad, b.position_rad)
    assert not np.array_equal(a.torque_nm, b.torque_nm)


def test_current_sensor_noise_moves_the_torque_made_away_from_the_demand() -> None:
    # 0.2 % of a 5 A range at 0.1 N·m/A: 1 mN·m RMS, an ideal current loop passes all of it
    params = PlantParams(inertia_kg_m2=0.003, torque_limit_nm=0.5,
                         current_sensor_noise_rms_rel=0.002)
    trace = Plant(params, fs_hz=FS, seed=3).run(Mode.TORQUE, np.full(40_000, 0.05))
    made = trace.torque_actual_nm[1:]
    assert np.mean(made) == pytest.approx(0.05, abs=3e-5)
    assert np.std(made) == pytest.approx(1e-3, rel=0.03)
    sensor_a = trace.current_a - trace.torque_actual_nm / 0.1  # the drive reads the noise too
    assert np.std(sensor_a) == pytest.approx(0.01, rel=0.03)
    # the motion carries it: acceleration (T_made)/J, not the demand's
    acceleration = np.diff(trace.position_rad, 2) * FS**2
    assert np.std(acceleration[5:]) == pytest.approx(1e-3 / 0.003, rel=0.05)


def test_shaft_disturbance_accelerates_a_free_inertia_by_its_rms_over_j() -> None:
    params = PlantParams(inertia_kg_m2=0.002, shaft_disturbance_rms_nm=2e-4)
    trace = Plant(params, fs_hz=FS, seed=4).run(Mode.TORQUE, np.zeros(40_000))
    acceleration = np.diff(trace.position_rad, 2) * FS**2
    assert np.std(acceleration) == pytest.approx(2e-4 / 0.002, rel=0.03)
    np.testing.assert_array_equal(trace.torque_nm, 0.0)  # the drive commanded nothing


def test_low_frequency_disturbance_has_its_rms_and_corner() -> None:
    rms_nm, corner_hz = 1e-3, 2.0
    params = PlantParams(inertia_kg_m2=0.002, shaft_disturbance_lf_rms_nm=rms_nm,
                         shaft_disturbance_lf_hz=corner_hz)
    plant = Plant(params, fs_hz=FS, seed=5)
    n = 400_000  # 100 s: 200 corner periods
    acceleration = np.diff(plant.run(Mode.TORQUE, np.zeros(n)).position_rad, 2) * FS**2
    torque = acceleration * 0.002
    assert np.std(torque) == pytest.approx(rms_nm, rel=0.15)
    lag = round(FS / (2 * math.pi * corner_hz))  # one time constant: correlation 1/e
    corr = np.corrcoef(torque[:-lag], torque[lag:])[0, 1]
    assert corr == pytest.approx(math.exp(-1), abs=0.08)


def test_encoder_jitter_reaches_the_reading_of_an_axis_at_rest() -> None:
    counts = 1 << 19
    params = PlantParams(inertia_kg_m2=0.003, static_friction_nm=0.05, coulomb_nm=0.04,
                         encoder_counts_per_rev=counts, encoder_noise_rms_counts=0.3)
    trace = Plant(params, fs_hz=FS, seed=6, initial_position_rad=0.1234567).run(
        Mode.TORQUE, np.zeros(20_000))
    steps = np.round(trace.position_rad / (2 * math.pi / counts))
    assert 2 <= len(np.unique(steps)) <= 5  # a count or two either side, never more
    assert 0.25 < np.std(steps) < 0.5  # 0.3 counts of jitter through the quantiser


def test_refuses_negative_noise_and_a_zero_corner() -> None:
    from hil.errors import ProfileError

    for key in LOOP_NOISE_KEYS:
        with pytest.raises(ProfileError, match=key):
            PlantParams(inertia_kg_m2=0.003, **{key: -1.0})
    with pytest.raises(ProfileError, match="shaft_disturbance_lf_hz"):
        PlantParams(inertia_kg_m2=0.003, shaft_disturbance_lf_hz=0.0)
