"""Injected faults over CANopen: a DriveError naming the cause, the partial recording kept,
and the axis left not enabled."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import sine
from hil.drives.cia402.acquire import MAX_CONSECUTIVE_LOST
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.cia402.emulator import ENABLED, FAULT, Cia402Emulator
from hil.drives.emulated import canopen_emulator
from hil.drives.emulator_faults import CanFaults
from hil.errors import DriveCommunicationError, DriveFaultError
from hil.profile import UnitProfile

FS = 1000.0  # the emulator station's SYNC rate: row k answers the run's SYNC k + 1


def _run_sync_reaching(emulator: Cia402Emulator, plant_s: float) -> int:
    """The SYNC of the next run (counted from 1) at which the emulator's time in OPERATION
    ENABLED reaches ``plant_s``: its fault times are on that clock, summed as it sums them
    (one communication period per SYNC), so where a fault lands in a run is a SYNC count,
    however loaded the machine is."""
    period_s = emulator.steps_per_sync() / emulator.fs_hz
    time_s, sync = emulator.time_enabled_s, 0
    while time_s < plant_s:
        time_s += period_s
        sync += 1
    return sync


def _rows(recording: object) -> np.ndarray:
    """The SYNC index (from the run's first SYNC) of each row, from its time stamp."""
    steps = np.asarray(recording.time_s) * FS  # type: ignore[attr-defined]
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)  # on the SYNC count
    return np.round(steps).astype(int)


def test_emcy_mid_run(profile: UnitProfile) -> None:
    faults = CanFaults(emcy_after_s=0.3, emcy_code=0x2310)
    with canopen_emulator(profile, seed=1, faults=faults) as (emulator, station):
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            fault_sync = _run_sync_reaching(emulator, 0.3)
            with pytest.raises(DriveFaultError, match="0x2310") as caught:
                drive.run(sine(0.5, fs_hz=FS))
            assert caught.value.code == 0x2310
            partial = caught.value.partial_recording
            assert partial is not None
            rows = _rows(partial)
            lost = int(partial.metadata["lost_samples"])
            assert len(rows) + lost == rows[-1] + 1  # every SYNC of the run: a row or lost
            # the run stops at the row answering the SYNC the drive faulted at (a later one
            # only if that answer was lost: later than the PDO timeout and an SDO round trip)
            assert fault_sync - 1 <= rows[-1] <= fault_sync - 1 + lost
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
    """Exactly the rows of the SYNCs whose TPDO frame the drive dropped are missing: a late
    answer (a loaded host) is not lost, and no row carries another SYNC's feedback."""
    drop_every = 97
    faults = CanFaults(drop_tpdo_every=drop_every)
    station_changes = {"pdo_timeout_s": 0.05, "lost_sample_fraction": 0.05}
    with (
        canopen_emulator(profile, seed=1, faults=faults, station_changes=station_changes) as (
            emulator,
            station,
        ),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable()
        sent_before = emulator._tpdo_frames  # TPDO1 and TPDO2 answer each SYNC
        excitation = sine(0.5, fs_hz=FS, periods=1)
        recording = drive.run(excitation)
    n = len(excitation.command)
    dropped = {
        k  # the run's SYNC k + 1 sends frames sent_before + 2k + 1 and + 2k + 2
        for k in range(n)
        if any((sent_before + 2 * k + i) % drop_every == 0 for i in (1, 2))
    }
    lost = int(recording.metadata["lost_samples"])
    assert 0 < lost == n - len(recording) == len(dropped)
    assert set(range(n)) - set(_rows(recording)) == dropped  # the gaps sit on those SYNCs


def test_all_pdos_lost_is_a_communication_error(profile: UnitProfile) -> None:
    faults = CanFaults(drop_all_tpdo_after_s=0.2)
    with canopen_emulator(
        profile, seed=1, faults=faults, station_changes={"pdo_timeout_s": 0.02}
    ) as (emulator, station), CanOpenDrive(station, limits=profile.limits) as drive:
        drive.enable()
        silent_sync = _run_sync_reaching(emulator, 0.2)  # the first SYNC left unanswered
        with pytest.raises(DriveCommunicationError, match="no feedback PDOs") as caught:
            drive.run(sine(0.5, fs_hz=FS))
        partial = caught.value.partial_recording
        assert partial is not None
        rows = _rows(partial)
        lost = int(partial.metadata["lost_samples"])
        # SYNCs sent: the answered ones, then one more than MAX_CONSECUTIVE_LOST unanswered
        assert len(rows) + lost == silent_sync - 1 + MAX_CONSECUTIVE_LOST + 1
        # the last row answers the last SYNC the drive answered (an earlier one only if
        # answers were lost: later than the PDO timeout and an SDO round trip)
        lost_before = lost - (MAX_CONSECUTIVE_LOST + 1)
        assert silent_sync - 2 - lost_before <= rows[-1] <= silent_sync - 2
    assert emulator.state != ENABLED


def test_slow_sdo_within_timeout_works_beyond_it_fails_cleanly(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=1, faults=CanFaults(sdo_delay_s=0.02)) as (_, station):  # noqa: SIM117
        with CanOpenDrive(station, limits=profile.limits) as drive:
            assert drive.info.firmware_version == profile.firmware.version
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
            error_sync = _run_sync_reaching(emulator, 0.3)  # answered, then the bus-off
            with pytest.raises(DriveCommunicationError, match="bus-off") as caught:
                drive.run(sine(0.5, fs_hz=FS))
            partial = caught.value.partial_recording
            assert partial is not None
            rows = _rows(partial)
            lost = int(partial.metadata["lost_samples"])
            # the bus-off is queued after the TPDOs answering error_sync (row error_sync - 1)
            # and read while waiting for the next SYNC's answer: that SYNC is counted lost,
            # or its answer was collected first (both seen); an earlier last row only if
            # answers were lost
            assert rows[-1] + 1 <= len(rows) + lost <= rows[-1] + 2  # every SYNC sent
            assert error_sync - 1 - lost <= rows[-1] <= error_sync
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
