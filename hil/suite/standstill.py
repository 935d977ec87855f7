"""standstill: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_standstill.py``.

The drive holds a position (position mode; after a short move from where the axis is, or
at the profile's ``position_rad``): torque ripple (RMS of
the reported torque about its mean) and position jitter (RMS of the encoder about its
mean), over blocks after a settling time. Numerics in :mod:`hil.closed_loop.standstill`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hil.closed_loop.standstill import Standstill, block_estimate, standstill_blocks
from hil.drives.base import DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.quantisation import quantisation_step
from hil.motion import Excitation
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.needs import Need
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec, move_excitation, on_command_grid

NAME = "standstill"
NUDGE_RAD = 0.05  # the hold follows a move this long: a held pointing, and the encoder's
# resolution shows in the recording (a position that never changed reads as none)
MEASUREMENTS = ("standstill_torque_ripple_mnm", "standstill_jitter_urad")

#: what it takes from earlier protocols (:mod:`hil.suite.needs`): nothing
NEEDS: tuple[Need, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """Hold ``settle_s`` then ``hold_s`` analysed in ``blocks``, at ``position_rad``."""

    position_rad: float | None  # None: NUDGE_RAD from where the axis is, towards the centre
    settle_s: float
    hold_s: float
    blocks: int
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
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        return spec


def excitation(spec: Spec, *, position_rad: float) -> Excitation:
    """The move to the hold position and the hold, one position-mode excitation (a
    separate hold would start with a step of the move's residual error)."""
    if spec.position_rad is None:  # a short move towards the centre, then the hold
        centre = (spec.travel_min_rad + spec.travel_max_rad) / 2
        target = position_rad + math.copysign(NUDGE_RAD, centre - position_rad)
    else:
        target = spec.position_rad
    return move_excitation("move_and_hold", position_rad, target, fs_hz=spec.fs_hz,
                           speed_rad_s=spec.move_speed_rad_s, hold_s=spec.settle_s + spec.hold_s)


def analyse(recording: Recording, excitation: Excitation, spec: Spec
            ) -> tuple[dict[str, Estimate], Standstill]:
    """Torque ripple (mN·m) and position jitter (µrad) after the settling time."""
    position, torque, _ = on_command_grid(recording, excitation)
    held = round(spec.hold_s * spec.fs_hz)
    blocks = standstill_blocks(position[-held:], torque[-held:], blocks=spec.blocks)
    return {
        "standstill_torque_ripple_mnm": block_estimate(
            "standstill_torque_ripple_mnm", blocks.torque_rms_nm, scale=1e3, unit="mN·m",
            resolution=quantisation_step(recording.effort), what="reported torque"),
        "standstill_jitter_urad": block_estimate(
            "standstill_jitter_urad", blocks.position_rms_rad, scale=1e6, unit="µrad",
            resolution=quantisation_step(recording.position), what="encoder"),
    }, blocks
