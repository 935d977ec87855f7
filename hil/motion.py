"""The motion vocabulary every layer shares: control modes, the unit's envelope, a sampled
command trajectory, and the recording column each mode's command goes to.

It sits below the drives, the simulator and the protocols; it imports nothing of theirs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class Mode(Enum):
    """Control mode of an excitation; command units: N·m, rad/s, rad."""

    TORQUE = "torque"
    VELOCITY = "velocity"
    POSITION = "position"


@dataclass(frozen=True, slots=True, kw_only=True)
class Limits:
    """The unit's safe envelope; every backend refuses commands outside it before moving."""

    velocity_rad_s: float
    torque_nm: float
    travel_min_rad: float
    travel_max_rad: float


#: ``Excitation.metadata[PURPOSE]`` of a move no protocol analyses
PURPOSE, POSITIONING = "purpose", "positioning"


@dataclass(frozen=True, slots=True, kw_only=True)
class Excitation:
    """A sampled command trajectory: one sample per control period at ``fs_hz``.

    ``torque_offset_nm`` (one per command sample, optional): the torque feedforward the
    master sends beside the command (CiA 402 0x60B2); a drive whose firmware has
    ``feedforward`` adds it to its torque command, any other ignores it.

    ``elevation_path_rad`` (one per command sample, optional): the gimbal's elevation axis,
    held by its own drive, follows this path while this axis runs; only a station that
    declares it can (``Capability.ELEVATION_MOTION``) runs such an excitation, and its
    recording has the elevation's measured angle as ``elevation_rad``.
    """

    name: str
    mode: Mode
    command: FloatArray
    fs_hz: float
    metadata: dict[str, str] = field(default_factory=dict)
    torque_offset_nm: FloatArray | None = None
    elevation_path_rad: FloatArray | None = None

    def __post_init__(self) -> None:
        for what, values in (("torque_offset_nm", self.torque_offset_nm),
                             ("elevation_path_rad", self.elevation_path_rad)):
            if values is not None and len(values) != len(self.command):
                raise ValueError(f"excitation '{self.name}': {what} has {len(values)} "
                                 f"samples, the command {len(self.command)}")

    @property
    def duration_s(self) -> float:
        return len(self.command) / self.fs_hz

    @property
    def positioning(self) -> bool:
        """A move that only takes the axis somewhere: no protocol analyses its rows."""
        return self.metadata.get(PURPOSE) == POSITIONING


@dataclass(frozen=True, slots=True, kw_only=True)
class PositionHarmonic:
    """``amplitude·sin(order·θ + phase_rad)`` over the motor position θ (rad)."""

    order: int
    amplitude: float
    phase_rad: float


@dataclass(frozen=True, slots=True, kw_only=True)
class CompensationTable:
    """A cogging compensation table as a drive takes it (``cogging_compensation.json``):
    the drive adds ``Σ cogging`` (N·m) to its torque command and divides it by
    ``1 + Σ kt_ripple`` (relative)."""

    cogging_nm: tuple[PositionHarmonic, ...]
    kt_ripple: tuple[PositionHarmonic, ...] = ()


COMMAND_COLUMN: dict[Mode, str] = {
    Mode.TORQUE: "torque_cmd_nm",
    Mode.VELOCITY: "velocity_cmd_rad_s",
    Mode.POSITION: "position_cmd_rad",
}
"""The recording column that holds a command of each mode."""

MODE_OF_COLUMN: dict[str, Mode] = {column: mode for mode, column in COMMAND_COLUMN.items()}
