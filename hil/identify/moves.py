"""Pure command builders shared by protocols: repositioning moves between excitations."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def position_move(
    start_rad: float, stop_rad: float, *, fs_hz: float, speed_rad_s: float, hold_s: float
) -> FloatArray:
    """Position command for a smooth (raised-cosine velocity) move ``start → stop`` with a
    peak speed of ``speed_rad_s``, then a hold at ``stop_rad`` for ``hold_s``."""
    distance = stop_rad - start_rad
    duration = 2.0 * abs(distance) / speed_rad_s  # raised cosine: peak = 2 × mean speed
    n_move = max(math.ceil(duration * fs_hz), 1)
    phase = np.arange(1, n_move + 1) / n_move
    path = start_rad + distance * (phase - np.sin(2 * math.pi * phase) / (2 * math.pi))
    return np.concatenate([path, np.full(max(round(hold_s * fs_hz), 1), stop_rad)])


def travel_shortfall_rad(
    *, needed_rad: float, travel_min_rad: float, travel_max_rad: float, margin_rad: float
) -> float:
    """How much more travel a one-way excitation needs than the limits leave (≤ 0: fits),
    keeping ``margin_rad`` clear of each end."""
    return needed_rad - (travel_max_rad - travel_min_rad - 2 * margin_rad)
