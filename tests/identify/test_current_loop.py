"""Current-loop lag: the sampled-data model, synthetic recovery, the simulator's hold, and
recovery of a hidden τ from the demo plant (effects on)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from hil.drives.base import check_limits
from hil.drives.sim import SimDrive
from hil.errors import IdentificationError
from hil.identify.current_loop import (
    FrequencyPoint,
    TorqueHold,
    analyse_frequency,
    boxcar,
    fit_current_loop_lag,
    sampled_response,
    torque_hold_s,
)
from hil.motion import Mode
from hil.profile import load_profile
from hil.suite import current_loop as protocol
from plant_sim.firmware import Firmware
from plant_sim.model import Plant
from plant_sim.params import PlantParams
from tests.helpers import drive_info

PROFILE = load_profile()
FS = 4000.0
INFO = drive_info(PROFILE, FS)
SPEC = protocol.Spec.from_profile(PROFILE, INFO)
ACCURACY = PROFILE.measurement("current_loop_time_constant_ms").accuracy_rel


def test_rigid_response_is_the_half_sample_delayed_double_integrator() -> None:
    for f in (20.0, 150.0, 900.0):
        theta = 2 * math.pi * f / FS
        closed = -math.cos(theta / 2) / (4 * math.sin(theta / 2) ** 2) / FS**2
        closed_form = closed * np.exp(-0.5j * theta)
        model = sampled_response(f, fs_hz=FS, inertia_kg_m2=1.0, viscous_over_inertia_1_s=0.0,
                                 time_constant_s=0.0)[0]
        assert model == pytest.approx(closed_form, rel=1e-6)


@pytest.mark.parametrize("tau_s", [1e-4, 5e-4])
def test_response_matches_an_exact_zoh_simulation(tau_s: float) -> None:
    """Σ over images equals a state-space simulation of 1/(s(Js+B)(τs+1)) under a held input
    (matrix exponential: exact for piecewise-constant torque)."""
    j, b = 0.004, 0.01
    a = np.array([[0.0, 1.0, 0.0], [0.0, -b / j, 1 / j], [0.0, 0.0, -1 / tau_s]])
    augmented = np.zeros((4, 4))
    augmented[:3, :3] = a
    augmented[2, 3] = 1 / tau_s
    phi = expm(augmented / FS)
    for f in (30.0, 120.0):
        t = np.arange(round(FS / f * 40)) / FS
        u = np.cos(2 * math.pi * f * t)
        state = np.zeros(4)
        position = np.empty(t.size)
        for k in range(t.size):
            position[k] = state[0]
            state[3] = u[k]
            state = phi @ state
        tail = t >= 20 / f
        design = np.column_stack([np.cos(2 * math.pi * f * t[tail]),
                                  np.sin(2 * math.pi * f * t[tail]), np.ones(tail.sum()),
                                  t[tail]])
        coef = np.linalg.lstsq(design, position[tail], rcond=None)[0]
        model = sampled_response(f, fs_hz=FS, inertia_kg_m2=j, viscous_over_inertia_1_s=b / j,
                                 time_constant_s=tau_s)[0]
        assert complex(coef[0], -coef[1]) == pytest.approx(model, rel=1e-3)


def _lagged_axis(j: float, b: float, tau_s: float, step_s: float) -> np.ndarray:
    """Transition matrix of (position, velocity, delivered torque, held command) over one
    hold period: exact for a piecewise-constant command."""
    a = np.array([[0.0, 1.0, 0.0], [0.0, -b / j, 1 / j], [0.0, 0.0, -1 / tau_s]])
    augmented = np.zeros((4, 4))
    augmented[:3, :3] = a
    augmented[2, 3] = 1 / tau_s
    return np.asarray(expm(augmented * step_s))


def test_boxcar_is_a_pure_delay_of_half_the_averaged_span() -> None:
    """Mean of 4 held 0.25 ms samples: delay (T_s − T_c)/2 = 0.375 ms, real gain ≤ 1."""
    for f in (20.0, 150.0, 450.0):
        w = 2 * math.pi * f
        b = boxcar(np.array([w * 2.5e-4]), 4)[0]
        gain = math.sin(w * 1e-3 / 2) / (4 * math.sin(w * 2.5e-4 / 2))
        assert b == pytest.approx(gain * np.exp(-1j * w * 3.75e-4), rel=1e-12)


@pytest.mark.parametrize("tau_s", [1e-4, 3e-4])
def test_mean_torque_response_matches_an_exact_control_rate_simulation(tau_s: float) -> None:
    """A 4 kHz drive streaming at 1 kHz: row k is the position at the start of control
    period 4k−1 and the mean of the torques held over periods 4k−4 … 4k−1 (0x2077). The
    phasor ratio is G_d(T_c)/B exactly, and a fit with the point-sample model (or with
    a hold of the row period) misses τ by the averaging delay."""
    j, b, control_s, n = 0.004, 0.01, 2.5e-4, 4
    phi = _lagged_axis(j, b, tau_s, control_s)
    for f in (30.0, 120.0):
        fine = np.arange(round(160 / f / control_s)) * control_s
        u = np.cos(2 * math.pi * f * fine)
        state = np.zeros(4)
        position = np.empty(fine.size)
        for k in range(fine.size):
            position[k] = state[0]
            state[3] = u[k]
            state = phi @ state
        rows = np.arange(1, fine.size // n)
        p_rows = position[n * rows - 1]
        m_rows = u[: n * rows[-1]].reshape(-1, n).mean(axis=1)[rows - 1]
        t = rows * n * control_s
        tail = t >= 140 / f  # B/J = 2.5/s: the start's velocity offset has decayed
        design = np.column_stack([np.cos(2 * math.pi * f * t[tail]),
                                  np.sin(2 * math.pi * f * t[tail]), np.ones(tail.sum()),
                                  t[tail]])
        cp, cm = np.linalg.lstsq(design, np.column_stack([p_rows[tail], m_rows[tail]]),
                                 rcond=None)[0][:2].T
        measured = complex(cp[0], -cp[1]) / complex(cm[0], -cm[1])
        model = sampled_response(f, fs_hz=1 / control_s, inertia_kg_m2=j,
                                 viscous_over_inertia_1_s=b / j, time_constant_s=tau_s,
                                 mean_samples=n)[0]
        assert measured == pytest.approx(model, rel=1e-3)
        point = sampled_response(f, fs_hz=1 / control_s, inertia_kg_m2=j,
                                 viscous_over_inertia_1_s=b / j, time_constant_s=tau_s)[0]
        assert abs(np.angle(measured / point)) > 0.9 * 2 * math.pi * f * 3.75e-4


def test_mean_sampling_from_the_metadata() -> None:
    meta = {"torque_sample": "mean", "control_period_s": "0.00025",
            "command_interpolation": "linear", "torque_mean_period_s": "0.001"}
    hold = torque_hold_s(meta, fs_hz=1000.0)
    assert isinstance(hold, TorqueHold)
    assert (hold.hold_s, hold.mean_samples) == (pytest.approx(2.5e-4), 4)
    assert torque_hold_s({**meta, "torque_sample": "instantaneous"},
                         fs_hz=1000.0).mean_samples == 1
    assert torque_hold_s({}, fs_hz=1000.0).hold_s == pytest.approx(1e-3)
    with pytest.raises(IdentificationError, match="averaged over"):
        torque_hold_s({**meta, "torque_mean_period_s": "0.002"}, fs_hz=1000.0)
    with pytest.raises(IdentificationError, match="control period"):
        torque_hold_s({"torque_sample": "mean", "command_interpolation": "linear"},
                      fs_hz=1000.0)
    with pytest.raises(IdentificationError, match="alias"):
        torque_hold_s({**meta, "command_interpolation": "hold"}, fs_hz=1000.0)


def _synthetic_points(tau_s: float, *, noise_nm: float, seed: int) -> list[FrequencyPoint]:
    """Exact sampled responses of a lagged rigid axis with white torque-measurement noise."""
    rng = np.random.default_rng(seed)
    points = []
    for f in SPEC.frequencies_hz:
        t = np.arange(round(FS / f * round(0.25 * f))) / FS
        torque = 0.15 * np.cos(2 * math.pi * f * t)
        g = sampled_response(f, fs_hz=FS, inertia_kg_m2=0.0036, viscous_over_inertia_1_s=1.4,
                             time_constant_s=tau_s)[0]
        position = 0.15 * abs(g) * np.cos(2 * math.pi * f * t + np.angle(g)) + 0.3 * t
        points.append(analyse_frequency(t, position, torque + rng.normal(0, noise_nm, t.size),
                                        frequency_hz=f, fs_hz=FS, blocks=5))
    return points


def test_noise_free_lag_is_recovered_exactly() -> None:
    result = fit_current_loop_lag(_synthetic_points(4e-4, noise_nm=1e-9, seed=0),
                                  fs_hz=FS)
    assert result.time_constant.value == pytest.approx(0.4, rel=1e-4)
    assert result.viscous_over_inertia_1_s == pytest.approx(1.4, rel=0.02)
    assert result.inertia_kg_m2 == pytest.approx(0.0036, rel=1e-4)


def test_reported_uncertainty_matches_the_scatter() -> None:
    values, uncertainties = [], []
    for seed in range(40):
        result = fit_current_loop_lag(_synthetic_points(3e-4, noise_nm=0.01, seed=seed),
                                      fs_hz=FS)
        values.append(result.time_constant.value)
        uncertainties.append(result.time_constant.standard_uncertainty)
    scatter = float(np.std(values, ddof=1))
    u = float(np.median(uncertainties))
    # weights estimated from the same blocks: a small bias, well below one uncertainty
    assert abs(np.mean(values) - 0.3) < 0.5 * u
    assert 0.6 < u / scatter < 1.6


def test_two_frequencies_are_refused() -> None:
    points = _synthetic_points(3e-4, noise_nm=1e-3, seed=0)[:2]
    with pytest.raises(IdentificationError, match="at least 3"):
        fit_current_loop_lag(points, fs_hz=FS)


def test_simulator_holds_the_torque_over_the_period() -> None:
    """Torque mode, no effects but the lag, exact hold (as SimDrive runs it): the sim's
    sampled response is the model's (a constant-torque kick first: no reversal)."""
    for tau_s in (0.0, 3e-4):
        plant = Plant(PlantParams(inertia_kg_m2=0.0036, exact_torque_hold=True),
                      firmware=Firmware(current_loop_time_constant_s=tau_s), fs_hz=FS, seed=0)
        f = 110.0
        t = np.arange(round(FS / f * 44)) / FS
        plant.run(Mode.TORQUE, np.full(40, 0.1))
        trace = plant.run(Mode.TORQUE, 0.2 * np.cos(2 * math.pi * f * (t + 0.5 / FS)))
        tail = t >= 11 / f
        point = analyse_frequency(t[tail], trace.position_rad[tail], trace.torque_nm[tail],
                                  frequency_hz=f, fs_hz=FS, blocks=4)
        model = sampled_response(f, fs_hz=FS, inertia_kg_m2=0.0036,
                                 viscous_over_inertia_1_s=0.0, time_constant_s=tau_s)[0]
        assert point.response_rad_nm == pytest.approx(model, rel=2e-3)


@pytest.mark.parametrize("start", [-1.4, 0.0, 1.4])
def test_excitation_is_inside_the_limits(start: float) -> None:
    move, sines = protocol.excitation(SPEC, position_rad=start)
    check_limits(move, PROFILE.limits, start_position_rad=start)
    check_limits(sines, PROFILE.limits, start_position_rad=SPEC.start_rad)
    assert sines.command.min() >= 0.0  # the carrier keeps the axis moving one way


@settings(max_examples=10, deadline=None)
@given(tau_ms=st.floats(0.1, 1.0), inertia=st.floats(0.0025, 0.006),
       coulomb=st.floats(0.01, 0.04), seed=st.integers(0, 2**16))
def test_hidden_lag_is_recovered_within_the_claimed_accuracy(
    tau_ms: float, inertia: float, coulomb: float, seed: int
) -> None:
    assert PROFILE.plant is not None
    assert ACCURACY is not None
    firmware = PROFILE.firmware.with_changes(current_loop_time_constant_s=tau_ms * 1e-3)
    plant = PROFILE.plant.with_changes(inertia_kg_m2=inertia, coulomb_nm=coulomb,
                                       static_friction_nm=1.3 * coulomb)
    with SimDrive(plant, firmware=firmware, limits=PROFILE.limits, fs_hz=FS, seed=seed) as drive:
        drive.enable()
        move, sines = protocol.excitation(SPEC, position_rad=drive.status().position_rad)
        drive.run(move)
        result = protocol.analyse(drive.run(sines), SPEC)
    assert result.time_constant.value == pytest.approx(tau_ms, rel=ACCURACY)
