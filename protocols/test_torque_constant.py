"""K_t from a locked rotor and the shaft torque sensor: current swept up and down at several
locked angles (numerics in :mod:`hil.identify.torque_constant`).

Needs a station with a shaft torque sensor and a locked-rotor fixture the harness can
engage (``drive.locked_rotor()``): its ``REQUIRES``; skips, naming what is missing,
otherwise.

Library: :mod:`hil.suite.torque_constant`.
"""

from __future__ import annotations

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.torque_constant import (
    LockedSweep,
    TorqueConstantResult,
    datasheet_torque_constant_nm_a,
    identify_torque_constant,
)
from hil.measurement import Declared, declare
from hil.motion import Mode
from hil.profile import UnitProfile
from hil.suite.needs import note_fallbacks
from hil.suite.stop_rule import run_repeated
from hil.suite.torque_constant import (
    MEASUREMENTS,
    NAME,
    NEEDS,
    REQUIRES,
    LockedAngle,
    Spec,
    TorqueConstantDetails,
    analyse_sweep,
    estimates,
    kt_ripple_from_cogging,
    locked_angles,
    motion,
    ripple_variant,
)

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("torque_constant_nm_a", "Torque constant",
             "K_t: shaft torque per ampere, rotor locked, current swept up and down at several "
             "angles against a shaft torque sensor"),
    Declared("torque_linearity_pct", "Torque linearity error",
             "Largest deviation of the shaft torque from its straight line against current, in % "
             "of full scale", non_negative=True),
    Declared("reported_torque_gain_error_pct", "Reported-torque gain error",
             "The torque the drive reports against the shaft sensor's: slope − 1, in %"),
    Declared("torque_constant_vs_datasheet_pct", "Torque constant against datasheet",
             "Measured K_t against the motor datasheet's 9.5493/KV, in %"),
)


@pytest.fixture(scope="module")
def result(
    drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
) -> dict[str, Estimate]:
    if (lacking := drive.info.lacking(REQUIRES)) is not None:
        pytest.skip(lacking)
    spec = Spec.from_profile(profile, drive_info)
    note_fallbacks(calibration, NAME, NEEDS)
    ripple = kt_ripple_from_cogging(calibration)
    angles = locked_angles(spec, ripple)

    def run_once() -> tuple[TorqueConstantResult, list[LockedSweep]]:
        sweeps: list[LockedSweep] = []
        # the protocol's one sequence (the planner sums the same): per angle a move, a sweep
        for e in motion(spec, angles_rad=angles, position=lambda: drive.status().position_rad):
            if e.mode is Mode.POSITION:
                calibration.run(drive, e, protocol=NAME)
                continue
            angle = angles[len(sweeps)]
            with drive.locked_rotor():
                recording = calibration.run(drive, e, protocol=NAME)
            sweeps.append(analyse_sweep(recording, spec, angle_rad=angle, excitation=e))
        return identify_torque_constant(sweeps, ripple=ripple), sweeps

    variant = ripple_variant(calibration)
    runs = run_repeated(run_once, lambda found: estimates(found[0], spec), rule=spec.stop,
                        calibration=calibration, variant=lambda _: variant)
    sweeps = runs.first[1]
    calibration.details[NAME] = TorqueConstantDetails(
        **runs.details(),
        kt_ripple_correction="cogging protocol's table" if ripple else "none",
        angles=("configured, each nudged so the largest K_t ripple harmonic averages out"
                if ripple else "configured"),
        per_angle=tuple(
            LockedAngle(angle_rad=s.angle_rad, slope_nm_a=s.slope_nm_a,
                        intercept_nm=s.intercept_nm, gain=s.gain,
                        max_residual_nm=s.max_residual_nm)
            for s in sweeps
        ),
        datasheet_torque_constant_nm_a=(
            None if spec.kv_rpm_per_v is None else datasheet_torque_constant_nm_a(spec.kv_rpm_per_v)
        ),
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_torque_constant(
    parameter: str, result: dict[str, Estimate], calibration: CalibrationRun
) -> None:
    if parameter not in result:
        pytest.skip("the profile's [unit] has no kv_rpm_per_v (datasheet KV)")
    measurement = calibration.record(NAME, result[parameter], declared=DECLARED[parameter],
                                     variant=ripple_variant(calibration))
    assert measurement.conforms, measurement.verdict()
