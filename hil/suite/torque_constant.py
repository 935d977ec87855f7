"""torque_constant: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_torque_constant.py``.

K_t from a locked rotor and the shaft torque sensor: current swept up and down at several
locked angles (numerics in :mod:`hil.identify.torque_constant`).

Needs a station with a shaft torque sensor and a locked-rotor fixture the harness can
engage (``drive.locked_rotor()``): :data:`REQUIRES`; skipped otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hil.beside import Beside
from hil.calibration import CalibrationRun
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.estimate import Component, Estimate
from hil.identify.torque_constant import (
    LockedSweep,
    TorqueConstantResult,
    analyse_locked_sweep,
    balanced_angles,
    datasheet_deviation,
)
from hil.measurement import WITHOUT_POSITION_TORQUE
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.cogging import CoggingDetails
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import move_excitation, move_speed_rad_s, values_on_command_grid

NAME = "torque_constant"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = (
    "torque_constant_nm_a",
    "torque_linearity_pct",
    "reported_torque_gain_error_pct",
    "torque_constant_vs_datasheet_pct",
)
#: what it takes from earlier protocols (:mod:`hil.suite.needs`)
RIPPLE = Need(protocol="cogging", result="kt_ripple",
              without="locked at the configured angles, no K_t ripple correction")
NEEDS: tuple[Need, ...] = (RIPPLE,)
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = (Capability.TORQUE_SENSOR, Capability.LOCKED_ROTOR)


#: samples averaged per level at least, and discarded at its start at least: over a link
#: polled at 100 Hz ``level_s`` alone left 4 samples a level, and the shaft torque, read
#: beside the drive's rows, a row's placement away from its level's start
MIN_LEVEL_SAMPLES = 20
MIN_SETTLE_SAMPLES = 3


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec:
    """Locked-rotor torque staircases, one per locked angle."""

    angles_rad: tuple[float, ...]
    peak_torque_nm: float
    levels: int  # per direction
    level_s: float
    settle_s: float
    move_speed_rad_s: float
    fs_hz: float
    kv_rpm_per_v: float | None
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)
    sensor: str = ""  # the shaft torque sensor and its calibration (DriveInfo.torque_sensor)
    sensor_relative_u: float = 0.0  # u of its sensitivity, relative (a Type B line)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.torque_constant]`` table and the drive.

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
        kv = profile.unit.get("kv_rpm_per_v")
        limit = min(info.limits.torque_nm, info.rated_torque_nm)
        spec = cls(
            angles_rad=settings.numbers("angles_rad"),
            peak_torque_nm=settings.number("peak_torque_fraction", 0.8) * limit,
            levels=settings.integer("levels", 9),
            level_s=settings.number("level_s", 0.05),
            settle_s=settings.number("settle_s", 0.01),
            move_speed_rad_s=move_speed_rad_s(settings, info),
            fs_hz=min(profile.sample_rate_hz, info.max_sample_rate_hz),
            kv_rpm_per_v=None if kv is None else float(kv),
            stop=StopRule.from_settings(settings),
            sensor=info.torque_sensor,
            sensor_relative_u=info.torque_sensor_relative_u,
        )
        settings.done()
        return spec

    @property
    def level_samples(self) -> int:
        """Samples per torque level: ``level_s``, and at least :data:`MIN_LEVEL_SAMPLES`
        beyond the settling (a slow polled link stretches each level in time)."""
        return max(round(self.level_s * self.fs_hz), self.settle_samples + MIN_LEVEL_SAMPLES)

    @property
    def settle_samples(self) -> int:
        """Samples discarded at the start of each level (and of the closing zero level)."""
        return max(math.ceil(self.settle_s * self.fs_hz), MIN_SETTLE_SAMPLES)

    @property
    def torque_levels_nm(self) -> np.ndarray:
        """Up from −peak to +peak, then back down: both directions at every level."""
        up = np.linspace(-self.peak_torque_nm, self.peak_torque_nm, self.levels)
        return np.concatenate([up, up[::-1]])


def move(spec: Spec, *, position_rad: float, angle_rad: float) -> Excitation:
    """The position move from ``position_rad`` to a locked angle, then a 0.1 s hold.

    Parameters
    ----------
    spec : Spec
        The protocol's spec (rate, move speed).
    position_rad : float
        Where the axis is now.
    angle_rad : float
        The angle the rotor is locked at next.

    Returns
    -------
    Excitation
        A position-mode excitation.
    """
    return move_excitation(
        f"move_to_{angle_rad:+.3f}rad",
        position_rad,
        angle_rad,
        fs_hz=spec.fs_hz,
        speed_rad_s=spec.move_speed_rad_s,
        hold_s=0.1,
    )


def locked_angles(spec: Spec, ripple: Sequence[tuple[int, float, float]]) -> tuple[float, ...]:
    """The angles the rotor is locked at: the configured ones, nudged so the largest
    measured K_t ripple harmonic averages out (:func:`balanced_angles`; as configured
    without a ripple table)."""
    return balanced_angles(spec.angles_rad, ripple)


def motion(spec: Spec, *, angles_rad: Sequence[float],
           position: Callable[[], float]) -> Iterator[Excitation]:
    """The protocol's motion, the one sequence the test runs and the planner sums: per
    locked angle, the move there (from ``position()``, read when the move is built) and
    the torque staircase (torque mode, run with the rotor locked).

    Parameters
    ----------
    spec : Spec
        The protocol's spec.
    angles_rad : sequence of float
        The locked angles (:func:`locked_angles`).
    position : callable
        Where the axis is now: the drive's position when run, the plan's when planned.

    Yields
    ------
    Excitation
        Move (position mode), sweep (torque mode), in that order per angle.
    """
    for angle in angles_rad:
        yield move(spec, position_rad=position(), angle_rad=angle)
        yield sweep(spec, angle_rad=angle)


def sweep(spec: Spec, *, angle_rad: float) -> Excitation:
    """Torque staircase for a locked rotor, ending with a short zero level (not analysed).

    Parameters
    ----------
    spec : Spec
        The protocol's spec (levels, durations).
    angle_rad : float
        The locked angle (names the excitation).

    Returns
    -------
    Excitation
        A torque-mode excitation: :attr:`Spec.torque_levels_nm` held ``level_samples``
        each, then ``settle_samples`` of zero.
    """
    command = np.concatenate(
        [np.repeat(spec.torque_levels_nm, spec.level_samples), np.zeros(spec.settle_samples)]
    )
    return Excitation(
        name=f"locked_sweep_{angle_rad:+.3f}rad",
        mode=Mode.TORQUE,
        fs_hz=spec.fs_hz,
        command=command,
    )


def analyse_sweep(recording: Recording, spec: Spec, *, angle_rad: float,
                  excitation: Excitation) -> LockedSweep:
    """Level means of current, shaft and reported torque, and their lines, of one sweep.

    Parameters
    ----------
    recording : Recording
        The locked sweep's recording (with ``current_a`` and ``load_torque_nm``).
    spec : Spec
        The protocol's spec (levels, durations).
    angle_rad : float
        The locked angle.
    excitation : Excitation
        The sweep run: a polled drive's rows are put on its command grid first.

    Returns
    -------
    LockedSweep
        See :func:`hil.identify.torque_constant.analyse_locked_sweep`.

    Raises
    ------
    KeyError
        The recording lacks the current or the shaft torque column.
    IdentificationError
        Fewer than 4 levels of different current, or a recording shorter than the sweep.
    """
    columns = recording.columns
    current, shaft, reported = (
        values_on_command_grid(recording, excitation, values)
        for values in (columns["current_a"], columns["load_torque_nm"], recording.effort))
    return analyse_locked_sweep(
        current,
        shaft,
        reported,
        angle_rad=angle_rad,
        level_samples=spec.level_samples,
        settle_samples=spec.settle_samples,
        levels=spec.torque_levels_nm.size,
    )


def estimates(result: TorqueConstantResult, spec: Spec) -> dict[str, Estimate]:
    """The protocol's declared measurements by name.

    Parameters
    ----------
    result : TorqueConstantResult
        K_t, linearity and reported-torque gain error.
    spec : Spec
        The protocol's spec: its ``kv_rpm_per_v`` adds the datasheet deviation.

    Returns
    -------
    dict of str to Estimate
        ``torque_constant_nm_a``, ``torque_linearity_pct``,
        ``reported_torque_gain_error_pct`` and, when the datasheet KV is known,
        ``torque_constant_vs_datasheet_pct``.
    """
    kt, gain = result.torque_constant, result.gain_error
    if spec.sensor_relative_u > 0:  # the sensor's sensitivity scales both
        source = f"shaft torque sensor's sensitivity: {spec.sensor}"
        line = Component(source=source, kind="B", standard_uncertainty=spec.sensor_relative_u,
                         unit="1", sensitivity=kt.value)
        kt = kt.with_components(line)
        gain = gain.with_components(Component(
            source=source, kind="B", standard_uncertainty=spec.sensor_relative_u, unit="1",
            sensitivity=100.0 + gain.value))
    found = {e.name: e for e in (kt, result.linearity, gain)}
    if spec.kv_rpm_per_v is not None:
        found["torque_constant_vs_datasheet_pct"] = datasheet_deviation(
            kt, kv_rpm_per_v=spec.kv_rpm_per_v
        )
    return found


def kt_ripple_from_cogging(calibration: CalibrationRun) -> list[tuple[int, float, float]]:
    """The cogging protocol's K_t ripple table, if it ran earlier in this calibration.

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress; the cogging protocol leaves its table in its
        details (:class:`hil.suite.cogging.CoggingDetails`).

    Returns
    -------
    list of (int, float, float)
        ``(order, amplitude, phase_rad)`` per harmonic of
        ``K_t(θ) = K_t·(1 + Σ a_n·sin(n·θ + ψ_n))``; empty when cogging did not run.
    """
    cogging = calibration.details.get(RIPPLE.protocol)
    if not isinstance(cogging, CoggingDetails):
        return []
    return [(h.order, h.amplitude, h.phase_rad) for h in cogging.kt_ripple]


def ripple_variant(calibration: CalibrationRun) -> str | None:
    """The method line's variant of a protocol that takes the cogging protocol's K_t ripple
    table out: the main line with the table, the wider one
    (:data:`hil.measurement.WITHOUT_POSITION_TORQUE`) without it."""
    return None if kt_ripple_from_cogging(calibration) else WITHOUT_POSITION_TORQUE


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    spec = Spec.from_profile(profile, info)
    # the cogging protocol's ripple table nudges the angles when the run gets there: not
    # known before, planned as configured (the moves differ by the nudges only)
    return motion(spec, angles_rad=locked_angles(spec, ()), position=at)


@dataclass(frozen=True, slots=True, kw_only=True)
class LockedAngle:
    """One locked angle's current sweep: shaft torque against current."""

    angle_rad: float
    slope_nm_a: float
    intercept_nm: float
    gain: float
    max_residual_nm: float


@dataclass(frozen=True, slots=True, kw_only=True)
class TorqueConstantDetails(RunDetails):
    """The certificate's details: the ripple correction, the angles, each sweep."""

    kt_ripple_correction: str
    angles: str
    per_angle: tuple[LockedAngle, ...]
    datasheet_torque_constant_nm_a: float | None


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=TorqueConstantDetails,
                    beside=Beside(still=True))  # the rotor clamped: nothing moves
