"""velocity_step: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_velocity_step.py``.

Velocity steps on a moving axis (no reversal inside a staircase: friction stays a
constant), small and large, up and down, in both directions of rotation: a staircase
``base → base + small → base → base + large → base`` and its mirror. Numerics in
:mod:`hil.closed_loop.step`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from hil.closed_loop.step import StepFigures, mean_estimate, smoothed_velocity, step_figures
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.estimate import Estimate
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec, on_command_grid, speed_ramp
from hil.suite.velocity_loop_frf import direction_from

NAME = "velocity_step"
SIZES = ("small", "large")
MEASUREMENTS = (
    "step_rise_time_small_ms", "step_rise_time_large_ms",
    "step_overshoot_small_pct", "step_overshoot_large_pct",
    "step_settling_time_small_ms", "step_settling_time_large_ms",
    "step_steady_state_error_pct",
)

#: what it takes from earlier protocols (:mod:`hil.suite.needs`): nothing
NEEDS: tuple[Need, ...] = ()
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """The staircase: ``base_rad_s`` with steps of ``small_rad_s`` and ``large_rad_s``."""

    base_rad_s: float
    small_rad_s: float
    large_rad_s: float
    hold_s: float
    ramp_s: float
    smooth_s: float
    min_sample_rate_hz: float  # a rise of ~10 ms needs ~10 samples: not over a polled link
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from ``[protocols.velocity_step]`` and the drive.

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key; a staircase past the travel limits.
        """
        settings = profile.settings(NAME)
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            base_rad_s=settings.positive("base_rad_s", 0.3),
            small_rad_s=settings.positive("small_rad_s", 0.5),
            large_rad_s=settings.positive("large_rad_s", 1.5),
            hold_s=settings.positive("hold_s", 0.4),
            ramp_s=settings.positive("ramp_s", 0.1),
            smooth_s=settings.positive("smooth_s", 0.005),
            min_sample_rate_hz=settings.positive("min_sample_rate_hz", 1000.0),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        spec.require_travel(spec.travel_rad, protocol=NAME, source=profile.source)
        return spec

    @property
    def levels_rad_s(self) -> tuple[float, ...]:
        """The staircase's velocity levels (rad/s)."""
        b = self.base_rad_s
        return (b, b + self.small_rad_s, b, b + self.large_rad_s, b)

    @property
    def travel_rad(self) -> float:
        """Travel of one staircase, ramps included (rad)."""
        return (sum(self.levels_rad_s) * self.hold_s + self.base_rad_s * self.ramp_s)

    @property
    def hold_samples(self) -> int:
        """Samples per level."""
        return round(self.hold_s * self.fs_hz)

    @property
    def ramp_samples(self) -> int:
        """Samples of the ramp to the base level."""
        return round(self.ramp_s * self.fs_hz)


def staircase(spec: Spec, sign: float) -> np.ndarray:
    """Ramp to ``sign·base``, the levels, ramp to rest."""
    up = speed_ramp(spec.base_rad_s, ramp_s=spec.ramp_s, fs_hz=spec.fs_hz, up=True)
    down = speed_ramp(spec.base_rad_s, ramp_s=spec.ramp_s, fs_hz=spec.fs_hz, up=False)
    levels = [np.full(spec.hold_samples, v) for v in spec.levels_rad_s]
    return sign * np.concatenate([up, *levels, down])


def excitation(spec: Spec, *, position_rad: float) -> list[Excitation]:
    """The staircase one way and its mirror back: from where the axis is, up first or down
    first, where that fits (else a move to the start first)."""
    sign = direction_from(spec, position_rad, spec.travel_rad)
    runs = [] if sign is not None else [spec.move_to_start(position_rad, hold_s=0.2)]
    first = sign or 1.0
    return [*runs,
            Excitation(name="steps_forward", mode=Mode.VELOCITY, fs_hz=spec.fs_hz,
                       command=staircase(spec, first)),
            Excitation(name="steps_backward", mode=Mode.VELOCITY, fs_hz=spec.fs_hz,
                       command=staircase(spec, -first))]


def step_results(recording: Recording, excitation: Excitation, spec: Spec
                 ) -> list[tuple[str, StepFigures]]:
    """Each step's figures, labelled by size."""
    position, _, _ = on_command_grid(recording, excitation)
    velocity = smoothed_velocity(position, fs_hz=spec.fs_hz, smooth_s=spec.smooth_s)
    sign = float(np.sign(excitation.command[spec.ramp_samples]))
    levels = [sign * v for v in spec.levels_rad_s]
    out = []
    trim = round(spec.smooth_s * spec.fs_hz)  # the smoothing would see the next step
    for i in range(1, len(levels)):
        start = spec.ramp_samples + i * spec.hold_samples
        segment = velocity[start: start + spec.hold_samples - trim]
        size = "small" if i in (1, 2) else "large"
        out.append((size, step_figures(segment, start_rad_s=levels[i - 1],
                                       target_rad_s=levels[i], fs_hz=spec.fs_hz)))
    return out


def analyse(runs: list[tuple[Recording, Excitation]], spec: Spec
            ) -> tuple[dict[str, Estimate], list[tuple[str, StepFigures]]]:
    """The declared figures: per size the mean over its steps (Type A: their scatter)."""
    steps = [s for recording, exc in runs for s in step_results(recording, exc, spec)]
    tick_ms = 1e3 / spec.fs_hz
    out: dict[str, Estimate] = {}
    for size in SIZES:
        mine = [f for s, f in steps if s == size]
        out[f"step_rise_time_{size}_ms"] = mean_estimate(
            f"step_rise_time_{size}_ms", [1e3 * f.rise_time_s for f in mine], "ms",
            resolution=tick_ms)
        out[f"step_overshoot_{size}_pct"] = mean_estimate(
            f"step_overshoot_{size}_pct", [f.overshoot_pct for f in mine], "%")
        out[f"step_settling_time_{size}_ms"] = mean_estimate(
            f"step_settling_time_{size}_ms", [1e3 * f.settling_time_s for f in mine], "ms",
            resolution=tick_ms)
    out["step_steady_state_error_pct"] = mean_estimate(
        "step_steady_state_error_pct", [f.steady_state_error_pct for _, f in steps], "%")
    return out, steps


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return excitation(Spec.from_profile(profile, info), position_rad=at())


@dataclass(frozen=True, slots=True, kw_only=True)
class SizedStep(StepFigures):
    """One step's figures and its size (``small``, ``large``)."""

    size: str


@dataclass(frozen=True, slots=True, kw_only=True)
class VelocityStepDetails(RunDetails):
    """The certificate's details: how the velocity was taken, every step's figures."""

    velocity: str
    steps: tuple[SizedStep, ...]
    smooth_s: float  # for the plot: the velocity as analysed


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=VelocityStepDetails)
