"""gravity_cable: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_gravity_cable.py``.

m·g·e (gravity unbalance) and k_cable from one slow two-way sweep of the travel.

One protocol for both because they are separated by one joint fit of the load torque
(``cos θ``, ``sin θ``, ``θ``, 1) over the same sweep: two sweeps would double the motion
for the same information. The sweep passes every elevation in both directions, so the
friction cancels in the half sum of the two passes (the 48 position bins are the
"holding" elevations).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.gravity_cable import (
    GravityCableResult,
    SweepPlan,
    identify_gravity_cable,
    sweep_plan,
)
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec

log = logging.getLogger(__name__)


NAME = "gravity_cable"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = (
    "gravity_mge_nm",
    "gravity_phase_rad",
    "eccentricity_mm",
    "cable_stiffness_nm_rad",
    "cable_hysteresis_nm",
)

#: what it takes from earlier protocols (:mod:`hil.suite.needs`): nothing
NEEDS: tuple[Need, ...] = ()
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """One sweep up the travel and back, between a slow reference and a slow probe."""

    speed_rad_s: float
    probe_rad: float
    probe_speed_rad_s: float
    probe_settle_s: float
    exclude_rad: float
    bins: int
    mass_kg: float | None
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.gravity_cable]`` table and the drive.

        Parameters
        ----------
        profile : UnitProfile
            The unit's profile.
        info : DriveInfo
            The drive: its limits and its highest sample rate.

        Returns
        -------
        Spec

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key.
        """
        settings = profile.settings(NAME)
        mass = profile.unit.get("mass_kg")
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            speed_rad_s=settings.number("speed_rad_s", 0.15),
            probe_rad=settings.number("probe_rad", 0.12),
            probe_speed_rad_s=settings.number("probe_speed_rad_s", 0.05),
            probe_settle_s=settings.number("probe_settle_s", 0.12),
            exclude_rad=settings.number("exclude_rad", 0.1),
            bins=settings.integer("bins", 48),
            mass_kg=None if mass is None else float(mass),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        return spec

    @property
    def stop_rad(self) -> float:
        """Where the sweep's up pass ends: the upper travel limit less the margin."""
        return self.travel_max_rad - self.margin_rad

    @property
    def excitation_start_rad(self) -> float:
        """Above :attr:`start_rad` by the run-in and the reference (see :attr:`plan`)."""
        return self.plan.start_rad

    @property
    def plan(self) -> SweepPlan:
        """The sweep's command and its phases (:func:`hil.identify.gravity_cable.sweep_plan`)."""
        return sweep_plan(
            start_rad=self.start_rad,
            stop_rad=self.stop_rad,
            speed_rad_s=self.speed_rad_s,
            probe_rad=self.probe_rad,
            probe_speed_rad_s=self.probe_speed_rad_s,
            fs_hz=self.fs_hz,
        )


def excitation(spec: Spec, *, position_rad: float) -> list[Excitation]:
    """A position move to where the sweep's command begins, then the sweep.

    Parameters
    ----------
    spec : Spec
        The protocol's spec.
    position_rad : float
        Where the axis is now.

    Returns
    -------
    list of Excitation
        The move to the plan's start (above :attr:`Spec.start_rad` by its run-in and
        reference), then the sweep (velocity mode).
    """
    return [
        spec.move_to_start(position_rad, hold_s=0.2),
        Excitation(name="sweep", mode=Mode.VELOCITY, fs_hz=spec.fs_hz,
                   command=spec.plan.command_rad_s),
    ]


def analyse(position_rad: np.ndarray, torque_nm: np.ndarray, spec: Spec) -> GravityCableResult:
    """m·g·e, its phase, k_cable and the cable's hysteresis from the sweep.

    Parameters
    ----------
    position_rad, torque_nm : ndarray
        The sweep's recording on the command grid (see
        :func:`hil.suite.travel.on_command_grid`).
    spec : Spec
        The protocol's spec (plan, bins, exclusions).

    Returns
    -------
    GravityCableResult
        See :func:`hil.identify.gravity_cable.identify_gravity_cable`.

    Raises
    ------
    IdentificationError
        The recording is shorter than the sweep, the usable sweep is under 1 rad, or fewer
        than 8 position bins hold both passes.
    """
    return identify_gravity_cable(
        position_rad=position_rad,
        torque_nm=torque_nm,
        plan=spec.plan,
        exclude_rad=spec.exclude_rad,
        bins=spec.bins,
        settle_rad=spec.probe_settle_s * spec.probe_speed_rad_s,
    )


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return excitation(Spec.from_profile(profile, info), position_rad=at())


@dataclass(frozen=True, slots=True, kw_only=True)
class GravityCableDetails(RunDetails):
    """The certificate's details: the sweep's fit, its cable loop (which the sine and
    Stribeck protocols take out) and the load per position for the plot."""

    recorded_rows: int
    offset_nm: float
    cable_hysteresis_angle_rad: float | None
    cable_hysteresis_angle_u_rad: float
    cable_hysteresis_covariance: float
    loop_half_width_nm: float
    sliding_friction_at_sweep_speed_nm: float
    bins: int
    residual_rms_nm: float
    load_nm_by_elevation_rad: tuple[tuple[float, float], ...]  # (bin centre, load)


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=GravityCableDetails)
