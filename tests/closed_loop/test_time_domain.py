"""Step, tracking, standstill and ripple numerics against responses known in closed form,
with noise on; and the tracking protocol's feedforward on the simulated drive."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.closed_loop.ripple import position_ripple
from hil.closed_loop.standstill import block_estimate, standstill_blocks
from hil.closed_loop.step import mean_estimate, smoothed_velocity, step_figures
from hil.closed_loop.tracking import (
    feedforward_change,
    following_error,
    reference_position,
    repeated,
)
from hil.drives.sim import SimDrive
from hil.profile import load_profile
from hil.suite import tracking

FS = 4000.0


def second_order_step(t: np.ndarray, *, zeta: float, wn: float) -> np.ndarray:
    """Unit step response of ``wn²/(s² + 2ζwn s + wn²)``."""
    wd = wn * math.sqrt(1 - zeta**2)
    phase = math.acos(zeta)
    return 1 - np.exp(-zeta * wn * t) * np.sin(wd * t + phase) / math.sqrt(1 - zeta**2)


def test_step_figures_of_a_second_order_response() -> None:
    zeta, wn = 0.5, 2 * math.pi * 20
    t = np.arange(round(0.5 * FS)) / FS
    response = 0.3 + 0.5 * second_order_step(t, zeta=zeta, wn=wn)
    dense = second_order_step(np.arange(0, 0.5, 1e-6), zeta=zeta, wn=wn)
    rise = (np.argmax(dense >= 0.9) - np.argmax(dense >= 0.1)) * 1e-6
    outside = np.flatnonzero(np.abs(dense - 1) > 0.02)
    figures = step_figures(response, start_rad_s=0.3, target_rad_s=0.8, fs_hz=FS)
    assert figures.overshoot_pct == pytest.approx(
        100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), rel=2e-3)
    assert figures.rise_time_s == pytest.approx(rise, abs=0.02 / FS)
    assert figures.settling_time_s == pytest.approx((outside[-1] + 1) * 1e-6, abs=1 / FS)
    assert figures.steady_state_error_pct == pytest.approx(0.0, abs=1e-6)


def test_noisy_steps_scatter_around_the_truth_within_their_uncertainty() -> None:
    """Encoder-like noise on position, the protocol's smoothing: the mean of four steps
    and its uncertainty cover the closed form."""
    zeta, wn = 0.6, 2 * math.pi * 25
    truth = 100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    rng = np.random.default_rng(3)
    t = np.arange(round(0.4 * FS)) / FS
    overshoots = []
    for _ in range(4):
        velocity = 0.5 + 1.0 * second_order_step(t, zeta=zeta, wn=wn)
        position = np.cumsum(velocity) / FS + rng.uniform(-6e-6, 6e-6, len(t))
        smooth = smoothed_velocity(position, fs_hz=FS, smooth_s=0.002)
        overshoots.append(step_figures(smooth[10:-10], start_rad_s=0.5, target_rad_s=1.5,
                                       fs_hz=FS).overshoot_pct)
    estimate = mean_estimate("overshoot", overshoots, "%")
    assert estimate.dof == 3
    assert abs(estimate.value - truth) < estimate.expanded_uncertainty + 0.3  # smoothing bias


def test_following_error_of_a_known_lag() -> None:
    rng = np.random.default_rng(0)
    command = np.concatenate([np.linspace(0, 1, 2000), np.full(4000, 1.0)])
    reference = reference_position(command, start_rad=-0.5, fs_hz=FS)
    error = 1e-3 * np.sin(np.arange(len(command)) / 300.0)
    noise = 3e-6
    found = following_error(reference + error + noise * rng.standard_normal(len(command)),
                            command, fs_hz=FS)
    assert found.rms_rad == pytest.approx(float(np.sqrt(np.mean(error**2))), rel=1e-3)
    assert found.peak_rad == pytest.approx(1e-3, abs=4 * noise)


def test_repeated_runs_state_the_scatter_of_their_mean() -> None:
    """Runs of one move whose difference is an offset left by a breakaway at the start
    (friction holds the axis until the noise tips it: a few µrad, persisting) on top of a
    slow wander: over 300 draws the stated u of the mean RMS matches its scatter, where a
    within-run smoothing (the old Type A) sees a small fraction of it."""
    rng = np.random.default_rng(3)
    command = np.concatenate([np.linspace(0, 1.0, 1500), np.full(4000, 1.0),
                              np.linspace(1.0, 0, 1500)])
    lag = 2e-3 * command + 1e-4  # a one-signed following error, as a velocity move has
    rho = np.exp(-1 / (0.05 * FS))
    values, stated, within, dof = [], [], [], []
    for _ in range(300):
        runs = []
        for _ in range(3):
            wander = np.empty(len(command))
            drive = 3e-6 * np.sqrt(1 - rho**2) * rng.standard_normal(len(command))
            wander[0] = 0.0
            for i in range(1, len(command)):
                wander[i] = rho * wander[i - 1] + drive[i]
            offset = 4e-6 * rng.standard_normal() * (np.arange(len(command)) > 40)
            true = reference_position(command, start_rad=0.37, fs_hz=FS) + lag + wander + offset
            read = np.round((true + 1e-6 * rng.standard_normal(true.size)) / 1e-6) * 1e-6
            runs.append(following_error(read, command, fs_hz=FS))
        found = repeated(runs)
        values.append(found.rms_rad)
        stated.append(found.u_rms_rad)
        dof.append(found.dof)
        error = runs[0].error_rad
        width = 21
        smooth = np.convolve(np.pad(error, width // 2, mode="edge"), np.ones(width) / width,
                             mode="valid")
        within.append(float(np.std(error - smooth, ddof=1)) / math.sqrt(len(error) * 3))
    scatter = float(np.std(values, ddof=1))
    assert dof == [2.0] * 300
    # s² of 3 runs is unbiased for the variance: its mean over the draws matches
    assert 0.85 < scatter / float(np.sqrt(np.mean(np.square(stated)))) < 1.15
    assert scatter / float(np.sqrt(np.mean(np.square(within)))) > 10


def test_feedforward_change_is_the_superposition_of_the_two_runs() -> None:
    command = np.full(4000, 0.2)
    reference = reference_position(command, start_rad=0.0, fs_hz=FS)
    shape = 1e-3 * np.sin(np.arange(4000) / 200.0)
    off = following_error(reference + 2 * shape, command, fs_hz=FS)
    on = following_error(reference + shape, command, fs_hz=FS)
    d_rms, d_peak = feedforward_change(off, on, relative=0.5)  # half again: half the error
    assert d_rms == pytest.approx(-0.5 * on.rms_rad, rel=1e-9)
    assert d_peak == pytest.approx(-0.5 * on.peak_rad, rel=1e-9)


def test_ripple_amplitude_at_the_orders_and_its_uncertainty() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(6000) / FS
    theta = -1.0 + 0.3 * t
    true = 20e-6
    misses = []
    for _ in range(20):
        position = theta + true * np.sin(84 * theta + 0.3) + 2e-6 * rng.standard_normal(t.size)
        amplitude, u, order = position_ripple(t, position, orders=[42, 84, 168])
        assert order == 84
        misses.append((amplitude - true) / u)
    assert np.sqrt(np.mean(np.square(misses))) < 2.0  # u describes the scatter


def test_ripple_uncertainty_with_a_slowly_wandering_position() -> None:
    """A velocity loop's noise wanders the position over the ripple's own periods (here an
    AR(1) with a 50 ms time constant, the ripple at 4 Hz over 6 periods) on white reading
    noise. The usual rule's 9 lags stated u at 1/5.4 of the scatter."""
    rng = np.random.default_rng(1)
    t = np.arange(6000) / FS
    theta = -1.0 + 0.3 * t
    true = 20e-6
    rho = math.exp(-1 / (0.05 * FS))
    amplitudes, stated = [], []
    for _ in range(100):
        drive = 8e-6 * math.sqrt(1 - rho**2) * rng.standard_normal(t.size)
        wander = np.empty(t.size)
        wander[0] = 8e-6 * rng.standard_normal()
        for i in range(1, t.size):
            wander[i] = rho * wander[i - 1] + drive[i]
        read = theta + true * np.sin(84 * theta + 0.3) + wander + 4e-6 * rng.standard_normal(
            t.size)
        amplitude, u, _ = position_ripple(t, read, orders=[42, 84, 168])
        amplitudes.append(amplitude)
        stated.append(u)
    ratio = float(np.std(amplitudes, ddof=1)) / float(np.sqrt(np.mean(np.square(stated))))
    assert 0.8 < ratio < 1.3


def test_standstill_blocks_and_their_resolution_line() -> None:
    rng = np.random.default_rng(2)
    position = np.round(rng.normal(0.0, 5e-6, 4000) / 1e-6) * 1e-6
    torque = rng.normal(0.01, 1.5e-3, 4000)
    blocks = standstill_blocks(position, torque, [(k * 800, (k + 1) * 800) for k in range(5)])
    jitter = block_estimate("j", blocks.position_rms_rad, scale=1e6, unit="µrad",
                            resolution=1e-6, what="encoder")
    ripple = block_estimate("r", blocks.torque_rms_nm, scale=1e3, unit="mN·m", resolution=0.0,
                            what="torque")
    assert jitter.value == pytest.approx(5.0, rel=0.05)
    assert ripple.value == pytest.approx(1.5, rel=0.05)
    assert [c.kind for c in jitter.budget] == ["A", "B"]


@pytest.mark.parametrize("feedforward", [True, False])
def test_the_drives_feedforward_reduces_the_following_error_of_the_standard_move(
    feedforward: bool
) -> None:
    profile = load_profile()
    assert profile.plant is not None
    firmware = profile.firmware.with_changes(feedforward=feedforward)
    with SimDrive(profile.plant, firmware=firmware, limits=profile.limits,
                  fs_hz=profile.sample_rate_hz, seed=0) as drive:
        spec = tracking.Spec.from_profile(profile, drive.info)
        pair = tracking.excitation(spec, viscous_nm_s_rad=0.005, coulomb_nm=0.02)
        drive.enable()
        runs = tracking.run_motion(spec, pair, drive=drive, run=drive.run)
    estimates, _, _ = tracking.analyse(runs[0::2], runs[1::2], spec)
    ratio = estimates["tracking_ff_reduction"]
    if feedforward:
        assert ratio.value > 1.5
    else:  # the firmware ignores the offset: the same move twice, from the same place
        assert abs(ratio.value - 1.0) < ratio.expanded_uncertainty
