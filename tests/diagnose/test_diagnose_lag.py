"""The current-loop lag's search pieces (hil/diagnose/lag.py) on small synthetic signals."""

from __future__ import annotations

import math

import numpy as np

from hil.diagnose.lag import quantisation_noise
from hil.diagnose.signals import prepare
from hil.recording import Recording


def _recording(position: np.ndarray, fs_hz: float = 2000.0) -> Recording:
    time_s = np.arange(position.size) / fs_hz
    return Recording(source="synthetic", columns={
        "time_s": time_s, "position_rad": position, "velocity_rad_s": np.gradient(position),
        "torque_nm": np.sin(2 * np.pi * 3.0 * time_s)})


def test_continuous_position_has_no_quantisation_noise() -> None:
    time_s = np.arange(8000) / 2000.0
    signals = prepare(_recording(0.3 * np.sin(2 * np.pi * 1.7 * time_s) + 1e-4 * time_s**2))
    assert quantisation_noise(signals) == ()


def test_stand_in_error_stays_within_half_a_step() -> None:
    """Each stand-in is a re-quantisation error of the recording's own step: |e| ≤ q/2."""
    step = 2 * math.pi / 2**16
    time_s = np.arange(8000) / 2000.0
    position = np.round(0.3 * np.sin(2 * np.pi * 1.7 * time_s) / step) * step
    noise = quantisation_noise(prepare(_recording(position)))
    assert len(noise) == 4
    for signals in noise:
        assert np.max(np.abs(signals.position)) <= step / 2 * (1 + 1e-9)
        assert np.std(signals.position) > step / 6  # a real error, not zeros
