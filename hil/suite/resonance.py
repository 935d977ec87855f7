"""resonance: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_resonance.py``.

Two-mass resonance f_r, anti-resonance f_a, damping and f_r / velocity-loop bandwidth from
the FRF of encoder position over reported torque (numerics in
:mod:`hil.identify.resonance`), excited in velocity mode on a constant-speed carrier (no
reversal, so friction stays linear). Skips on a unit whose profile has no
``[protocols.resonance]`` (a rigid axis: nothing to find).

``excitation = "multisine"`` (the default, :class:`MultisineSpec`): one periodic multisine of
log-spaced lines on the period's grid, Schroeder phases for its amplitudes: one settling
serves every line, and every analysed period measures every line.
``excitation = "stepped_sine"`` (:class:`SteppedSpec`): one sine per frequency, each with
its own settling.

A multisine longer than the drive's own recorder (:class:`hil.drives.base.Recorder`) is
played in as many pieces as it takes for each to fit, each with its ramps and settling
periods, the carrier turning back each piece (the lines keep their phase); the analysed
periods of all pieces are one set (a period is a period: the FRF and its jackknife do not
care which piece it came from).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from hil.calibration import CalibrationRun
from hil.details import Details
from hil.drives.base import Capability, DriveInfo
from hil.errors import ProfileError
from hil.identify.multisine import log_harmonics, multisine, schroeder_phases_for
from hil.identify.resonance import ResonanceResult, frf_lines, frf_point, identify_resonance
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.rate import needed_sample_rate_hz
from hil.suite.travel import SteppedSineSpec, TravelSpec, speed_ramp
from hil.suite.velocity_loop_frf import direction_from

NAME = "resonance"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = (
    "resonance_frequency_hz",
    "antiresonance_frequency_hz",
    "resonance_damping_ratio",
    "resonance_to_bandwidth_ratio",
)
#: τ's start value when the current-loop protocol has not measured it (s)
LAG_START_S = 2e-4
#: what it takes from earlier protocols (:mod:`hil.suite.needs`)
LAG = Need(protocol="current_loop", result="current_loop_time_constant_ms",
           without=f"the model's current-loop τ starts from {LAG_START_S:g} s")
NEEDS: tuple[Need, ...] = (LAG,)
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()
EXCITATIONS = ("multisine", "stepped_sine")


def shaped_amplitude_rad_s(frequency_hz: float, amplitude_rad_s: float, *, knee_hz: float,
                           cap_rad_s: float) -> float:
    """``amplitude_rad_s`` up to ``knee_hz``, ∝ f above it (the motor responds ∝ 1/f),
    capped at ``cap_rad_s``."""
    return min(amplitude_rad_s * max(1.0, frequency_hz / knee_hz), cap_rad_s)


@dataclass(frozen=True, slots=True, kw_only=True)
class SteppedSpec(SteppedSineSpec):
    """A stepped sine over a geometric band on a constant-speed carrier."""

    amplitude_rad_s: float  # velocity sine amplitude up to amplitude_knee_hz
    amplitude_knee_hz: float  # above: amplitude ∝ f (the motor responds ∝ 1/f)
    max_amplitude_rad_s: float
    segment_s: float
    min_periods: int

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> SteppedSpec:
        """The spec from the profile's ``[protocols.resonance]`` table (``excitation =
        "stepped_sine"``) and the drive.

        Parameters
        ----------
        profile : UnitProfile
            The unit's profile.
        info : DriveInfo
            The drive: its limits and its highest sample rate.

        Returns
        -------
        SteppedSpec

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key, another excitation, or a carrier that runs
            past the travel limits.
        """
        settings = profile.settings(NAME)
        settings.choice("excitation", ("stepped_sine",), "stepped_sine")
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
        """The sine's velocity amplitude at ``frequency_hz`` (:func:`shaped_amplitude_rad_s`)."""
        return shaped_amplitude_rad_s(frequency_hz, self.amplitude_rad_s,
                                      knee_hz=self.amplitude_knee_hz,
                                      cap_rad_s=self.max_amplitude_rad_s)

    def settle_samples(self, frequency_hz: float) -> int:
        """Samples discarded at the start of a segment: ≥ 2 whole periods covering
        ``settle_s``."""
        periods = max(2, math.ceil(self.settle_s * frequency_hz))
        return round(periods * self.fs_hz / frequency_hz)

    def segment_samples(self, frequency_hz: float) -> int:
        """Settling plus analysed whole periods of ``frequency_hz``."""
        periods = max(self.min_periods, round(self.segment_s * frequency_hz))
        return self.settle_samples(frequency_hz) + round(periods * self.fs_hz / frequency_hz)


@dataclass(frozen=True, slots=True, kw_only=True)
class MultisineSpec(TravelSpec):
    """A periodic multisine of log-spaced lines over a band on a constant-speed carrier."""

    band_hz: tuple[float, float]
    lines: int  # asked for; fewer where the log spacing is finer than the grid
    dense_hz: tuple[float, float] | None  # every grid line inside is excited too
    speed_rad_s: float  # the carrier
    amplitude_rad_s: float  # per line up to amplitude_knee_hz
    amplitude_knee_hz: float  # above: amplitude ∝ f (the motor responds ∝ 1/f)
    max_amplitude_rad_s: float
    period_s: float
    settle_periods: int
    periods: int
    ramp_s: float
    pieces: int = 1  # runs the periods are played in (each fits the drive's recorder)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> MultisineSpec:
        """The spec from the profile's ``[protocols.resonance]`` table (``excitation =
        "multisine"``, the default) and the drive.

        Parameters
        ----------
        profile : UnitProfile
            The unit's profile.
        info : DriveInfo
            The drive: its limits and its highest sample rate.

        Returns
        -------
        MultisineSpec

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key, another excitation, a period that is not a
            whole number of samples, fewer than 6 lines or 3 analysed periods, a command
            past the velocity limit, or a carrier that runs past the travel limits.
        """
        settings = profile.settings(NAME)
        settings.choice("excitation", ("multisine",), "multisine")
        low, high = settings.numbers("band_hz", count=2)
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            band_hz=(low, high),
            lines=settings.integer("lines", 16),
            dense_hz=_band(settings.numbers("dense_hz", count=2)) if "dense_hz" in settings
            else None,
            speed_rad_s=settings.positive("speed_rad_s", 0.5),
            amplitude_rad_s=settings.positive("amplitude_rad_s", 0.07),
            amplitude_knee_hz=settings.positive("amplitude_knee_hz", 15.0),
            max_amplitude_rad_s=settings.positive("max_amplitude_rad_s", 0.08),
            period_s=settings.positive("period_s", 0.25),
            settle_periods=settings.integer("settle_periods", 1),
            periods=settings.integer("periods", 17),
            ramp_s=settings.positive("ramp_s", 0.1),
            pieces=1,
        )
        settings.done()
        spec.check(source=profile.source, velocity_limit_rad_s=info.limits.velocity_rad_s)
        return replace(spec, pieces=spec.pieces_for(info))

    def pieces_for(self, info: DriveInfo) -> int:
        """How many runs the periods take: 1, or as many as the drive's recorder needs when
        the spec runs at its rate (each piece its ramps and settling, at least 3 periods)."""
        recorder = info.recorder
        if recorder is None or self.fs_hz <= recorder.stream_rate_hz * (1 + 1e-9):
            return 1
        period = round(self.period_s * self.fs_hz)
        overhead = 2 * round(self.ramp_s * self.fs_hz) + self.settle_periods * period
        fits = (recorder.samples - overhead) // period  # analysed periods a piece holds
        if fits < 3:
            return 1  # it cannot be split: the planner streams it, saying why
        return math.ceil(self.periods / fits)

    def piece_periods(self) -> tuple[int, ...]:
        """The analysed periods of each piece, as even as they go."""
        base, extra = divmod(self.periods, self.pieces)
        return tuple(base + (1 if i < extra else 0) for i in range(self.pieces))

    def check(self, *, source: str, velocity_limit_rad_s: float) -> None:
        """Refuse a design the drive cannot run or the analysis cannot use.

        The torque the lines need depends on the plant (unknown here): the drive's torque
        limit is the profile author's to respect (the demo's peak is 0.35 of 0.5 N·m).

        Parameters
        ----------
        source : str
            The profile's path, for the error.
        velocity_limit_rad_s : float
            The unit's velocity limit: carrier plus the multisine's peak stays below it.

        Raises
        ------
        ProfileError
            A period that is not a whole number of samples, fewer than 3 analysed periods,
            fewer than 6 lines, a command past the velocity limit, or a run past the travel.
        """
        where = f"[protocols.{NAME}]"
        samples = self.period_s * self.fs_hz
        if abs(samples - round(samples)) > 1e-6:
            raise ProfileError(f"{where} period_s = {self.period_s:g} s is not a whole number "
                               f"of samples at {self.fs_hz:g} Hz", source=source)
        if self.periods < 3 or self.settle_periods < 0:
            raise ProfileError(f"{where} needs periods ≥ 3 (the jackknife) and settle_periods "
                               "≥ 0", source=source)
        try:
            count = len(self.harmonics)
        except ValueError as error:
            raise ProfileError(f"{where} {error}", source=source) from None
        if count < 6:
            raise ProfileError(f"{where} gives {count} lines on the {1 / self.period_s:g} Hz "
                               "grid, the fit needs at least 6", source=source)
        peak = self.speed_rad_s + float(np.max(np.abs(self.lines_command(periods=1))))
        if peak > velocity_limit_rad_s:
            raise ProfileError(f"{where} commands {peak:.3g} rad/s (carrier + multisine "
                               f"peak), above the {velocity_limit_rad_s:g} rad/s limit",
                               source=source)
        self.require_travel(self.speed_rad_s * self.duration_s, protocol=NAME, source=source)

    @property
    def harmonics(self) -> tuple[int, ...]:
        """The lines in cycles per period: log-spaced over the band on the grid, and every
        grid line inside ``dense_hz``."""
        lines = set(log_harmonics(*self.band_hz, self.lines, period_s=self.period_s))
        if self.dense_hz is not None:
            low, high = self.dense_hz
            lines.update(range(max(math.ceil(low * self.period_s - 1e-9), 1),
                               math.floor(high * self.period_s + 1e-9) + 1))
        return tuple(sorted(lines))

    @property
    def frequencies_hz(self) -> tuple[float, ...]:
        """The lines (Hz)."""
        return tuple(h / self.period_s for h in self.harmonics)

    @property
    def amplitudes_rad_s(self) -> tuple[float, ...]:
        """Each line's velocity amplitude (:func:`shaped_amplitude_rad_s`)."""
        return tuple(shaped_amplitude_rad_s(f, self.amplitude_rad_s,
                                            knee_hz=self.amplitude_knee_hz,
                                            cap_rad_s=self.max_amplitude_rad_s)
                     for f in self.frequencies_hz)

    @property
    def needed_sample_rate_hz(self) -> float:
        """4 × the highest line (Hz)."""
        return needed_sample_rate_hz(max(self.frequencies_hz))

    @property
    def duration_s(self) -> float:
        """Ramps and periods of the multisine runs (s)."""
        return (2 * self.ramp_s * self.pieces
                + (self.settle_periods * self.pieces + self.periods) * self.period_s)

    def analysed(self, periods: int) -> slice:
        """The analysed samples of a multisine run of ``periods`` analysed periods."""
        n = round(self.period_s * self.fs_hz)
        start = round(self.ramp_s * self.fs_hz) + self.settle_periods * n
        return slice(start, start + periods * n)

    def lines_command(self, *, periods: int) -> NDArray[np.float64]:
        """The multisine alone (rad/s, zero mean) over ``periods`` periods, Schroeder phases
        for its amplitudes."""
        amplitudes = self.amplitudes_rad_s
        return multisine(harmonics=self.harmonics, amplitudes_rad_s=amplitudes,
                         period_s=self.period_s, periods=periods, fs_hz=self.fs_hz,
                         phases=schroeder_phases_for(amplitudes))


Spec = SteppedSpec | MultisineSpec


def _band(values: tuple[float, ...]) -> tuple[float, float]:
    return values[0], values[1]


def spec_from_profile(profile: UnitProfile, info: DriveInfo) -> Spec:
    """The spec of the excitation the profile's ``[protocols.resonance]`` names.

    Parameters
    ----------
    profile : UnitProfile
        The unit's profile; ``excitation`` is ``"multisine"`` (default) or ``"stepped_sine"``.
    info : DriveInfo
        The drive: its limits and its highest sample rate.

    Returns
    -------
    SteppedSpec or MultisineSpec

    Raises
    ------
    ProfileError
        An unknown excitation, or see the spec's ``from_profile``.
    """
    kind = profile.settings(NAME).choice("excitation", EXCITATIONS, "multisine")
    if kind == "stepped_sine":
        return SteppedSpec.from_profile(profile, info)
    return MultisineSpec.from_profile(profile, info)


def excitation(spec: Spec, *, position_rad: float) -> list[Excitation]:
    """The protocol's excitations (velocity mode after any move).

    Multisine: ramp to the carrier, the periods, ramp down, from where the axis is, up or
    down where that fits (else a move to the lower end first). Stepped sine: the move to the
    lower end, then ramp, the sines, ramp down.

    Parameters
    ----------
    spec : SteppedSpec or MultisineSpec
        The protocol's spec.
    position_rad : float
        Where the axis is now.

    Returns
    -------
    list of Excitation
        Any move first, the measured run last.
    """
    if isinstance(spec, SteppedSpec):
        return [
            spec.move_to_start(position_rad, hold_s=0.1),
            Excitation(name="stepped_sine", mode=Mode.VELOCITY, fs_hz=spec.fs_hz,
                       command=spec.carrier_command()),
        ]
    up = speed_ramp(spec.speed_rad_s, ramp_s=spec.ramp_s, fs_hz=spec.fs_hz, up=True)
    down = speed_ramp(spec.speed_rad_s, ramp_s=spec.ramp_s, fs_hz=spec.fs_hz, up=False)
    if spec.pieces == 1:
        lines = spec.lines_command(periods=spec.settle_periods + spec.periods)
        command = np.concatenate([up, spec.speed_rad_s + lines, down])
        sign = direction_from(spec, position_rad, float(np.sum(command)) / spec.fs_hz)
        moves = [] if sign is not None else [spec.move_to_start(position_rad, hold_s=0.1)]
        return [*moves, Excitation(name="multisine", mode=Mode.VELOCITY, fs_hz=spec.fs_hz,
                                   command=(sign or 1.0) * command)]
    # pieces: the carrier turns back each piece (the first one's way decides), the lines
    # keep their sign and phase
    carrier = np.concatenate([up, np.full(round((spec.settle_periods + max(
        spec.piece_periods())) * spec.period_s * spec.fs_hz), spec.speed_rad_s), down])
    sign = direction_from(spec, position_rad, float(np.sum(carrier)) / spec.fs_hz)
    moves = [] if sign is not None else [spec.move_to_start(position_rad, hold_s=0.1)]
    runs = []
    for i, periods in enumerate(spec.piece_periods()):
        way = (sign or 1.0) * (1 if i % 2 == 0 else -1)
        lines = spec.lines_command(periods=spec.settle_periods + periods)
        command = np.concatenate([way * up, way * spec.speed_rad_s + lines, way * down])
        runs.append(Excitation(name=f"multisine_{i + 1}of{spec.pieces}", mode=Mode.VELOCITY,
                               fs_hz=spec.fs_hz, command=command))
    return [*moves, *runs]


def analyse(recordings: Sequence[Recording], spec: Spec, *,
            time_constant_s: float = 2e-4) -> ResonanceResult:
    """The FRF (per line or per frequency) and the two-mass model fitted to it.

    Parameters
    ----------
    recordings : sequence of Recording
        The measured runs' recordings (the multisine's pieces in order, or the stepped
        sine), each with its velocity command.
    spec : SteppedSpec or MultisineSpec
        The protocol's spec.
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
        Too few samples, periods or frequencies, a line or segment without torque, or a
        model fit that fails.
    """
    if any(r.velocity_cmd is None for r in recordings):
        raise ValueError("the resonance recording lacks its velocity command")
    if isinstance(spec, MultisineSpec):
        pieces = spec.piece_periods()
        if len(recordings) != len(pieces):
            raise ValueError(f"the multisine was planned in {len(pieces)} run(s), "
                             f"{len(recordings)} recorded")
        windows = [(r, spec.analysed(periods)) for r, periods in zip(recordings, pieces,
                                                                    strict=True)]
        # each piece's carrier offset goes with its own mean (the lines have none)
        lines = np.concatenate([r.velocity_cmd[w] - np.mean(r.velocity_cmd[w])  # type: ignore[index]
                                for r, w in windows])
        points = frf_lines(np.concatenate([r.position[w] for r, w in windows]),
                           np.concatenate([r.effort[w] for r, w in windows]),
                           lines, harmonics=spec.harmonics, period_s=spec.period_s,
                           fs_hz=spec.fs_hz, periods=spec.periods)
        return identify_resonance(points, fs_hz=spec.fs_hz, time_constant_s=time_constant_s)
    (recording,) = recordings
    command = recording.velocity_cmd
    assert command is not None
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
    tau = LAG.read(calibration)
    return LAG_START_S if tau is None else tau.value * 1e-3


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return excitation(spec_from_profile(profile, info), position_rad=at())


@dataclass(frozen=True, slots=True, kw_only=True)
class FrfPoint:
    """One frequency of the measured response (rad/N·m)."""

    frequency_hz: float
    magnitude_rad_nm: float
    phase_rad: float
    relative_u: float
    coherence: float


@dataclass(frozen=True, slots=True, kw_only=True)
class ResonanceDetails(Details):
    """The certificate's details: the excitation, the two-mass model and its fit, the
    response it was fitted to."""

    excitation: str
    model: str
    inertia_total_kg_m2: float
    antiresonance_damping_ratio: float
    viscous_over_inertia_1_s: float
    current_loop_time_constant_s: float
    velocity_loop_bandwidth_hz: float
    chi2_per_dof: float
    frf: tuple[FrfPoint, ...]


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=ResonanceDetails)
