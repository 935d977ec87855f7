"""m·g·e (gravity unbalance) and k_cable from one slow two-way sweep of the travel.

One protocol for both because they are separated by one joint fit of the load torque
(``cos θ``, ``sin θ``, ``θ``, 1) over the same sweep: two sweeps would double the motion
for the same information. The sweep passes every elevation in both directions, so the
friction cancels in the half sum of the two passes (the 48 position bins are the
"holding" elevations).

Library: :mod:`hil.suite.gravity_cable`.
"""

from __future__ import annotations

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.gravity_cable import (
    GravityCableResult,
    eccentricity_mm,
)
from hil.measurement import Declared, declare
from hil.profile import UnitProfile
from hil.suite.gravity_cable import (
    MEASUREMENTS,
    NAME,
    GravityCableDetails,
    Spec,
    analyse,
    excitation,
)
from hil.suite.stop_rule import run_repeated
from hil.suite.travel import on_command_grid

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("gravity_mge_nm", "Gravity unbalance torque",
             "m·g·e: the largest torque gravity exerts on the load's off-axis centre of mass, from"
             " a slow two-way sweep of the travel", non_negative=True),
    Declared("gravity_phase_rad", "Gravity unbalance angle",
             "φ in m·g·e·cos(θ + φ): where the unbalance torque peaks, relative to the axis zero"),
    Declared("eccentricity_mm", "Centre-of-mass offset",
             "e: distance of the load's centre of mass from the axis, m·g·e over the declared load"
             " mass and g", non_negative=True),
    Declared("cable_stiffness_nm_rad", "Cable stiffness",
             "k: torque per radian the cable harness adds across the travel, from the same sweep's"
             " joint fit"),
    Declared("cable_hysteresis_nm", "Cable hysteresis",
             "h: half width of the cable's torque loop between the up and down passes, from its "
             "turn-over after a reversal", non_negative=True),
)


@pytest.fixture(scope="module")
def spec(drive_info: DriveInfo, profile: UnitProfile) -> Spec:
    return Spec.from_profile(profile, drive_info)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, spec: Spec) -> dict[str, Estimate]:

    def run_once() -> tuple[GravityCableResult, int]:
        move, sweep = excitation(spec, position_rad=drive.status().position_rad)
        calibration.run(drive, move, protocol=NAME)
        recording = calibration.run(drive, sweep, protocol=NAME)
        position, torque, rows = on_command_grid(recording, sweep)
        return analyse(position, torque, spec), rows

    runs = run_repeated(run_once, lambda found: {e.name: e for e in (
        found[0].mge, found[0].phase, found[0].stiffness, found[0].hysteresis)},
        rule=spec.stop, calibration=calibration)
    analysed, rows = runs.first
    calibration.details[NAME] = GravityCableDetails(
        **runs.details(),
        recorded_rows=rows,
        offset_nm=analysed.offset_nm,
        cable_hysteresis_angle_rad=analysed.hysteresis_angle_rad,
        cable_hysteresis_angle_u_rad=analysed.hysteresis_angle_u_rad,
        cable_hysteresis_covariance=analysed.hysteresis_covariance,
        loop_half_width_nm=analysed.loop_half_width_nm,
        sliding_friction_at_sweep_speed_nm=analysed.friction_nm,
        bins=analysed.bins,
        residual_rms_nm=analysed.residual_rms_nm,
        load_nm_by_elevation_rad=tuple(
            (float(c), float(v))
            for c, v in zip(analysed.bin_centres_rad, analysed.load_nm, strict=True)
        ),
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_gravity_cable(
    parameter: str, result: dict[str, Estimate], spec: Spec, calibration: CalibrationRun
) -> None:
    estimates = dict(result)
    if parameter == "eccentricity_mm":
        if spec.mass_kg is None:
            pytest.skip("the profile's [unit] gives no mass_kg: e cannot be derived from m·g·e")
        estimates[parameter] = eccentricity_mm(result["gravity_mge_nm"], mass_kg=spec.mass_kg)
    measurement = calibration.record(NAME, estimates[parameter],
                                     declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
