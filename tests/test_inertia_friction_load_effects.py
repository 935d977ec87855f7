"""J/B/T_c next to the load: gravity's gradient and the cable's hysteresis loop, measured by
``gravity_cable``, bias the sine method; the protocol takes them out. Each test hides the
effect in a simulated plant and checks the bias is real and that the correction removes it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import hil.suite.inertia_friction as protocol
from hil.drives.sim import SimDrive
from hil.identify.estimate import Estimate
from hil.identify.gravity_cable import CableLoop, cable_loop_torque_nm, load_stiffness
from hil.identify.inertia_friction import InertiaFrictionResult, stiffness_corrected_inertia
from hil.profile import load_profile
from hil.recording import Recording
from plant_sim.params import PlantParams

PROFILE = load_profile()
BASE = PlantParams(
    inertia_kg_m2=0.0036,
    viscous_nm_s_rad=0.005,
    coulomb_nm=0.020,
    torque_noise_nm=0.0015,
    encoder_counts_per_rev=1 << 19,
)
FIRMWARE = PROFILE.firmware.with_changes(velocity_filter_hz=0.0, current_loop_time_constant_s=0.0)


def _record(plant: PlantParams, *, centre_rad: float) -> tuple[list[Recording], protocol.Spec]:
    with SimDrive(plant, firmware=FIRMWARE, limits=PROFILE.limits, fs_hz=4000.0, seed=3) as drive:
        drive.enable()
        spec = dataclasses.replace(
            protocol.Spec.from_profile(PROFILE, drive.info), centre_rad=centre_rad
        )
        drive.run(protocol.move_to_centre(spec, centre_rad, position_rad=0.0))
        return [drive.run(e) for e in protocol.excitation(spec)], spec


def _estimate(value: float, u: float, name: str = "x") -> Estimate:
    return Estimate(name=name, value=value, standard_uncertainty=u, unit="", dof=math.inf)


def test_cable_loop_follows_the_fitted_dahl_law() -> None:
    """Saturates at ±h after a long travel; after a reversal it is ``h − 2h·exp(−s/s₀)``."""
    h, s0 = 0.002, 0.02
    out = np.linspace(0.0, 0.3, 3001)
    back = np.linspace(0.3, 0.2, 1001)[1:]
    torque = cable_loop_torque_nm(np.concatenate([out, back]), half_width_nm=h, angle_rad=s0)
    assert torque[len(out) - 1] == pytest.approx(h, rel=1e-5)
    travel_back = 0.3 - back
    expected = -(h - 2 * h * np.exp(-travel_back / s0))
    np.testing.assert_allclose(torque[len(out) :], expected, atol=2e-7)


def test_load_stiffness_is_the_slope_of_gravity_and_spring() -> None:
    mge, phase, k = 0.015, 0.05, 0.004

    def load(theta: float) -> float:
        return mge * math.cos(theta + phase) + k * theta

    for theta in (-1.2, 0.0, 0.7):
        found = load_stiffness(
            mge=_estimate(mge, 1e-4),
            phase=_estimate(phase, 0.01),
            cable_stiffness=_estimate(k, 2e-4),
            position_rad=theta,
        )
        slope = (load(theta + 1e-6) - load(theta - 1e-6)) / 2e-6
        assert found.value == pytest.approx(slope, rel=1e-6)
        assert found.standard_uncertainty > 2e-4  # the inputs' uncertainties propagate


def test_gravity_gradient_biases_j_and_the_measured_stiffness_removes_it() -> None:
    plant = dataclasses.replace(BASE, gravity_mge_nm=0.05)
    recordings, spec = _record(plant, centre_rad=-1.0)
    found = protocol.analyse(recordings, spec)
    centre = float(np.mean([np.mean(r.position) for r in recordings]))
    stiffness = _estimate(-0.05 * math.sin(centre), 0.0)
    corrected = stiffness_corrected_inertia(
        found.inertia, stiffness=stiffness, frequency_hz=spec.frequency_hz
    )
    assert found.inertia.value / plant.inertia_kg_m2 - 1 < -0.05  # the bias is real
    assert corrected.value == pytest.approx(plant.inertia_kg_m2, rel=0.01)


def test_cable_hysteresis_biases_b_and_removing_the_measured_loop_restores_it() -> None:
    plant = dataclasses.replace(
        BASE, cable_hysteresis_nm=0.002, cable_hysteresis_angle_rad=0.02
    )
    recordings, spec = _record(plant, centre_rad=0.0)
    loop = CableLoop(half_width_nm=0.002, half_width_u_nm=0.0002, angle_rad=0.02)
    raw: InertiaFrictionResult = protocol.analyse(recordings, spec)
    clean = protocol.analyse(recordings, spec, cable_loop=loop)
    assert raw.viscous.value / plant.viscous_nm_s_rad - 1 > 0.15  # the bias is real
    assert clean.viscous.value == pytest.approx(plant.viscous_nm_s_rad, rel=0.05)
    assert clean.inertia.value == pytest.approx(plant.inertia_kg_m2, rel=0.01)
    assert clean.coulomb.value == pytest.approx(plant.coulomb_nm, rel=0.02)
    widened = protocol.with_earlier_inputs(recordings, spec, lag=None, loop=loop)
    viscous = widened["viscous_nm_s_rad"]
    assert viscous.value == clean.viscous.value
    assert viscous.standard_uncertainty > clean.viscous.standard_uncertainty
    (line,) = (c for c in viscous.budget if c.source.startswith("cable hysteresis loop"))
    assert line.standard_uncertainty == loop.half_width_u_nm
    # B falls as more of the loop is taken out: the sensitivity's sign is the physics'
    assert line.sensitivity < 0


def test_the_loop_s_h_and_s0_are_propagated_together() -> None:
    """h and s₀ come from one fit and err together: the budget's two loop lines must
    state the scatter J, B and T_c show when (h, s₀) are drawn from that fit's joint
    distribution (holding s₀ fixed, as a single h line would, understates T_c's 10 ×)."""
    plant = dataclasses.replace(
        BASE, cable_hysteresis_nm=0.002, cable_hysteresis_angle_rad=0.02
    )
    recordings, spec = _record(plant, centre_rad=0.0)
    u_h, u_s, rho = 0.0003, 0.005, -0.8
    loop = CableLoop(half_width_nm=0.002, half_width_u_nm=u_h, angle_rad=0.02,
                     angle_u_rad=u_s, covariance=rho * u_h * u_s)
    stated = protocol.with_earlier_inputs(recordings, spec, lag=None, loop=loop)
    rng = np.random.default_rng(5)
    draws = rng.multivariate_normal([0.002, 0.02], [[u_h**2, rho * u_h * u_s],
                                                    [rho * u_h * u_s, u_s**2]], size=48)
    found = [protocol.sine_estimates(protocol.analyse(recordings, spec, cable_loop=CableLoop(
        half_width_nm=h, half_width_u_nm=u_h, angle_rad=s0))) for h, s0 in draws]
    for name in ("viscous_nm_s_rad", "coulomb_nm"):
        loop_lines = [c for c in stated[name].budget if "cable hysteresis" in c.source]
        assert len(loop_lines) == 3  # h (with s₀'s share), s₀'s rest, s₀'s curvature
        stated_u = math.sqrt(sum(c.contribution**2 for c in loop_lines))
        scatter = float(np.std([f[name].value for f in found], ddof=1))
        assert 0.75 < scatter / stated_u < 1.3, (name, scatter / stated_u)


def test_an_unresolved_loop_angle_is_a_line_over_its_range() -> None:
    """A gravity sweep too coarse for the loop's turn-over leaves u(s₀) ≥ s₀: the loop is
    taken out at the s₀ read, and a line states the results' range over s₀ from an abrupt
    loop to s₀ + 2u (rectangular); the true loop's results lie within that range."""
    plant = dataclasses.replace(
        BASE, cable_hysteresis_nm=0.002, cable_hysteresis_angle_rad=0.02
    )
    recordings, spec = _record(plant, centre_rad=0.0)
    loop = CableLoop(half_width_nm=0.002, half_width_u_nm=0.0003, angle_rad=0.05,
                     angle_u_rad=0.08)
    stated = protocol.with_earlier_inputs(recordings, spec, lag=None, loop=loop)
    true_loop = protocol.sine_estimates(protocol.analyse(recordings, spec, cable_loop=CableLoop(
        half_width_nm=0.002, half_width_u_nm=0.0003, angle_rad=0.02)))
    for name in ("viscous_nm_s_rad", "coulomb_nm"):
        (line,) = (c for c in stated[name].budget if "not resolved" in c.source)
        half_range = math.sqrt(3) * line.contribution  # rectangular: range/√12
        assert half_range > 0
        assert abs(true_loop[name].value - stated[name].value) <= 2 * half_range, name


def test_a_current_loop_not_measured_is_taken_from_the_profile_with_its_limits() -> None:
    """No current-loop protocol (a drive too slow for it): the sines take the profile's
    nominal τ out, its limits a rectangular line, not 0 s without a line."""
    spec = PROFILE.measurement("current_loop_time_constant_ms")
    lag = protocol.declared_current_loop_lag(PROFILE)
    assert lag is not None
    assert lag.value == pytest.approx(spec.nominal / 1000)
    half_width_s = (spec.upper_limit - spec.nominal) / 1000
    assert lag.standard_uncertainty == pytest.approx(half_width_s / math.sqrt(3))


def test_a_cable_spring_is_taken_out_where_gravitys_phase_is_not_measured(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The azimuth measures m·g·e (to check the axis is level) but no phase: its cable's
    spring was left in J (−k/(ω²J): the demo azimuth's whole −0.21 % method bias, session
    32). Now k_cable is taken out and gravity, whose phase is unknown, bounds it."""
    from hil.calibration import CalibrationRun
    from hil.measurement import MethodBiasMap
    from hil.profile import builtin_profile_path

    k, mge = 0.02, 1e-4
    plant = dataclasses.replace(BASE, cable_stiffness_nm_rad=k)
    recordings, spec = _record(plant, centre_rad=0.0)
    azimuth = load_profile(builtin_profile_path("demo_gimbal_azimuth"))
    run = CalibrationRun(profile=azimuth, unit_serial="X", out_dir=tmp_path, drive_kind="sim",
                         method_bias=MethodBiasMap(source="none", sha256="", entries={}))
    assert "gravity_phase_rad" not in azimuth.measurements
    assert protocol.measured_load_stiffness(run, position_rad=0.0) is None  # nothing yet
    run.record("gravity_cable", _estimate(k, 1e-4, "cable_stiffness_nm_rad"))
    run.record("gravity_cable", _estimate(mge, 2e-5, "gravity_mge_nm"))
    stiffness = protocol.measured_load_stiffness(run, position_rad=0.0)
    assert stiffness is not None
    assert stiffness.value == k
    assert stiffness.standard_uncertainty == pytest.approx(math.hypot(1e-4, 1.2e-4 / math.sqrt(3)))
    found = protocol.analyse(recordings, spec)
    corrected = stiffness_corrected_inertia(found.inertia, stiffness=stiffness,
                                            frequency_hz=spec.frequency_hz)
    assert found.inertia.value / plant.inertia_kg_m2 - 1 < -0.03  # the spring's bias is real
    assert corrected.value == pytest.approx(plant.inertia_kg_m2, rel=0.01)
