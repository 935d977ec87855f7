"""The ODrive backend against the emulator on the wall clock (realtime pacing: the
emulator's own timer sends the feedback, the host answers each set half a period later)."""

from __future__ import annotations

import dataclasses
import time
import uuid

import numpy as np
import pytest

from conftest import sine
from hil.drives.emulated import builtin_station, odrive_emulator
from hil.drives.odrive.drive import OdriveDrive
from hil.drives.odrive.emulator import OdriveEmulator
from hil.drives.odrive.protocol import AxisState
from hil.drives.odrive.station import OdriveStation
from hil.drives.station import load_station
from hil.errors import ProfileError
from hil.profile import UnitProfile

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = pytest.mark.realtime


def test_a_sine_on_the_drives_own_clock(profile: UnitProfile) -> None:
    """With the ODrive's watchdog (0.1 s) on, the host's hold setpoint feeds it between
    runs: a pause of three watchdog times does not trip it."""
    changes = {"pacing": "realtime", "frame_timeout_s": 0.2, "watchdog_timeout_s": 0.1}
    with odrive_emulator(profile, seed=1, station_changes=changes) as (emulator, station):
        with OdriveDrive(station, limits=profile.limits) as drive:
            assert drive.info.max_sample_rate_hz == 500.0
            drive.enable()
            time.sleep(0.3)  # the host analysing between runs
            recording = drive.run(sine(0.5, fs_hz=500.0, periods=2))
            assert emulator.active_errors == 0
        assert emulator.axis_state == AxisState.IDLE
    lost = int(recording.metadata["lost_samples"])
    assert len(recording) + lost == 500
    assert lost <= 10
    assert recording.metadata["pacing"] == "realtime"
    velocity = recording.columns["velocity_rad_s"]
    assert np.corrcoef(velocity, recording.columns["velocity_cmd_rad_s"])[0, 1] > 0.95


def test_a_feedback_period_other_than_the_stations_is_refused(profile: UnitProfile) -> None:
    assert profile.plant is not None
    channel = f"odrive-test-{uuid.uuid4().hex[:8]}"
    station = load_station(builtin_station("station_odrive_emulator.toml"))
    assert isinstance(station, OdriveStation)
    station = dataclasses.replace(station, channel=channel, pacing="realtime")
    emulator = OdriveEmulator(profile.plant, firmware=profile.firmware, fs_hz=4000.0, seed=1,
                              channel=channel, pacing="realtime", feedback_period_ms=4)
    with emulator:  # noqa: SIM117
        with pytest.raises(ProfileError, match=r"encoder_period_ms = 2: .* sends every "
                                               r"(3\.9\d|4|4\.0\d) ms \(odrivetool: "
                                               r"axis0\.config\.can\.encoder_msg_rate_ms"):
            OdriveDrive(station, limits=profile.limits)
