"""Cogging torque and K_t(θ) ripple from constant-velocity passes up and down the travel.

The two directions are the two torque levels (``L̄ + F`` and ``L̄ − F``): cogging is the
same in both, K_t ripple scales with the torque. A compensation table (JSON, format in
:mod:`hil.identify.cogging`) is written next to the certificate. With ``passes =
"gravity_cable"`` the passes are the gravity sweep's (no motion of its own).

Library: :mod:`hil.suite.cogging`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, cast

import numpy as np
import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.cogging import CoggingResult, compensation_table
from hil.identify.estimate import Estimate
from hil.measurement import Declared, declare
from hil.profile import UnitProfile
from hil.suite.cogging import (
    COMPENSATION_FILE,
    MEASUREMENTS,
    NAME,
    NEEDS,
    SWEEP_PASSES,
    CoggingDetails,
    CoggingHarmonic,
    RippleHarmonic,
    Spec,
    analyse,
    excitation,
    inertia_for_correction,
    sweep_passes,
)
from hil.suite.needs import note_fallbacks
from hil.suite.plan import acquisition_info
from hil.suite.rate import sample_rate_shortfall
from hil.suite.stop_rule import run_repeated
from hil.suite.travel import on_command_grid

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("cogging_peak_nm", "Cogging torque",
             "Largest harmonic amplitude of the motor's cogging torque over a revolution, from "
             "constant-velocity passes up and down", non_negative=True),
    Declared("kt_ripple_peak_pct", "Torque-constant ripple",
             "Largest harmonic of the torque constant's variation with rotor angle, in % of K_t",
             non_negative=True),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
           ) -> dict[str, Estimate]:
    spec = Spec.from_profile(profile, drive_info)
    if spec.passes == SWEEP_PASSES:  # the gravity sweep's recording: at the rate it ran
        drive_info, _ = acquisition_info(SWEEP_PASSES, profile, drive.info)
        spec = Spec.from_profile(profile, drive_info)
    shortfall = sample_rate_shortfall(
        spec.needed_sample_rate_hz,
        drive_info,
        protocol=NAME,
        why=(
            f"4 × order {spec.max_order} at {spec.speed_rad_s:g} rad/s = "
            f"{spec.highest_frequency_hz:.3g} Hz, and ≥ {spec.min_samples_per_pass} samples "
            f"in a {spec.pass_s:.3g} s pass"
        ),
    )
    if shortfall is not None:
        pytest.skip(shortfall)
    analysed_elsewhere: dict[str, str] = {}
    if spec.passes == SWEEP_PASSES:  # the sweep's one recording: the spec refuses a rule
        position, torque, passes_from, first_sample = sweep_passes(calibration, profile,
                                                                   drive_info)
        passes_from = Path(passes_from).relative_to(calibration.unit_dir).as_posix()
        analysed_elsewhere["passes"] = passes_from
    else:
        passes_from = "passes (this protocol's own)"
        first_sample = 0
    note_fallbacks(calibration, NAME, NEEDS)
    inertia, source = inertia_for_correction(calibration, profile)

    def run_once() -> tuple[CoggingResult, int]:
        if spec.passes == SWEEP_PASSES:
            at_rad, torque_nm, rows = position, torque, len(position)
        else:
            move, passes = excitation(spec, position_rad=drive.status().position_rad)
            calibration.run(drive, move, protocol=NAME)
            recording = calibration.run(drive, passes, protocol=NAME)
            at_rad, torque_nm, rows = on_command_grid(recording, passes)
        time_s = np.arange(len(at_rad)) / spec.fs_hz
        return analyse(time_s, at_rad, torque_nm, spec, inertia_kg_m2=inertia), rows

    runs = run_repeated(run_once, lambda found: {
        e.name: e for e in (found[0].cogging_peak, found[0].kt_ripple_peak)},
        rule=spec.stop, calibration=calibration)
    analysed, rows = runs.first  # the table is the first run's passes
    table = compensation_table(analysed)
    path = calibration.write_artifact(
        NAME,
        COMPENSATION_FILE,
        json.dumps(table, indent=2, ensure_ascii=False) + "\n",
        description="cogging and K_t ripple compensation table (format: hil/identify/cogging.py)",
    )
    calibration.details[NAME] = CoggingDetails(
        **runs.details(),
        compensation_table=path.relative_to(calibration.unit_dir).as_posix(),
        passes=passes_from,
        recordings_analysed=analysed_elsewhere,
        pass_samples=spec.pass_samples,
        pass_first_sample=first_sample,
        speed_rad_s=spec.speed_rad_s,
        orders=tuple(h.order for h in analysed.cogging),
        cogging=tuple(CoggingHarmonic(**h) for h in cast(list[dict[str, Any]], table["cogging"])),
        kt_ripple=tuple(RippleHarmonic(**h)
                        for h in cast(list[dict[str, Any]], table["kt_ripple"])),
        torque_levels_nm=tuple(analysed.torque_levels_nm),
        inertia_for_acceleration_correction_kg_m2=inertia,
        inertia_source=source,
        noise_rms_nm=analysed.noise_rms_nm,
        recorded_rows=rows,
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_cogging(parameter: str, result: dict[str, Estimate],
                 calibration: CalibrationRun) -> None:
    measurement = calibration.record(NAME, result[parameter],
                                     declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
