"""K_t from a locked rotor: exact synthetic lines, the datasheet conversion, the ripple
correction, the simulator's locked rotor, and recovery of a hidden K_t error (effects on)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.drives.sim import SimDrive
from hil.errors import IdentificationError
from hil.identify.cogging import compensation_table
from hil.identify.torque_constant import (
    LockedSweep,
    analyse_locked_sweep,
    balanced_angles,
    datasheet_deviation,
    datasheet_torque_constant_nm_a,
    identify_torque_constant,
)
from hil.profile import load_profile
from hil.suite import cogging as cogging_suite
from hil.suite import torque_constant as torque_constant_suite
from plant_sim.params import Harmonic
from tests.helpers import drive_info

PROFILE = load_profile()
FS = 4000.0
INFO = drive_info(PROFILE, FS)
SPEC = torque_constant_suite.Spec.from_profile(PROFILE, INFO)
ACCURACY = PROFILE.measurement("torque_constant_nm_a").accuracy_rel


def _sweep(kt: float, angle: float, *, offset: float = 0.01, noise: float = 0.0,
           seed: int = 0) -> LockedSweep:
    levels = np.concatenate([np.linspace(-4, 4, 9), np.linspace(4, -4, 9)])
    current = np.repeat(levels, 200)
    rng = np.random.default_rng(seed)
    sensor = kt * current + offset + rng.normal(0, noise, current.size) if noise else (
        kt * current + offset)
    return analyse_locked_sweep(current, sensor, 0.1 * current, angle_rad=angle,
                                level_samples=200, settle_samples=40, levels=18)


def test_datasheet_constant_is_60_over_2pi_kv() -> None:
    assert datasheet_torque_constant_nm_a(100.0) == pytest.approx(0.095493, rel=1e-5)
    estimate = identify_torque_constant([_sweep(0.1, 0.0), _sweep(0.1, 1.0)]).torque_constant
    assert datasheet_deviation(estimate, kv_rpm_per_v=95.493).value == pytest.approx(
        0.0, abs=1e-3)


def test_noise_free_lines_give_slope_gain_and_zero_linearity() -> None:
    result = identify_torque_constant([_sweep(0.104, a) for a in (-0.5, 0.0, 0.5)])
    assert result.torque_constant.value == pytest.approx(0.104, rel=1e-12)
    assert result.gain_error.value == pytest.approx(4.0, rel=1e-9)
    assert result.linearity.value == pytest.approx(0.0, abs=1e-9)


def test_a_bent_line_shows_in_the_linearity() -> None:
    levels = np.concatenate([np.linspace(-4, 4, 9), np.linspace(4, -4, 9)])
    current = np.repeat(levels, 100)
    sensor = 0.1 * current * (1 - 0.02 * np.abs(current) / 4)  # 2 % saturation at full scale
    sweep = analyse_locked_sweep(current, sensor, 0.1 * current, angle_rad=0.0,
                                 level_samples=100, settle_samples=10, levels=18)
    result = identify_torque_constant([sweep, sweep])
    i = sweep.current_a
    bent = 0.1 * i * (1 - 0.02 * np.abs(i) / 4)
    residual = bent - np.polyval(np.polyfit(i, bent, 1), i)
    assert result.linearity.value == pytest.approx(
        100 * np.max(np.abs(residual)) / np.max(np.abs(bent - bent.mean())), rel=1e-6)
    assert result.linearity.value > 0.2


def test_ripple_correction_removes_the_angle_dependence() -> None:
    ripple = [(42, 0.02, 0.4)]
    angles = (-0.9, -0.43, 0.04, 0.51, 0.98)
    sweeps = [_sweep(0.1 * (1 + 0.02 * math.sin(42 * a + 0.4)), a) for a in angles]
    assert identify_torque_constant(sweeps, ripple=ripple).torque_constant.value == (
        pytest.approx(0.1, rel=1e-12))


def test_uncertainty_covers_the_noise() -> None:
    values, uncertainties = [], []
    for seed in range(30):
        result = identify_torque_constant(
            [_sweep(0.1, a, noise=0.05, seed=seed * 7 + i) for i, a in enumerate((0, 1, 2))])
        values.append(result.torque_constant.value)
        uncertainties.append(result.torque_constant.standard_uncertainty)
    assert 0.5 < float(np.median(uncertainties)) / float(np.std(values, ddof=1)) < 2.0


def test_one_angle_is_refused() -> None:
    with pytest.raises(IdentificationError, match="at least 2"):
        identify_torque_constant([_sweep(0.1, 0.0)])


def test_locked_rotor_holds_still_and_reads_the_true_torque() -> None:
    assert PROFILE.plant is not None
    plant = PROFILE.plant.with_changes(torque_constant_error_rel=0.05, kt_ripple=(),
                                       cogging=(), gravity_mge_nm=0.0, cable_stiffness_nm_rad=0.0,
                                       cable_hysteresis_nm=0.0)
    drive = SimDrive(plant, firmware=PROFILE.firmware, limits=PROFILE.limits, fs_hz=FS, seed=0)
    with drive:
        drive.enable()
        before = drive.status().position_rad
        with drive.locked_rotor():
            recording = drive.run(torque_constant_suite.sweep(SPEC, angle_rad=0.0))
        assert drive.status().position_rad == before
        released = drive.run(torque_constant_suite.move(SPEC, position_rad=before, angle_rad=0.1))
    assert "load_torque_nm" not in released.columns
    settled = np.abs(np.diff(recording.effort, prepend=0.0)) == 0
    sensor = recording.columns["load_torque_nm"][settled]
    assert sensor == pytest.approx(1.05 * recording.effort[settled], abs=1e-9)


def _measured_ripple(drive: SimDrive) -> list[tuple[int, float, float]]:
    """What the cogging protocol (which runs first) hands over."""
    own = {**PROFILE.protocols["cogging"], "passes": "own", "speed_rad_s": 0.6}
    profile = dataclasses.replace(PROFILE, protocols={**PROFILE.protocols, "cogging": own})
    spec = cogging_suite.Spec.from_profile(profile, drive.info)
    move, passes = cogging_suite.excitation(spec, position_rad=drive.status().position_rad)
    drive.run(move)
    rec = drive.run(passes)
    table = compensation_table(cogging_suite.analyse(rec.time_s, rec.position, rec.effort, spec,
                                                    inertia_kg_m2=0.0036))
    return [(h["order"], h["amplitude"], h["phase_rad"])
            for h in json.loads(json.dumps(table))["kt_ripple"]]


@settings(max_examples=8, deadline=None)
@given(error=st.floats(-0.1, 0.1), ripple=st.floats(0.0, 0.02), order=st.integers(20, 100),
       phase=st.floats(0.0, 6.28), noise=st.floats(0.0, 0.004), seed=st.integers(0, 2**16))
def test_hidden_torque_constant_is_recovered_within_the_claimed_accuracy(
    error: float, ripple: float, order: int, phase: float, noise: float, seed: int
) -> None:
    assert PROFILE.plant is not None
    assert ACCURACY is not None
    plant = PROFILE.plant.with_changes(
        torque_constant_error_rel=error, load_torque_noise_nm=noise,
        kt_ripple=(Harmonic(order=order, amplitude=ripple, phase_rad=phase),))
    drive = SimDrive(plant, firmware=PROFILE.firmware, limits=PROFILE.limits, fs_hz=FS, seed=seed)
    with drive:
        drive.enable()
        table = _measured_ripple(drive)
        sweeps = []
        for angle in SPEC.angles_rad:
            drive.run(torque_constant_suite.move(SPEC, position_rad=drive.status().position_rad,
                                                angle_rad=angle))
            with drive.locked_rotor():
                swept = torque_constant_suite.sweep(SPEC, angle_rad=angle)
                recording = drive.run(swept)
            sweeps.append(torque_constant_suite.analyse_sweep(recording, SPEC, angle_rad=angle,
                                                              excitation=swept))
    result = identify_torque_constant(sweeps, ripple=table)
    truth = plant.torque_constant_nm_a * (1 + error)
    assert result.torque_constant.value == pytest.approx(truth, rel=ACCURACY)
    assert result.gain_error.value == pytest.approx(100 * error, abs=100 * ACCURACY)


@settings(max_examples=25, deadline=None)
@given(order=st.integers(10, 200), count=st.integers(2, 8), start=st.floats(-2.5, 0.0),
       step=st.floats(0.05, 1.2), phase=st.floats(-math.pi, math.pi))
def test_balanced_angles_average_the_largest_ripple_harmonic_out(
    order: int, count: int, start: float, step: float, phase: float
) -> None:
    configured = [start + k * step for k in range(count)]
    ripple = [(order, 0.01, phase), (2 * order + 1, 0.002, 0.3)]
    angles = np.array(balanced_angles(configured, ripple))
    # the largest harmonic sums to zero over the angles: its table's error cannot bias K_t
    assert abs(np.exp(1j * order * angles).mean()) < 1e-9
    # each angle stays within half a period of that harmonic of where it was configured
    assert np.all(np.abs(angles - configured) <= math.pi / order + 1e-12)


def test_balanced_angles_without_a_ripple_table_are_the_configured_ones() -> None:
    assert balanced_angles([-0.9, 0.0, 0.9], []) == (-0.9, 0.0, 0.9)
