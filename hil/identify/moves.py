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
    peak speed of ``speed_rad_s``, then a hold at ``stop_rad`` for ``hold_s``.

    Parameters
    ----------
    start_rad, stop_rad : float
        Where the move starts and ends (rad).
    fs_hz : float
        Command sample rate (Hz).
    speed_rad_s : float
        Peak speed (rad/s), twice the mean.
    hold_s : float
        Time held at ``stop_rad`` after the move (s; at least one sample).

    Returns
    -------
    ndarray
        Position command (rad), one value per sample, without ``start_rad`` itself.
    """
    distance = stop_rad - start_rad
    duration = 2.0 * abs(distance) / speed_rad_s  # raised cosine: peak = 2 × mean speed
    n_move = max(math.ceil(duration * fs_hz), 1)
    phase = np.arange(1, n_move + 1) / n_move
    path = start_rad + distance * (phase - np.sin(2 * math.pi * phase) / (2 * math.pi))
    return np.concatenate([path, np.full(max(round(hold_s * fs_hz), 1), stop_rad)])


def travel_shortfall_rad(
    *, needed_rad: float, travel_min_rad: float, travel_max_rad: float, margin_rad: float
) -> float:
    """How much more travel a one-way excitation needs than the limits leave.

    Parameters
    ----------
    needed_rad : float
        Travel the excitation covers (rad).
    travel_min_rad, travel_max_rad : float
        The travel limits (rad).
    margin_rad : float
        Clearance kept from each limit (rad).

    Returns
    -------
    float
        The shortfall (rad); ≤ 0: the excitation fits.
    """
    return needed_rad - (travel_max_rad - travel_min_rad - 2 * margin_rad)
