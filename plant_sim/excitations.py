"""Built-in excitation sequences (pure functions of duration, rate and limits)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def sine(
    amplitude_rad_s: float, frequency_hz: float, duration_s: float, fs_hz: float
) -> FloatArray:
    t = np.arange(round(duration_s * fs_hz)) / fs_hz
    return amplitude_rad_s * np.sin(2 * math.pi * frequency_hz * t)


def staircase(speeds_rad_s: tuple[float, ...], step_s: float, fs_hz: float) -> FloatArray:
    """Constant speeds, each held ``step_s``, both directions (+v then −v)."""
    steps = [np.full(round(step_s * fs_hz), sign * v) for v in speeds_rad_s for sign in (1, -1)]
    return np.concatenate(steps)


def sweep(travel_rad: float, speed_rad_s: float, fs_hz: float) -> FloatArray:
    """Out to +travel, back to −travel, home again at constant speed."""
    leg = round(travel_rad / speed_rad_s * fs_hz)
    return np.concatenate(
        [np.full(leg, speed_rad_s), np.full(2 * leg, -speed_rad_s), np.full(leg, speed_rad_s)]
    )


def log_chirp(
    amplitude_rad_s: float, f0_hz: float, f1_hz: float, duration_s: float, fs_hz: float
) -> FloatArray:
    t = np.arange(round(duration_s * fs_hz)) / fs_hz
    rate = math.log(f1_hz / f0_hz) / duration_s
    phase = 2 * math.pi * f0_hz * (np.exp(rate * t) - 1) / rate
    return amplitude_rad_s * np.sin(phase)


def identification_sequence(
    duration_s: float, fs_hz: float, *, travel_rad: float, max_velocity_rad_s: float
) -> FloatArray:
    """A velocity command that exercises every effect, like the shared example recordings:
    two 2 Hz sines, a slow staircase, a full-travel sweep and a log chirp, scaled to fill
    ``duration_s`` (at least 8 s)."""
    if duration_s < 8:
        raise ValueError(f"duration must be at least 8 s, got {duration_s}")
    scale = duration_s / 32.0
    top = min(1.0, max_velocity_rad_s)
    sweep_speed = min(0.4, max_velocity_rad_s)
    parts = [
        sine(0.5 * top, 2.0, round(4 * scale) or 1, fs_hz),
        sine(top, 2.0, round(4 * scale) or 1, fs_hz),
        staircase((0.01, 0.03, 0.1), 1.0 * scale, fs_hz),
        sweep(min(1.2, 0.9 * travel_rad), sweep_speed, fs_hz),
    ]
    used = sum(len(p) for p in parts) / fs_hz
    parts.append(log_chirp(0.2, 1.0, min(150.0, fs_hz / 8), max(duration_s - used, 1.0), fs_hz))
    return np.concatenate(parts)[: round(duration_s * fs_hz)]
