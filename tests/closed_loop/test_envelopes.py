"""The closed-loop protocols stay inside both demo units' limits from any start position."""

from __future__ import annotations

import numpy as np
import pytest

from hil.drives.base import DriveInfo, check_limits
from hil.motion import Excitation, Mode
from hil.profile import load_profile
from hil.suite import cogging_compensation, standstill, tracking, velocity_loop_frf, velocity_step


@pytest.mark.parametrize("name", ["demo_gimbal_elevation", "demo_gimbal_azimuth"])
@pytest.mark.parametrize("fraction", [0.0, 0.3, 0.5, 1.0])
def test_every_closed_loop_excitation_is_inside_the_limits(name: str, fraction: float) -> None:
    profile = load_profile(name)
    limits = profile.limits
    info = DriveInfo(vendor="t", model="t", firmware_version="0", serial="0",
                     rated_torque_nm=0.5, limits=limits, modes=tuple(Mode),
                     max_sample_rate_hz=profile.sample_rate_hz)
    start = limits.travel_min_rad + fraction * (limits.travel_max_rad - limits.travel_min_rad)

    def run_from(position: float, *runs: Excitation) -> None:
        for run in runs:
            check_limits(run, limits, start_position_rad=position)
            if run.mode is Mode.VELOCITY:
                position += float(np.sum(run.command)) / run.fs_hz
            else:
                position = float(run.command[-1])

    frf = velocity_loop_frf.Spec.from_profile(profile, info)
    run_from(start, *velocity_loop_frf.excitation(frf, position_rad=start))
    step = velocity_step.Spec.from_profile(profile, info)
    run_from(start, *velocity_step.excitation(step, position_rad=start))
    track = tracking.Spec.from_profile(profile, info)
    for move in tracking.excitation(track, viscous_nm_s_rad=0.005, coulomb_nm=0.02):
        run_from(start, track.move_to_start(start, hold_s=0.2), move)
    hold = standstill.Spec.from_profile(profile, info)
    run_from(start, standstill.excitation(hold, position_rad=start))
    cog = cogging_compensation.Spec.from_profile(profile, info)
    for run in cogging_compensation.excitation(cog):
        run_from(start, cog.move_to_start(start, hold_s=0.2), run)
