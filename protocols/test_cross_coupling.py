"""The torque the azimuth needs while the elevation swings: the inner gimbal's products of
inertia with its elevation axis (numerics in :mod:`hil.identify.cross_coupling`).

Skips without a ``[protocols.cross_coupling]`` table (not an azimuth axis) and on a station
that cannot move the elevation along a path while the azimuth runs (``REQUIRES``).

Library: :mod:`hil.suite.cross_coupling`.
"""

from __future__ import annotations

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.cross_coupling import CrossCouplingResult, fit_cross_coupling
from hil.identify.estimate import Estimate
from hil.measurement import Declared, declare
from hil.motion import Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.cross_coupling import (
    MEASUREMENTS,
    NAME,
    NEEDS,
    REQUIRES,
    CrossCouplingDetails,
    Spec,
    azimuth_inertia_kg_m2,
    coupling_runs,
    motion,
)
from hil.suite.inertia_elevation import reported_torque_gain
from hil.suite.needs import note_fallbacks
from hil.suite.stop_rule import run_repeated

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("coupling_product_level_kg_m2", "Elevation–azimuth product of inertia, level",
             "C_level in c(el) = C_level·cos(el) + C_vertical·sin(el): the inner gimbal's "
             "product of inertia of its elevation axis with the zenith axis, from the "
             "azimuth's torque while the elevation swings (the swing's fundamental)"),
    Declared("coupling_product_vertical_kg_m2", "Elevation–line-of-sight product of inertia",
             "C_vertical in c(el): the inner gimbal's product of inertia of its elevation "
             "axis with the line of sight, from the same passes (the swing's second "
             "harmonic)"),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo) -> dict[str, Estimate]:
    if NAME not in profile.protocols:
        pytest.skip(f"the profile has no [protocols.{NAME}] table (not an azimuth axis)")
    if (lacking := drive.info.lacking(REQUIRES)) is not None:
        pytest.skip(lacking)
    spec = Spec.from_profile(profile, drive_info)
    note_fallbacks(calibration, NAME, NEEDS)
    gain = reported_torque_gain(calibration)
    scale, scale_u = gain if gain is not None else (1.0, 0.0)
    inertia = azimuth_inertia_kg_m2(calibration, profile)

    def run_once() -> CrossCouplingResult:
        passes: dict[str, Recording] = {}
        # the protocol's one sequence (the planner sums the same): the elevation to the
        # swing's centre, the move to the travel's start, the four passes
        for e in motion(spec, position=lambda: drive.status().position_rad,
                        set_elevation=drive.set_elevation):
            recording = calibration.run(drive, e, protocol=NAME)
            if e.mode is not Mode.POSITION:
                passes[e.name] = recording
        return fit_cross_coupling(coupling_runs(spec, passes), azimuth_inertia_kg_m2=inertia,
                                  torque_scale=scale, torque_scale_u=scale_u)

    runs = run_repeated(run_once, lambda found: {e.name: e for e in (found.level,
                                                                      found.vertical)},
                        rule=spec.stop, calibration=calibration)
    analysed = runs.first
    calibration.details[NAME] = CrossCouplingDetails(
        **runs.details(),
        model="T_az = J·ψ̈ + J'(el)·el̇·ψ̇ + d/dt[c(el)·el̇] + (the azimuth's own torques, "
              "cancelled by the standing pass), c(el) = C_level·cos(el) + C_vertical·sin(el)"
              "; J·Δψ̈ (the loop's give) taken out with the azimuth's J",
        swing=f"elevation {spec.centre_rad:+.2f} rad ± {spec.amplitude_rad:g} rad at "
              f"{spec.frequency_hz:g} Hz, {spec.periods} periods per pass",
        azimuth_speed_rad_s=spec.speed_rad_s,
        coriolis_delta_j_kg_m2=analysed.coriolis_delta_j_kg_m2,
        coriolis_product_kg_m2=analysed.coriolis_product_kg_m2,
        azimuth_inertia_kg_m2=inertia,
        azimuth_give_rms_nm=analysed.azimuth_give_rms_nm,
        residual_rms_nm=analysed.residual_rms_nm,
        samples=analysed.samples,
        torque_scale=("shaft torque (K_t protocol's gain applied)" if gain is not None
                      else "reported torque (no K_t result)"),
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_cross_coupling(parameter: str, result: dict[str, Estimate],
                        calibration: CalibrationRun) -> None:
    measurement = calibration.record(NAME, result[parameter], declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
