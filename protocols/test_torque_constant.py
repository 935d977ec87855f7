"""K_t from a locked rotor and the shaft torque sensor: current swept up and down at several
locked angles (numerics in :mod:`hil.identify.torque_constant`).

Needs a station with a shaft torque sensor (``drive.info.has_torque_sensor``) and a
locked-rotor fixture the harness can engage (``drive.locked_rotor()``); skips otherwise.
"""

from __future__ import annotations

import math
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.torque_constant import (
    LockedSweep,
    TorqueConstantResult,
    analyse_locked_sweep,
    datasheet_deviation,
    datasheet_torque_constant_nm_a,
    identify_torque_constant,
)
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from protocols._travel import move_excitation, move_speed_rad_s

NAME = "torque_constant"
MEASUREMENTS = (
    "torque_constant_nm_a",
    "torque_linearity_pct",
    "reported_torque_gain_error_pct",
    "torque_constant_vs_datasheet_pct",
)
pytestmark = pytest.mark.protocol(NAME)


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec:
    angles_rad: tuple[float, ...]
    peak_torque_nm: float
    levels: int  # per direction
    level_s: float
    settle_s: float
    move_speed_rad_s: float
    fs_hz: float
    kv_rpm_per_v: float | None

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        settings = profile.settings(NAME)
        kv = profile.unit.get("kv_rpm_per_v")
        limit = min(info.limits.torque_nm, info.rated_torque_nm)
        spec = cls(
            angles_rad=settings.numbers("angles_rad"),
            peak_torque_nm=settings.number("peak_torque_fraction", 0.8) * limit,
            levels=settings.integer("levels", 9),
            level_s=settings.number("level_s", 0.05),
            settle_s=settings.number("settle_s", 0.01),
            move_speed_rad_s=move_speed_rad_s(settings, info),
            fs_hz=min(profile.sample_rate_hz, info.max_sample_rate_hz),
            kv_rpm_per_v=None if kv is None else float(kv),
        )
        settings.done()
        return spec

    @property
    def level_samples(self) -> int:
        return round(self.level_s * self.fs_hz)

    @property
    def settle_samples(self) -> int:
        return math.ceil(self.settle_s * self.fs_hz)

    @property
    def torque_levels_nm(self) -> np.ndarray:
        """Up from −peak to +peak, then back down: both directions at every level."""
        up = np.linspace(-self.peak_torque_nm, self.peak_torque_nm, self.levels)
        return np.concatenate([up, up[::-1]])


def move(spec: Spec, *, position_rad: float, angle_rad: float) -> Excitation:
    return move_excitation(
        f"move_to_{angle_rad:+.3f}rad",
        position_rad,
        angle_rad,
        fs_hz=spec.fs_hz,
        speed_rad_s=spec.move_speed_rad_s,
        hold_s=0.1,
    )


def sweep(spec: Spec, *, angle_rad: float) -> Excitation:
    """Torque staircase for a locked rotor, ending with a short zero level (not analysed)."""
    command = np.concatenate(
        [np.repeat(spec.torque_levels_nm, spec.level_samples), np.zeros(spec.settle_samples)]
    )
    return Excitation(
        name=f"locked_sweep_{angle_rad:+.3f}rad",
        mode=Mode.TORQUE,
        fs_hz=spec.fs_hz,
        command=command,
    )


def analyse_sweep(recording: Recording, spec: Spec, *, angle_rad: float) -> LockedSweep:
    columns = recording.columns
    return analyse_locked_sweep(
        columns["current_a"],
        columns["load_torque_nm"],
        recording.effort,
        angle_rad=angle_rad,
        level_samples=spec.level_samples,
        settle_samples=spec.settle_samples,
        levels=spec.torque_levels_nm.size,
    )


def estimates(result: TorqueConstantResult, spec: Spec) -> dict[str, Estimate]:
    found = {e.name: e for e in (result.torque_constant, result.linearity, result.gain_error)}
    if spec.kv_rpm_per_v is not None:
        found["torque_constant_vs_datasheet_pct"] = datasheet_deviation(
            result.torque_constant, kv_rpm_per_v=spec.kv_rpm_per_v
        )
    return found


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
    sweeps = []
    for angle in spec.angles_rad:
        calibration.run(
            drive,
            move(spec, position_rad=drive.status().position_rad, angle_rad=angle),
            protocol=NAME,
        )
        with cast(AbstractContextManager[Any], locked_rotor()):
            recording = calibration.run(drive, sweep(spec, angle_rad=angle), protocol=NAME)
        sweeps.append(analyse_sweep(recording, spec, angle_rad=angle))
    ripple = [
        (int(h["order"]), float(h["amplitude"]), float(h["phase_rad"]))
        for h in cast(
            list[dict[str, Any]], calibration.details.get("cogging", {}).get("kt_ripple", [])
        )
    ]
    analysed = identify_torque_constant(sweeps, ripple=ripple)
    calibration.details[NAME] = {
        "kt_ripple_correction": "cogging protocol's table" if ripple else "none",
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
