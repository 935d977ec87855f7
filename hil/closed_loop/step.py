"""Velocity step response: rise time (10–90 %), overshoot, 2 % settling time, steady-state
error of each step of a staircase, from the velocity measured by the encoder.

The velocity is the encoder position's central difference smoothed by a zero-phase moving
average of ``smooth_s`` (the drive's own estimate is filtered, i.e. delayed: its delay
would count as rise time). Each step is judged on its own: from the command's step
instant to the end of its level, against the command's new level ``v₁`` and the step
``Δ = v₁ − v₀``:

- rise time: from the first crossing of ``v₀ + 0.1·Δ`` to the first of ``v₀ + 0.9·Δ``;
- overshoot: ``max((v − v₁)·sgn Δ)/|Δ|`` in %, 0 when the response never passes ``v₁``;
- settling time: from the step to the last sample outside ``v₁ ± 2 %·|Δ|``;
- steady-state error: ``|mean(v) − v₁|/|Δ|`` in % over the last ``tail_fraction`` of
  the level.

Steps of the same size are repeated (up and down, both directions of rotation); the result
of each size is their mean, its Type A uncertainty their scatter ``s/√n`` (``n − 1``
degrees of freedom).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Component, Estimate, with_budget

FloatArray = NDArray[np.float64]
SETTLING_BAND = 0.02


@dataclass(frozen=True, slots=True, kw_only=True)
class StepFigures:
    """One step's figures (times in s, overshoot and error in % of the step)."""

    start_rad_s: float
    target_rad_s: float
    rise_time_s: float
    overshoot_pct: float
    settling_time_s: float
    steady_state_error_pct: float


def smoothed_velocity(position_rad: FloatArray, *, fs_hz: float, smooth_s: float) -> FloatArray:
    """Central-difference velocity of ``position_rad``, smoothed by a centred moving average
    of ``smooth_s`` (an odd number of samples, at least 1): zero phase."""
    velocity = np.gradient(position_rad) * fs_hz
    width = max(1, round(smooth_s * fs_hz) // 2 * 2 + 1)
    if width == 1:
        return velocity
    kernel = np.ones(width) / width
    padded = np.pad(velocity, width // 2, mode="edge")
    return np.convolve(padded, kernel, mode="valid")


def step_figures(velocity: FloatArray, *, start_rad_s: float, target_rad_s: float,
                 fs_hz: float, tail_fraction: float = 0.25) -> StepFigures:
    """The figures of one step; ``velocity`` runs from the step instant to the level's end.

    Raises
    ------
    IdentificationError
        A zero step, or a response that never reaches 90 % of it.
    """
    delta = target_rad_s - start_rad_s
    if delta == 0:
        raise IdentificationError("a step of zero size")
    sign = math.copysign(1.0, delta)
    progress = (velocity - start_rad_s) / delta  # 0 before, 1 at the target
    above10 = np.flatnonzero(progress >= 0.1)
    above90 = np.flatnonzero(progress >= 0.9)
    if above90.size == 0 or above10.size == 0:
        raise IdentificationError(
            f"the step {start_rad_s:g} → {target_rad_s:g} rad/s never reached 90 %")
    rise = (_crossing(progress, above90[0], 0.9) - _crossing(progress, above10[0], 0.1)) / fs_hz
    overshoot = max(0.0, float(np.max((velocity - target_rad_s) * sign)) / abs(delta))
    outside = np.flatnonzero(np.abs(velocity - target_rad_s) > SETTLING_BAND * abs(delta))
    settling = 0.0 if outside.size == 0 else (outside[-1] + 1) / fs_hz
    tail = velocity[-max(1, round(tail_fraction * len(velocity))):]
    error = abs(float(np.mean(tail)) - target_rad_s) / abs(delta)
    return StepFigures(start_rad_s=start_rad_s, target_rad_s=target_rad_s, rise_time_s=rise,
                       overshoot_pct=100 * overshoot, settling_time_s=settling,
                       steady_state_error_pct=100 * error)


def _crossing(progress: FloatArray, index: int, level: float) -> float:
    """Fractional sample where ``progress`` first reaches ``level`` (linear interpolation)."""
    if index == 0:
        return 0.0
    before, after = progress[index - 1], progress[index]
    return index - 1 + (level - before) / (after - before) if after != before else float(index)


def mean_estimate(name: str, values: Sequence[float], unit: str, *, resolution: float = 0.0
                  ) -> Estimate:
    """The mean of repeated figures: Type A ``s/√n`` with ``n − 1`` degrees of freedom, and
    the ``resolution`` of a figure read on a sample grid as a rectangular Type B line
    (``resolution/√12``; identical repeats would otherwise claim no uncertainty at all).

    Raises
    ------
    IdentificationError
        Fewer than two values.
    """
    data = np.asarray(values, dtype=np.float64)
    if data.size < 2:
        raise IdentificationError(f"{name}: need at least two repeated steps, got {data.size}")
    scatter = Component(source=f"scatter of {data.size} repeated steps (Type A)", kind="A",
                        standard_uncertainty=float(data.std(ddof=1)) / math.sqrt(data.size),
                        unit=unit, dof=data.size - 1)
    grid = Component(source="resolution of the sample grid (rectangular)", kind="B",
                     standard_uncertainty=resolution / math.sqrt(12), unit=unit)
    lines = [c for c in (scatter, grid) if c.contribution > 0] or [scatter]
    base = Estimate(name=name, value=float(data.mean()), standard_uncertainty=0.0, unit=unit)
    return with_budget(base, lines, value=float(data.mean()))
