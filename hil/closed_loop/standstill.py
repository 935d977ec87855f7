"""Standstill: torque ripple and position jitter while the drive holds a position.

Over ``b`` blocks, each the end of a hold at a position of its own: the RMS of the reported
torque about its block mean and trend (N·m) and the RMS of the encoder position about its
block mean and trend (rad; a slow settling after the move is not jitter). The result is
the RMS over all blocks; its Type A uncertainty the scatter of the block values ``s/√b``
(``b − 1`` degrees of freedom). Holding each block at another position makes that scatter
include what depends on where the axis stands: where inside an encoder count it rests
(a position held near a count's edge toggles it, one near its middle does not), the
local cogging slope; blocks of one hold would see one such place only, and runs held
elsewhere scatter beyond it. The encoder's resolution is a rectangular Type B line of
the jitter (a position held inside one count reads as no jitter at all), the torque's
resolution one of the ripple.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Component, Estimate, with_budget

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True)
class Standstill:
    """Per-block RMS of torque and position about their block means."""

    torque_rms_nm: FloatArray
    position_rms_rad: FloatArray


def hold_windows(command: FloatArray, *, block_samples: int) -> list[tuple[int, int]]:
    """``(start, stop)`` sample indices of the last ``block_samples`` of each stretch of
    ``command`` that holds one value at least that long (the analysed end of each hold)."""
    values = np.asarray(command, dtype=float)
    changes = np.flatnonzero(np.diff(values) != 0.0) + 1
    starts = np.concatenate(([0], changes))
    stops = np.concatenate((changes, [len(values)]))
    return [(int(stop) - block_samples, int(stop))
            for start, stop in zip(starts, stops, strict=True) if stop - start >= block_samples]


def standstill_blocks(position_rad: FloatArray, torque_nm: FloatArray,
                      windows: list[tuple[int, int]]) -> Standstill:
    """Block RMS values, one block per window (``(start, stop)`` sample indices).

    Raises
    ------
    IdentificationError
        Fewer than 2 windows, windows of unequal length, or fewer than 10 samples a block.
    """
    lengths = {stop - start for start, stop in windows}
    if len(windows) < 2 or len(lengths) != 1 or min(lengths) < 10:
        raise IdentificationError(
            f"standstill: {len(windows)} holds of {sorted(lengths)} samples (at least 2 "
            "holds of one length, each at least 10 samples, are needed)")
    pos = _detrended(np.stack([position_rad[a:b] for a, b in windows]))
    tq = _detrended(np.stack([torque_nm[a:b] for a, b in windows]))
    return Standstill(torque_rms_nm=tq.std(axis=1), position_rms_rad=pos.std(axis=1))


def _detrended(blocks: FloatArray) -> FloatArray:
    """Each block less its straight line (a slow settling is not jitter)."""
    ramp = np.arange(blocks.shape[1]) - (blocks.shape[1] - 1) / 2
    slope = blocks @ ramp / (ramp @ ramp)
    return np.asarray(blocks - slope[:, None] * ramp[None, :], dtype=np.float64)


def block_estimate(name: str, values: FloatArray, *, scale: float, unit: str,
                   resolution: float, what: str) -> Estimate:
    """The RMS over blocks (``√mean(vᵢ²)``) in ``unit`` (``scale`` per SI unit), Type A from
    the block scatter, the resolution of ``what`` as a rectangular Type B line."""
    value = float(np.sqrt(np.mean(values**2))) * scale
    lines = [Component(source=f"scatter of {len(values)} blocks (Type A)", kind="A",
                       standard_uncertainty=float(np.std(values * scale, ddof=1))
                       / math.sqrt(len(values)), unit=unit, dof=len(values) - 1)]
    if resolution > 0:
        lines.append(Component(source=f"{what} resolution (rectangular, LSB/√12)", kind="B",
                               standard_uncertainty=resolution * scale / math.sqrt(12),
                               unit=unit))
    kept = [c for c in lines if c.contribution > 0] or lines[:1]
    base = Estimate(name=name, value=value, standard_uncertainty=0.0, unit=unit)
    return with_budget(base, kept, value=value)
