"""velocity_loop_frf: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_velocity_loop_frf.py``.

The velocity loop's closed-loop FRF (command → velocity) and sensitivity from a periodic
multisine on a constant-speed carrier; −3 dB bandwidth, peak closed-loop gain, gain and
phase margins, peak of ``|S|`` (python-control on the measured loop gain). Numerics in
:mod:`hil.closed_loop.frf`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from hil.closed_loop.frf import FrfResult, analyse_frf
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.errors import ProfileError
from hil.identify.multisine import multisine
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.rate import needed_sample_rate_hz
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec, speed_ramp

NAME = "velocity_loop_frf"
MEASUREMENTS = ("velocity_bandwidth_hz", "velocity_peak_gain_db", "velocity_gain_margin_db",
                "velocity_phase_margin_deg", "velocity_sensitivity_peak_db")

#: what it takes from earlier protocols (:mod:`hil.suite.needs`): nothing
NEEDS: tuple[Need, ...] = ()
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """A multisine of ``frequencies_hz`` (each a multiple of ``1/period_s``) on a carrier."""

    frequencies_hz: tuple[float, ...]
    amplitude_rad_s: float  # per line below high_from_hz
    amplitude_high_rad_s: float  # per line from high_from_hz on (the loop's response is small)
    high_from_hz: float
    speed_rad_s: float  # the carrier
    period_s: float
    settle_periods: int
    periods: int
    ramp_s: float
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from ``[protocols.velocity_loop_frf]`` and the drive.

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key, a line that is not a harmonic of the
            period, or a carrier that runs past the travel limits.
        """
        settings = profile.settings(NAME)
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            frequencies_hz=settings.numbers("frequencies_hz"),
            amplitude_rad_s=settings.positive("amplitude_rad_s", 0.02),
            amplitude_high_rad_s=settings.positive("amplitude_high_rad_s", 0.04),
            high_from_hz=settings.positive("high_from_hz", 100.0),
            speed_rad_s=settings.positive("speed_rad_s", 0.4),
            period_s=settings.positive("period_s", 0.5),
            settle_periods=settings.integer("settle_periods", 1),
            periods=settings.integer("periods", 4),
            ramp_s=settings.positive("ramp_s", 0.2),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        for f in spec.frequencies_hz:
            if abs(f * spec.period_s - round(f * spec.period_s)) > 1e-9 or f <= 0:
                raise ProfileError(f"[protocols.{NAME}] line {f:g} Hz is not a multiple of "
                                   f"1/period_s = {1 / spec.period_s:g} Hz", source=profile.source)
        spec.require_travel(spec.speed_rad_s * spec.duration_s, protocol=NAME,
                            source=profile.source)
        return spec

    @property
    def harmonics(self) -> tuple[int, ...]:
        """Each line in cycles per period."""
        return tuple(round(f * self.period_s) for f in self.frequencies_hz)

    @property
    def amplitudes_rad_s(self) -> tuple[float, ...]:
        """Each line's velocity amplitude (rad/s)."""
        return tuple(self.amplitude_high_rad_s if f >= self.high_from_hz
                     else self.amplitude_rad_s for f in self.frequencies_hz)

    @property
    def duration_s(self) -> float:
        """Ramps and periods of the multisine run (s)."""
        return 2 * self.ramp_s + (self.settle_periods + self.periods) * self.period_s

    @property
    def needed_sample_rate_hz(self) -> float:
        """4 × the highest line (Hz)."""
        return needed_sample_rate_hz(max(self.frequencies_hz))

    @property
    def analysed(self) -> slice:
        """The analysed periods' samples in the multisine excitation."""
        start = round(self.ramp_s * self.fs_hz) + self.settle_periods * round(
            self.period_s * self.fs_hz)
        return slice(start, start + self.periods * round(self.period_s * self.fs_hz))


def direction_from(spec: TravelSpec, position_rad: float, needed_rad: float) -> float | None:
    """+1 or −1 when a one-way run of ``needed_rad`` fits from ``position_rad`` (up first),
    ``None`` when it fits neither way or the axis stands inside a margin (the run then starts
    at :attr:`TravelSpec.start_rad`)."""
    low, high = spec.travel_min_rad + spec.margin_rad, spec.travel_max_rad - spec.margin_rad
    if not low <= position_rad <= high:
        return None
    if position_rad + needed_rad <= spec.travel_max_rad - spec.margin_rad:
        return 1.0
    if position_rad - needed_rad >= spec.travel_min_rad + spec.margin_rad:
        return -1.0
    return None


def excitation(spec: Spec, *, position_rad: float) -> list[Excitation]:
    """Ramp to the carrier, the multisine's periods on it, ramp down: from where the axis
    is, up or down, where that fits (else a move to the start first)."""
    lines = multisine(harmonics=spec.harmonics, amplitudes_rad_s=spec.amplitudes_rad_s,
                      period_s=spec.period_s, periods=spec.settle_periods + spec.periods,
                      fs_hz=spec.fs_hz)
    up = speed_ramp(spec.speed_rad_s, ramp_s=spec.ramp_s, fs_hz=spec.fs_hz, up=True)
    down = speed_ramp(spec.speed_rad_s, ramp_s=spec.ramp_s, fs_hz=spec.fs_hz, up=False)
    command = np.concatenate([up, spec.speed_rad_s + lines, down])
    sign = direction_from(spec, position_rad, float(np.sum(command)) / spec.fs_hz)
    runs = [] if sign is not None else [spec.move_to_start(position_rad, hold_s=0.2)]
    return [*runs, Excitation(name="multisine", mode=Mode.VELOCITY, fs_hz=spec.fs_hz,
                              command=(sign or 1.0) * command)]


def analyse(recording: Recording, spec: Spec) -> FrfResult:
    """The FRFs and figures of the analysed periods (one row per command sample).

    Raises
    ------
    IdentificationError
        See :func:`hil.closed_loop.frf.analyse_frf`.
    """
    window = spec.analysed
    command = recording.velocity_cmd
    assert command is not None
    sign = 1.0 if float(np.mean(command)) >= 0 else -1.0  # a run down: the same loop
    return analyse_frf(command=sign * command[window], velocity=sign * recording.velocity[window],
                       torque=sign * recording.effort[window], harmonics=spec.harmonics,
                       period_s=spec.period_s, fs_hz=spec.fs_hz, periods=spec.periods)


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return excitation(Spec.from_profile(profile, info), position_rad=at())


@dataclass(frozen=True, slots=True, kw_only=True)
class VelocityLoopFrfDetails(RunDetails):
    """The certificate's details: the responses per frequency (dB, degrees) for the Bode
    plot, the periods analysed, how the margins were computed."""

    frequencies_hz: tuple[float, ...]
    closed_loop_db: tuple[float, ...]
    closed_loop_deg: tuple[float, ...]
    sensitivity_db: tuple[float, ...]
    loop_gain_db: tuple[float, ...]
    loop_gain_deg: tuple[float, ...]
    controller_db: tuple[float, ...]
    plant_db: tuple[float, ...]
    periods: int
    margins: str


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=VelocityLoopFrfDetails)
