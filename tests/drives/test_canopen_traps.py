"""canopen 2.4 traps, each reproduced against the emulator with the library's own
BaseNode402, next to the backend handling the same situation."""

from __future__ import annotations

import time

import canopen
import pytest
from canopen.profiles.p402 import BaseNode402

from conftest import sine
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.cia402.emulator import ENABLED, FAULT, SWITCH_ON_DISABLED
from hil.drives.emulated import canopen_emulator
from hil.drives.emulator_faults import CanFaults
from hil.errors import DriveFaultError, DriveStateError
from hil.motion import Mode
from hil.profile import UnitProfile


def _library_node(station: object) -> tuple[canopen.Network, BaseNode402]:
    network = canopen.Network()
    network.connect(interface="virtual", channel=station.channel)  # type: ignore[attr-defined]
    node = BaseNode402(station.node_id, str(station.eds_path))  # type: ignore[attr-defined]
    # these tests are about the library's behaviour, not the link's timing: its 0.3 s SDO
    # default went unanswered once on a loaded CI runner, the emulator's bus thread behind
    # the 1 kHz SYNCs of the harness's drive still connected beside it
    node.sdo.RESPONSE_TIMEOUT = 2.0
    network.add_node(node)
    return network, node


def test_setup_pdos_asserts_on_an_nmt_state_it_has_not_heard(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=1) as (_, station):
        network, node = _library_node(station)
        try:
            assert node.nmt.state == "INITIALISING"  # no heartbeat seen yet: unknown
            with pytest.raises(AssertionError):
                node.setup_pdos()
        finally:
            network.disconnect()
        with CanOpenDrive(station, limits=profile.limits) as drive:  # waits for the heartbeat
            drive.enable()


def test_synchronous_rpdo_is_never_sent_by_the_controlword_setter(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=1) as (emulator, station):
        drive = CanOpenDrive(station, limits=profile.limits)  # maps cw in a SYNC RPDO
        network, node = _library_node(station)
        try:
            node.rpdo.read()
            node.tpdo.read()
            node.setup_pdos(upload=False)
            node.controlword = 0x06  # RPDO type 1 counts as "periodic": not transmitted
            for _ in range(5):
                network.sync.transmit()
                time.sleep(0.01)
            assert emulator.state == SWITCH_ON_DISABLED
        finally:
            network.disconnect()
        with drive:
            drive.enable()  # transmits the RPDO itself before every SYNC
            assert emulator.state == ENABLED


def test_event_tpdo_turns_periodic_and_check_statusword_times_out(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=1) as (_, station):  # EDS default: TPDO1 = event
        network, node = _library_node(station)
        try:
            node.nmt.state = "OPERATIONAL"
            node.tpdo.read()
            node.rpdo.read()
            node.setup_pdos(upload=False)
            for word in (0x06, 0x07):  # two statusword changes -> two event TPDOs
                node.sdo[0x6040].raw = word
                time.sleep(0.05)
            tpdo = node.tpdo_pointers[0x6041].pdo_parent
            assert tpdo.trans_type == 255
            assert tpdo.is_periodic
            with pytest.raises(RuntimeError, match="Timeout"):
                node.check_statusword()
        finally:
            network.disconnect()
        with CanOpenDrive(station, limits=profile.limits) as drive:  # SYNC TPDOs, own count
            drive.enable()


def test_op_mode_setter_swallows_a_refused_switch(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=1, lock_mode_while_enabled=True) as (emulator, station):  # noqa: SIM117
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            network, node = _library_node(station)
            try:
                node.op_mode = "CYCLIC SYNCHRONOUS TORQUE"  # logs a warning, returns
                assert emulator.mode_display == 9  # still velocity
            finally:
                network.disconnect()
            torque = sine(0.0, fs_hz=1000.0)
            torque = type(torque)(name="t", mode=Mode.TORQUE, command=torque.command, fs_hz=1000.0)
            with pytest.raises(DriveStateError, match="0x6061"):
                drive.run(torque)  # the backend reads 0x6061 back and refuses


def test_reset_from_fault_does_not_guarantee_a_clear(profile: UnitProfile) -> None:
    faults = CanFaults(emcy_after_s=0.02, emcy_code=0x7300, fault_persists=True)
    with canopen_emulator(profile, seed=1, faults=faults) as (emulator, station):  # noqa: SIM117
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveFaultError):
                drive.run(sine(0.5, fs_hz=1000.0))
            network, node = _library_node(station)
            try:  # the library: a bare RuntimeError (or nothing) and no code
                with pytest.raises(RuntimeError):
                    node.reset_from_fault()
            finally:
                network.disconnect()
            assert emulator.state == FAULT
            with pytest.raises(DriveFaultError) as caught:
                drive.enable()
            assert caught.value.code == 0x7300
