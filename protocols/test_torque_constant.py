"""K_t from a locked rotor and the shaft torque sensor: current swept up and down at several
locked angles (numerics in :mod:`hil.identify.torque_constant`).

Needs a station with a shaft torque sensor (``drive.info.has_torque_sensor``) and a
locked-rotor fixture the harness can engage (``drive.locked_rotor()``); skips otherwise.

Library: :mod:`hil.suite.torque_constant`.
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any, cast

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive
from hil.identify.torque_constant import (
    TorqueConstantResult,
    balanced_angles,
    datasheet_torque_constant_nm_a,
    identify_torque_constant,
)
from hil.profile import UnitProfile
from hil.suite.torque_constant import (
    NAME,
    Spec,
    analyse_sweep,
    estimates,
    kt_ripple_from_cogging,
    move,
    sweep,
)

MEASUREMENTS = (
    "torque_constant_nm_a",
    "torque_linearity_pct",
    "reported_torque_gain_error_pct",
    "torque_constant_vs_datasheet_pct",
)
pytestmark = pytest.mark.protocol(NAME)


@pytest.fixture(scope="module")
def result(
    drive: Drive, calibration: CalibrationRun, profile: UnitProfile
) -> tuple[TorqueConstantResult, Spec]:
    if not drive.info.has_torque_sensor:
        pytest.skip("the station has no shaft torque sensor (drive.info.has_torque_sensor)")
    locked_rotor = getattr(drive, "locked_rotor", None)
    if locked_rotor is None:
        pytest.skip(f"{type(drive).__name__} offers no locked-rotor fixture (locked_rotor())")
    spec = Spec.from_profile(profile, drive.info)
    ripple = kt_ripple_from_cogging(calibration)
    angles = balanced_angles(spec.angles_rad, ripple)
    sweeps = []
    for angle in angles:
        calibration.run(
            drive,
            move(spec, position_rad=drive.status().position_rad, angle_rad=angle),
            protocol=NAME,
        )
        with cast(AbstractContextManager[Any], locked_rotor()):
            recording = calibration.run(drive, sweep(spec, angle_rad=angle), protocol=NAME)
        sweeps.append(analyse_sweep(recording, spec, angle_rad=angle))
    analysed = identify_torque_constant(sweeps, ripple=ripple)
    calibration.details[NAME] = {
        "kt_ripple_correction": "cogging protocol's table" if ripple else "none",
        "angles": ("configured, each nudged so the largest K_t ripple harmonic averages out"
                   if ripple else "configured"),
        "per_angle": [
            {
                "angle_rad": s.angle_rad,
                "slope_nm_a": s.slope_nm_a,
                "intercept_nm": s.intercept_nm,
                "gain": s.gain,
                "max_residual_nm": s.max_residual_nm,
            }
            for s in sweeps
        ],
        "datasheet_torque_constant_nm_a": (
            None if spec.kv_rpm_per_v is None else datasheet_torque_constant_nm_a(spec.kv_rpm_per_v)
        ),
    }
    return analysed, spec


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_torque_constant(
    parameter: str, result: tuple[TorqueConstantResult, Spec], calibration: CalibrationRun
) -> None:
    found = estimates(*result)
    if parameter not in found:
        pytest.skip("the profile's [unit] has no kv_rpm_per_v (datasheet KV)")
    measurement = calibration.record(NAME, found[parameter])
    assert measurement.conforms, measurement.verdict()
