"""Two-mass resonance: the model, exact recovery from synthetic stepped-sine FRF data, the
quality measures, the bandwidth, and recovery of a hidden shaft from the azimuth demo plant
(effects on) by the profile's excitation (the multisine; its design and FRF in
``test_resonance_multisine.py``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.drives.base import check_limits
from hil.drives.sim import SimDrive
from hil.errors import IdentificationError
from hil.identify.current_loop import sampled_response
from hil.identify.resonance import (
    FrfPoint,
    TwoMassModel,
    bandwidth_relative_u,
    frf_point,
    identify_resonance,
    two_mass_response,
    velocity_loop_bandwidth_hz,
)
from hil.profile import load_profile
from hil.suite import resonance as protocol
from tests.helpers import drive_info

PROFILE = load_profile("demo_gimbal_azimuth")
FS = 4000.0
INFO = drive_info(PROFILE, FS)
STEPPED_TABLE = {"excitation": "stepped_sine", "band_hz": [6.0, 300.0], "points": 24,
                 "amplitude_rad_s": 0.25, "max_amplitude_rad_s": 0.6, "segment_s": 0.1,
                 "min_periods": 5, "settle_s": 0.12, "blocks": 5}
SPEC = protocol.SteppedSpec.from_profile(
    dataclasses.replace(PROFILE, protocols={**PROFILE.protocols, "resonance": STEPPED_TABLE}),
    INFO)
DESIGNED = protocol.spec_from_profile(PROFILE, INFO)
TRUTH = TwoMassModel(inertia_kg_m2=0.008, antiresonance_hz=50.0, antiresonance_damping=0.03,
                     resonance_hz=81.65, resonance_damping=0.05, viscous_over_inertia_1_s=0.75,
                     time_constant_s=2e-4)


def _accuracy(name: str) -> float:
    accuracy = PROFILE.measurement(name).accuracy_rel
    assert accuracy is not None
    return accuracy


def test_without_a_shaft_the_model_is_the_rigid_lagged_axis() -> None:
    rigid = TwoMassModel(inertia_kg_m2=0.004, antiresonance_hz=80.0, antiresonance_damping=0.05,
                         resonance_hz=80.0, resonance_damping=0.05,
                         viscous_over_inertia_1_s=1.2, time_constant_s=3e-4)
    f = np.array([10.0, 100.0, 400.0])
    expected = sampled_response(f, fs_hz=FS, inertia_kg_m2=0.004, viscous_over_inertia_1_s=1.2,
                                time_constant_s=3e-4)
    assert two_mass_response(rigid, f, fs_hz=FS) == pytest.approx(expected, rel=1e-9)


def _synthetic(model: TwoMassModel, *, noise_nm: float, seed: int) -> list[FrfPoint]:
    """Exact sampled response to the protocol's stepped sine, white noise on the torque."""
    rng = np.random.default_rng(seed)
    points = []
    for f in SPEC.frequencies_hz:
        n = SPEC.segment_samples(f) - SPEC.settle_samples(f)
        t = np.arange(n) / FS
        torque = 0.1 * np.cos(2 * math.pi * f * t)
        g = two_mass_response(model, np.array([f]), fs_hz=FS)[0]
        position = 0.1 * abs(g) * np.cos(2 * math.pi * f * t + np.angle(g)) + 0.5 * t
        closed = 1.0 / (1.0 + 1j * f / 12.0)  # a first-order loop at 12 Hz
        command = 0.1 * abs(g) * 2 * math.pi * f / abs(closed) * np.cos(
            2 * math.pi * f * t + np.angle(g) + math.pi / 2 - np.angle(closed))
        points.append(frf_point(t, position, torque + rng.normal(0, noise_nm, n), command,
                                frequency_hz=f, fs_hz=FS, blocks=SPEC.blocks))
    return points


def test_noise_free_frf_gives_the_model_back() -> None:
    result = identify_resonance(_synthetic(TRUTH, noise_nm=1e-7, seed=0), fs_hz=FS)
    assert result.resonance.value == pytest.approx(81.65, rel=1e-4)
    assert result.antiresonance.value == pytest.approx(50.0, rel=1e-4)
    assert result.damping.value == pytest.approx(0.05, rel=1e-3)
    assert result.model.inertia_kg_m2 == pytest.approx(0.008, rel=1e-4)
    assert result.bandwidth_hz == pytest.approx(12.0, rel=0.02)
    assert all(p.coherence > 0.999999 for p in result.points)


def test_noise_lowers_the_coherence_where_the_response_is_small() -> None:
    points = _synthetic(TRUTH, noise_nm=0.05, seed=1)
    notch = min(points, key=lambda p: abs(p.frequency_hz - 50.0))
    flank = min(points, key=lambda p: abs(p.frequency_hz - 10.0))
    assert notch.coherence < flank.coherence
    assert 0.0 <= notch.coherence <= 1.0


def test_reported_uncertainty_matches_the_scatter() -> None:
    values, uncertainties = [], []
    for seed in range(25):
        result = identify_resonance(_synthetic(TRUTH, noise_nm=0.003, seed=seed), fs_hz=FS)
        values.append(result.resonance.value)
        uncertainties.append(result.resonance.standard_uncertainty)
    scatter = float(np.std(values, ddof=1))
    u = float(np.median(uncertainties))
    # a nonlinear fit: a small noise-induced bias (∝ σ²), well below one standard uncertainty
    assert abs(np.mean(values) - 81.65) < 0.5 * u
    assert 0.5 < u / scatter < 2.0


def test_the_bandwidths_uncertainty_from_the_two_lines_about_its_crossing() -> None:
    """Two lines straddling 1/√2; moving each |T| by its u (one at a time) moves the
    interpolated bandwidth by what the propagated u says, to first order."""
    def line(frequency_hz: float, gain: float, u: float) -> FrfPoint:
        return FrfPoint(frequency_hz=frequency_hz, frf_rad_nm=1.0 + 0j, relative_u=0.01,
                        coherence=1.0, closed_loop=complex(gain), blocks=17,
                        closed_loop_relative_u=u)

    points = [line(10.0, 0.95, 0.0), line(20.0, 0.80, 0.004), line(30.0, 0.60, 0.006)]
    found = velocity_loop_bandwidth_hz(points)
    shifts = []
    for k in (1, 2):
        moved = list(points)
        moved[k] = dataclasses.replace(points[k], closed_loop=points[k].closed_loop
                                       * (1 + 1e-3 * points[k].closed_loop_relative_u))
        shifts.append(math.log(velocity_loop_bandwidth_hz(moved) / found) / 1e-3)
    assert bandwidth_relative_u(points) == pytest.approx(math.hypot(*shifts), rel=1e-3)
    assert bandwidth_relative_u(points) > 0


def test_a_band_without_the_resonance_is_refused() -> None:
    points = [p for p in _synthetic(TRUTH, noise_nm=1e-4, seed=0) if p.frequency_hz < 40]
    with pytest.raises(IdentificationError):
        identify_resonance(points, fs_hz=FS)


def test_bandwidth_needs_the_band_to_bracket_it() -> None:
    points = [p for p in _synthetic(TRUTH, noise_nm=1e-4, seed=0) if p.frequency_hz > 20]
    with pytest.raises(IdentificationError, match="bracket"):
        velocity_loop_bandwidth_hz(points)


def test_stepped_sine_is_inside_the_limits_and_the_followed_sines_stay_on_the_carrier(
) -> None:
    for start in (-3.0, 0.0, 3.0):
        move, sine = protocol.excitation(SPEC, position_rad=start)
        check_limits(move, PROFILE.limits, start_position_rad=start)
        check_limits(sine, PROFILE.limits, start_position_rad=SPEC.start_rad)
    # below the knee the motor follows the command: its sine must not reverse the carrier
    assert SPEC.amplitude(SPEC.amplitude_knee_hz) < SPEC.speed_rad_s


@settings(max_examples=8, deadline=None)
@given(load_ratio=st.floats(0.6, 3.0), antiresonance_hz=st.floats(35.0, 70.0),
       damping=st.floats(0.03, 0.1), seed=st.integers(0, 2**16))
def test_hidden_shaft_is_recovered_within_the_claimed_accuracy(
    load_ratio: float, antiresonance_hz: float, damping: float, seed: int
) -> None:
    """J_load/J_motor, f_a and ζ_r drawn; total inertia kept; effects of the demo on."""
    assert PROFILE.plant is not None
    j_total = PROFILE.plant.total_inertia_kg_m2
    j_m = j_total / (1 + load_ratio)
    j_l = j_total - j_m
    k = j_l * (2 * math.pi * antiresonance_hz) ** 2
    j_red = j_m * j_l / j_total
    c = 2 * damping * math.sqrt(k * j_red)
    plant = PROFILE.plant.with_changes(inertia_kg_m2=j_m, load_inertia_kg_m2=j_l,
                                       shaft_stiffness_nm_rad=k, shaft_damping_nm_s_rad=c,
                                       inertia_elevation_kg_m2=0.0)
    with SimDrive(plant, firmware=PROFILE.firmware, limits=PROFILE.limits, fs_hz=FS,
                  seed=seed) as drive:
        drive.enable()
        *moves, measured = protocol.excitation(DESIGNED,
                                               position_rad=drive.status().position_rad)
        for move in moves:
            drive.run(move)
        result = protocol.analyse([drive.run(measured)], DESIGNED)
    assert result.resonance.value == pytest.approx(plant.resonance_hz,
                                                   rel=_accuracy("resonance_frequency_hz"))
    assert result.antiresonance.value == pytest.approx(
        antiresonance_hz, rel=_accuracy("antiresonance_frequency_hz"))
    # the motor's viscous friction adds to the shaft's damping of the resonant mode
    b = PROFILE.plant.viscous_nm_s_rad
    zeta = damping + b / (2 * j_m * 2 * math.pi * plant.resonance_hz) * (j_l / j_total)
    assert result.damping.value == pytest.approx(zeta, rel=_accuracy("resonance_damping_ratio"))


def test_the_stepped_sine_stays_available_through_the_profile() -> None:
    """``excitation = "stepped_sine"`` runs the former protocol: it still finds the demo's
    shaft within the claimed accuracy (effects on)."""
    profile = dataclasses.replace(PROFILE, protocols={**PROFILE.protocols,
                                                      "resonance": STEPPED_TABLE})
    spec = protocol.spec_from_profile(profile, INFO)
    assert isinstance(spec, protocol.SteppedSpec)
    plant = PROFILE.plant
    assert plant is not None
    with SimDrive(plant, firmware=PROFILE.firmware, limits=PROFILE.limits, fs_hz=FS,
                  seed=5) as drive:
        drive.enable()
        move, sine = protocol.excitation(spec, position_rad=drive.status().position_rad)
        drive.run(move)
        result = protocol.analyse([drive.run(sine)], spec)
    assert result.resonance.value == pytest.approx(plant.resonance_hz,
                                                   rel=_accuracy("resonance_frequency_hz"))
