"""Tracking: the standard gimbal move without and with the certificate's friction
feedforward ``B·ω* + T_c·sgn(ω*)`` (the drive's torque offset); following error and the
feedforward's reduction of it.

Library: :mod:`hil.suite.tracking`.
"""

from __future__ import annotations

import math

import pytest

from hil.calibration import CalibrationRun
from hil.closed_loop.tracking import Repeated
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.measurement import Declared, declare
from hil.profile import UnitProfile
from hil.suite.needs import note_fallbacks
from hil.suite.rate import sample_rate_shortfall
from hil.suite.stop_rule import run_repeated
from hil.suite.tracking import (
    FEEDFORWARD_LINE,
    MEASUREMENTS,
    MICRO,
    NAME,
    NEEDS,
    Feedforward,
    RunToRun,
    Spec,
    TrackingDetails,
    analyse,
    excitation,
    feedforward_values,
    run_motion,
)

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("tracking_rms_error_urad", "Following error (RMS), feedforward on",
             "RMS position error over the standard gimbal move (slew, track, reversal) with this "
             "certificate's friction feedforward", non_negative=True),
    Declared("tracking_peak_error_urad", "Following error (peak), feedforward on",
             "Largest position error over the same move with the feedforward", non_negative=True),
    Declared("tracking_rms_error_no_ff_urad", "Following error (RMS), feedforward off",
             "RMS position error over the same move without feedforward", non_negative=True),
    Declared("tracking_ff_reduction", "Feedforward improvement",
             "RMS following error without feedforward over that with it (2: halved)",
             non_negative=True),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
           ) -> dict[str, Estimate]:
    spec = Spec.from_profile(profile, drive_info)
    shortfall = sample_rate_shortfall(
        spec.min_sample_rate_hz, drive_info, protocol=NAME,
        why="the torque offset follows the command sample by sample; a polled link holds it "
            "a whole poll and writes it with the host's jitter")
    if shortfall is not None:
        pytest.skip(shortfall)
    note_fallbacks(calibration, NAME, NEEDS)
    viscous, coulomb, u_rel, source = feedforward_values(calibration, profile, spec)
    off, on = excitation(spec, viscous_nm_s_rad=viscous, coulomb_nm=coulomb)

    def run_once() -> tuple[dict[str, Estimate], Repeated, Repeated]:
        # the protocol's one sequence (the planner sums the same): per run a move, the run
        recorded = run_motion(spec, (off, on), drive=drive,
                              run=lambda e: calibration.run(drive, e, protocol=NAME))
        return analyse(recorded[0::2], recorded[1::2], spec, feedforward_u_rel=u_rel)

    runs = run_repeated(run_once, lambda found: found[0], rule=spec.stop,
                        calibration=calibration, shared=(FEEDFORWARD_LINE,))
    _, f_off, f_on = runs.first
    calibration.details[NAME] = TrackingDetails(
        **runs.details(),
        feedforward=Feedforward(viscous_nm_s_rad=viscous, coulomb_nm=coulomb,
                                relative_uncertainty=u_rel, source=source,
                                sent_as="torque offset (CiA 402 0x60B2)"),
        repeats=spec.repeats,
        run_to_run_sd_urad=RunToRun(no_ff=f_off.u_rms_rad * math.sqrt(f_off.runs) * MICRO,
                                    ff=f_on.u_rms_rad * math.sqrt(f_on.runs) * MICRO),
        peak_error_no_ff_urad=f_off.peak_rad * MICRO,
        move_s=len(on.command) / on.fs_hz,
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_tracking(parameter: str, result: dict[str, Estimate],
                  calibration: CalibrationRun) -> None:
    measurement = calibration.record(NAME, result[parameter],
                                     declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
