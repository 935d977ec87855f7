"""The Modbus backend against the Modbus emulator (real time, 127.0.0.1)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from conftest import sine
from hil.drives.connect import open_drive
from hil.drives.emulated import builtin_station, modbus_emulator
from hil.drives.emulator_faults import ModbusFaults
from hil.drives.modbus.drive import ModbusDrive
from hil.drives.modbus.regmap import load_register_map
from hil.errors import DriveCommunicationError, DriveFaultError
from hil.profile import UnitProfile

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = pytest.mark.realtime


def test_register_codec_word_order() -> None:
    regmap = load_register_map(builtin_station("regmap_gimbal_hil_servo.toml"))
    position = regmap["position"]  # int32, low word first
    assert position.encode(-1 * position.scale) == [0xFFFF, 0xFFFF]
    assert position.encode(0x00012345 * position.scale) == [0x2345, 0x0001]
    assert regmap["velocity"].encode(0x00012345 * 1e-5) == [0x0001, 0x2345]
    assert regmap.blocks(("status_word", "position", "current")) == [(0, 8)]


def test_sine_over_modbus_tcp(profile: UnitProfile) -> None:
    with open_drive("modbus-emulator", profile=profile, unit_serial="GMB-M1", seed=1) as drive:
        fs = drive.info.max_sample_rate_hz
        assert 10 <= fs <= 500
        drive.enable()
        recording = drive.run(sine(0.5, fs_hz=fs, periods=2))
    assert np.all(np.diff(recording.time_s) > 0)  # host timestamps, irregular
    velocity = recording.columns["velocity_rad_s"]
    assert np.corrcoef(velocity, recording.columns["velocity_cmd_rad_s"])[0, 1] > 0.9
    assert recording.metadata["firmware"] == "1.4"  # major.minor of [firmware] version


def test_rtu_over_socket_url(profile: UnitProfile) -> None:
    with modbus_emulator(profile, seed=1, transport="rtu") as (_, station):
        assert station.serial_port.startswith("socket://")
        with ModbusDrive(station, limits=profile.limits) as drive:
            drive.enable()
            recording = drive.run(sine(0.3, fs_hz=drive.info.max_sample_rate_hz, periods=2))
    assert len(recording) >= 2  # RTU framing here polls slowly (pymodbus serial client)
    assert recording.metadata["transport"].startswith("modbus rtu socket://")


@pytest.mark.parametrize(
    ("faults", "error", "code"),
    [
        (ModbusFaults(exception_after_s=0.3, exception_code=4), DriveFaultError, 4),
        (ModbusFaults(drive_fault_after_s=0.3, drive_fault_code=0x2310), DriveFaultError, 0x2310),
        (ModbusFaults(drop_connection_after_s=0.3), DriveCommunicationError, None),
        (ModbusFaults(stop_answering_after_s=0.3), DriveCommunicationError, None),
    ],
    ids=["exception", "drive-fault", "dropped-connection", "timeout"],
)
def test_faults_mid_run(
    profile: UnitProfile, faults: ModbusFaults, error: type, code: int | None
) -> None:
    # the station's own request timeout (0.5 s, one resend): a shorter one made every request
    # of the run, not only the swallowed ones, time out on a loaded runner (seen at load 8)
    with modbus_emulator(profile, seed=1, faults=faults) as (emulator, station):
        with ModbusDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(error) as caught:
                drive.run(sine(0.5, fs_hz=drive.info.max_sample_rate_hz, periods=2))
            if code is not None:
                assert caught.value.code == code
            partial = caught.value.partial_recording
            assert partial is not None
            assert len(partial) > 0
            assert partial.time_s[-1] < 1.0
        deadline = time.monotonic() + 5.0  # stopped by us, or else by its watchdog (0.5 s)
        while emulator.enabled and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not emulator.enabled
