"""The second simulator (plant_sim.variant): the same physics as the main one, other choices."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hil.motion import Mode
from plant_sim.firmware import Firmware
from plant_sim.model import simulate
from plant_sim.params import Harmonic, PlantParams
from plant_sim.variant import MAIN_LIKE, Variant, draw_variant, simulate_variant

FIRMWARE = Firmware(velocity_filter_hz=300.0, velocity_kp_nm_s_rad=0.45, velocity_ki_nm_rad=12.0)
PLANT = PlantParams(inertia_kg_m2=0.004, viscous_nm_s_rad=0.005, coulomb_nm=0.02,
                    static_friction_nm=0.03, stribeck_velocity_rad_s=0.02,
                    gravity_mge_nm=0.03, cogging=(Harmonic(order=40, amplitude=0.004),))


def _ramp_and_sine(fs_hz: float) -> np.ndarray:
    t = np.arange(int(3.0 * fs_hz)) / fs_hz
    return np.concatenate([0.8 * np.sin(2 * np.pi * 1.5 * t), np.full(len(t), 0.3)])


def _steady_torque(variant: Variant, speed_rad_s: float) -> float:
    plant = dataclasses.replace(PLANT, gravity_mge_nm=0.0, cogging=())
    fs = variant.sample_rate_hz
    command = np.full(int(2.0 * fs), speed_rad_s)
    recording = simulate_variant(plant, FIRMWARE, variant, velocity_command_rad_s=command,
                                 seed=1)
    return float(np.mean(recording.effort[len(command) // 2:]))


def test_the_main_like_variant_moves_as_the_main_simulator() -> None:
    """Same unit, same command, no noise: the two implementations agree to a few encoder
    counts in position and a small share of the torque (they differ in their integrator's
    details, the stick test and the encoder's rounding)."""
    command = _ramp_and_sine(2000.0)
    main = simulate(PLANT, mode=Mode.VELOCITY, command=command, fs_hz=2000.0, seed=1,
                    firmware=FIRMWARE)
    other = simulate_variant(PLANT, FIRMWARE, MAIN_LIKE, velocity_command_rad_s=command, seed=1)
    step = 2 * np.pi / MAIN_LIKE.encoder_counts_per_rev
    # measured: 6.5 counts and 4.8 % of the torque's spread
    assert np.max(np.abs(main.position - other.position)) < 20 * step
    torque_gap = np.sqrt(np.mean((main.effort - other.effort) ** 2))
    assert torque_gap < 0.08 * np.std(main.effort)


@pytest.mark.parametrize("speed_rad_s", [0.3, -0.3, 0.02])
def test_lugre_friction_settles_on_the_static_map(speed_rad_s: float) -> None:
    """At constant speed the bristles settle and LuGre's friction is the Stribeck map's."""
    static = _steady_torque(MAIN_LIKE, speed_rad_s)
    lugre = _steady_torque(dataclasses.replace(MAIN_LIKE, friction_law="lugre"), speed_rad_s)
    ratio = abs(speed_rad_s) / PLANT.stribeck_velocity_rad_s
    expected = (PLANT.coulomb_nm + (PLANT.static_friction_nm - PLANT.coulomb_nm)
                * np.exp(-ratio**2)) * np.sign(speed_rad_s) + PLANT.viscous_nm_s_rad * speed_rad_s
    assert static == pytest.approx(expected, rel=0.03)
    assert lugre == pytest.approx(expected, rel=0.03)


def test_the_integrators_converge_to_one_motion() -> None:
    command = _ramp_and_sine(2000.0)
    runs = [simulate_variant(PLANT, FIRMWARE, dataclasses.replace(
        MAIN_LIKE, integrator=name, substeps=16, encoder_counts_per_rev=0),
        velocity_command_rad_s=command, seed=1) for name in ("symplectic_euler", "heun", "rk4")]
    for run in runs[:2]:
        assert np.max(np.abs(run.position - runs[2].position)) < 2e-5


def test_a_torque_reported_after_the_current_loop_trails_the_command() -> None:
    """The measured current's torque is the command through the loop's lag."""
    firmware = FIRMWARE.with_changes(current_loop_time_constant_s=0.003)
    fs = 2000.0
    t = np.arange(int(2.0 * fs)) / fs
    command = 0.2 * np.sin(2 * np.pi * 40.0 * t)
    quiet = dataclasses.replace(PLANT, torque_noise_nm=0.0)
    before = simulate_variant(quiet, firmware, MAIN_LIKE, velocity_command_rad_s=command, seed=1)
    after = simulate_variant(quiet, firmware, dataclasses.replace(MAIN_LIKE, torque_tap="measured"),
                             velocity_command_rad_s=command, seed=1)
    assert np.array_equal(before.position, after.position)  # one run, two taps
    lag = np.argmax(np.correlate(after.effort[2000:] - after.effort[2000:].mean(),
                                 before.effort[2000:] - before.effort[2000:].mean(), "full"))
    delay_samples = lag - (len(t) - 2000 - 1)
    # a 3 ms lag at 40 Hz delays by atan(2π·40·0.003)/(2π·40) = 2.6 ms ≈ 5 samples
    assert 4 <= delay_samples <= 7


def test_drawn_variants_run_and_jitter_their_periods() -> None:
    rng = np.random.default_rng(3)
    jittered = 0
    for _ in range(12):
        variant = draw_variant(rng)
        command = _ramp_and_sine(variant.sample_rate_hz)
        recording = simulate_variant(PLANT, FIRMWARE, variant, velocity_command_rad_s=command,
                                     seed=2)
        assert np.all(np.isfinite(recording.position))
        assert np.max(np.abs(recording.position)) < 1.5  # 0.9 rad of ramp + the sine
        periods = np.diff(recording.time_s)
        assert np.mean(periods) == pytest.approx(1 / variant.sample_rate_hz, rel=1e-3)
        jittered += bool(variant.period_jitter_rel) == bool(np.std(periods) > 1e-9)
    assert jittered == 12


def test_what_it_does_not_model_is_refused() -> None:
    plant = dataclasses.replace(PLANT, cable_hysteresis_nm=0.01)
    with pytest.raises(ValueError, match="cable_hysteresis_nm"):
        simulate_variant(plant, FIRMWARE, MAIN_LIKE, velocity_command_rad_s=np.zeros(200),
                         seed=1)
