"""Velocity step response: rise time, overshoot, settling time, steady-state error.

Small and large steps, up and down, both directions of rotation, on a moving axis.

Library: :mod:`hil.suite.velocity_step`.
"""

from __future__ import annotations

import dataclasses

import pytest

from hil.calibration import CalibrationRun
from hil.closed_loop.step import StepFigures
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.measurement import Declared, declare
from hil.profile import UnitProfile
from hil.suite.rate import sample_rate_shortfall
from hil.suite.stop_rule import run_repeated
from hil.suite.velocity_step import (
    MEASUREMENTS,
    NAME,
    SizedStep,
    Spec,
    VelocityStepDetails,
    analyse,
    excitation,
)

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("step_rise_time_small_ms", "Rise time, small step",
             "10–90 % rise time of the speed after the velocity staircase's small steps",
             non_negative=True),
    Declared("step_rise_time_large_ms", "Rise time, large step",
             "10–90 % rise time of the speed after the staircase's large steps", non_negative=True),
    Declared("step_overshoot_small_pct", "Overshoot, small step",
             "How far the speed overshoots its new setpoint after a small step, in % of the step",
             non_negative=True),
    Declared("step_overshoot_large_pct", "Overshoot, large step",
             "How far the speed overshoots its new setpoint after a large step, in % of the step",
             non_negative=True),
    Declared("step_settling_time_small_ms", "Settling time, small step",
             "Time until the speed stays within 2 % of the step around its setpoint, small steps",
             non_negative=True),
    Declared("step_settling_time_large_ms", "Settling time, large step",
             "Time until the speed stays within 2 % of the step around its setpoint, large steps",
             non_negative=True),
    Declared("step_steady_state_error_pct", "Steady-state speed error",
             "Mean speed error once settled, in % of the setpoint"),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
           ) -> dict[str, Estimate]:
    spec = Spec.from_profile(profile, drive_info)
    shortfall = sample_rate_shortfall(spec.min_sample_rate_hz, drive_info, protocol=NAME,
                                      why="≥ 10 samples in a 10 ms rise")
    if shortfall is not None:
        pytest.skip(shortfall)

    def run_once() -> tuple[dict[str, Estimate], list[tuple[str, StepFigures]]]:
        *moves, forward, backward = excitation(spec, position_rad=drive.status().position_rad)
        for move in moves:
            calibration.run(drive, move, protocol=NAME)
        return analyse([(calibration.run(drive, e, protocol=NAME), e)
                        for e in (forward, backward)], spec)

    runs = run_repeated(run_once, lambda found: found[0], rule=spec.stop,
                        calibration=calibration)
    steps = runs.first[1]
    calibration.details[NAME] = VelocityStepDetails(
        **runs.details(),
        velocity=f"encoder position, central difference, {spec.smooth_s * 1e3:g} ms "
                 "zero-phase moving average",
        steps=tuple(SizedStep(size=size, **dataclasses.asdict(f)) for size, f in steps),
        smooth_s=spec.smooth_s,  # for the plot: the velocity as analysed
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_velocity_step(parameter: str, result: dict[str, Estimate],
                       calibration: CalibrationRun) -> None:
    measurement = calibration.record(NAME, result[parameter],
                                     declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
