"""tracking: the protocol's library (spec, excitation, analysis); the test and its declared
measurements are in ``protocols/test_tracking.py``.

The standard gimbal move (slew, constant-rate track, reversal) without and with the
certificate's friction feedforward ``B·ω* + T_c·sgn(ω*)`` sent as the drive's torque
offset (CiA 402 0x60B2; a drive adds it only when its firmware has ``feedforward``), the
pair ``repeats`` times (the runs' scatter is the Type A: see :mod:`hil.closed_loop.tracking`).
RMS and peak following error, and the reduction (RMS without / with). Each run starts at
rest at the same place with the drive just re-enabled (its velocity integrator empty): in
velocity mode the position error is the integrator's change over ``Ki``, so a run that
inherited a holding torque from the move before it would carry that offset all along.
Numerics in :mod:`hil.closed_loop.tracking`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from hil.calibration import CalibrationRun
from hil.closed_loop.tracking import (
    Repeated,
    as_estimate,
    feedforward_change,
    following_error,
    friction_feedforward,
    gimbal_move,
    reduction,
    repeated,
)
from hil.details import RunDetails
from hil.drives.base import Capability, Drive, DriveInfo
from hil.identify.estimate import Component, Estimate
from hil.identify.quantisation import quantisation_step
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec, on_command_grid, runs_from_start

NAME = "tracking"
FEEDFORWARD_LINE = "the feedforward's B and T_c"  # shared by repeated runs (stop_rule)
MEASUREMENTS = ("tracking_rms_error_urad", "tracking_peak_error_urad",
                "tracking_rms_error_no_ff_urad", "tracking_ff_reduction")
#: what it takes from earlier protocols (:mod:`hil.suite.needs`)
NEEDS: tuple[Need, ...] = tuple(
    Need(protocol="inertia_friction", result=name,
         without="the declared nominal B and T_c as the feedforward")
    for name in ("viscous_nm_s_rad", "coulomb_nm"))
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()
MICRO = 1e6


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """The move's rates and durations."""

    slew_rad_s: float
    track_rad_s: float
    ramp_s: float
    slew_s: float
    track_s: float
    reversal_s: float
    min_sample_rate_hz: float  # the offset follows ω* sample by sample (not a polled link)
    repeats: int  # runs of the pair (without, with): their scatter is the Type A
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from ``[protocols.tracking]`` and the drive.

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key; a move past the travel limits.
        """
        settings = profile.settings(NAME)
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            slew_rad_s=settings.positive("slew_rad_s", 1.5),
            track_rad_s=settings.positive("track_rad_s", 0.2),
            ramp_s=settings.positive("ramp_s", 0.15),
            slew_s=settings.positive("slew_s", 0.3),
            track_s=settings.positive("track_s", 0.5),
            reversal_s=settings.positive("reversal_s", 0.5),
            min_sample_rate_hz=settings.positive("min_sample_rate_hz", 1000.0),
            repeats=settings.integer("repeats", 3),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        if spec.repeats < 2:
            raise settings.error("repeats", "must be at least 2 (the Type A is the scatter of "
                                            f"the repeated runs), not {spec.repeats}")
        spec.require_travel(float(np.sum(spec.command())) / spec.fs_hz, protocol=NAME,
                            source=profile.source)
        return spec

    def command(self) -> np.ndarray:
        """The standard move's velocity command (rad/s)."""
        return gimbal_move(slew_rad_s=self.slew_rad_s, track_rad_s=self.track_rad_s,
                           ramp_s=self.ramp_s, slew_s=self.slew_s, track_s=self.track_s,
                           reversal_s=self.reversal_s, fs_hz=self.fs_hz)


def feedforward_values(calibration: CalibrationRun, profile: UnitProfile, spec: Spec
                       ) -> tuple[float, float, float, str]:
    """``(B, T_c, u_rel, source)``: this calibration's results, else the declared nominals.

    ``u_rel`` is the feedforward's relative standard uncertainty over the move, the two
    terms weighted by their RMS over it: ``√((T_c·u_r(T_c))² + (B·ω*_rms·u_r(B))²) /
    √(T_c² + (B·ω*_rms)²)`` (0 for declared nominals: no measurement, nothing propagated).
    """
    found = calibration.results(*(need.result for need in NEEDS))
    if found is None:
        return (profile.measurement("viscous_nm_s_rad").nominal,
                profile.measurement("coulomb_nm").nominal, 0.0, "declared nominals")
    viscous, coulomb = found
    w_rms = float(np.sqrt(np.mean(spec.command() ** 2)))
    b_part, c_part = viscous.value * w_rms, coulomb.value
    u_rel = math.hypot(b_part * viscous.relative_uncertainty,
                       c_part * coulomb.relative_uncertainty) / math.hypot(b_part, c_part)
    return viscous.value, coulomb.value, u_rel, "measured (inertia_friction)"


def excitation(spec: Spec, *, viscous_nm_s_rad: float, coulomb_nm: float
               ) -> tuple[Excitation, Excitation]:
    """The move without and with the feedforward (each run from :attr:`Spec.start_rad`,
    reached by ``spec.move_to_start`` from wherever the axis is)."""
    command = spec.command()
    offset = friction_feedforward(command, viscous_nm_s_rad=viscous_nm_s_rad,
                                  coulomb_nm=coulomb_nm)
    return (Excitation(name="move_no_ff", mode=Mode.VELOCITY, fs_hz=spec.fs_hz,
                       command=command),
            Excitation(name="move_ff", mode=Mode.VELOCITY, fs_hz=spec.fs_hz, command=command,
                       torque_offset_nm=offset))


def motion(spec: Spec, runs: tuple[Excitation, Excitation], *,
           position: Callable[[], float]) -> Iterator[Excitation]:
    """The protocol's motion, the one sequence the test runs and the planner sums: the pair
    ``runs`` (:func:`excitation`: without, then with the feedforward) ``spec.repeats`` times,
    each run after a move to :attr:`Spec.start_rad` from ``position()`` (the drive is
    re-enabled between them); repeats after the first are named ``<name>_<k>``."""
    return runs_from_start(spec, (dataclasses.replace(run, name=repeat_name(run.name, k))
                                  for k in range(1, spec.repeats + 1) for run in runs),
                           position=position)


def run_motion(spec: Spec, runs: tuple[Excitation, Excitation], *, drive: Drive,
               run: Callable[[Excitation], Recording]) -> list[tuple[Recording, Excitation]]:
    """Run :func:`motion` on ``drive`` through ``run`` (the drive's, or the calibration's
    that keeps the recording), the drive re-enabled after each move so that each run's
    velocity integrator starts empty; the runs' recordings with their excitations, in
    order (without, with the feedforward, repeated)."""
    recorded = []
    for e in motion(spec, runs, position=lambda: drive.status().position_rad):
        if e.mode is Mode.POSITION:
            run(e)
            drive.disable()
            drive.enable()
            continue
        recorded.append((run(e), e))
    return recorded


def repeat_name(name: str, repeat: int) -> str:
    """The excitation's name in its ``repeat``-th run (1: the name itself)."""
    return name if repeat == 1 else f"{name}_{repeat}"


def analyse(off: list[tuple[Recording, Excitation]], on: list[tuple[Recording, Excitation]],
            spec: Spec, *, feedforward_u_rel: float = 0.0
            ) -> tuple[dict[str, Estimate], Repeated, Repeated]:
    """The declared figures from the repeated runs without (``off``) and with (``on``) the
    feedforward; ``feedforward_u_rel`` (the feedforward's relative uncertainty, see
    :func:`feedforward_values`) adds a Type A line to the figures with feedforward, its
    size by superposition of the two (:func:`~hil.closed_loop.tracking.feedforward_change`)."""
    lsb = quantisation_step(on[0][0].position)  # the encoder's resolution, as recorded
    f_off, f_on = (repeated([following_error(on_command_grid(rec, exc)[0], exc.command,
                                             fs_hz=spec.fs_hz) for rec, exc in runs])
                   for runs in (off, on))
    per_sample = lsb / math.sqrt(12)

    def est(name: str, value: float, u: float, dof: float, resolution: float) -> Estimate:
        return as_estimate(name, value, u, scale=MICRO, unit="µrad", dof=dof,
                           resolution_rad=resolution)

    rms_resolution = per_sample / math.sqrt(len(f_on.error_rad) * f_on.runs)
    rms_on = est("tracking_rms_error_urad", f_on.rms_rad, f_on.u_rms_rad, f_on.dof,
                 rms_resolution)
    peak_on = est("tracking_peak_error_urad", f_on.peak_rad, f_on.u_peak_rad, f_on.dof,
                  per_sample / math.sqrt(f_on.runs))
    if feedforward_u_rel > 0:
        d_rms, d_peak = feedforward_change(f_off, f_on, relative=feedforward_u_rel)
        lines = [Component(source=f"{FEEDFORWARD_LINE} (this calibration's u), by "
                                  "superposition of the runs without and with it (Type A)",
                           kind="A", standard_uncertainty=abs(change) * MICRO, unit="µrad")
                 for change in (d_rms, d_peak)]
        rms_on = rms_on.with_components(lines[0])
        peak_on = peak_on.with_components(lines[1])
    rms_off = est("tracking_rms_error_no_ff_urad", f_off.rms_rad, f_off.u_rms_rad, f_off.dof,
                  rms_resolution)
    out = {
        "tracking_rms_error_urad": rms_on,
        "tracking_peak_error_urad": peak_on,
        "tracking_rms_error_no_ff_urad": rms_off,
        "tracking_ff_reduction": reduction(rms_off, rms_on, name="tracking_ff_reduction"),
    }
    return out, f_off, f_on


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    spec = Spec.from_profile(profile, info)
    # the feedforward's size (known only after inertia_friction) does not change the time
    return motion(spec, excitation(spec, viscous_nm_s_rad=0.0, coulomb_nm=0.0), position=at)


@dataclass(frozen=True, slots=True, kw_only=True)
class Feedforward:
    """The friction feedforward the move sent, and where its values came from."""

    viscous_nm_s_rad: float
    coulomb_nm: float
    relative_uncertainty: float
    source: str
    sent_as: str


@dataclass(frozen=True, slots=True, kw_only=True)
class RunToRun:
    """The run-to-run standard deviation of the RMS error (µrad), without and with it."""

    no_ff: float
    ff: float


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackingDetails(RunDetails):
    """The certificate's details: the feedforward, the repeats and their spread."""

    feedforward: Feedforward
    repeats: int
    run_to_run_sd_urad: RunToRun
    peak_error_no_ff_urad: float
    move_s: float


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=TrackingDetails)
