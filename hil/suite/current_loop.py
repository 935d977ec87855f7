"""current_loop: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_current_loop.py``.

Current-loop lag τ from the phase of the motion against the reported torque, 20–150 Hz.

Velocity-mode sines on top of a constant speed (the axis never reverses, so friction stays
linear); numerics and the sampled-data model in :mod:`hil.identify.current_loop`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.current_loop import (
    CurrentLoopResult,
    TorqueHold,
    analyse_frequency,
    fit_current_loop_lag,
    torque_hold_s,
)
from hil.identify.lag_model import LagModelCheck, certified, check_lag_model
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import SteppedSineSpec, TravelSpec

NAME = "current_loop"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = ("current_loop_time_constant_ms",)

#: what it takes from earlier protocols (:mod:`hil.suite.needs`): nothing
NEEDS: tuple[Need, ...] = ()
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(SteppedSineSpec):
    """Velocity sines of one amplitude on a constant-speed carrier, one segment each."""

    amplitude_rad_s: float  # velocity command sine amplitude
    segment_s: float  # analysed time per frequency
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.current_loop]`` table and the drive.

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
            A missing, mistyped or unknown key, or a carrier that runs past the travel limits.
        """
        settings = profile.settings(NAME)
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            frequencies_hz=settings.numbers("frequencies_hz"),
            speed_rad_s=settings.number("speed_rad_s", 0.6),
            amplitude_rad_s=settings.number("amplitude_rad_s", 0.3),
            segment_s=settings.number("segment_s", 0.25),
            settle_s=settings.number("settle_s", 0.05),
            ramp_s=settings.number("ramp_s", 0.1),
            blocks=settings.integer("blocks", 10),
            stop=StopRule.from_settings(settings),
        )
        spec.require_carrier_travel(protocol=NAME, source=profile.source)
        settings.done()
        return spec

    def amplitude(self, frequency_hz: float) -> float:
        """The same velocity amplitude at every frequency."""
        return self.amplitude_rad_s

    def settle_samples(self, frequency_hz: float) -> int:
        """Samples discarded at the start of a segment: whole periods covering ``settle_s``."""
        return round(math.ceil(self.settle_s * frequency_hz) * self.fs_hz / frequency_hz)

    def segment_samples(self, frequency_hz: float) -> int:
        """Settling plus analysed samples: whole periods of ``frequency_hz``."""
        periods = math.ceil(self.settle_s * frequency_hz) + round(self.segment_s * frequency_hz)
        return round(periods * self.fs_hz / frequency_hz)


def excitation(spec: Spec, *, position_rad: float) -> list[Excitation]:
    """Move to the lower end; ramp to the carrier speed; one sine segment per frequency.

    Parameters
    ----------
    spec : Spec
        The protocol's spec.
    position_rad : float
        Where the axis is now.

    Returns
    -------
    list of Excitation
        The move to :attr:`Spec.start_rad`, then the sines (velocity mode).
    """
    return [
        spec.move_to_start(position_rad, hold_s=0.1),
        Excitation(
            name="sines", mode=Mode.VELOCITY, fs_hz=spec.fs_hz, command=spec.carrier_command()
        ),
    ]


def analyse(recording: Recording, spec: Spec) -> CurrentLoopResult:
    """τ from the phase of motion against reported torque in each frequency's segment:
    :func:`analyse_checked` without its model test."""
    return analyse_checked(recording, spec)[0]


def analyse_checked(recording: Recording, spec: Spec) -> tuple[CurrentLoopResult, LagModelCheck]:
    """τ from the phase of motion against reported torque in each frequency's segment, and
    the first-order lag's test on those phases (τ + dead time certified,
    :func:`hil.identify.lag_model.certified`).

    Parameters
    ----------
    recording : Recording
        The sines' recording (one row per command sample).
    spec : Spec
        The protocol's spec (segments, blocks).

    Returns
    -------
    CurrentLoopResult
        See :func:`hil.identify.current_loop.fit_current_loop_lag`.
    LagModelCheck
        See :func:`hil.identify.lag_model.check_lag_model`.

    Raises
    ------
    IdentificationError
        A segment too short for its blocks or without torque at its frequency, fewer than
        3 frequencies, or a fit that does not converge or cannot separate τ from B/J.
    """
    hold = torque_hold_s(recording.metadata, fs_hz=spec.fs_hz)
    start = round(spec.ramp_s * spec.fs_hz)
    points = []
    for f in spec.frequencies_hz:
        a, b = start + spec.settle_samples(f), start + spec.segment_samples(f)
        points.append(
            analyse_frequency(
                recording.time_s[a:b],
                recording.position[a:b],
                recording.effort[a:b],
                frequency_hz=f,
                fs_hz=spec.fs_hz,
                blocks=spec.blocks,
                hold_s=hold.hold_s,
                mean_samples=hold.mean_samples,
            )
        )
        start += spec.segment_samples(f)
    first_order = fit_current_loop_lag(
        points, fs_hz=spec.fs_hz, hold_s=hold.hold_s, mean_samples=hold.mean_samples
    )
    check = check_lag_model(first_order, fs_hz=spec.fs_hz, hold_s=hold.hold_s,
                            mean_samples=hold.mean_samples)
    return certified(first_order, check), check


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return excitation(Spec.from_profile(profile, info), position_rad=at())


@dataclass(frozen=True, slots=True, kw_only=True)
class LagPoint:
    """One frequency's lag phase and what it was fitted with."""

    frequency_hz: float
    lag_phase_rad: float
    lag_phase_u_rad: float
    inertia_kg_m2: float
    torque_amplitude_nm: float


@dataclass(frozen=True, slots=True, kw_only=True)
class CurrentLoopDetails(RunDetails):
    """The certificate's details: how the drive held its torque, the fit, each point."""

    torque_hold: TorqueHold
    acquisition: str  # the rows' path: its method line (hil.identify.current_loop)
    viscous_over_inertia_1_s: float
    chi2_per_dof: float
    lag_model_p_value: float  # χ² test of the first-order lag (hil.identify.lag_model)
    dead_time_ms: float | None  # fitted beside τ (the τ certified is their sum)
    dead_time_u_ms: float | None
    points: tuple[LagPoint, ...]


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=CurrentLoopDetails)
