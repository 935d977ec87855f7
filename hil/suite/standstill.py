"""standstill: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_standstill.py``.

The drive holds a position (position mode; after a short move from where the axis is, or
at the profile's ``position_rad``), then ``blocks − 1`` more, each ``spacing_rad`` further
towards the centre: torque ripple (RMS of the reported torque about its mean) and position
jitter (RMS of the encoder about its mean), one block at the end of each hold after a
settling time. Numerics in :mod:`hil.closed_loop.standstill`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from hil.closed_loop.standstill import (
    Standstill,
    block_estimate,
    hold_windows,
    standstill_blocks,
)
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.quantisation import quantisation_step
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec, move_excitation, on_command_grid

NAME = "standstill"
NUDGE_RAD = 0.05  # the hold follows a move this long: a held pointing, and the encoder's
# resolution shows in the recording (a position that never changed reads as none)
MEASUREMENTS = ("standstill_torque_ripple_mnm", "standstill_jitter_urad")

#: what it takes from earlier protocols (:mod:`hil.suite.needs`): nothing
NEEDS: tuple[Need, ...] = ()
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """``blocks`` holds from ``position_rad``, ``spacing_rad`` apart: each ``settle_s``, then
    its block of ``hold_s / blocks`` analysed."""

    position_rad: float | None  # None: NUDGE_RAD from where the axis is, towards the centre
    settle_s: float
    hold_s: float  # analysed in all, over the blocks
    blocks: int
    spacing_rad: float
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from ``[protocols.standstill]`` and the drive.

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key.
        """
        settings = profile.settings(NAME)
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            position_rad=settings.number("position_rad") if "position_rad" in settings else None,
            settle_s=settings.positive("settle_s", 0.2),
            hold_s=settings.positive("hold_s", 1.0),
            blocks=settings.integer("blocks", 5),
            spacing_rad=settings.positive("spacing_rad", 0.01),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        if spec.blocks < 2:
            raise settings.error("blocks", "must be at least 2 (the Type A is their "
                                           f"scatter), not {spec.blocks}")
        return spec

    @property
    def block_samples(self) -> int:
        """Samples analysed at the end of each hold."""
        return round(self.hold_s / self.blocks * self.fs_hz)


def hold_positions(spec: Spec, *, position_rad: float) -> list[float]:
    """Where each block is held: the first (``position_rad`` of the profile, else
    :data:`NUDGE_RAD` from ``position_rad`` towards the centre), the others each
    ``spacing_rad`` further towards the centre."""
    centre = (spec.travel_min_rad + spec.travel_max_rad) / 2
    start = spec.position_rad if spec.position_rad is not None else position_rad
    direction = math.copysign(1.0, centre - start)
    first = start if spec.position_rad is not None else start + direction * NUDGE_RAD
    return [first + direction * k * spec.spacing_rad for k in range(spec.blocks)]


def excitation(spec: Spec, *, position_rad: float) -> Excitation:
    """The moves to each hold position and the holds, one position-mode excitation (a
    separate hold would start with a step of the move's residual error)."""
    hold_s = spec.settle_s + spec.block_samples / spec.fs_hz
    parts, here = [], position_rad
    for target in hold_positions(spec, position_rad=position_rad):
        parts.append(move_excitation("hold", here, target, fs_hz=spec.fs_hz,
                                     speed_rad_s=spec.move_speed_rad_s, hold_s=hold_s).command)
        here = target
    return Excitation(name="move_and_hold", mode=Mode.POSITION, fs_hz=spec.fs_hz,
                      command=np.concatenate(parts))


def analyse(recording: Recording, excitation: Excitation, spec: Spec
            ) -> tuple[dict[str, Estimate], Standstill]:
    """Torque ripple (mN·m) and position jitter (µrad), a block at the end of each hold."""
    position, torque, _ = on_command_grid(recording, excitation)
    blocks = standstill_blocks(position, torque, analysed_windows(excitation, spec))
    return {
        "standstill_torque_ripple_mnm": block_estimate(
            "standstill_torque_ripple_mnm", blocks.torque_rms_nm, scale=1e3, unit="mN·m",
            resolution=quantisation_step(recording.effort), what="reported torque"),
        "standstill_jitter_urad": block_estimate(
            "standstill_jitter_urad", blocks.position_rms_rad, scale=1e6, unit="µrad",
            resolution=quantisation_step(recording.position), what="encoder"),
    }, blocks


def analysed_windows(excitation: Excitation, spec: Spec) -> list[tuple[int, int]]:
    """``(start, stop)`` samples of each hold's analysed block in ``excitation``."""
    return hold_windows(excitation.command, block_samples=spec.block_samples)


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return [excitation(Spec.from_profile(profile, info), position_rad=at())]


@dataclass(frozen=True, slots=True, kw_only=True)
class StandstillDetails(RunDetails):
    """The certificate's details: the holds and, for the plot, each block's samples and
    RMS."""

    hold_positions_rad: tuple[float, ...]
    hold_s: float
    block_windows: tuple[tuple[int, int], ...]  # each block's samples in the recording
    block_torque_rms_mnm: tuple[float, ...]
    block_position_rms_urad: tuple[float, ...]


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=StandstillDetails)
