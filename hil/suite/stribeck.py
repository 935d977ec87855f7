"""stribeck: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_stribeck.py``.

Stribeck friction (T_s, v_s) from a slow constant-velocity staircase in both directions.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from hil.calibration import CalibrationRun
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.estimate import Component, Estimate
from hil.identify.stribeck import Staircase, StribeckResult, identify_stribeck, staircase
from hil.identify.torque_constant import ripple_factors
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec

log = logging.getLogger(__name__)


NAME = "stribeck"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = ("static_friction_nm", "stribeck_velocity_rad_s")


# the sine protocol's results that this one cross-checks: (its name, ours)
CROSS_CHECK = (
    ("coulomb_nm", "stribeck_coulomb_nm"),
    ("viscous_nm_s_rad", "stribeck_viscous_nm_s_rad"),
)
#: what it takes from earlier protocols (:mod:`hil.suite.needs`)
RIPPLE = Need(protocol="cogging", result="kt_ripple",
              without="no K_t ripple correction of the staircase's torque")
CABLE = Need(protocol="gravity_cable", result="cable_hysteresis_nm",
             without="T_s still holds the cable loop's half-width (steady sliding drags "
                     "the loop along), and the sines' T_c is cross-checked without it")
CABLE_LINE = "cable loop's half-width h taken out (gravity_cable)"
NEEDS: tuple[Need, ...] = (
    RIPPLE, CABLE,
    *(Need(protocol="inertia_friction", result=other, without=f"no cross-check of {other}")
      for other, _ in CROSS_CHECK),
)
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """A slow velocity staircase up and down, centred in the travel."""

    speeds_rad_s: tuple[float, ...]
    step_travel_rad: float
    settle_s: float
    turnaround_rad: float
    turnaround_speed_rad_s: float
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.stribeck]`` table and the drive.

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
            **TravelSpec.envelope(settings, profile, info),
            speeds_rad_s=settings.numbers("speeds_rad_s"),
            step_travel_rad=settings.number("step_travel_rad", 0.03),
            settle_s=settings.number("settle_s", 0.3),
            turnaround_rad=settings.number("turnaround_rad", 0.08),
            turnaround_speed_rad_s=settings.number("turnaround_speed_rad_s", 0.1),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        return spec

    @property
    def stairs(self) -> Staircase:
        """The staircase's command and steps (see :func:`hil.identify.stribeck.staircase`)."""
        return staircase(
            self.speeds_rad_s,
            fs_hz=self.fs_hz,
            step_travel_rad=self.step_travel_rad,
            settle_s=self.settle_s,
            turnaround_rad=self.turnaround_rad,
            turnaround_speed_rad_s=self.turnaround_speed_rad_s,
        )

    @property
    def start_rad(self) -> float:
        """Start so that the staircase and its turnaround are centred in the travel.

        Raises
        ------
        ValueError
            The staircase and its turnaround need more than 90 % of the travel.
        """
        stairs = self.stairs
        extent = stairs.travel_rad + 2 * stairs.turnaround_rad  # run-in and turnaround
        middle = (self.travel_min_rad + self.travel_max_rad) / 2
        if extent > 0.9 * (self.travel_max_rad - self.travel_min_rad):
            raise ValueError(f"staircase needs {extent:.3g} rad, more than 90 % of the travel")
        return middle - extent / 2


def excitation(spec: Spec, *, position_rad: float) -> list[Excitation]:
    """A position move from ``position_rad`` to the start, then the velocity staircase.

    Parameters
    ----------
    spec : Spec
        The protocol's spec.
    position_rad : float
        Where the axis is now.

    Returns
    -------
    list of Excitation
        The move to :attr:`Spec.start_rad`, then the staircase (velocity mode).
    """
    return [
        spec.move_to_start(position_rad, hold_s=0.2),
        Excitation(
            name="staircase",
            mode=Mode.VELOCITY,
            fs_hz=spec.fs_hz,
            command=spec.stairs.command_rad_s,
        ),
    ]


def analyse(
    time_s: np.ndarray, position_rad: np.ndarray, torque_nm: np.ndarray, spec: Spec,
    *, ripple: Sequence[tuple[int, float, float]] = (),
) -> StribeckResult:
    """T_s, v_s (and T_c, B) from the staircase's steady steps.

    The slow steps cover a few hundredths of a radian, so the K_t ripple there does not
    average out: the reported torque (nominal K_t × current) is off by the ripple at that
    stretch, a bounded error set by the ripple's phase (over simulated units it carried
    97 % of the static friction's error). With the cogging protocol's ripple table the
    torque is first put back into the motor's torque.

    Parameters
    ----------
    time_s, position_rad, torque_nm : ndarray
        The staircase's recording on the command grid (see
        :func:`hil.suite.travel.on_command_grid`).
    spec : Spec
        The protocol's spec (staircase, settling).
    ripple : sequence of (int, float, float)
        K_t ripple harmonics ``(order, relative amplitude, phase_rad)``
        (:func:`hil.suite.torque_constant.kt_ripple_from_cogging`); empty: none known.

    Returns
    -------
    StribeckResult
        See :func:`hil.identify.stribeck.identify_stribeck`.

    Raises
    ------
    IdentificationError
        The recording is shorter than the staircase.
    """
    return identify_stribeck(
        time_s=time_s,
        position_rad=position_rad,
        torque_nm=torque_nm * ripple_factors(position_rad, ripple) if ripple else torque_nm,
        stairs=spec.stairs,
        settle_s=spec.settle_s,
    )


def without_cable_loop(static: Estimate, loop: Estimate | None) -> Estimate:
    """T_s less the cable loop's half-width ``h`` (``None``: not measured, T_s as found).

    In steady sliding the cable's hysteresis loop is dragged along at its half-width, in
    the direction of motion like friction: the staircase's half difference of the two
    directions is ``T_s + h`` (and ``T_c + h``; ``v_s`` is unchanged). The certificate's
    static friction is the friction: ``h`` comes out, its uncertainty a Type B line (an
    earlier protocol's result, measured again in each calibration)."""
    if loop is None:
        return static
    return static.with_components(
        Component(source=CABLE_LINE, kind="B", standard_uncertainty=loop.standard_uncertainty,
                  unit=static.unit, sensitivity=-1.0, dof=loop.dof),
        value=static.value - loop.value)


def finite_or_none(value: float) -> float | None:
    """JSON has no NaN or infinity: a stick-slip speed has no friction value.

    Parameters
    ----------
    value : float
        A friction value or its uncertainty.

    Returns
    -------
    float or None
        ``value`` if finite, else ``None``.
    """
    return value if math.isfinite(value) else None


def cross_check(result: StribeckResult, calibration: CalibrationRun) -> dict[str, CrossCheck]:
    """Compare T_c and B with the sine protocol's, when it ran: normalised error
    ``|Δ| / √(U₁² + U₂²)`` (≤ 1: consistent within the expanded uncertainties). The sine's
    T_c excludes the cable loop's half-width h (taken out there), the staircase's sliding
    friction includes it: when h was measured it is added to the sine's side.

    Parameters
    ----------
    result : StribeckResult
        This protocol's result.
    calibration : CalibrationRun
        The calibration in progress (earlier results); a normalised error above 1 is
        logged as a warning.

    Returns
    -------
    dict of str to CrossCheck
        Per sine result measured (``coulomb_nm``, ``viscous_nm_s_rad``): the staircase's
        value, the sine's and the normalised error; empty when the sine did not run.
    """
    ours = {e.name: e for e in (result.coulomb, result.viscous)}
    loop = CABLE.read(calibration)
    checks: dict[str, CrossCheck] = {}
    for other, mine in CROSS_CHECK:
        b = calibration.result(other)
        if b is None:
            continue
        a = ours[mine]
        b_value, b_expanded = b.value, b.expanded_uncertainty
        if other == "coulomb_nm" and loop is not None:
            b_value += loop.value
            b_expanded = float(np.hypot(b_expanded, loop.expanded_uncertainty))
        expanded = float(np.hypot(a.expanded_uncertainty, b_expanded))
        error = abs(a.value - b_value) / expanded
        checks[other] = CrossCheck(stribeck=a.value, sine=b_value, normalised_error=error)
        if error > 1:
            log.warning(
                "%s: staircase %.4g vs sine %.4g differ by %.1f expanded uncertainties",
                other,
                a.value,
                b_value,
                error,
            )
    return checks


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return excitation(Spec.from_profile(profile, info), position_rad=at())


@dataclass(frozen=True, slots=True, kw_only=True)
class FrictionPoint:
    """One staircase speed's steady friction (``None``: not finite there)."""

    speed_rad_s: float
    friction_nm: float | None
    friction_u_nm: float | None
    stick_slip: bool


@dataclass(frozen=True, slots=True, kw_only=True)
class CrossCheck:
    """The staircase's value against the sine protocol's, and ``|Δ|/√(U₁² + U₂²)``."""

    stribeck: float
    sine: float
    normalised_error: float


@dataclass(frozen=True, slots=True, kw_only=True)
class StribeckDetails(RunDetails):
    """The certificate's details: the fit, each speed's friction, the cross-check with the
    sine protocol, and what the sliding friction holds."""

    recorded_rows: int
    coulomb_nm: float
    viscous_nm_s_rad: float
    residual_rms_nm: float
    kt_ripple_correction: str
    lowest_clean_speed_rad_s: float
    stick_slip_speeds_rad_s: tuple[float, ...]
    points: tuple[FrictionPoint, ...]
    cross_check_sine: dict[str, CrossCheck]
    note: str


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=StribeckDetails)
