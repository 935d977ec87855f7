"""J, B, T_c from sinusoidal velocity at two or more amplitudes (orthogonal correlation)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo, Excitation, Mode
from hil.identify.inertia_friction import (
    HOLD_SAMPLES,
    InertiaFrictionResult,
    Method,
    analyse_sine_run,
    identify_inertia_friction,
    inertia_amplitude_spread,
)
from hil.profile import UnitProfile
from hil.recording import Recording

NAME = "inertia_friction"
MEASUREMENTS = ("inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm", "inertia_amplitude_spread_pct")
pytestmark = pytest.mark.protocol(NAME)


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec:
    frequency_hz: float
    amplitudes_rad_s: tuple[float, ...]
    settle_periods: int
    periods: int
    fs_hz: float
    method: Method = "orthogonal"

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        settings = profile.settings(NAME)
        method: Method = (
            "least_squares"
            if settings.choice("method", ("orthogonal", "least_squares"), "orthogonal")
            == "least_squares"
            else "orthogonal"
        )
        spec = cls(
            frequency_hz=settings.number("frequency_hz"),
            amplitudes_rad_s=settings.numbers("amplitudes_rad_s"),
            settle_periods=settings.integer("settle_periods", 2),
            periods=settings.integer("periods", 8),
            fs_hz=min(profile.sample_rate_hz, info.max_sample_rate_hz),
            method=method,
        )
        settings.done()
        return spec


def excitation(spec: Spec) -> list[Excitation]:
    """One velocity sine per amplitude, whole periods, starting and ending at rest."""
    samples = round((spec.settle_periods + spec.periods) * spec.fs_hz / spec.frequency_hz)
    t = np.arange(samples) / spec.fs_hz
    shape = np.sin(2 * math.pi * spec.frequency_hz * t)
    return [
        Excitation(
            name=f"sine_{spec.frequency_hz:g}hz_{amplitude:g}rad_s",
            mode=Mode.VELOCITY,
            command=amplitude * shape,
            fs_hz=spec.fs_hz,
        )
        for amplitude in spec.amplitudes_rad_s
    ]


def analyse(
    recordings: list[Recording], spec: Spec, *, current_loop_lag_s: float = 0.0
) -> InertiaFrictionResult:
    """J, B, T_c; the reported torque reaches the shaft half a sample (zero-order hold) plus
    the current loop's lag later, which would otherwise leak into B as ``c·2πf·τ``."""
    hold = HOLD_SAMPLES + current_loop_lag_s * spec.fs_hz
    runs = [
        analyse_sine_run(
            r, frequency_hz=spec.frequency_hz, settle_periods=spec.settle_periods, hold_samples=hold
        )
        for r in recordings
    ]
    return identify_inertia_friction(runs, method=spec.method)


def measured_current_loop_lag_s(calibration: CalibrationRun) -> float:
    """The current-loop time constant if that protocol ran earlier, else 0."""
    for measurement in calibration.measurements:
        if measurement.spec.name == "current_loop_time_constant_ms":
            return measurement.estimate.value / 1000.0
    return 0.0


@pytest.fixture(scope="module")
def result(
    drive: Drive, calibration: CalibrationRun, profile: UnitProfile
) -> InertiaFrictionResult:
    spec = Spec.from_profile(profile, drive.info)
    recordings = [calibration.run(drive, e, protocol=NAME) for e in excitation(spec)]
    lag_s = measured_current_loop_lag_s(calibration)
    analysed = analyse(recordings, spec, current_loop_lag_s=lag_s)
    calibration.details[NAME] = {
        "current_loop_lag_compensated_s": lag_s,
        "fit_pct": round(analysed.fit_pct, 2),
        "noise_rms_nm": analysed.noise_rms_nm,
        "components": [
            {
                "velocity_amplitude_rad_s": r.velocity_amplitude_rad_s,
                "quadrature_c_nm": r.quadrature_nm,
                "in_phase_s_nm": r.in_phase_nm,
                "periods": r.periods,
            }
            for r in analysed.runs
        ],
    }
    return analysed


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_inertia_friction(
    parameter: str, result: InertiaFrictionResult, calibration: CalibrationRun
) -> None:
    estimates = {e.name: e for e in (result.inertia, result.viscous, result.coulomb)}
    estimates["inertia_amplitude_spread_pct"] = inertia_amplitude_spread(result)
    measurement = calibration.record(NAME, estimates[parameter])
    assert measurement.outcome.value in ("PASS", "MARGINAL"), (
        f"{parameter} = {measurement.estimate.value:.6g} {measurement.spec.unit} outside "
        f"[{measurement.spec.lower_limit:.6g}, {measurement.spec.upper_limit:.6g}]"
    )
