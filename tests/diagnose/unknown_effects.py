"""Effects outside the diagnoser's library, hidden in a simulated recording.

Each adds the torque the effect needs to the recorded effort: the drive would have had to
deliver it for the same motion, so ``effort = J·α + B·ω + T_c·sgn ω + d(θ, ω)`` holds
exactly, with ``d`` a shape no known effect has.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from hil.recording import Recording

FloatArray = NDArray[np.float64]


def _direction(velocity: FloatArray) -> FloatArray:
    band = 1e-3 * float(np.percentile(np.abs(velocity), 99))
    return np.sign(velocity) * (np.abs(velocity) > band)


def friction_bump(position: FloatArray, velocity: FloatArray, *, size: float,
                  detail: float) -> FloatArray:
    """A tight spot in the bearing: Coulomb friction raised over a short stretch of travel.

    ``ΔT·sgn(ω)·exp(−½((θ − θ₀)/w)²)``, ``ΔT`` 10–30 mN·m, ``w`` = 30 mrad, ``θ₀`` between
    the 25th and 75th percentile of the positions.
    """
    centre = bump_centre(position, detail)
    height = 0.01 + 0.02 * size
    bump: FloatArray = np.exp(-0.5 * ((position - centre) / 0.03) ** 2)
    return height * _direction(velocity) * bump


def bump_centre(position: FloatArray, detail: float) -> float:
    """Where :func:`friction_bump` puts the tight spot: ``detail`` of the way from the 25th
    to the 75th percentile of the positions."""
    low, high = (float(v) for v in np.percentile(position, [25, 75]))
    return low + (high - low) * detail


def backlash(position: FloatArray, velocity: FloatArray, *, size: float,
             detail: float) -> FloatArray:
    """A dead zone after each reversal: the load decouples while the gap is crossed.

    Over the first ``gap`` (2–6 mrad) of travel after a reversal the friction that the load
    carries (half the Coulomb-like torque, 10–20 mN·m here) is missing.
    """
    gap = 0.002 + 0.004 * detail
    load_friction = 0.01 + 0.01 * size
    direction = _direction(velocity)
    out = np.zeros_like(position)
    anchor = position[0]
    current = 0.0
    for i in range(len(position)):
        if direction[i] != 0 and direction[i] != current:
            current, anchor = direction[i], position[i]
        if current != 0 and abs(position[i] - anchor) < gap:
            out[i] = -load_friction * current
    return out


def cubic_spring(position: FloatArray, velocity: FloatArray, *, size: float,
                 detail: float) -> FloatArray:
    """A stiffening spring ``k₃·(θ − θ_c)³``: no linear part at its centre."""
    del velocity
    centre = float(np.median(position)) + 0.1 * (detail - 0.5)
    k3 = 0.05 + 0.1 * size
    return k3 * (position - centre) ** 3


SHAPES = {"friction_bump": friction_bump, "backlash": backlash, "cubic_spring": cubic_spring}


def hide_unknown(recording: Recording, kind: str, *, size: float, detail: float) -> Recording:
    """``recording`` with the torque of an unknown effect ``kind`` added to its effort."""
    shape = SHAPES[kind]
    extra = shape(recording.position, recording.velocity, size=size, detail=detail)
    columns = dict(recording.columns)
    columns["torque_nm"] = columns["torque_nm"] + extra
    return replace(recording, columns=columns)
