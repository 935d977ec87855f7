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

Type A: the move is run ``R ≥ 2`` times (interleaved without and with feedforward); each
figure is the mean over its runs, its Type A the runs' scatter ``s/√R`` with ``R − 1``
degrees of freedom. Nothing less holds on a real axis: the runs differ by the noise in the
loop, and the largest differences are not noise-like at all. Where friction holds the
axis (the start, the reversal) the noise decides the instant it breaks away, and the
offset that leaves in the position persists until the next such event; a velocity loop
turns a white disturbance into a slow wander besides. Within one run no smoothing or
blocking separates either from the move's own error.
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
    """The following error of one run: RMS and peak (rad)."""

    rms_rad: float
    peak_rad: float
    samples: int
    error_rad: FloatArray  # θ − θ*, one per sample


def following_error(position_rad: FloatArray, velocity_cmd_rad_s: FloatArray, *,
                    fs_hz: float) -> Following:
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
    return Following(rms_rad=float(np.sqrt(np.mean(error**2))),
                     peak_rad=float(np.max(np.abs(error))), samples=len(error),
                     error_rad=error)


@dataclass(frozen=True, slots=True, kw_only=True)
class Repeated:
    """The following error of one move run ``runs`` times: mean figures and Type A."""

    rms_rad: float  # mean of the runs' RMS
    peak_rad: float  # mean of the runs' peaks
    u_rms_rad: float  # s/√R of the runs' RMS
    u_peak_rad: float  # s/√R of the runs' peaks
    runs: int
    error_rad: FloatArray  # the runs' mean θ − θ*

    @property
    def dof(self) -> float:
        """Degrees of freedom of both Type A lines."""
        return float(self.runs - 1)


def repeated(runs: list[Following]) -> Repeated:
    """Mean figures of repeated runs of one move and their Type A from the runs' scatter.

    Raises
    ------
    IdentificationError
        Fewer than 2 runs, or runs of different lengths.
    """
    if len(runs) < 2 or len({r.samples for r in runs}) != 1:
        raise IdentificationError(
            f"the tracking move needs at least 2 runs of one length, got "
            f"{[r.samples for r in runs]}")
    rms = np.array([r.rms_rad for r in runs])
    peak = np.array([r.peak_rad for r in runs])
    root = math.sqrt(len(runs))
    return Repeated(rms_rad=float(rms.mean()), peak_rad=float(peak.mean()),
                    u_rms_rad=float(rms.std(ddof=1)) / root,
                    u_peak_rad=float(peak.std(ddof=1)) / root, runs=len(runs),
                    error_rad=np.mean([r.error_rad for r in runs], axis=0))


def feedforward_change(off: Repeated | Following, on: Repeated | Following, *, relative: float
                       ) -> tuple[float, float]:
    """Change of (RMS, peak) of the run with feedforward when the feedforward were
    ``1 + relative`` times as large: by superposition of the runs without and with it,
    ``e = e_on + relative·(e_on − e_off)`` (the loop linear about the run with it), each
    figure against the same figure of ``e_on`` (of repeated runs: their mean error)."""
    base = on.error_rad
    error = base + relative * (base - off.error_rad)
    return (float(np.sqrt(np.mean(error**2)) - np.sqrt(np.mean(base**2))),
            float(np.max(np.abs(error)) - np.max(np.abs(base))))


def as_estimate(name: str, value_rad: float, u_rad: float, *, scale: float, unit: str,
                dof: float, resolution_rad: float) -> Estimate:
    """A following-error figure (rad) as an estimate in ``unit`` (``scale`` per rad): Type A
    from the runs' scatter (``dof``), and the encoder's resolution as Type B:
    ``resolution_rad`` is that line's size in the figure (LSB/√12 for a peak; for an RMS
    over ``N`` samples, whose reading errors are independent while the axis moves,
    ``LSB/√(12·N)``)."""
    lines = [Component(source="noise of the following error, scatter of the repeated runs "
                              "(Type A)", kind="A", standard_uncertainty=u_rad * scale,
                       unit=unit, dof=dof)]
    if resolution_rad > 0:
        lines.append(Component(source="encoder resolution (rectangular)", kind="B",
                               standard_uncertainty=resolution_rad * scale, unit=unit))
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
