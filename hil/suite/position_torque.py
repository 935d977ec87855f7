"""Cogging and K_t ripple for the protocols that run before ``cogging``: found on the
gravity sweep already recorded, by the cogging protocol's own analysis, for the sine
protocols to take out (:mod:`hil.identify.position_torque`)."""

from __future__ import annotations

import numpy as np

from hil.calibration import CalibrationRun
from hil.drives.base import DriveInfo
from hil.errors import IdentificationError
from hil.identify.position_torque import PositionTorque
from hil.profile import UnitProfile
from hil.suite import cogging
from hil.suite.plan import acquisition_info


def position_torque_of_sweep(calibration: CalibrationRun, profile: UnitProfile,
                             info: DriveInfo) -> tuple[PositionTorque | None, str]:
    """Cogging and K_t ripple from the gravity sweep, with the declared J (or the measured
    one, if any) for the passes' acceleration correction, as the cogging protocol uses.

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress: the sweep's raw recording.
    profile : UnitProfile
        The unit's profile: ``[protocols.cogging]`` with ``passes = "gravity_cable"``.
    info : DriveInfo
        The drive as the gravity protocol saw it (its acquisition).

    Returns
    -------
    PositionTorque or None
        The significant harmonics; ``None`` without such a sweep or with nothing above
        its noise.
    str
        Why not, when ``None``.
    """
    if cogging.NAME not in profile.protocols:
        return None, f"the profile has no [protocols.{cogging.NAME}]"
    spec = cogging.Spec.from_profile(profile, info)
    if spec.passes != cogging.SWEEP_PASSES:
        return None, f"[protocols.{cogging.NAME}] has passes of its own, run later"
    try:
        position, torque, _, _ = cogging.sweep_passes(calibration, profile, info)
        inertia, _ = cogging.inertia_for_correction(calibration, profile)
        found = cogging.analyse(np.arange(len(position)) / spec.fs_hz, position, torque, spec,
                                inertia_kg_m2=inertia)
    except IdentificationError as exc:
        return None, str(exc)
    torque_map = PositionTorque.of(found)
    return (torque_map, "") if torque_map else (None, "no harmonic above the sweep's noise")


def measured_position_torque(calibration: CalibrationRun, profile: UnitProfile,
                             info: DriveInfo, *, protocol: str) -> PositionTorque | None:
    """:func:`position_torque_of_sweep` at the sweep's acquisition (``info``: the drive as
    it is); when there is none, ``protocol``'s certificate entry says why."""
    sweep_info, _ = acquisition_info(cogging.SWEEP_PASSES, profile, info)
    found, why_not = position_torque_of_sweep(calibration, profile, sweep_info)
    if found is None:
        line = f"cogging and K_t ripple not taken out: {why_not}"
        messages = calibration.protocol(protocol).messages
        if line not in messages:
            messages.append(line)
    return found
