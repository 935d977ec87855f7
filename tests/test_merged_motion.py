"""One motion serving two identifications: the cogging protocol analysing the gravity
sweep's up and down passes (no motion of its own), on the simulator with noise,
quantisation, lag, gravity, the cable and the K_t ripple on; the truth is drawn and hidden
from the analysis."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import hil.suite.cogging as cogging
import hil.suite.gravity_cable as gravity
from hil.calibration import CalibrationRun
from hil.drives.base import DriveInfo
from hil.drives.sim import SimDrive
from hil.errors import IdentificationError, ProfileError
from hil.measurement import MethodBiasMap
from hil.profile import UnitProfile, load_profile
from plant_sim.params import Harmonic

ELEVATION = load_profile("demo_gimbal_elevation")
NO_MAP = MethodBiasMap(source="off", sha256="", entries={})


def _calibration(profile: UnitProfile, tmp_path: Path) -> CalibrationRun:
    return CalibrationRun(profile=profile, unit_serial="MERGE-1", out_dir=tmp_path,
                          drive_kind="sim", method_bias=NO_MAP)


def _drawn_unit(seed: int) -> UnitProfile:
    """The elevation demo with its cogging and K_t ripple drawn (orders, sizes, phases)."""
    rng = np.random.default_rng(seed)
    assert ELEVATION.plant is not None
    plant = dataclasses.replace(
        ELEVATION.plant,
        cogging=(Harmonic(order=int(rng.choice([36, 72, 84, 96])),
                          amplitude=float(rng.uniform(2e-4, 6e-4)),
                          phase_rad=float(rng.uniform(0, 2 * math.pi))),),
        kt_ripple=(Harmonic(order=int(rng.choice([30, 42, 48])),
                            amplitude=float(rng.uniform(0.006, 0.02)),
                            phase_rad=float(rng.uniform(0, 2 * math.pi))),),
    )
    return dataclasses.replace(ELEVATION, plant=plant)


@pytest.mark.parametrize("seed", [3, 17])
def test_cogging_from_the_gravity_sweep_finds_the_hidden_ripple(seed: int,
                                                                tmp_path: Path) -> None:
    unit = _drawn_unit(seed)
    assert unit.plant is not None
    calibration = _calibration(unit, tmp_path)
    with SimDrive(unit.plant, firmware=unit.firmware, limits=unit.limits,
                  fs_hz=unit.sample_rate_hz, seed=seed) as drive:
        drive.enable()
        spec = gravity.Spec.from_profile(unit, drive.info)
        for excitation in gravity.excitation(spec, position_rad=drive.status().position_rad):
            calibration.run(drive, excitation, protocol=gravity.NAME)
        passes = cogging.Spec.from_profile(unit, drive.info)
        assert cogging.excitation(passes, position_rad=0.0) == []  # no motion of its own
        position, torque, path, _ = cogging.sweep_passes(calibration, unit, drive.info)
    assert path.endswith("gravity_cable__sweep.csv.gz")
    found = cogging.analyse(np.arange(len(position)) / passes.fs_hz, position, torque, passes,
                            inertia_kg_m2=unit.measurement("inertia_kg_m2").nominal)
    gain = 1.0 + unit.plant.torque_constant_error_rel  # results are in reported torque
    cog, ripple = unit.plant.cogging[0], unit.plant.kt_ripple[0]
    assert max(found.cogging, key=lambda h: h.amplitude).order == cog.order
    assert max(found.kt_ripple, key=lambda h: h.amplitude).order == ripple.order
    assert found.cogging_peak.value == pytest.approx(cog.amplitude / gain, rel=0.2)
    assert found.kt_ripple_peak.value == pytest.approx(100 * ripple.amplitude, rel=0.3)


def test_cogging_from_the_sweep_takes_its_speed_and_travel_and_refuses_its_own_speed() -> None:
    info = _info(ELEVATION)
    sweep = gravity.Spec.from_profile(ELEVATION, info)
    spec = cogging.Spec.from_profile(ELEVATION, info)
    assert spec.passes == cogging.SWEEP_PASSES
    assert spec.speed_rad_s == sweep.speed_rad_s
    assert spec.pass_samples == sweep.plan.up[1] - sweep.plan.up[0]
    assert spec.pass_range_rad == (sweep.start_rad, sweep.stop_rad)
    protocols = {**ELEVATION.protocols,
                 "cogging": {**ELEVATION.protocols["cogging"], "speed_rad_s": 0.6}}
    with pytest.raises(ProfileError, match=r"speed_rad_s.*is the sweep's"):
        cogging.Spec.from_profile(dataclasses.replace(ELEVATION, protocols=protocols), info)


def test_cogging_from_the_sweep_without_a_sweep_says_what_is_missing(tmp_path: Path) -> None:
    with pytest.raises(IdentificationError, match="needs the gravity_cable protocol's"):
        cogging.sweep_passes(_calibration(ELEVATION, tmp_path), ELEVATION, _info(ELEVATION))


def _info(profile: UnitProfile) -> DriveInfo:
    assert profile.plant is not None
    with SimDrive(profile.plant, firmware=profile.firmware, limits=profile.limits,
                  fs_hz=profile.sample_rate_hz, seed=0) as drive:
        return drive.info
