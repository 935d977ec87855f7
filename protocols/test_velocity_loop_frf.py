"""Velocity-loop frequency response: closed loop, sensitivity, bandwidth and margins.

A periodic multisine on a constant-speed carrier (the axis never reverses); the closed
loop ``T = V/R``, the sensitivity ``S = E/R`` and the loop gain ``L = V/E = C·P`` (the
torque command splits it: ``C = U/E``, ``P = V/U``); margins by python-control.

Library: :mod:`hil.suite.velocity_loop_frf`.
"""

from __future__ import annotations

import numpy as np
import pytest

from hil.calibration import CalibrationRun
from hil.closed_loop.frf import FrfResult
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.measurement import Declared, declare
from hil.profile import UnitProfile
from hil.suite.rate import sample_rate_shortfall
from hil.suite.stop_rule import run_repeated
from hil.suite.velocity_loop_frf import (
    MEASUREMENTS,
    NAME,
    Spec,
    VelocityLoopFrfDetails,
    analyse,
    excitation,
)

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("velocity_bandwidth_hz", "Velocity-loop bandwidth",
             "−3 dB frequency of the closed velocity loop (command to speed), from a multisine's "
             "frequency response", non_negative=True),
    Declared("velocity_peak_gain_db", "Closed-loop peak gain",
             "Largest gain of the closed velocity loop over frequency, in dB (0 dB: no peaking)"),
    Declared("velocity_gain_margin_db", "Gain margin",
             "How far the loop gain could rise before the velocity loop turns unstable, from the "
             "measured loop gain"),
    Declared("velocity_phase_margin_deg", "Phase margin",
             "Phase left at the loop gain's crossover before the velocity loop turns unstable"),
    Declared("velocity_sensitivity_peak_db", "Sensitivity peak",
             "Largest gain from a disturbance to the speed error (|S|), in dB: how much the loop "
             "can amplify a disturbance", non_negative=True),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
           ) -> dict[str, Estimate]:
    spec = Spec.from_profile(profile, drive_info)
    shortfall = sample_rate_shortfall(
        spec.needed_sample_rate_hz, drive_info, protocol=NAME,
        why=f"4 × its highest line, {max(spec.frequencies_hz):g} Hz")
    if shortfall is not None:
        pytest.skip(shortfall)

    def run_once() -> FrfResult:
        *moves, lines = excitation(spec, position_rad=drive.status().position_rad)
        for move in moves:
            calibration.run(drive, move, protocol=NAME)
        return analyse(calibration.run(drive, lines, protocol=NAME), spec)

    runs = run_repeated(run_once, lambda found: {e.name: e for e in found.estimates.values()},
                        rule=spec.stop, calibration=calibration)
    analysed = runs.first

    def db(values: np.ndarray) -> tuple[float, ...]:
        return tuple(float(v) for v in 20 * np.log10(np.abs(values)))

    def deg(values: np.ndarray) -> tuple[float, ...]:
        return tuple(float(v) for v in np.degrees(np.angle(values)))

    calibration.details[NAME] = VelocityLoopFrfDetails(
        **runs.details(),
        frequencies_hz=tuple(float(f) for f in analysed.frequencies_hz),
        closed_loop_db=db(analysed.closed_loop), closed_loop_deg=deg(analysed.closed_loop),
        sensitivity_db=db(analysed.sensitivity),
        loop_gain_db=db(analysed.loop_gain), loop_gain_deg=deg(analysed.loop_gain),
        controller_db=db(analysed.controller), plant_db=db(analysed.plant),
        periods=analysed.periods,
        margins="python-control stability_margins on frd(L = V/E)",
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_velocity_loop_frf(parameter: str, result: dict[str, Estimate],
                           calibration: CalibrationRun) -> None:
    measurement = calibration.record(NAME, result[parameter],
                                     declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
