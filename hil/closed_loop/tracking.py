"""A standard gimbal move and its following error, with the friction feedforward off and on.

The move (velocity command ``ω*``, smooth: raised-cosine acceleration ramps): a slew at
``slew_rad_s``, a constant-rate track at ``track_rad_s``, a sinusoidal reversal through
zero (amplitude ``track_rad_s``) and a ramp back to rest. The reference position is the
command's running sum ``θ*[k] = θ₀ + Σ_{j<k} ω*[j]/fs`` (what a drive integrates: the
position the encoder reads at period ``k`` is the result of the commands before it); the
following error is ``e = θ − θ*``.

Feedforward (the certificate's ``B·ω* + T_c·sgn(ω*)``) is sent as the drive's torque
offset; a drive whose firmware has ``feedforward`` adds it to its command. Figures: RMS
and peak of ``|e|`` over the move, and the RMS ratio off/on (the reduction).

Type A: the error's noise (encoder quantisation, torque noise through the loop) is what
the sample-to-sample scatter of ``e`` about its smoothed course shows (``σ_n``, the
residual of a centred moving average over ``smooth_s``). Propagated: ``u(RMS) =
σ_n·√(Σeᵢ²)/(N·RMS)`` (the first-order change of the RMS with white noise on each
sample) and ``u(peak) = σ_n``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Component, Estimate, with_budget

FloatArray = NDArray[np.float64]


def _ramp(start: float, end: float, samples: int) -> FloatArray:
    x = (np.arange(samples) + 1) / samples
    return start + (end - start) * (1 - np.cos(math.pi * x)) / 2


def gimbal_move(*, slew_rad_s: float, track_rad_s: float, ramp_s: float, slew_s: float,
                track_s: float, reversal_s: float, fs_hz: float) -> FloatArray:
    """The standard move's velocity command: ramp up, slew, ramp down to the track rate,
    track, a half sine through zero to ``−track_rad_s``, ramp to rest.

    Returns
    -------
    ndarray
        Velocity command (rad/s), one sample per control period, starting and ending at 0.
    """
    n_ramp = max(1, round(ramp_s * fs_hz))
    t = np.arange(round(reversal_s * fs_hz)) / fs_hz
    parts = [
        _ramp(0.0, slew_rad_s, n_ramp),
        np.full(round(slew_s * fs_hz), slew_rad_s),
        _ramp(slew_rad_s, track_rad_s, n_ramp),
        np.full(round(track_s * fs_hz), track_rad_s),
        track_rad_s * np.cos(math.pi * t / reversal_s),
        _ramp(-track_rad_s, 0.0, n_ramp),
        np.zeros(n_ramp),
    ]
    return np.concatenate(parts)


def friction_feedforward(velocity_cmd_rad_s: FloatArray, *, viscous_nm_s_rad: float,
                         coulomb_nm: float) -> FloatArray:
    """``B·ω* + T_c·sgn(ω*)`` (N·m), the certificate's friction feedforward."""
    return np.asarray(viscous_nm_s_rad * velocity_cmd_rad_s
                      + coulomb_nm * np.sign(velocity_cmd_rad_s), dtype=np.float64)


def reference_position(velocity_cmd_rad_s: FloatArray, *, start_rad: float,
                       fs_hz: float) -> FloatArray:
    """``θ*[k] = θ₀ + Σ_{j<k} ω*[j]/fs``."""
    return start_rad + np.concatenate(([0.0], np.cumsum(velocity_cmd_rad_s)[:-1])) / fs_hz


@dataclass(frozen=True, slots=True, kw_only=True)
class Following:
    """The following error of one run: RMS and peak (rad) with their Type A uncertainty."""

    rms_rad: float
    peak_rad: float
    noise_rad: float
    u_rms_rad: float
    samples: int
    error_rad: FloatArray  # θ − θ*, one per sample


def following_error(position_rad: FloatArray, velocity_cmd_rad_s: FloatArray, *,
                    fs_hz: float, smooth_s: float = 0.005) -> Following:
    """RMS and peak following error of a velocity-mode run from its first sample's position.

    Raises
    ------
    IdentificationError
        Recording and command differ in length or are too short.
    """
    if len(position_rad) != len(velocity_cmd_rad_s) or len(position_rad) < 10:
        raise IdentificationError("the tracking recording does not match its command")
    error = position_rad - reference_position(velocity_cmd_rad_s, start_rad=position_rad[0],
                                              fs_hz=fs_hz)
    width = max(3, round(smooth_s * fs_hz) // 2 * 2 + 1)
    smooth = np.convolve(np.pad(error, width // 2, mode="edge"), np.ones(width) / width,
                         mode="valid")
    noise = float(np.std(error - smooth, ddof=1)) * math.sqrt(width / (width - 1))
    rms = float(np.sqrt(np.mean(error**2)))
    u_rms = noise * float(np.sqrt(np.sum(error**2))) / (len(error) * rms) if rms > 0 else noise
    return Following(rms_rad=rms, peak_rad=float(np.max(np.abs(error))), noise_rad=noise,
                     u_rms_rad=u_rms, samples=len(error), error_rad=error)


def feedforward_change(off: Following, on: Following, *, relative: float
                       ) -> tuple[float, float]:
    """Change of (RMS, peak) of the run with feedforward when the feedforward were
    ``1 + relative`` times as large: by superposition of the runs without and with it,
    ``e = e_on + relative·(e_on − e_off)`` (the loop linear about the run with it)."""
    error = on.error_rad + relative * (on.error_rad - off.error_rad)
    return (float(np.sqrt(np.mean(error**2))) - on.rms_rad,
            float(np.max(np.abs(error))) - on.peak_rad)


def as_estimate(name: str, value_rad: float, u_rad: float, *, scale: float, unit: str,
                resolution_rad: float) -> Estimate:
    """A following-error figure (rad) as an estimate in ``unit`` (``scale`` per rad): Type A
    from the noise, and the encoder's resolution (rectangular) as Type B."""
    lines = [Component(source="noise of the following error (Type A)", kind="A",
                       standard_uncertainty=u_rad * scale, unit=unit)]
    if resolution_rad > 0:
        lines.append(Component(source="encoder resolution (rectangular, LSB/√12)", kind="B",
                               standard_uncertainty=resolution_rad / math.sqrt(12) * scale,
                               unit=unit))
    base = Estimate(name=name, value=value_rad * scale, standard_uncertainty=0.0, unit=unit)
    return with_budget(base, [c for c in lines if c.contribution > 0] or lines[:1],
                       value=value_rad * scale)


def reduction(off: Estimate, on: Estimate, *, name: str,
              labels: tuple[str, str] = ("without feedforward", "with feedforward")
              ) -> Estimate:
    """``off/on`` with both estimates' budgets propagated (relative, first order); each
    line keeps its source, tagged with ``labels``."""
    ratio = off.value / on.value
    lines = [Component(source=f"{c.source} [{labels[0]}]", kind=c.kind,
                       standard_uncertainty=c.standard_uncertainty, unit=c.unit,
                       sensitivity=c.sensitivity * ratio / off.value, dof=c.dof)
             for c in off.components()]
    lines += [Component(source=f"{c.source} [{labels[1]}]", kind=c.kind,
                        standard_uncertainty=c.standard_uncertainty, unit=c.unit,
                        sensitivity=-c.sensitivity * ratio / on.value, dof=c.dof)
              for c in on.components()]
    base = Estimate(name=name, value=ratio, standard_uncertainty=0.0, unit="")
    return with_budget(base, lines, value=ratio)
