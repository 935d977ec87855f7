"""Azimuth inertia across elevation: the J/B/T_c sine at several elevations of the other axis,
then ``J(el) = J_zenith + ΔJ·cos²(el) + P·sin(2el)`` (numerics in
:mod:`hil.identify.inertia_elevation`).

Skips without a ``[protocols.inertia_elevation]`` table (not an azimuth axis) and on a
station without an elevation axis the harness can move (``REQUIRES``). When the
torque-constant protocol ran first, J is scaled by its reported-torque gain (shaft torque
over reported torque): the result is in shaft-torque units.

Library: :mod:`hil.suite.inertia_elevation`.
"""

from __future__ import annotations

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.inertia_elevation import InertiaElevationResult, fit_inertia_elevation
from hil.measurement import WITHOUT_POSITION_TORQUE, Declared, declare
from hil.motion import Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.inertia_elevation import (
    MEASUREMENTS,
    NAME,
    NEEDS,
    REQUIRES,
    ElevationPoint,
    InertiaElevationDetails,
    Spec,
    inertia_at_elevation,
    motion,
    reported_torque_gain,
)
from hil.suite.needs import note_fallbacks
from hil.suite.position_torque import measured_position_torque
from hil.suite.stop_rule import run_repeated

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("azimuth_inertia_level_kg_m2", "Azimuth inertia, elevation level",
             "Azimuth J with the elevation axis level, from the inertia sine at several elevations"
             " and a cos² fit", non_negative=True),
    Declared("azimuth_inertia_zenith_kg_m2", "Azimuth inertia, elevation at zenith",
             "Azimuth J with the payload pointing at the zenith, from the same fit",
             non_negative=True),
    Declared("azimuth_inertia_product_kg_m2", "Elevation stage product of inertia",
             "P in J_az(el) = J_zenith + ΔJ·cos²(el) + P·sin(2el): the payload's inertia"
             " off its principal axes, which moves the extremes of J away from level and"
             " zenith"),
    Declared("azimuth_inertia_ratio", "Azimuth inertia ratio",
             "Largest over smallest azimuth J on the elevation travel: how much the inertia a "
             "fixed velocity-loop gain meets changes with elevation (does a fixed gain hold?)",
             non_negative=True),
)


@pytest.fixture(scope="module")
def result(
    drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
) -> dict[str, Estimate]:
    if NAME not in profile.protocols:
        pytest.skip(f"the profile has no [protocols.{NAME}] table (not an azimuth axis)")
    if (lacking := drive.info.lacking(REQUIRES)) is not None:
        pytest.skip(lacking)
    spec = Spec.from_profile(profile, drive_info)
    note_fallbacks(calibration, NAME, NEEDS)
    gain = reported_torque_gain(calibration)
    position_torque = measured_position_torque(calibration, profile, drive.info, protocol=NAME)

    def run_once() -> tuple[InertiaElevationResult, list[Estimate]]:
        by_elevation: list[list[Recording]] = []

        def to_elevation(elevation: float) -> None:
            drive.set_elevation(elevation)
            by_elevation.append([])

        # the protocol's one sequence (the planner sums the same): the centre move, then
        # each elevation's sines (the station's other axis moved before them)
        for e in motion(spec, position=lambda: drive.status().position_rad,
                        set_elevation=to_elevation):
            recording = calibration.run(drive, e, protocol=NAME)
            if e.mode is not Mode.POSITION:
                by_elevation[-1].append(recording)
        inertias = [inertia_at_elevation(recordings, spec, calibration, gain=gain,
                                         position_torque=position_torque)
                    for recordings in by_elevation]
        return fit_inertia_elevation(spec.elevations_rad, inertias,
                                     travel_rad=spec.travel_rad), inertias

    try:
        runs = run_repeated(run_once, lambda found: {
            e.name: e for e in (found[0].level, found[0].zenith, found[0].product,
                                found[0].ratio)},
            rule=spec.stop, calibration=calibration,
            variant=lambda _: None if position_torque is not None else WITHOUT_POSITION_TORQUE)
    finally:
        drive.set_elevation(spec.park_elevation_rad)
    analysed, inertias = runs.first
    calibration.details[NAME] = InertiaElevationDetails(
        **runs.details(),
        model="J(el) = J_zenith + ΔJ·cos²(el) + P·sin(2el)",
        travel_rad=analysed.travel_rad,
        largest_at_elevation_rad=analysed.extremes_rad[0],
        smallest_at_elevation_rad=analysed.extremes_rad[1],
        per_elevation=tuple(
            ElevationPoint(elevation_rad=el, inertia_kg_m2=j.value,
                           standard_uncertainty=j.standard_uncertainty)
            for el, j in zip(spec.elevations_rad, inertias, strict=True)
        ),
        torque_scale=(
            "shaft torque (K_t protocol's gain applied)"
            if gain is not None
            else "reported torque (no K_t result)"
        ),
        chi2_per_dof=analysed.chi2_per_dof,
        position_torque_taken_out=position_torque is not None,
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_inertia_elevation(
    parameter: str, result: dict[str, Estimate], calibration: CalibrationRun
) -> None:
    details = calibration.details[NAME]
    taken_out = isinstance(details, InertiaElevationDetails) and details.position_torque_taken_out
    measurement = calibration.record(NAME, result[parameter], declared=DECLARED[parameter],
                                     variant=None if taken_out else WITHOUT_POSITION_TORQUE)
    assert measurement.conforms, measurement.verdict()
