"""The simulated axis: physics checks that do not depend on identification code."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hil.motion import Mode
from hil.profile import load_profile
from plant_sim.firmware import Firmware
from plant_sim.model import Plant, simulate
from plant_sim.params import Harmonic, PlantParams

FS = 4000.0


def test_every_effect_is_off_by_default_torque_step_gives_alpha_t_over_j() -> None:
    params = PlantParams(inertia_kg_m2=0.002)
    trace = Plant(params, fs_hz=FS, seed=0).run(Mode.TORQUE, np.full(4000, 0.01))
    velocity = np.diff(trace.position_rad) * FS
    acceleration = np.diff(velocity) * FS
    np.testing.assert_allclose(acceleration[10:], 0.01 / 0.002, rtol=1e-6)
    np.testing.assert_array_equal(trace.torque_nm, 0.01)


def test_runs_are_deterministic_given_the_seed() -> None:
    params = PlantParams(
        inertia_kg_m2=0.003,
        coulomb_nm=0.02,
        torque_noise_nm=0.002,
        encoder_counts_per_rev=4096,
    )
    firmware = Firmware(velocity_filter_hz=200.0)
    command = 0.5 * np.sin(np.linspace(0, 20, 8000))
    a = simulate(params, mode=Mode.VELOCITY, command=command, fs_hz=FS, seed=7, firmware=firmware)
    b = simulate(params, mode=Mode.VELOCITY, command=command, fs_hz=FS, seed=7, firmware=firmware)
    c = simulate(params, mode=Mode.VELOCITY, command=command, fs_hz=FS, seed=8, firmware=firmware)
    np.testing.assert_array_equal(a.effort, b.effort)
    assert not np.array_equal(a.effort, c.effort)


@pytest.mark.parametrize("fraction", [0.2, 0.6, 0.95])
def test_stiction_holds_below_breakaway_without_chattering(fraction: float) -> None:
    params = PlantParams(inertia_kg_m2=0.003, coulomb_nm=0.02, static_friction_nm=0.03)
    torque = fraction * 0.03
    trace = Plant(params, fs_hz=FS, seed=0).run(Mode.TORQUE, np.full(8000, torque))
    assert np.all(trace.position_rad == 0.0)


def test_breakaway_above_static_friction_and_stribeck_curve() -> None:
    params = PlantParams(
        inertia_kg_m2=0.003, coulomb_nm=0.02, static_friction_nm=0.03, stribeck_velocity_rad_s=0.02
    )
    plant = Plant(params, fs_hz=FS, seed=0)
    trace = plant.run(Mode.TORQUE, np.full(4000, 0.031))
    assert trace.position_rad[-1] > 0
    # at constant speed the drive's torque equals the Stribeck friction at that speed
    for speed in (0.005, 0.05, 0.3):
        held = Plant(
            params, firmware=Firmware(velocity_kp_nm_s_rad=0.5, velocity_ki_nm_rad=20.0),
            fs_hz=FS, seed=0,
        ).run(Mode.VELOCITY, np.full(16000, speed))
        expected = 0.02 + 0.01 * math.exp(-((speed / 0.02) ** 2))
        assert np.mean(held.torque_nm[-4000:]) == pytest.approx(expected, rel=0.02)


def test_reversal_sticks_then_moves_the_other_way() -> None:
    params = PlantParams(inertia_kg_m2=0.003, coulomb_nm=0.02)
    firmware = Firmware(velocity_kp_nm_s_rad=0.3, velocity_ki_nm_rad=10.0)
    t = np.arange(8000) / FS
    trace = Plant(params, firmware=firmware, fs_hz=FS, seed=0).run(Mode.VELOCITY,
                  0.5 * np.sin(2 * np.pi * t[:3600]))
    steps = np.diff(trace.position_rad)
    sign_changes = np.count_nonzero(np.diff(np.sign(steps[steps != 0])))
    assert sign_changes == 1  # exactly one reversal: no chattering at zero speed


def test_two_mass_resonance_frequency() -> None:
    params = PlantParams(
        inertia_kg_m2=0.002,
        load_inertia_kg_m2=0.006,
        shaft_stiffness_nm_rad=200.0,
        shaft_damping_nm_s_rad=0.001,
    )
    trace = Plant(params, fs_hz=FS, seed=0).run(
        Mode.TORQUE, np.concatenate([[0.05], np.zeros(16383)])
    )
    velocity = np.diff(trace.position_rad) * FS
    spectrum = np.abs(np.fft.rfft(velocity - velocity.mean()))
    peak_hz = np.fft.rfftfreq(velocity.size, 1 / FS)[np.argmax(spectrum[5:]) + 5]
    assert peak_hz == pytest.approx(params.resonance_hz, rel=0.03)


def test_encoder_quantisation_saturation_and_gravity() -> None:
    params = PlantParams(
        inertia_kg_m2=0.003,
        encoder_counts_per_rev=65536,
        torque_limit_nm=0.05,
        gravity_mge_nm=0.04,
        gravity_phase_rad=0.0,
        position_kp_1_s=20.0,
    )
    firmware = Firmware(velocity_kp_nm_s_rad=0.3, velocity_ki_nm_rad=10.0,
                        velocity_filter_hz=100.0)
    trace = Plant(params, firmware=firmware, fs_hz=FS, seed=0).run(Mode.POSITION, np.full(20000,
                  0.5))
    counts = trace.position_rad / (2 * math.pi / 65536)
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    assert np.max(np.abs(trace.torque_nm)) <= 0.05
    # holding at 0.5 rad needs m·g·e·cos(0.5)
    assert np.mean(trace.torque_nm[-4000:]) == pytest.approx(0.04 * math.cos(0.5), rel=0.02)


def test_cogging_is_periodic_in_position() -> None:
    params = PlantParams(
        inertia_kg_m2=0.003,
        cogging=(Harmonic(order=12, amplitude=0.01),),
    )
    firmware = Firmware(velocity_kp_nm_s_rad=0.5, velocity_ki_nm_rad=20.0)
    speed = 0.5
    trace = Plant(params, firmware=firmware, fs_hz=FS, seed=0).run(Mode.VELOCITY,
                  np.full(int(FS * 8), speed))
    keep = slice(int(FS), None)
    theta, torque = trace.position_rad[keep], trace.torque_nm[keep]
    design = np.column_stack([np.sin(12 * theta), np.cos(12 * theta), np.ones_like(theta)])
    amplitude = np.hypot(*np.linalg.lstsq(design, torque, rcond=None)[0][:2])
    assert amplitude == pytest.approx(0.01, rel=0.05)


def test_invalid_parameters_are_refused() -> None:
    from hil.errors import ProfileError

    with pytest.raises(ProfileError, match="inertia"):
        PlantParams(inertia_kg_m2=0.0)
    with pytest.raises(ProfileError, match="two-mass"):
        PlantParams(inertia_kg_m2=0.001, load_inertia_kg_m2=0.01)


def test_frictionless_axis_passes_through_zero_speed_without_stopping() -> None:
    """Under a held (zero-order-hold) torque that reverses the motion every few ms, the
    position equals the exact double integral of the held torque: no step is lost at the
    reversals."""
    inertia, amplitude, w, h = 0.002, 0.01, 2 * math.pi * 110.0, 1 / FS
    torque = amplitude * np.cos(w * np.arange(4000) * h)
    trace = Plant(PlantParams(inertia_kg_m2=inertia, exact_torque_hold=True), fs_hz=FS,
                  seed=0).run(Mode.TORQUE, torque)
    velocity = np.concatenate([[0.0], np.cumsum(torque) * h / inertia])
    position = np.concatenate([[0.0], np.cumsum(velocity[:-1] * h + torque * h * h / 2 / inertia)])
    assert np.count_nonzero(np.diff(np.sign(velocity)) != 0) > 100  # many reversals
    np.testing.assert_allclose(trace.position_rad, position[:-1], atol=1e-3 * np.ptp(position))


@pytest.mark.parametrize("speed_rad_s", [0.005, 0.02, 0.2])
def test_at_constant_speed_the_encoder_moves_at_the_speed_friction_sees(
    speed_rad_s: float,
) -> None:
    """The exact-hold position correction must not act on torque that friction balances:
    it once let the encoder lag the internal velocity by h/2·T/J (0.0008 rad/s, 16 % of
    the slowest Stribeck step), which biased T_s and v_s."""
    profile = load_profile()
    demo = profile.plant
    assert demo is not None
    plant = dataclasses.replace(
        demo, torque_noise_nm=0.0, cogging=(), kt_ripple=(),
        cable_hysteresis_nm=0.0, gravity_mge_nm=0.0, cable_stiffness_nm_rad=0.0,
    )
    trace = Plant(plant, firmware=profile.firmware, fs_hz=4000.0, seed=0).run(
        Mode.VELOCITY, np.full(40000, speed_rad_s))
    rate = (trace.position_rad[-1] - trace.position_rad[20000]) / (19999 / 4000.0)
    assert rate == pytest.approx(speed_rad_s, rel=1e-3)


@pytest.mark.parametrize("hysteresis_nm", [5e-324, 2.2e-309, 1e-300])
def test_a_vanishing_cable_hysteresis_moves_the_axis_as_none_does(
    hysteresis_nm: float,
) -> None:
    """The Dahl update divided by the loop's half width; under fastmath a subnormal width's
    reciprocal overflowed to inf, the hysteresis torque became NaN and the axis stood still
    (found by Hypothesis drawing h = 2.2e-309 in the gravity/cable test)."""
    profile = load_profile()
    assert profile.plant is not None
    command = np.concatenate((np.full(2000, 0.3), np.full(2000, -0.3)))
    traces = [
        Plant(dataclasses.replace(profile.plant, cable_hysteresis_nm=h),
              firmware=profile.firmware, fs_hz=2000.0, seed=1).run(Mode.VELOCITY, command)
        for h in (0.0, hysteresis_nm)
    ]
    np.testing.assert_allclose(traces[1].position_rad, traces[0].position_rad, atol=1e-9)


LUGRE = PlantParams(inertia_kg_m2=0.003, viscous_nm_s_rad=0.004, coulomb_nm=0.02,
                    static_friction_nm=0.03, stribeck_velocity_rad_s=0.02,
                    presliding_rad=5e-5)


def test_lugre_sliding_friction_is_the_stribeck_map() -> None:
    """LuGre's steady state is the static map: at each constant speed the drive's torque is
    T_c + (T_s − T_c)·exp(−(v/v_s)²) + B·v, as with the static law."""
    for speed in (0.005, 0.05, 0.3):
        held = Plant(LUGRE, firmware=Firmware(velocity_kp_nm_s_rad=0.5, velocity_ki_nm_rad=20.0),
                     fs_hz=FS, seed=0).run(Mode.VELOCITY, np.full(16000, speed))
        expected = 0.02 + 0.01 * math.exp(-((speed / 0.02) ** 2)) + 0.004 * speed
        assert np.mean(held.torque_nm[-4000:]) == pytest.approx(expected, rel=0.01)


def test_lugre_pre_slides_where_the_static_law_sticks() -> None:
    """Below breakaway the static law holds the rotor still; under LuGre the rotor moves
    by more than the bristles' final deflection torque/σ0 (σ0 = T_s / presliding: part of
    the transient's motion slips) and less than twice it, then stands still."""
    torque = 0.5 * LUGRE.static_friction_nm
    static = Plant(dataclasses.replace(LUGRE, presliding_rad=0.0), fs_hz=FS, seed=0)
    assert np.all(static.run(Mode.TORQUE, np.full(4000, torque)).position_rad == 0.0)
    moved = Plant(LUGRE, fs_hz=FS, seed=0).run(Mode.TORQUE, np.full(4000, torque)).position_rad
    deflection = torque / LUGRE.bristle_stiffness_nm_rad
    assert deflection < moved[-1] < 2 * deflection
    assert np.ptp(moved[-2000:]) < 1e-3 * deflection  # settled: no sliding


def test_stiff_bristles_raise_the_physics_steps() -> None:
    from plant_sim.model import substeps_for

    stiff = dataclasses.replace(LUGRE, presliding_rad=1e-6)
    assert substeps_for(LUGRE, FS) < substeps_for(stiff, FS)
    held = Plant(stiff, firmware=Firmware(velocity_kp_nm_s_rad=0.5, velocity_ki_nm_rad=20.0),
                 fs_hz=FS, seed=0).run(Mode.VELOCITY, np.full(8000, 0.05))
    assert np.all(np.isfinite(held.torque_nm))
    assert np.mean(held.torque_nm[-2000:]) == pytest.approx(
        0.02 + 0.01 * math.exp(-6.25) + 0.004 * 0.05, rel=0.01)
