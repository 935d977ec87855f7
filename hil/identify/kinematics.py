"""Phase-free velocity and acceleration from encoder position (no filter lag)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_filter

FloatArray = NDArray[np.float64]
IRREGULAR_JITTER = 0.01  # relative spread of sample steps above which we resample


def phase_free_derivatives(
    position: FloatArray, *, time_s: FloatArray, window_s: float
) -> tuple[FloatArray, FloatArray]:
    """Velocity and acceleration of ``position`` by a centred Savitzky–Golay fit (quintic,
    ``window_s`` wide): zero phase, so torque and motion stay aligned.

    Irregular timestamps (polled transports) are handled by a cubic spline onto a uniform
    grid at the median step and back: linear interpolation across a missed poll cuts the
    corner of the path and biased J low (−3 % with 10 % of 200 Hz polls missing).

    Parameters
    ----------
    position : array
        Encoder position (rad).
    time_s : array
        Sample times (s); irregular times are resampled as above.
    window_s : float
        Width of the Savitzky–Golay window (s).

    Returns
    -------
    velocity, acceleration : array
        At the input's samples (rad/s, rad/s²).

    Raises
    ------
    ValueError
        The window (at least 7 samples) is not shorter than ``position``.
    """
    steps = np.diff(time_s)
    step = float(np.median(steps))
    window = max(7, round(window_s / step) | 1)
    if window >= len(position):
        raise ValueError(f"derivative window {window} samples exceeds the {len(position)} given")
    if np.ptp(steps) <= IRREGULAR_JITTER * step:
        velocity = savgol_filter(position, window, 5, deriv=1, delta=step)
        acceleration = savgol_filter(position, window, 5, deriv=2, delta=step)
        return np.asarray(velocity, dtype=np.float64), np.asarray(acceleration, dtype=np.float64)
    grid, uniform = uniform_position(position, time_s=time_s, step_s=step)
    velocity = savgol_filter(uniform, window, 5, deriv=1, delta=step)
    acceleration = savgol_filter(uniform, window, 5, deriv=2, delta=step)
    return np.interp(time_s, grid, velocity), np.interp(time_s, grid, acceleration)


def uniform_position(
    position: FloatArray, *, time_s: FloatArray, step_s: float
) -> tuple[FloatArray, FloatArray]:
    """Position on a uniform grid from irregular samples, by a cubic spline.

    The one resampling rule of identification and diagnosis: linear interpolation across
    a missed poll cuts the corner of the path (and biased J low, see
    :func:`phase_free_derivatives`); a cubic spline follows it.

    Parameters
    ----------
    position : array
        Encoder position (rad, or m on a linear axis) at ``time_s``.
    time_s : array
        Strictly increasing sample times (s).
    step_s : float
        The grid's period (s), usually the median sample step.

    Returns
    -------
    grid_s, position_on_grid : array
        ``time_s[0] + step_s·i`` for ``i = 0 … ⌊(time_s[−1] − time_s[0]) / step_s⌋``, and
        the spline there.
    """
    grid = time_s[0] + step_s * np.arange(int((time_s[-1] - time_s[0]) / step_s) + 1)
    return grid, np.asarray(CubicSpline(time_s, position)(grid), dtype=np.float64)
