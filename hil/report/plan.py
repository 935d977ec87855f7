"""The motion each protocol plans: its excitations' commanded time, from the same
sequence the protocol's test runs (its suite module's ``motion`` or ``excitation``), each
protocol's moves from where the one before left the axis (the first from the travel's
centre). The console turns it into the time left."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable

import numpy as np

from hil.drives.base import DriveInfo
from hil.errors import HilError, ProfileError
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.suite import (
    cogging,
    cogging_compensation,
    current_loop,
    gravity_cable,
    inertia_elevation,
    inertia_friction,
    resonance,
    standstill,
    stribeck,
    torque_constant,
    tracking,
    velocity_loop_frf,
    velocity_step,
)
from hil.suite.catalogue import REQUIRES

log = logging.getLogger(__name__)


#: where the axis is, as the plan walks it: a callable, read when a move is built
Position = Callable[[], float]


class _Track:
    """The planned axis position, advanced by each excitation as the drive would be: a
    move ends at its last command, a velocity run at its start plus the command's
    integral, a torque run (sines about a point, a locked rotor) where it began."""

    def __init__(self, at_rad: float) -> None:
        self.at_rad = at_rad

    def position(self) -> float:
        return self.at_rad

    def walk(self, excitations: Iterable[Excitation]) -> list[Excitation]:
        out = []
        for e in excitations:  # a generator builds its next move after the last advance
            out.append(e)
            if e.mode is Mode.POSITION:
                self.at_rad = float(e.command[-1])
            elif e.mode is Mode.VELOCITY:
                self.at_rad += float(np.sum(e.command)) / e.fs_hz
        return out


def _tracking(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    spec = tracking.Spec.from_profile(profile, info)
    # the feedforward's size (known only after inertia_friction) does not change the time
    runs = tracking.excitation(spec, viscous_nm_s_rad=0.0, coulomb_nm=0.0)
    return tracking.motion(spec, runs, position=at)


def _compensation(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    spec = cogging_compensation.Spec.from_profile(profile, info)
    return cogging_compensation.motion(spec, cogging_compensation.excitation(spec), position=at)


def _torque_constant(profile: UnitProfile, info: DriveInfo, at: Position
                     ) -> Iterable[Excitation]:
    spec = torque_constant.Spec.from_profile(profile, info)
    # the cogging protocol's ripple table nudges the angles when the run gets there: not
    # known before, planned as configured (the moves differ by the nudges only)
    return torque_constant.motion(spec, angles_rad=torque_constant.locked_angles(spec, ()),
                                  position=at)


#: protocol → its motion: the suite module's own sequence (``motion`` or ``excitation``,
#: what the protocol's test runs), built from the profile and the planned position
PLANNERS: dict[str, Callable[[UnitProfile, DriveInfo, Position], Iterable[Excitation]]] = {
    "current_loop": lambda p, i, at: current_loop.excitation(
        current_loop.Spec.from_profile(p, i), position_rad=at()),
    "gravity_cable": lambda p, i, at: gravity_cable.excitation(
        gravity_cable.Spec.from_profile(p, i), position_rad=at()),
    "inertia_friction": lambda p, i, at: inertia_friction.motion(
        inertia_friction.Spec.from_profile(p, i), position=at),
    "stribeck": lambda p, i, at: stribeck.excitation(
        stribeck.Spec.from_profile(p, i), position_rad=at()),
    "cogging": lambda p, i, at: cogging.excitation(
        cogging.Spec.from_profile(p, i), position_rad=at()),
    "torque_constant": _torque_constant,
    "resonance": lambda p, i, at: resonance.excitation(
        resonance.spec_from_profile(p, i), position_rad=at()),
    "inertia_elevation": lambda p, i, at: inertia_elevation.motion(
        inertia_elevation.Spec.from_profile(p, i), position=at),
    "velocity_loop_frf": lambda p, i, at: velocity_loop_frf.excitation(
        velocity_loop_frf.Spec.from_profile(p, i), position_rad=at()),
    "velocity_step": lambda p, i, at: velocity_step.excitation(
        velocity_step.Spec.from_profile(p, i), position_rad=at()),
    "tracking": _tracking,
    "standstill": lambda p, i, at: [standstill.excitation(
        standstill.Spec.from_profile(p, i), position_rad=at())],
    "cogging_compensation": _compensation,
}


def planned_motion_s(profile: UnitProfile, info: DriveInfo) -> dict[str, float]:
    """Commanded motion time of each protocol the profile configures, in run order.

    Parameters
    ----------
    profile : UnitProfile
        The unit's profile (its ``[protocols.*]`` tables, in order).
    info : DriveInfo
        The drive (sample rate and limits shape the excitations).

    Returns
    -------
    dict
        Protocol → seconds of commanded motion (one run: a stop rule's repeats are not
        planned); 0 for one this module cannot plan (an unknown protocol, or settings its
        protocol will refuse with an error of its own) and for one the station lacks a
        capability for (it will be skipped).
    """
    track = _Track((info.limits.travel_min_rad + info.limits.travel_max_rad) / 2)
    plan = {}
    for name in profile.protocols:  # each from where the one before left the axis
        planner = PLANNERS.get(name)
        if info.lacking(REQUIRES.get(name, ())):
            planner = None  # skipped on this station: no motion
        try:
            excitations = track.walk(planner(profile, info, track.position)) if planner else []
        except (HilError, ValueError) as exc:
            log.debug("no motion plan for %s: %s", name, exc)
            excitations = []
        plan[name] = sum(e.duration_s for e in excitations)
    return plan


def check_protocol_settings(profile: UnitProfile, info: DriveInfo) -> None:
    """Read every configured protocol's settings and build its motion, as the run will, so
    that a misspelt or impossible setting stops the run before the first motion.

    Raises
    ------
    HilError
        The protocol's own one-line error (file, table and key); a ``ValueError`` of an
        excitation builder becomes a :class:`ProfileError` naming the protocol's table.
    """
    track = _Track((info.limits.travel_min_rad + info.limits.travel_max_rad) / 2)
    for name in profile.protocols:
        planner = PLANNERS.get(name)
        if planner is None:
            continue
        try:
            track.walk(planner(profile, info, track.position))
        except ValueError as exc:
            raise ProfileError(f"[protocols.{name}]: {exc}", source=profile.source) from None
