"""cogging: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_cogging.py``.

Cogging torque and K_t(θ) ripple from constant-velocity passes up and down the travel.

The two directions are the two torque levels (``L̄ + F`` and ``L̄ − F``): cogging is the
same in both, K_t ripple scales with the torque. A compensation table (JSON, format in
:mod:`hil.identify.cogging`) is written next to the certificate.

With ``passes = "gravity_cable"`` the protocol moves nothing: its two passes are the
gravity sweep's up and down passes (constant velocity over the same travel, read back from
that protocol's raw recording), so one motion serves both identifications. The sweep's
slower speed gives each pass more samples, and the ripple's orders reach the velocity loop
at lower frequencies, where it rejects them less (the acceleration correction is smaller).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from hil.calibration import CalibrationRun
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.errors import IdentificationError
from hil.identify.cogging import CoggingResult, identify_cogging
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import read_recording
from hil.suite import gravity_cable
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.rate import needed_sample_rate_hz
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec, on_command_grid

NAME = "cogging"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = ("cogging_peak_nm", "kt_ripple_peak_pct")
#: what it takes from earlier protocols (:mod:`hil.suite.needs`); with passes =
#: "gravity_cable" it also reads that sweep, refused without it (:func:`sweep_passes`)
INERTIA = Need(protocol="inertia_friction", result="inertia_kg_m2",
               without="the declared nominal J for the acceleration correction (none "
                       "when the profile declares no J)")
NEEDS: tuple[Need, ...] = (INERTIA,)
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()


COMPENSATION_FILE = "cogging_compensation.json"


# Below this the demo unit's 0.4 mN·m cogging sinks under the detection floor
# (hil.identify.cogging.PROMINENCE) at its reported-torque noise: 399 samples a pass over
# Modbus (100 Hz) found nothing; the 4 kHz sim (16 000–38 000 a pass) finds it at 300–700×
# the floor in power (the ratio grows with the samples N).
MIN_SAMPLES_PER_PASS = 4000

OWN_PASSES = "own"
SWEEP_PASSES = gravity_cable.NAME  # the gravity sweep's up and down passes


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """Two constant-velocity passes over the travel and the harmonic orders searched."""

    speed_rad_s: float
    skip_rad: float
    min_order: int
    max_order: int
    min_samples_per_pass: int
    passes: str  # OWN_PASSES or SWEEP_PASSES
    pass_range_rad: tuple[float, float]  # the travel a pass covers (start, stop)
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.cogging]`` table and the drive.

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
        passes = settings.choice("passes", (OWN_PASSES, SWEEP_PASSES), OWN_PASSES)
        envelope = TravelSpec.envelope(settings, profile, info)
        if passes == SWEEP_PASSES:
            if "speed_rad_s" in settings:
                raise settings.error("speed_rad_s", "is the sweep's with passes = "
                                     f"'{SWEEP_PASSES}' (set it in [protocols.{SWEEP_PASSES}])")
            StopRule.refuse(settings, f"passes = '{SWEEP_PASSES}' analyses the sweep's one "
                            "recording, and pooling it with itself is not a repeat (set "
                            f"the rule in [protocols.{SWEEP_PASSES}], or passes = '{OWN_PASSES}')")
            sweep = gravity_cable.Spec.from_profile(profile, info)
            speed = sweep.speed_rad_s
            pass_range = (sweep.start_rad, sweep.stop_rad)
        else:
            speed = settings.number("speed_rad_s", 0.4)
            margin = envelope["margin_rad"]
            pass_range = (envelope["travel_min_rad"] + margin, envelope["travel_max_rad"] - margin)
        spec = cls(
            **envelope,
            speed_rad_s=speed,
            skip_rad=settings.number("skip_rad", 0.1),
            min_order=settings.integer("min_order", 10),
            max_order=settings.integer("max_order", 200),
            min_samples_per_pass=settings.integer("min_samples_per_pass", MIN_SAMPLES_PER_PASS),
            passes=passes,
            pass_range_rad=pass_range,
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        return spec

    @property
    def highest_frequency_hz(self) -> float:
        """Temporal frequency of the highest harmonic order searched, at the pass speed."""
        return self.max_order * self.speed_rad_s / (2 * math.pi)

    @property
    def pass_s(self) -> float:
        """Duration of one pass over :attr:`pass_range_rad`."""
        return (self.pass_range_rad[1] - self.pass_range_rad[0]) / self.speed_rad_s

    @property
    def needed_sample_rate_hz(self) -> float:
        """4 × the highest order's frequency, and enough samples a pass to average the
        torque noise under the cogging (the harmonic floor falls as 1/√N)."""
        return max(
            needed_sample_rate_hz(self.highest_frequency_hz),
            self.min_samples_per_pass / self.pass_s,
        )

    @property
    def pass_samples(self) -> int:
        """Command samples in one pass."""
        return round(self.pass_s * self.fs_hz)


def excitation(spec: Spec, *, position_rad: float) -> list[Excitation]:
    """Move to the lower end, then one pass up and one down at constant speed.

    Parameters
    ----------
    spec : Spec
        The protocol's spec.
    position_rad : float
        Where the axis is now.

    Returns
    -------
    list of Excitation
        The move to :attr:`Spec.start_rad`, then the passes (velocity mode); none when the
        passes are the gravity sweep's.
    """
    if spec.passes == SWEEP_PASSES:
        return []
    n = spec.pass_samples
    return [
        spec.move_to_start(position_rad, hold_s=0.2),
        Excitation(
            name="passes",
            mode=Mode.VELOCITY,
            fs_hz=spec.fs_hz,
            command=np.concatenate([np.full(n, spec.speed_rad_s), np.full(n, -spec.speed_rad_s)]),
        ),
    ]


def analyse(
    time_s: np.ndarray,
    position_rad: np.ndarray,
    torque_nm: np.ndarray,
    spec: Spec,
    *,
    inertia_kg_m2: float,
) -> CoggingResult:
    """Cogging and K_t ripple from the two passes, each with its first ``skip_rad`` dropped.

    Parameters
    ----------
    time_s, position_rad, torque_nm : ndarray
        The passes' recording on the command grid (see
        :func:`hil.suite.travel.on_command_grid`).
    spec : Spec
        The protocol's spec (pass length, skip, orders).
    inertia_kg_m2 : float
        J for the acceleration correction (see :func:`inertia_for_correction`).

    Returns
    -------
    CoggingResult
        See :func:`hil.identify.cogging.identify_cogging`.

    Raises
    ------
    IdentificationError
        No harmonic above the noise, or torque levels too close to separate ripple.
    """
    n = spec.pass_samples
    skip = math.ceil(spec.skip_rad / spec.speed_rad_s * spec.fs_hz)
    if len(position_rad) < 2 * n:
        raise IdentificationError(
            f"the cogging passes need {2 * n} samples, the recording has {len(position_rad)}")
    passes = [
        (time_s[a:b], position_rad[a:b], torque_nm[a:b]) for a, b in ((skip, n), (n + skip, 2 * n))
    ]
    return identify_cogging(
        passes, inertia_kg_m2=inertia_kg_m2, min_order=spec.min_order, max_order=spec.max_order
    )


def inertia_for_correction(calibration: CalibrationRun, profile: UnitProfile) -> tuple[float, str]:
    """Measured J if the sine protocol ran already, else the unit type's declared nominal.

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress (earlier results).
    profile : UnitProfile
        The unit's profile: the declared ``inertia_kg_m2``.

    Returns
    -------
    inertia_kg_m2 : float
        J for the acceleration correction.
    source : str
        Where it came from, for the certificate's details.

    """
    inertia = INERTIA.read(calibration)
    if inertia is not None:
        return inertia.value, "measured (inertia_friction)"
    if "inertia_kg_m2" in profile.measurements:
        return profile.measurement("inertia_kg_m2").nominal, "declared nominal"
    # a unit type that neither measures nor declares J: the passes run at constant speed,
    # only their ramps (left out of the fit's core) carry J·α
    return 0.0, "none (J neither measured nor declared: no acceleration correction)"


def sweep_passes(
    calibration: CalibrationRun, profile: UnitProfile, info: DriveInfo
) -> tuple[np.ndarray, np.ndarray, str, int]:
    """Position and torque of the gravity sweep (command grid), read back from its raw
    recording: the cogging passes when ``passes = "gravity_cable"``.

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress: the sweep's raw file.
    profile : UnitProfile
        The unit's profile (rebuilds the sweep's excitation for its command grid).
    info : DriveInfo
        The drive.

    Returns
    -------
    position_rad, torque_nm : ndarray
        The sweep from its up pass on (the up pass, then the down pass, then the rest).
    path : str
        The raw recording read, for the certificate's details: the first complete sweep
        (the gravity protocol's stop rule may have run more; this one every calibration has).
    first_sample : int
        Where the up pass begins in that recording (its run-in and reference come first).

    Raises
    ------
    IdentificationError
        The gravity protocol has not recorded a complete sweep in this calibration.
    """
    raw = [r for r in calibration.raw_files
           if r.protocol == SWEEP_PASSES and r.excitation == "sweep" and r.complete]
    if not raw:
        raise IdentificationError(
            f"[protocols.{NAME}] passes = '{SWEEP_PASSES}' needs the {SWEEP_PASSES} protocol's "
            "complete sweep earlier in this calibration (its table before this one)")
    spec = gravity_cable.Spec.from_profile(profile, info)
    sweep = gravity_cable.excitation(spec, position_rad=spec.start_rad)[-1]
    # the first sweep: the one a calibration without the gravity stop rule has too
    recording = read_recording(raw[0].path, log_warnings=False)
    position, torque, _ = on_command_grid(recording, sweep)
    first = spec.plan.up[0]
    return position[first:], torque[first:], str(raw[0].path), first


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return excitation(Spec.from_profile(profile, info), position_rad=at())


@dataclass(frozen=True, slots=True, kw_only=True)
class CoggingHarmonic:
    """One order of the cogging torque (the compensation table's line)."""

    order: int
    amplitude_nm: float
    phase_rad: float
    amplitude_u_nm: float


@dataclass(frozen=True, slots=True, kw_only=True)
class RippleHarmonic:
    """One order of the K_t ripple (relative amplitude)."""

    order: int
    amplitude: float
    phase_rad: float
    amplitude_u: float


@dataclass(frozen=True, slots=True, kw_only=True)
class CoggingDetails(RunDetails):
    """The certificate's details: the table written, where its passes came from, the
    harmonics (the K_t ripple is what the Stribeck and torque-constant protocols take)."""

    compensation_table: str  # the table's file, relative to the unit's folder
    passes: str  # the recording analysed (relative to the unit's folder), or its own
    recordings_analysed: dict[str, str]  # excitation → file (relative to the unit folder)
    pass_samples: int
    pass_first_sample: int
    speed_rad_s: float
    orders: tuple[int, ...]
    cogging: tuple[CoggingHarmonic, ...]
    kt_ripple: tuple[RippleHarmonic, ...]
    torque_levels_nm: tuple[float, ...]
    inertia_for_acceleration_correction_kg_m2: float | None
    inertia_source: str
    noise_rms_nm: float
    recorded_rows: int


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=CoggingDetails)
