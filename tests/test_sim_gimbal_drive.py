"""The simulator as a whole gimbal: the axis under test and the gimbal's other axis in one
two-axis plant, the other held by its own drive and moved for real (issue 27)."""

from __future__ import annotations

import numpy as np
import pytest

from hil.drives.base import Capability
from hil.drives.connect import open_drive
from hil.errors import DriveStateError, LimitViolationError
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile, load_profile

AZIMUTH = load_profile("demo_gimbal_azimuth")
ELEVATION = load_profile("demo_gimbal_elevation")


def _sine(profile: UnitProfile, name: str) -> Excitation:
    fs = profile.sample_rate_hz
    t = np.arange(int(fs)) / fs
    return Excitation(name=name, mode=Mode.VELOCITY, fs_hz=fs,
                      command=0.5 * np.sin(2 * np.pi * 2.0 * t))


def test_the_azimuth_moves_the_elevation_for_real_and_its_records_say_where() -> None:
    with open_drive("sim", profile=AZIMUTH, unit_serial="SIM-0001",
                    gimbal_axes={"elevation": ELEVATION}) as drive:
        assert Capability.ELEVATION_AXIS in drive.info.capabilities
        assert Capability.ELEVATION_MOTION in drive.info.capabilities
        drive.enable()
        before = drive.status().position_rad
        drive.set_elevation(0.6)
        # the azimuth held its place while the elevation drive moved the stage
        assert abs(drive.status().position_rad - before) < 1e-3
        recording = drive.run(_sine(AZIMUTH, "sine_at_0.6"))
        drive.set_elevation(-0.3)
        second = drive.run(_sine(AZIMUTH, "sine_at_-0.3"))
        here = drive.status().position_rad
        with pytest.raises(LimitViolationError):  # beyond the elevation's travel (±1.4 rad)
            drive.set_elevation(1.6)
        assert drive.status().position_rad == here  # nothing moved
    assert recording.metadata["held_axes"] == (
        "elevation (simulated, held by its drive) at +0.6000 rad")
    assert second.metadata["held_axes"] == (
        "elevation (simulated, held by its drive) at -0.3000 rad")
    # the same sine needs more torque where the azimuth's inertia is larger (level)
    assert np.std(second.effort) > np.std(recording.effort)


def test_the_elevation_under_test_has_no_elevation_to_move() -> None:
    with open_drive("sim", profile=ELEVATION, unit_serial="SIM-0001",
                    gimbal_axes={"azimuth": AZIMUTH}) as drive:
        assert Capability.ELEVATION_AXIS not in drive.info.capabilities
        assert Capability.ELEVATION_MOTION not in drive.info.capabilities
        drive.enable()
        with pytest.raises(DriveStateError, match="elevation axis"):
            drive.set_elevation(0.3)
        recording = drive.run(_sine(ELEVATION, "sine"))
    assert recording.metadata["held_axes"] == (
        "azimuth (simulated, held by its drive) at +0.0000 rad")


def test_a_one_axis_unit_is_simulated_alone_as_before() -> None:
    with open_drive("sim", profile=AZIMUTH, unit_serial="SIM-0001") as alone, \
            open_drive("sim", profile=AZIMUTH, unit_serial="SIM-0001",
                       gimbal_axes={"elevation": ELEVATION}) as coupled:
        recordings = []
        for drive in (alone, coupled):
            drive.enable()
            recordings.append(drive.run(_sine(AZIMUTH, "sine")))
    assert "held_axes" not in recordings[0].metadata
    # the held elevation stands still under the azimuth's sine: the same recording
    np.testing.assert_allclose(recordings[1].effort, recordings[0].effort, atol=1e-9)
