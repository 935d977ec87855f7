"""The staircase, sweep and pass protocols stay inside the demo unit's limits from any start
position (the drive keeps its position between protocols)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hil.drives.base import check_limits
from hil.motion import Mode
from hil.profile import load_profile
from hil.suite import cogging as cogging_suite
from hil.suite import gravity_cable as gravity_cable_suite
from hil.suite import stribeck as stribeck_suite
from tests.helpers import drive_info

PROFILE = load_profile()
# the demo's cogging protocol analyses the gravity sweep's passes (no motion of its own):
# its own passes are checked with a table that asks for them
OWN_PASSES = dataclasses.replace(PROFILE, protocols={
    **PROFILE.protocols, "cogging": {**PROFILE.protocols["cogging"], "passes": "own",
                                     "speed_rad_s": 0.6}})
INFO = drive_info(PROFILE, PROFILE.sample_rate_hz)
MODULES = (stribeck_suite, gravity_cable_suite, cogging_suite)


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
@pytest.mark.parametrize("start", [-1.4, -0.7, 0.0, 0.9, 1.4])
def test_every_excitation_is_inside_the_limits(module: object, start: float) -> None:
    spec = module.Spec.from_profile(OWN_PASSES, INFO)  # type: ignore[attr-defined]
    move, main = module.excitation(spec, position_rad=start)  # type: ignore[attr-defined]
    check_limits(move, PROFILE.limits, start_position_rad=start)
    assert move.command[-1] == pytest.approx(spec.excitation_start_rad)
    check_limits(main, PROFILE.limits, start_position_rad=spec.excitation_start_rad)
    assert main.mode is Mode.VELOCITY
    assert np.all(np.isfinite(main.command))


@pytest.mark.parametrize("start", [-1.4, 0.0, 1.4])
def test_cogging_from_the_sweep_moves_nothing(start: float) -> None:
    spec = cogging_suite.Spec.from_profile(PROFILE, INFO)
    assert spec.passes == cogging_suite.SWEEP_PASSES
    assert cogging_suite.excitation(spec, position_rad=start) == []
