"""resonance: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_resonance.py``.

Two-mass resonance f_r, anti-resonance f_a, damping and f_r / velocity-loop bandwidth from a
stepped-sine FRF (numerics in :mod:`hil.identify.resonance`).

Velocity-mode sines over the profile's band, on a constant-speed carrier (no reversal, so
friction stays linear). Skips on a unit whose profile has no ``[protocols.resonance]``
(a rigid axis: nothing to find).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.calibration import CalibrationRun
from hil.drives.base import DriveInfo
from hil.identify.resonance import ResonanceResult, frf_point, identify_resonance
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.travel import SteppedSineSpec, TravelSpec

NAME = "resonance"


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(SteppedSineSpec):
    """A stepped sine over a geometric band on a constant-speed carrier."""

    amplitude_rad_s: float  # velocity sine amplitude up to amplitude_knee_hz
    amplitude_knee_hz: float  # above: amplitude ∝ f (the motor responds ∝ 1/f)
    max_amplitude_rad_s: float
    segment_s: float
    min_periods: int

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.resonance]`` table and the drive.

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
        low, high = settings.numbers("band_hz", count=2)
        points = settings.integer("points", 28)
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            frequencies_hz=tuple(float(f) for f in np.geomspace(low, high, points)),
            speed_rad_s=settings.number("speed_rad_s", 0.5),
            amplitude_rad_s=settings.number("amplitude_rad_s", 0.25),
            amplitude_knee_hz=settings.number("amplitude_knee_hz", 15.0),
            max_amplitude_rad_s=settings.number("max_amplitude_rad_s", 0.8),
            segment_s=settings.number("segment_s", 0.12),
            min_periods=settings.integer("min_periods", 6),
            settle_s=settings.number("settle_s", 0.03),
            blocks=settings.integer("blocks", 6),
            ramp_s=settings.number("ramp_s", 0.1),
        )
        spec.require_carrier_travel(protocol=NAME, source=profile.source)
        settings.done()
        return spec

    def amplitude(self, frequency_hz: float) -> float:
        """``amplitude_rad_s``, ∝ f above the knee, capped at ``max_amplitude_rad_s``."""
        scaled = self.amplitude_rad_s * max(1.0, frequency_hz / self.amplitude_knee_hz)
        return min(scaled, self.max_amplitude_rad_s)

    def settle_samples(self, frequency_hz: float) -> int:
        """Samples discarded at the start of a segment: ≥ 2 whole periods covering
        ``settle_s``."""
        periods = max(2, math.ceil(self.settle_s * frequency_hz))
        return round(periods * self.fs_hz / frequency_hz)

    def segment_samples(self, frequency_hz: float) -> int:
        """Settling plus analysed whole periods of ``frequency_hz``."""
        periods = max(self.min_periods, round(self.segment_s * frequency_hz))
        return self.settle_samples(frequency_hz) + round(periods * self.fs_hz / frequency_hz)


def excitation(spec: Spec, *, position_rad: float) -> list[Excitation]:
    """Move to the lower end; ramp to the carrier speed; the stepped sine; ramp down.

    Parameters
    ----------
    spec : Spec
        The protocol's spec.
    position_rad : float
        Where the axis is now.

    Returns
    -------
    list of Excitation
        The move to the start, then the stepped sine (velocity mode).
    """
    return [
        spec.move_to_start(position_rad, hold_s=0.1),
        Excitation(
            name="stepped_sine",
            mode=Mode.VELOCITY,
            fs_hz=spec.fs_hz,
            command=spec.carrier_command(),
        ),
    ]


def analyse(recording: Recording, spec: Spec, *, time_constant_s: float = 2e-4) -> ResonanceResult:
    """The FRF point of each frequency's segment, and the two-mass model fitted to them.

    Parameters
    ----------
    recording : Recording
        The stepped sine's recording, with its velocity command.
    spec : Spec
        The protocol's spec (frequencies, segments, carrier).
    time_constant_s : float
        The current loop's τ, the fit's start value (see :func:`measured_time_constant_s`).

    Returns
    -------
    ResonanceResult
        See :func:`hil.identify.resonance.identify_resonance`.

    Raises
    ------
    ValueError
        The recording has no velocity command.
    IdentificationError
        A segment too short for its blocks or without torque at its frequency, fewer
        than 6 frequencies, or a model fit that fails.
    """
    command = recording.velocity_cmd
    if command is None:
        raise ValueError("the stepped-sine recording lacks its velocity command")
    start = round(spec.ramp_s * spec.fs_hz)
    points = []
    for f in spec.frequencies_hz:
        a, b = start + spec.settle_samples(f), start + spec.segment_samples(f)
        points.append(
            frf_point(
                recording.time_s[a:b],
                recording.position[a:b],
                recording.effort[a:b],
                command[a:b] - spec.speed_rad_s,
                frequency_hz=f,
                fs_hz=spec.fs_hz,
                blocks=spec.blocks,
            )
        )
        start = b
    return identify_resonance(points, fs_hz=spec.fs_hz, time_constant_s=time_constant_s)


def measured_time_constant_s(calibration: CalibrationRun) -> float:
    """The current-loop protocol's τ when it ran already (a start value only).

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress (earlier results).

    Returns
    -------
    float
        τ in seconds; 2e-4 when the current-loop protocol has not measured it.
    """
    tau = calibration.result("current_loop_time_constant_ms")
    return 2e-4 if tau is None else tau.value * 1e-3
