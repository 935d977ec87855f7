"""Velocity-loop FRF numerics against an analytic loop: PI on ``J s + B`` with a transport
delay, ``L = (Kp + Ki/s)·e^{−sd}/(J s + B)``, whose bandwidth, peak gain and margins
follow from ``L`` itself; the measured signals carry white noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from hil.closed_loop.frf import analyse_frf
from hil.errors import IdentificationError
from hil.identify.multisine import multisine, period_phasors, schroeder_phases

J, B, KP, KI, DELAY_S = 0.0036, 0.005, 0.45, 12.0, 1.2e-3
FS, PERIOD_S, PERIODS = 4000.0, 0.5, 6
HARMONICS = (1, 2, 3, 4, 5, 6, 7, 10, 12, 16, 20, 26, 33, 43, 55, 71, 91, 117, 151, 194, 249,
             320)
AMPLITUDE = 0.03


def loop(f_hz: np.ndarray | float) -> np.ndarray:
    s = 2j * math.pi * np.asarray(f_hz, dtype=np.float64)
    return np.asarray((KP + KI / s) * np.exp(-s * DELAY_S) / (J * s + B))


def closed(f_hz: np.ndarray | float) -> np.ndarray:
    value = loop(f_hz)
    return value / (1 + value)


def truth() -> dict[str, float]:
    """The figures from the analytic loop (roots of |T| = 1/√2, |L| = 1, ∠L = −180°)."""
    bandwidth = brentq(lambda f: abs(closed(f)) - 1 / math.sqrt(2), 5.0, 300.0)
    crossover = brentq(lambda f: abs(loop(f)) - 1.0, 1.0, 300.0)
    def phase(f: float) -> float:  # continuous ∠L
        w = 2 * math.pi * f
        return -math.pi / 2 + math.atan2(KP * w, KI) - w * DELAY_S - math.atan2(J * w, B)

    phase_crossover = brentq(lambda f: phase(f) + math.pi, 30.0, 600.0)
    dense = np.geomspace(1.0, 700.0, 200_000)
    lines = np.asarray(HARMONICS) / PERIOD_S
    return {
        "bandwidth_hz": bandwidth,
        "peak_gain_db": float(20 * np.log10(np.max(np.abs(closed(lines))))),
        "gain_margin_db": float(-20 * np.log10(abs(loop(phase_crossover)))),
        "phase_margin_deg": float(180 + np.degrees(np.angle(loop(crossover)))),
        "sensitivity_peak_db": float(20 * np.log10(np.max(np.abs(1 / (1 + loop(dense)))))),
    }


def signals(noise_rad_s: float, seed: int, harmonics: tuple[int, ...] = HARMONICS
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Command, velocity and torque of the analytic loop at its lines, with noise."""
    rng = np.random.default_rng(seed)
    n = round(PERIOD_S * FS) * PERIODS
    t = np.arange(n) / FS
    command = multisine(harmonics=harmonics, amplitudes_rad_s=[AMPLITUDE] * len(harmonics),
                        period_s=PERIOD_S, periods=PERIODS, fs_hz=FS)
    velocity = np.zeros(n)
    torque = np.zeros(n)
    for h, phi in zip(harmonics, schroeder_phases(len(harmonics)), strict=True):
        f = h / PERIOD_S
        r = AMPLITUDE * np.exp(1j * phi)
        v = closed(f) * r
        u = (KP + KI / (2j * math.pi * f)) * (r - v)
        phase = np.exp(2j * math.pi * f * t)
        velocity += np.real(v * phase)
        torque += np.real(u * phase)
    velocity += noise_rad_s * rng.standard_normal(n) + 0.01 * t  # and a slow drift
    return 0.4 + command, 0.4 + velocity, torque


def test_phasors_recover_amplitude_and_phase_beside_a_drift() -> None:
    t = np.arange(2000) / 2000.0
    x = 0.7 * np.cos(2 * math.pi * 3 * t + 0.4) + 0.2 * np.cos(2 * math.pi * t - 1.0) + 5 * t
    p = period_phasors(x, period_samples=2000, periods=1, harmonics=[1, 3])[0]
    assert p[1] == pytest.approx(0.7 * np.exp(0.4j), abs=1e-9)
    assert p[0] == pytest.approx(0.2 * np.exp(-1.0j), abs=1e-9)


def test_noise_free_figures_are_the_analytic_loops() -> None:
    command, velocity, torque = signals(0.0, seed=0)
    result = analyse_frf(command=command, velocity=velocity, torque=torque, harmonics=HARMONICS,
                         period_s=PERIOD_S, fs_hz=FS, periods=PERIODS)
    expected = truth()
    # interpolation between lines is the only error left (python-control's frd, log-f dB)
    tolerance = {"bandwidth_hz": 0.01, "peak_gain_db": 1e-6, "gain_margin_db": 0.01,
                 "phase_margin_deg": 0.005, "sensitivity_peak_db": 0.03}
    for name, value in expected.items():
        assert result.estimates[name].value == pytest.approx(value, rel=tolerance[name]), name
    f = result.frequencies_hz
    np.testing.assert_allclose(result.sensitivity, 1 / (1 + loop(f)), rtol=1e-9)
    np.testing.assert_allclose(result.controller, KP + KI / (2j * math.pi * f), rtol=1e-9)


@pytest.mark.parametrize("seed", [1, 2])
def test_noisy_figures_cover_the_analytic_loop(seed: int) -> None:
    command, velocity, torque = signals(0.02, seed=seed)
    result = analyse_frf(command=command, velocity=velocity, torque=torque, harmonics=HARMONICS,
                         period_s=PERIOD_S, fs_hz=FS, periods=PERIODS)
    for name, value in truth().items():
        estimate = result.estimates[name]
        assert estimate.dof == PERIODS - 1
        assert estimate.standard_uncertainty > 0
        # the expanded uncertainty and the line interpolation of the noise-free case
        allowed = estimate.expanded_uncertainty + 0.03 * abs(value)
        assert abs(estimate.value - value) < allowed, (name, estimate.value, value)


def test_lines_short_of_the_phase_crossover_are_refused() -> None:
    low = HARMONICS[:12]
    command, velocity, torque = signals(0.0, seed=0, harmonics=low)
    with pytest.raises(IdentificationError, match="phase crossover"):
        analyse_frf(command=command, velocity=velocity, torque=torque, harmonics=low,
                    period_s=PERIOD_S, fs_hz=FS, periods=PERIODS)
