"""inertia_elevation: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_inertia_elevation.py``.

Azimuth inertia across elevation: the J/B/T_c sine at several elevations of the other axis,
then ``J(el) = J_zenith + ΔJ·cos²(el) + P·sin(2el)`` (numerics in
:mod:`hil.identify.inertia_elevation`): J level and at the zenith, the elevation stage's
product of inertia P, and the largest over the smallest J on the elevation axis's travel
(``travel_rad``, default a half turn): the ratio a fixed velocity-loop gain meets.

Skips without a ``[protocols.inertia_elevation]`` table (not an azimuth axis) and on a
station whose drive cannot move the elevation axis (``drive.set_elevation``). When the
torque-constant protocol ran first, J is scaled by its reported-torque gain (shaft torque
over reported torque): the result is in shaft-torque units.

The sines run at ``centre_rad`` when the table gives it (else where the previous protocol
left the axis): J's misfit to the sine model depends on the stretch of travel (cogging and
K_t ripple there; on the azimuth demo J's Type A is 2–11 × 10⁻⁶ kg·m² from one stretch to
the next), so the stretch is stated rather than inherited.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace

from hil.beside import Beside
from hil.calibration import CalibrationRun
from hil.config import ConfigTable
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.inertia_elevation import HALF_TURN_RAD, scale_by_gain
from hil.identify.position_torque import PositionTorque
from hil.identify.two_mass import ShaftModes
from hil.motion import Excitation
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite import inertia_friction as sine
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.shaft_input import SHAFT, shaft_input
from hil.suite.stop_rule import StopRule
from hil.suite.travel import move_speed_rad_s

NAME = "inertia_elevation"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = (
    "azimuth_inertia_level_kg_m2",
    "azimuth_inertia_zenith_kg_m2",
    "azimuth_inertia_product_kg_m2",
    "azimuth_inertia_ratio",
)
#: what it takes from earlier protocols (:mod:`hil.suite.needs`): the K_t protocol's gain,
#: and what the sine analysis takes (:data:`hil.suite.inertia_friction.SINE_NEEDS`)
GAIN = Need(protocol="torque_constant", result="reported_torque_gain_error_pct",
            without="J in reported-torque units (no shaft-torque gain applied)")
SHAFT_HERE = replace(SHAFT, without="the profile's nominal shaft modes taken out of each "
                                    "elevation's sines (rigid where it declares none)")
NEEDS: tuple[Need, ...] = (GAIN, *sine.SINE_NEEDS, SHAFT_HERE)
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = (Capability.ELEVATION_AXIS,)


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec:
    """The elevations visited and the J/B/T_c sine run at each."""

    elevations_rad: tuple[float, ...]
    park_elevation_rad: float  # where the elevation axis is left afterwards
    travel_rad: tuple[float, float]  # the elevation axis's travel: the ratio is taken over it
    sine: sine.Spec  # centre_rad: where the sines run (None: where the axis is)
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.inertia_elevation]`` table and the drive.

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
        spec = cls(
            elevations_rad=settings.numbers("elevations_rad"),
            park_elevation_rad=settings.number("park_elevation_rad", 0.0),
            travel_rad=_travel(settings),
            sine=sine.Spec(
                frequency_hz=settings.number("frequency_hz", 2.0),
                amplitudes_rad_s=settings.numbers("amplitudes_rad_s"),
                settle_periods=settings.integer("settle_periods", 2),
                periods=settings.integer("periods", 8),
                fs_hz=min(profile.sample_rate_hz, info.max_sample_rate_hz),
                centre_rad=(settings.number("centre_rad") if "centre_rad" in settings
                            else None),
                move_speed_rad_s=move_speed_rad_s(settings, info),
            ),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        return spec


def _travel(settings: ConfigTable) -> tuple[float, float]:
    """``travel_rad = [lowest, highest]`` of the elevation axis (default a half turn)."""
    if "travel_rad" not in settings:
        return HALF_TURN_RAD
    low, high = settings.numbers("travel_rad", count=2)
    if not low < high:
        raise settings.error("travel_rad", f"must be [lowest, highest], got [{low}, {high}]")
    return low, high


def motion(spec: Spec, *, position: Callable[[], float],
           set_elevation: Callable[[float], None] = lambda _: None) -> Iterator[Excitation]:
    """The protocol's motion, the one sequence the test runs and the planner sums: the move
    to the sines' centre (when the spec has one), then per elevation the J/B/T_c sines,
    named after it. ``set_elevation`` moves the station's other axis before that
    elevation's sines are yielded (not this drive's motion; the planner passes none).

    Yields
    ------
    Excitation
        At most one position-mode move, then the velocity sines of each elevation.
    """
    if spec.sine.centre_rad is not None:
        yield sine.move_to_centre(spec.sine, spec.sine.centre_rad, position_rad=position())
    for elevation in spec.elevations_rad:
        set_elevation(elevation)
        for e in sine.excitation(spec.sine):
            yield replace(e, name=f"{e.name}_el{elevation:+.2f}rad")


def reported_torque_gain(calibration: CalibrationRun) -> tuple[float, float] | None:
    """Shaft over reported torque (and its standard uncertainty) from the K_t protocol.

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress (earlier results).

    Returns
    -------
    tuple of (float, float) or None
        ``(gain, u(gain))`` from ``reported_torque_gain_error_pct``, or ``None`` when the
        torque-constant protocol has not measured it.
    """
    gain_error = GAIN.read(calibration)
    if gain_error is None:
        return None
    return 1.0 + gain_error.value / 100.0, gain_error.standard_uncertainty / 100.0


def inertia_at_elevation(
    recordings: list[Recording],
    spec: Spec,
    calibration: CalibrationRun,
    *,
    gain: tuple[float, float] | None,
    position_torque: PositionTorque | None = None,
) -> Estimate:
    """J from the sines run at one elevation, in shaft-torque units when the gain is known.

    Parameters
    ----------
    recordings : list of Recording
        One per amplitude of ``spec.sine``, run at this elevation.
    spec : Spec
        The protocol's spec.
    calibration : CalibrationRun
        The calibration in progress: earlier results the sine analysis takes out (see
        :func:`hil.suite.inertia_friction.inertia_at_earlier_inputs`).
    gain : tuple of (float, float) or None
        Shaft over reported torque and its standard uncertainty (see
        :func:`reported_torque_gain`); ``None`` leaves J in reported-torque units.
    position_torque : PositionTorque or None
        Cogging and K_t ripple to take out, if measured.

    Returns
    -------
    Estimate
        J at this elevation.

    Raises
    ------
    IdentificationError
        The sine analysis fails (see :func:`hil.suite.inertia_friction.analyse`).
    """
    inertia = sine.inertia_at_earlier_inputs(recordings, spec.sine, calibration,
                                             position_torque=position_torque)
    shaft = shaft_here(calibration, inertia_kg_m2=inertia.value)
    if shaft is not None:
        inertia = sine.inertia_at_earlier_inputs(recordings, spec.sine, calibration,
                                                 position_torque=position_torque, shaft=shaft)
    if gain is None:
        return inertia
    return scale_by_gain(inertia, gain=gain[0], gain_u=gain[1])


def shaft_here(calibration: CalibrationRun, *, inertia_kg_m2: float) -> ShaftModes | None:
    """A two-mass azimuth's shaft at this elevation: the resonance protocol's modes (measured
    where the J/B/T_c sines ran, the elevation parked) with the load this elevation's rigid
    J shows against the J/B/T_c protocol's (left rigid, the demo azimuth's population read
    J level +0.27 %, J zenith +0.18 %). ``None``: rigid, or either not measured."""
    measured = shaft_input(calibration)
    parked = calibration.result(sine.MEASUREMENTS[0])  # J, in reported-torque units too
    if measured is None or parked is None or not parked.value > 0:
        return None
    return measured.modes.with_total_inertia(inertia_kg_m2 / parked.value)


def travel_of(profile: UnitProfile) -> tuple[float, float]:
    """The elevation travel the profile's ratio is taken over (``travel_rad``)."""
    return _travel(profile.settings(NAME))


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return motion(Spec.from_profile(profile, info), position=at)


@dataclass(frozen=True, slots=True, kw_only=True)
class ElevationPoint:
    """The azimuth inertia measured at one elevation."""

    elevation_rad: float
    inertia_kg_m2: float
    standard_uncertainty: float


@dataclass(frozen=True, slots=True, kw_only=True)
class InertiaElevationDetails(RunDetails):
    """The certificate's details: the model, the travel and where J_az is extreme, each
    elevation's inertia, the torque's scale."""

    model: str
    travel_rad: tuple[float, float]
    largest_at_elevation_rad: float
    smallest_at_elevation_rad: float
    per_elevation: tuple[ElevationPoint, ...]
    torque_scale: str
    chi2_per_dof: float
    position_torque_taken_out: bool  # cogging and K_t ripple from the gravity sweep


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=InertiaElevationDetails,
                    beside=Beside(moves_other=True))  # the elevation to each angle
