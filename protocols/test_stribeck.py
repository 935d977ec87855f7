"""Stribeck friction (T_s, v_s) from a slow constant-velocity staircase in both directions.

Library: :mod:`hil.suite.stribeck`.
"""

from __future__ import annotations

import numpy as np
import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.stribeck import StribeckResult
from hil.measurement import Declared, declare
from hil.profile import UnitProfile
from hil.suite.needs import note_fallbacks
from hil.suite.stop_rule import run_repeated
from hil.suite.stribeck import (
    CABLE,
    MEASUREMENTS,
    NAME,
    NEEDS,
    FrictionPoint,
    Spec,
    StribeckDetails,
    analyse,
    cross_check,
    excitation,
    finite_or_none,
    without_cable_loop,
)
from hil.suite.torque_constant import kt_ripple_from_cogging, ripple_variant
from hil.suite.travel import on_command_grid

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("static_friction_nm", "Static (breakaway) friction",
             "T_s: the friction torque as sliding starts, from a slow velocity staircase in both "
             "directions, the cable loop's half-width taken out"),
    Declared("stribeck_velocity_rad_s", "Stribeck velocity",
             "v_s: the speed over which friction falls from T_s to the Coulomb level"),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
           ) -> dict[str, Estimate]:
    spec = Spec.from_profile(profile, drive_info)
    note_fallbacks(calibration, NAME, NEEDS)
    ripple = kt_ripple_from_cogging(calibration)
    variant = ripple_variant(calibration)

    def run_once() -> tuple[StribeckResult, int]:
        move, stairs = excitation(spec, position_rad=drive.status().position_rad)
        calibration.run(drive, move, protocol=NAME)
        recording = calibration.run(drive, stairs, protocol=NAME)
        position, torque, rows = on_command_grid(recording, stairs)
        time_s = np.arange(len(position)) / stairs.fs_hz
        return analyse(time_s, position, torque, spec, ripple=ripple), rows

    loop = CABLE.read(calibration)
    runs = run_repeated(run_once, lambda found: {
        e.name: e for e in (without_cable_loop(found[0].static, loop),
                            found[0].stribeck_velocity)},
        rule=spec.stop, calibration=calibration, variant=lambda _: variant)
    analysed, rows = runs.first
    calibration.details[NAME] = StribeckDetails(
        **runs.details(),
        recorded_rows=rows,
        coulomb_nm=analysed.coulomb.value,
        viscous_nm_s_rad=analysed.viscous.value,
        residual_rms_nm=analysed.residual_rms_nm,
        kt_ripple_correction="cogging protocol's table" if ripple else "none",
        lowest_clean_speed_rad_s=analysed.lowest_clean_speed_rad_s,
        stick_slip_speeds_rad_s=tuple(p.speed_rad_s for p in analysed.points if p.stick_slip),
        points=tuple(
            FrictionPoint(speed_rad_s=p.speed_rad_s, friction_nm=finite_or_none(p.friction_nm),
                          friction_u_nm=finite_or_none(p.friction_u_nm),
                          stick_slip=p.stick_slip)
            for p in analysed.points
        ),
        cross_check_sine=cross_check(analysed, calibration),
        note="steady sliding friction includes the cable's hysteresis half-width "
        "(direction-dependent, not separable at constant speed): coulomb_nm here holds it, "
        "static_friction_nm has it taken out when gravity_cable measured it",
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_stribeck(parameter: str, result: dict[str, Estimate],
                  calibration: CalibrationRun) -> None:
    measurement = calibration.record(NAME, result[parameter], declared=DECLARED[parameter],
                                     variant=ripple_variant(calibration))
    assert measurement.conforms, measurement.verdict()
