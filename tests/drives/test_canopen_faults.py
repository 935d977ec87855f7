"""Injected faults over CANopen: a DriveError naming the cause, the partial recording kept,
and the axis left not enabled."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import sine
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.cia402.emulator import ENABLED, FAULT
from hil.drives.emulated import canopen_emulator
from hil.drives.emulator_faults import CanFaults
from hil.errors import DriveCommunicationError, DriveFaultError
from hil.profile import UnitProfile

FS = 1000.0


def test_emcy_mid_run(profile: UnitProfile) -> None:
    faults = CanFaults(emcy_after_s=0.3, emcy_code=0x2310)
    with canopen_emulator(profile, seed=1, faults=faults) as (emulator, station):
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveFaultError, match="0x2310") as caught:
                drive.run(sine(0.5, fs_hz=FS))
            assert caught.value.code == 0x2310
            partial = caught.value.partial_recording
            assert partial is not None
            assert 250 <= len(partial) <= 320  # about 0.3 s of 1 kHz samples
            assert emulator.state == FAULT
        assert emulator.emcy_sent[0] == 0x2310
    assert emulator.state != ENABLED


def test_persistent_fault_is_not_reported_as_cleared(profile: UnitProfile) -> None:
    faults = CanFaults(emcy_after_s=0.05, emcy_code=0x4310, fault_persists=True)
    with canopen_emulator(profile, seed=1, faults=faults) as (emulator, station):  # noqa: SIM117
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveFaultError):
                drive.run(sine(0.5, fs_hz=FS))
            with pytest.raises(DriveFaultError, match="did not clear") as caught:
                drive.enable()
            assert caught.value.code == 0x4310
    assert emulator.state == FAULT


def test_lost_pdos_leave_gaps_not_invented_samples(profile: UnitProfile) -> None:
    faults = CanFaults(drop_tpdo_every=97)
    station_changes = {"pdo_timeout_s": 0.05, "lost_sample_fraction": 0.05}
    with (
        canopen_emulator(profile, seed=1, faults=faults, station_changes=station_changes) as (
            _,
            station,
        ),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable()
        recording = drive.run(sine(0.5, fs_hz=FS, periods=1))
    lost = int(recording.metadata["lost_samples"])
    assert 0 < lost == 500 - len(recording)
    steps = (recording.time_s[1:] - recording.time_s[:-1]) / 1e-3  # in SYNC periods
    # no invented samples: every sample sits on a SYNC count, gaps only where one was lost.
    # Under load a TPDO that arrives after the PDO timeout next to a dropped one is counted
    # lost too (seen: 2 of 9 runs), so a gap may span two SYNCs.
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
    assert 2 <= steps.max() <= 3
    assert int(np.sum(np.round(steps) - 1)) == lost


def test_all_pdos_lost_is_a_communication_error(profile: UnitProfile) -> None:
    faults = CanFaults(drop_all_tpdo_after_s=0.2)
    with canopen_emulator(
        profile, seed=1, faults=faults, station_changes={"pdo_timeout_s": 0.02}
    ) as (emulator, station), CanOpenDrive(station, limits=profile.limits) as drive:
        drive.enable()
        with pytest.raises(DriveCommunicationError, match="no feedback PDOs") as caught:
            drive.run(sine(0.5, fs_hz=FS))
        partial = caught.value.partial_recording
        assert partial is not None
        assert 150 <= len(partial) <= 200
    assert emulator.state != ENABLED


def test_slow_sdo_within_timeout_works_beyond_it_fails_cleanly(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=1, faults=CanFaults(sdo_delay_s=0.02)) as (_, station):  # noqa: SIM117
        with CanOpenDrive(station, limits=profile.limits) as drive:
            assert drive.info.firmware_version == "1.4.0"
    slow = CanFaults(sdo_delay_s=0.5)
    with canopen_emulator(profile, seed=1, faults=slow, station_changes={"sdo_timeout_s": 0.1}) as (
        emulator,
        station,
    ):
        with pytest.raises(DriveCommunicationError, match="0x1017"):
            CanOpenDrive(station, limits=profile.limits)
        assert emulator.state != ENABLED


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_bus_error_mid_run(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=1, faults=CanFaults(bus_error_after_s=0.3)) as (
        emulator,
        station,
    ):
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveCommunicationError, match="bus-off") as caught:
                drive.run(sine(0.5, fs_hz=FS))
            assert caught.value.partial_recording is not None
            assert len(caught.value.partial_recording) >= 250
        assert emulator.state != ENABLED


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_bus_error_between_runs_kills_the_notifier_and_is_noticed(profile: UnitProfile) -> None:
    """The trap: python-can's Notifier thread dies on the error; only network.check() tells."""
    with canopen_emulator(profile, seed=1, faults=CanFaults(bus_error_after_s=0.0)) as (
        emulator,
        station,
    ):
        drive = CanOpenDrive(station, limits=profile.limits)
        try:
            with pytest.raises(DriveCommunicationError, match="bus-off"):
                drive.enable()  # the bus-off arrives while enabling (Notifier receiving)
            assert drive.link.network.notifier is not None
            assert drive.link.network.notifier.exception is not None
        finally:
            drive.quick_stop()  # restarts reception to confirm the stop
            drive.close()
        assert emulator.state != ENABLED
