"""The current-loop protocol tests its first-order lag on its own phases: a drive whose new
command acts late within its period (a dead time beside the loop's lag) is told apart from
one without, and the dead time fitted beside τ is the simulated one. Recorded by the second
simulator (:mod:`plant_sim.variant`), written apart from the analysis."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hil.drives.sim import SimDrive
from hil.identify.current_loop import FrequencyPoint, fit_current_loop_lag, sampled_response
from hil.identify.estimate import coverage_factor
from hil.identify.lag_model import ADEQUACY_P, null_p_value
from hil.identify.scatter_weights import coverage_dof, draw_fits
from hil.profile import load_profile
from hil.suite import current_loop as protocol
from plant_sim.firmware import Firmware
from plant_sim.params import PlantParams
from plant_sim.variant import MAIN_LIKE, apply_delay_s, simulate_variant

PROFILE = load_profile("demo_gimbal_elevation")  # its current-loop protocol and limits
PLANT = PlantParams(inertia_kg_m2=0.0036, viscous_nm_s_rad=0.005, coulomb_nm=0.02,
                    static_friction_nm=0.026, stribeck_velocity_rad_s=0.02,
                    torque_noise_nm=0.0015)
PROFILE_FREQUENCIES_HZ = (20.0, 40.0, 70.0, 110.0, 150.0)
FIRMWARE = Firmware(velocity_filter_hz=300.0, velocity_kp_nm_s_rad=0.45,
                    velocity_ki_nm_rad=12.0, current_loop_time_constant_s=0.0003)


def _check(apply_delay_rel: float, *, seed: int = 5,  # type: ignore[no-untyped-def]
           encoder_counts_per_rev: int = MAIN_LIKE.encoder_counts_per_rev):
    variant = dataclasses.replace(MAIN_LIKE, sample_rate_hz=4000.0, integrator="rk4",
                                  apply_delay_rel=apply_delay_rel,
                                  encoder_counts_per_rev=encoder_counts_per_rev)
    info = SimDrive(PLANT, firmware=FIRMWARE, limits=PROFILE.limits, fs_hz=4000.0, seed=0).info
    spec = dataclasses.replace(protocol.Spec.from_profile(PROFILE, info), fs_hz=4000.0)
    recording = simulate_variant(PLANT, FIRMWARE, variant,
                                 velocity_command_rad_s=spec.carrier_command(), seed=seed)
    result, check = protocol.analyse_checked(recording, spec)
    return check, result, apply_delay_s(PLANT, FIRMWARE, variant)


def test_a_first_order_loop_passes_its_own_test() -> None:
    check, result, _ = _check(0.0)
    assert check.adequate, check
    assert check.message() is None
    assert check.dead_time_ms is not None
    if check.dead_time_u_ms is not None:  # none, within its u (or put at its bound, 0)
        assert check.dead_time_ms <= 2 * check.dead_time_u_ms, check
    tau = result.time_constant
    truth_ms = 1000 * FIRMWARE.current_loop_time_constant_s
    assert abs(tau.value - truth_ms) <= tau.expanded_uncertainty, (tau, truth_ms)


def test_a_dead_time_the_test_does_not_see_is_still_in_the_certified_lag() -> None:
    """Commands acting 0.02–0.25 of a 4 kHz period late, encoders of 2¹⁷–2²² counts: where
    the χ² test holds the first-order lag adequate, that lag's τ' reads above τ + d (about
    τ²·d·ω² at the band's top); the certified sum does not. Failed before: τ' was certified
    wherever the test held. (The encoder's steps bend the phases too, differently for each
    count: their error is the scatter the errors are judged against, not Type A's u.)"""
    rng = np.random.default_rng(23)
    certified, first_order = [], []
    for rel in rng.uniform(0.02, 0.25, 30):
        counts = int(2 ** rng.uniform(17, 22))
        check, result, delay_s = _check(float(rel), seed=int(rng.integers(2**31)),
                                        encoder_counts_per_rev=counts)
        if not check.adequate:
            continue
        assert check.first_order_ms is not None
        truth_ms = 1000 * (FIRMWARE.current_loop_time_constant_s + delay_s)
        certified.append(result.time_constant.value / truth_ms - 1)
        first_order.append(check.first_order_ms / truth_ms - 1)
    assert len(certified) >= 10, len(certified)
    standard_error = np.std(certified, ddof=1) / math.sqrt(len(certified))
    assert abs(np.mean(certified)) < 3 * standard_error, certified
    assert np.mean(first_order) > 3 * standard_error, first_order  # the bias the sum removes


@pytest.mark.parametrize("apply_delay_rel", [0.3, 0.6])
def test_a_dead_time_is_found_and_stated(apply_delay_rel: float) -> None:
    check, _, delay_s = _check(apply_delay_rel)
    assert not check.adequate, check
    assert check.dead_time_ms is not None
    assert check.dead_time_u_ms is not None
    assert abs(check.dead_time_ms - 1000 * delay_s) <= 2 * check.dead_time_u_ms, check
    assert check.time_constant_ms is not None
    assert check.time_constant_u_ms is not None
    assert abs(check.time_constant_ms - 1000 * FIRMWARE.current_loop_time_constant_s) \
        <= 2 * check.time_constant_u_ms, check
    message = check.message()
    assert message is not None
    assert "dead time" in message


@pytest.mark.parametrize("apply_delay_rel", [0.3, 0.6])
def test_with_a_dead_time_the_lag_below_the_band_is_certified(apply_delay_rel: float) -> None:
    """The certified τ is τ + dead time, within its U; the first-order τ over the band was
    not (it is the equivalent of both at 20–150 Hz, larger than their sum)."""
    check, result, delay_s = _check(apply_delay_rel)
    truth_ms = 1000 * (FIRMWARE.current_loop_time_constant_s + delay_s)
    tau = result.time_constant
    assert abs(tau.value - truth_ms) <= tau.expanded_uncertainty, (tau, truth_ms)
    assert check.first_order_ms is not None
    assert check.first_order_ms - truth_ms > abs(tau.value - truth_ms), (check, truth_ms)


def _first_order_points(rng: np.random.Generator, *, blocks: int) -> list[FrequencyPoint]:
    """The phases of a first-order lag (τ 0.3 ms, B/J 1.4/s at 4 kHz), each the mean of
    ``blocks`` block phases with its own scatter, as :func:`analyse_frequency` states them."""
    freqs = np.array(PROFILE_FREQUENCIES_HZ)
    model = sampled_response(freqs, fs_hz=4000.0, inertia_kg_m2=0.0036,
                             viscous_over_inertia_1_s=1.4, time_constant_s=3e-4)
    rigid = sampled_response(freqs, fs_hz=4000.0, inertia_kg_m2=0.0036,
                             viscous_over_inertia_1_s=0.0, time_constant_s=0.0)
    points = []
    for f, g, r, sigma in zip(freqs, model, rigid, (2e-3, 1.5e-3, 1e-3, 1e-3, 2e-3),
                              strict=True):
        block_phases = np.angle(g / r) + rng.normal(0.0, sigma, blocks)
        phase = float(np.mean(block_phases))
        points.append(FrequencyPoint(
            frequency_hz=float(f), response_rad_nm=complex(r * np.exp(1j * phase)),
            lag_phase_rad=phase, lag_phase_u_rad=float(np.std(block_phases, ddof=1))
            / math.sqrt(blocks), inertia_kg_m2=0.0036, torque_amplitude_nm=0.1, blocks=blocks))
    return points


@pytest.mark.parametrize("blocks", [5, 10])
def test_a_first_order_lag_is_rejected_at_the_stated_rate(blocks: int) -> None:
    """Each phase's weight is estimated from its blocks, so each χ² term is an F(1, blocks − 1):
    read against the χ² table, 5 blocks reject a right model several times too often."""
    rng = np.random.default_rng(11)
    p_values = np.array([  # check_lag_model's p_value, without its dead-time fit
        null_p_value(fit_current_loop_lag(_first_order_points(rng, blocks=blocks),
                                          fs_hz=4000.0), fs_hz=4000.0)
        for _ in range(600)])
    # binomial: at 1 %, 6 expected, ≥ 16 has probability < 1e-3; at 20 %, 120 ± 10
    assert np.count_nonzero(p_values < ADEQUACY_P) < 16
    assert 90 < np.count_nonzero(p_values < 0.2) < 150


def test_tau_covers_at_its_stated_rate_in_each_branch_of_its_weights() -> None:
    """Each phase weighs by its own 5 blocks' scatter. Fits whose misfit stayed below its
    expectation (u as fitted) and fits whose u was widened by √(χ²/ν) each keep 95.45 %
    within ±U: the pooled 20 degrees of freedom gave the first 90 % and ν = 3 the second
    99 % over these draws."""
    rng = np.random.default_rng(3)
    within: dict[bool, list[bool]] = {True: [], False: []}
    for _ in range(800):
        result = fit_current_loop_lag(_first_order_points(rng, blocks=5), fs_hz=4000.0)
        tau = result.time_constant
        within[result.chi2_per_dof > 1.0].append(abs(tau.value - 0.3) <= tau.expanded_uncertainty)
    for widened, hits in within.items():
        n = len(hits)
        sd = math.sqrt(0.9545 * 0.0455 / n)
        assert n > 250, widened
        assert abs(np.mean(hits) - 0.9545) < 3 * sd, (widened, n, np.mean(hits))


def test_many_blocks_per_phase_make_tau_normal() -> None:
    """With weights known all but exactly, τ's k is the normal's 2."""
    design = np.array([[1.0, 0.2], [1.0, 0.5], [1.0, 1.0], [1.0, 1.5], [1.0, 2.0]])
    drawn = draw_fits(design, np.full(5, 1e6))
    assert coverage_factor(coverage_dof(drawn, np.array([1.0, 0.0]), inflated=False)) == 2.0
    few = draw_fits(design, np.full(5, 4.0))
    assert 2.0 < coverage_factor(coverage_dof(few, np.array([1.0, 0.0]), inflated=False)) < 3.0
