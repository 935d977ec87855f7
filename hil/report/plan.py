"""The motion each protocol plans: its excitations' commanded time, built from the unit's
profile exactly as the protocol builds them (moves from the travel's centre). The console
turns it into the time left."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from hil.drives.base import DriveInfo
from hil.errors import HilError, ProfileError
from hil.motion import Excitation
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

log = logging.getLogger(__name__)


def _sine(profile: UnitProfile, info: DriveInfo, at_rad: float) -> list[Excitation]:
    spec = inertia_friction.Spec.from_profile(profile, info)
    moves = ([] if spec.centre_rad is None
             else [inertia_friction.move_to_centre(spec, spec.centre_rad, position_rad=at_rad)])
    return moves + inertia_friction.excitation(spec)


def _torque_constant(profile: UnitProfile, info: DriveInfo, at_rad: float) -> list[Excitation]:
    spec = torque_constant.Spec.from_profile(profile, info)
    out: list[Excitation] = []
    for angle in spec.angles_rad:
        out += [torque_constant.move(spec, position_rad=at_rad, angle_rad=angle),
                torque_constant.sweep(spec, angle_rad=angle)]
        at_rad = angle
    return out


def _elevation(profile: UnitProfile, info: DriveInfo, at_rad: float) -> list[Excitation]:
    spec = inertia_elevation.Spec.from_profile(profile, info)
    return [e for _ in spec.elevations_rad for e in inertia_friction.excitation(spec.sine)]


def _two_runs_from_start(spec: Any, runs: tuple[Excitation, Excitation],
                         at_rad: float) -> list[Excitation]:
    """A protocol that runs one excitation twice (without and with something), each from
    its start: two moves, the first from ``at_rad``, the second from the first run's end."""
    end_rad = float(spec.start_rad + runs[0].command.sum() / spec.fs_hz)
    return [spec.move_to_start(at_rad, hold_s=0.2), spec.move_to_start(end_rad, hold_s=0.2),
            *runs]


def _tracking(profile: UnitProfile, info: DriveInfo, at_rad: float) -> list[Excitation]:
    spec = tracking.Spec.from_profile(profile, info)
    return _two_runs_from_start(
        spec, tracking.excitation(spec, viscous_nm_s_rad=0.0, coulomb_nm=0.0), at_rad)


def _compensation(profile: UnitProfile, info: DriveInfo, at_rad: float) -> list[Excitation]:
    spec = cogging_compensation.Spec.from_profile(profile, info)
    return _two_runs_from_start(spec, cogging_compensation.excitation(spec), at_rad)


PLANNERS: dict[str, Callable[[UnitProfile, DriveInfo, float], list[Excitation]]] = {
    "current_loop": lambda p, i, at: current_loop.excitation(
        current_loop.Spec.from_profile(p, i), position_rad=at),
    "gravity_cable": lambda p, i, at: gravity_cable.excitation(
        gravity_cable.Spec.from_profile(p, i), position_rad=at),
    "inertia_friction": _sine,
    "stribeck": lambda p, i, at: stribeck.excitation(
        stribeck.Spec.from_profile(p, i), position_rad=at),
    "cogging": lambda p, i, at: cogging.excitation(
        cogging.Spec.from_profile(p, i), position_rad=at),
    "torque_constant": _torque_constant,
    "resonance": lambda p, i, at: resonance.excitation(
        resonance.spec_from_profile(p, i), position_rad=at),
    "inertia_elevation": _elevation,
    "velocity_loop_frf": lambda p, i, at: velocity_loop_frf.excitation(
        velocity_loop_frf.Spec.from_profile(p, i), position_rad=at),
    "velocity_step": lambda p, i, at: velocity_step.excitation(
        velocity_step.Spec.from_profile(p, i), position_rad=at),
    "tracking": _tracking,
    "standstill": lambda p, i, at: [standstill.excitation(
        standstill.Spec.from_profile(p, i), position_rad=at)],
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
        Protocol → seconds of commanded motion; 0 for one this module cannot plan (an
        unknown protocol, or settings its protocol will refuse with an error of its own).
    """
    centre = (info.limits.travel_min_rad + info.limits.travel_max_rad) / 2
    plan = {}
    for name in profile.protocols:
        planner = PLANNERS.get(name)
        try:
            excitations = planner(profile, info, centre) if planner else []
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
    centre = (info.limits.travel_min_rad + info.limits.travel_max_rad) / 2
    for name in profile.protocols:
        planner = PLANNERS.get(name)
        if planner is None:
            continue
        try:
            planner(profile, info, centre)
        except ValueError as exc:
            raise ProfileError(f"[protocols.{name}]: {exc}", source=profile.source) from None
