"""The acceleration a two-mass axis's motor torque drives, from the motor's encoder and the
shaft's modes: what a rigid-body regression ``J·α`` needs when the load hangs on a shaft.

A motor of inertia J_m drives a load J_l through a shaft (stiffness k, damping c); the
encoder reads the motor. The torque the motor delivers is ``J_m·α_m + J_l·α_l + friction``,
and the load follows the motor through ``G(s) = (c·s + k)/(J_l·s² + c·s + k)``, so

    J_m·α_m + J_l·α_l = (J_m + J_l)·α_eff,   α_eff = (α_m + r·G·α_m)/(1 + r),   r = J_l/J_m.

At the sines' frequency G ≈ 1 and α_eff ≈ α_m, but each friction reversal is a torque step
that rings the shaft, and the ringing of the reported torque is ``J_m·α_m``, not the rigid
``(J_m + J_l)·α_m``: left in, it biased the sines' B by −3.7 % on the demo azimuth (a
clean plant; 0.0 % with α_eff). Everything comes from the resonance fit's three figures:
``r = (f_r/f_a)² − 1``, ``ω_a = 2π·f_a`` and ``ζ_a = ζ_r·f_a/f_r`` (the relative mode's and
the load's damping share one c). It assumes friction on the motor side; friction on the
load would make the load's own equation carry it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IRREGULAR_STEP = 0.01  # relative spread of the steps above which the samples are resampled


@dataclass(frozen=True, slots=True, kw_only=True)
class ShaftModes:
    """A two-mass axis's shaft as the resonance fit states it."""

    resonance_hz: float  # f_r: the motor and load swinging against each other
    antiresonance_hz: float  # f_a: the load alone on the shaft
    damping_ratio: float  # ζ_r of the resonance

    @property
    def load_to_motor_inertia(self) -> float:
        """``r = J_l/J_m = (f_r/f_a)² − 1``."""
        return (self.resonance_hz / self.antiresonance_hz) ** 2 - 1.0

    def with_total_inertia(self, ratio: float) -> ShaftModes | None:
        """The modes when the axis's total inertia is ``ratio`` times the one they were
        measured with, all of the change in the load (the shaft, its damping and the motor
        the same: the load of a gimbal's azimuth changes with the elevation). ``None`` when
        no load would be left on the shaft."""
        before = self.load_to_motor_inertia
        after = ratio * (1.0 + before) - 1.0
        if not (before > 0.0 and after > 0.0):
            return None
        antiresonance = self.antiresonance_hz * math.sqrt(before / after)  # ω_a² = k/J_l
        resonance = antiresonance * math.sqrt(1.0 + after)
        # ζ_r = c·ω_r/(2k) for a shaft damping c
        return ShaftModes(resonance_hz=resonance, antiresonance_hz=antiresonance,
                          damping_ratio=self.damping_ratio * resonance / self.resonance_hz)

    def shifted(self, **changes: float) -> ShaftModes:
        """These modes with some figures moved (a budget line's re-analysis)."""
        return replace(self, **{name: getattr(self, name) + change
                                for name, change in changes.items()})


def driven_acceleration(
    acceleration_rad_s2: FloatArray, *, time_s: FloatArray, shaft: ShaftModes
) -> FloatArray:
    """``α_eff = (α_m + r·G·α_m)/(1 + r)``: the acceleration that times the total inertia
    gives the inertial torque of a two-mass axis whose motor moves as ``α_m``.

    ``G`` is applied in the frequency domain over the samples as one period of a periodic
    signal: exact for a run of whole periods of a steady sine (the sines' analysis window).
    Irregular timestamps are resampled onto their median step and back (linearly).

    Parameters
    ----------
    acceleration_rad_s2 : array
        The motor's acceleration α_m (rad/s²), from its encoder.
    time_s : array
        The samples' times (s), increasing.
    shaft : ShaftModes
        The shaft's resonance, anti-resonance and damping ratio.

    Returns
    -------
    ndarray
        α_eff at the same samples (rad/s²).
    """
    ratio = shaft.load_to_motor_inertia
    if ratio <= 0.0:  # no load on the shaft: rigid
        return np.asarray(acceleration_rad_s2, dtype=np.float64)
    steps = np.diff(time_s)
    step = float(np.median(steps))
    regular = np.ptp(steps) <= IRREGULAR_STEP * step
    grid = time_s if regular else time_s[0] + step * np.arange(
        round((time_s[-1] - time_s[0]) / step) + 1)
    motor = acceleration_rad_s2 if regular else np.interp(grid, time_s, acceleration_rad_s2)
    omega_a = 2 * math.pi * shaft.antiresonance_hz
    zeta_a = shaft.damping_ratio * shaft.antiresonance_hz / shaft.resonance_hz
    s = 2j * math.pi * np.fft.rfftfreq(len(grid), step)
    load_follows = (2 * zeta_a * omega_a * s + omega_a**2) / (
        s * s + 2 * zeta_a * omega_a * s + omega_a**2)
    load = np.fft.irfft(load_follows * np.fft.rfft(motor), len(grid))
    driven = (motor + ratio * load) / (1.0 + ratio)
    return np.asarray(driven if regular else np.interp(time_s, grid, driven), dtype=np.float64)
