"""Cogging and K_t ripple taken out of a recording before the J/B/T_c fit: the formula,
and a hidden K_t ripple's bias on J removed on the simulator with every other effect on."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.drives.sim import SimDrive
from hil.identify.cogging import HarmonicEstimate
from hil.identify.estimate import Estimate
from hil.identify.position_torque import PositionTorque
from hil.motion import Mode
from hil.profile import load_profile
from hil.recording import Recording
from hil.suite import inertia_friction as protocol
from plant_sim.params import Harmonic


def test_the_torque_becomes_what_a_model_without_them_sees() -> None:
    theta = np.linspace(0.0, 0.3, 200)
    torque = 0.05 + 0.01 * np.sin(theta)
    recording = Recording(columns={"time_s": np.arange(200) / 1000.0, "position_rad": theta,
                                   "velocity_rad_s": np.zeros(200), "torque_nm": torque})
    angle_map = PositionTorque(
        cogging=(HarmonicEstimate(order=84, amplitude=2e-4, phase_rad=0.3, amplitude_u=1e-5),),
        kt_ripple=(HarmonicEstimate(order=42, amplitude=0.02, phase_rad=-1.0,
                                    amplitude_u=1e-3),))
    expected = (torque * (1 + 0.02 * np.sin(42 * theta - 1.0))
                - 2e-4 * np.sin(84 * theta + 0.3))
    np.testing.assert_allclose(angle_map.without(recording).effort, expected, rtol=1e-12)
    assert angle_map.relative_u() == max(1e-5 / 2e-4, 1e-3 / 0.02)


@settings(max_examples=6, deadline=None)
@given(phase_rad=st.floats(-math.pi, math.pi), amplitude=st.floats(0.01, 0.03),
       seed=st.integers(0, 2**16))
def test_a_hidden_kt_ripple_no_longer_biases_the_inertia(phase_rad: float, amplitude: float,
                                                         seed: int) -> None:
    """The demo elevation with its noise, quantisation, lag and filter, and a K_t ripple
    (order 42) at a drawn phase and depth, without the effects other protocols take out
    (cable, gravity): with the ripple taken out J is within its U (Type A and the map's
    lines; the map given to within the 2 % its protocol states)."""
    profile = load_profile()
    assert profile.plant is not None
    plant = profile.plant.with_changes(
        cable_hysteresis_nm=0.0, cable_stiffness_nm_rad=0.0, gravity_mge_nm=0.0, cogging=(),
        kt_ripple=(Harmonic(order=42, amplitude=amplitude, phase_rad=phase_rad),))
    with SimDrive(plant, firmware=profile.firmware, limits=profile.limits,
                  fs_hz=profile.sample_rate_hz, seed=seed) as drive:
        drive.enable()
        spec = protocol.Spec.from_profile(profile, drive.info)
        sequence = list(protocol.motion(spec, position=lambda: drive.status().position_rad))
        recordings = [drive.run(e) for e in sequence]
    sines = [r for r, e in zip(recordings, sequence, strict=True) if e.mode is not Mode.POSITION]
    truth = plant.inertia_kg_m2 / (1 + plant.torque_constant_error_rel)
    tau_s = profile.firmware.current_loop_time_constant_s
    lag = Estimate(name="current_loop_time_constant_s", value=tau_s,
                   standard_uncertainty=0.01 * tau_s, unit="s", dof=math.inf)
    angle_map = PositionTorque(cogging=(), kt_ripple=(HarmonicEstimate(
        order=42, amplitude=amplitude, phase_rad=phase_rad, amplitude_u=0.02 * amplitude),))
    found = protocol.with_earlier_inputs(sines, spec, lag=lag, loop=None,
                                         position_torque=angle_map)["inertia_kg_m2"]
    bare = protocol.with_earlier_inputs(sines, spec, lag=lag, loop=None)["inertia_kg_m2"]
    assert abs(found.value - truth) <= found.expanded_uncertainty, (
        f"with the map {found.value / truth - 1:+.4%} (U {found.expanded_uncertainty / truth:.4%}),"
        f" without {bare.value / truth - 1:+.4%}")
