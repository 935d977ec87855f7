"""Current-loop lag τ from the phase of the motion against the reported torque, 20–150 Hz.

Velocity-mode sines on top of a constant speed (the axis never reverses, so friction stays
linear); numerics and the sampled-data model in :mod:`hil.identify.current_loop`.

Library: :mod:`hil.suite.current_loop`.
"""

from __future__ import annotations

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.current_loop import (
    CurrentLoopResult,
    acquisition_path,
    timing_problem,
    torque_hold_s,
)
from hil.identify.estimate import Estimate
from hil.identify.lag_model import LagModelCheck
from hil.measurement import Declared, declare
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.current_loop import (
    MEASUREMENTS,
    NAME,
    CurrentLoopDetails,
    LagPoint,
    Spec,
    analyse_checked,
    excitation,
)
from hil.suite.rate import sample_rate_shortfall
from hil.suite.stop_rule import run_repeated

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("current_loop_time_constant_ms", "Current-loop time constant",
             "Lag τ of the drive's current (torque) loop below its bandwidth, its time "
             "constant plus any dead time, from the phase of velocity sines against the "
             "reported torque", non_negative=True),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
           ) -> dict[str, Estimate]:
    spec = Spec.from_profile(profile, drive_info)
    shortfall = sample_rate_shortfall(
        spec.needed_sample_rate_hz,
        drive_info,
        protocol=NAME,
        why=f"4 × its highest excitation frequency, {max(spec.frequencies_hz):g} Hz",
    )
    if shortfall is not None:
        pytest.skip(shortfall)
    if (problem := timing_problem(drive_info.timing)) is not None:
        pytest.skip(f"[protocols.{NAME}]: {problem}")

    def run_once() -> tuple[CurrentLoopResult, LagModelCheck, Recording]:
        move, sines = excitation(spec, position_rad=drive.status().position_rad)
        calibration.run(drive, move, protocol=NAME)
        recording = calibration.run(drive, sines, protocol=NAME)
        return *analyse_checked(recording, spec), recording

    runs = run_repeated(run_once, lambda found: {MEASUREMENTS[0]: found[0].time_constant},
                        rule=spec.stop, calibration=calibration,
                        acquisition=lambda found: acquisition_path(found[2].metadata,
                                                                   fs_hz=spec.fs_hz))
    analysed, lag_model, recording = runs.first
    hold = torque_hold_s(recording.metadata, fs_hz=spec.fs_hz)
    if (line := lag_model.message()) is not None:
        calibration.protocol(NAME).messages.append(line)
    calibration.details[NAME] = CurrentLoopDetails(
        **runs.details(),
        torque_hold=hold,
        acquisition=acquisition_path(recording.metadata, fs_hz=spec.fs_hz),
        viscous_over_inertia_1_s=analysed.viscous_over_inertia_1_s,
        chi2_per_dof=analysed.chi2_per_dof,
        lag_model_p_value=lag_model.p_value,
        dead_time_ms=lag_model.dead_time_ms,
        dead_time_u_ms=lag_model.dead_time_u_ms,
        points=tuple(
            LagPoint(frequency_hz=p.frequency_hz, lag_phase_rad=p.lag_phase_rad,
                     lag_phase_u_rad=p.lag_phase_u_rad, inertia_kg_m2=p.inertia_kg_m2,
                     torque_amplitude_nm=p.torque_amplitude_nm)
            for p in analysed.points
        ),
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_current_loop(
    parameter: str, result: dict[str, Estimate], calibration: CalibrationRun
) -> None:
    details = calibration.details[NAME]
    measurement = calibration.record(
        NAME, result[parameter], declared=DECLARED[parameter],
        acquisition=details.acquisition if isinstance(details, CurrentLoopDetails) else None)
    assert measurement.conforms, measurement.verdict()
