"""Standstill: torque ripple and position jitter while the drive holds a position.

Library: :mod:`hil.suite.standstill`.
"""

from __future__ import annotations

import pytest

from hil.calibration import CalibrationRun
from hil.closed_loop.standstill import Standstill
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.measurement import Declared, declare
from hil.motion import Excitation
from hil.profile import UnitProfile
from hil.suite.standstill import (
    MEASUREMENTS,
    NAME,
    Spec,
    StandstillDetails,
    analyse,
    analysed_windows,
    excitation,
)
from hil.suite.stop_rule import run_repeated

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("standstill_torque_ripple_mnm", "Standstill torque ripple",
             "RMS of the reported torque about its mean while the drive holds a position",
             non_negative=True),
    Declared("standstill_jitter_urad", "Standstill position jitter",
             "RMS of the encoder position about its mean while the drive holds a position",
             non_negative=True),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
           ) -> dict[str, Estimate]:
    spec = Spec.from_profile(profile, drive_info)

    def run_once() -> tuple[dict[str, Estimate], Standstill, Excitation]:
        hold = excitation(spec, position_rad=drive.status().position_rad)
        return (*analyse(calibration.run(drive, hold, protocol=NAME), hold, spec), hold)

    runs = run_repeated(run_once, lambda found: found[0], rule=spec.stop,
                        calibration=calibration)
    _, blocks, hold = runs.first
    calibration.details[NAME] = StandstillDetails(
        **runs.details(),
        hold_positions_rad=tuple(float(hold.command[stop - 1])
                                 for _, stop in analysed_windows(hold, spec)),
        hold_s=spec.hold_s,
        # for the plot: each block's samples in the recording
        block_windows=tuple((int(a), int(b)) for a, b in analysed_windows(hold, spec)),
        block_torque_rms_mnm=tuple(float(v) * 1e3 for v in blocks.torque_rms_nm),
        block_position_rms_urad=tuple(float(v) * 1e6 for v in blocks.position_rms_rad),
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_standstill(parameter: str, result: dict[str, Estimate],
                    calibration: CalibrationRun) -> None:
    measurement = calibration.record(NAME, result[parameter],
                                     declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
