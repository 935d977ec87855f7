"""The ODrive backend (CANSimple 0.6) against the ODrive emulator on python-can's virtual
bus, in lockstep (the emulator steps one feedback period per setpoint: no wall clock)."""

from __future__ import annotations

import dataclasses
import math
import struct
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import sine
from hil.drives.base import Interrupted
from hil.drives.emulated import builtin_station, odrive_emulator
from hil.drives.odrive import protocol as p
from hil.drives.odrive.drive import OdriveDrive
from hil.drives.odrive.emulator import OdriveEmulator, OdriveFaults
from hil.drives.odrive.station import OdriveStation
from hil.drives.station import load_station
from hil.errors import (
    DriveCommunicationError,
    DriveFaultError,
    LimitViolationError,
    ProfileError,
)
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile

FS_HZ = 500.0  # the built-in emulator station's feedback rate (2 ms)


def eventually(condition: Callable[[], bool], within_s: float = 5.0) -> bool:
    """``condition()`` once it holds, polled until ``within_s`` (not a timing assertion: the
    emulator's own thread acts on a frame the backend sent without awaiting an answer)."""
    deadline = time.monotonic() + within_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)
    return condition()


float32s = st.floats(width=32, allow_nan=False, allow_infinity=False)
u32s = st.integers(0, 2**32 - 1)


# -- the protocol ------------------------------------------------------------------------
def test_a_documented_frame() -> None:
    """ODrive's own example: Set_Input_Vel to node 1, -2.5 turns/s, 0.25 N·m feed-forward."""
    assert p.arbitration_id(1, p.Cmd.SET_INPUT_VEL) == 0x02D
    assert p.encode_float_pair(-2.5, 0.25) == bytes.fromhex("000020c00000803e")
    assert p.split_id(0x021) == (1, p.Cmd.HEARTBEAT)
    beat = p.decode_heartbeat(bytes.fromhex("0100008008000100"))
    assert beat == p.Heartbeat(0x80000001, 8, 0, True)


@given(node=st.integers(0, p.NODE_ID_MAX), cmd=st.sampled_from(list(p.Cmd)))
def test_arbitration_ids_round_trip(node: int, cmd: p.Cmd) -> None:
    arbitration = p.arbitration_id(node, cmd)
    assert arbitration < 0x800  # 11 bits
    assert p.split_id(arbitration) == (node, cmd)


@given(first=float32s, second=float32s, a=u32s, b=u32s)
def test_payloads_round_trip(first: float, second: float, a: int, b: int) -> None:
    assert p.decode_float_pair(p.encode_float_pair(first, second)) == (first, second)
    assert p.decode_float(p.encode_float(first)) == first
    assert p.decode_u32_pair(p.encode_u32_pair(a, b)) == (a, b)
    assert p.decode_u32(p.encode_u32(a)) == a


@given(error=u32s, state=st.integers(0, 255), result=st.integers(0, 255), done=st.booleans())
def test_heartbeat_round_trip(error: int, state: int, result: int, done: bool) -> None:
    beat = p.Heartbeat(error, state, result, done)
    data = p.encode_heartbeat(beat)
    assert len(data) == 8
    assert p.decode_heartbeat(data) == beat


@given(pos=float32s, vel_ff=st.integers(-32767, 32767), torque_ff=st.integers(-32767, 32767))
def test_input_pos_round_trip(pos: float, vel_ff: int, torque_ff: int) -> None:
    data = p.encode_input_pos(pos, vel_ff * p.FF_SCALE, torque_ff * p.FF_SCALE)
    back = p.decode_input_pos(data)
    assert back[0] == pos
    assert back[1:] == pytest.approx((vel_ff * p.FF_SCALE, torque_ff * p.FF_SCALE), abs=1e-9)


@given(node=st.integers(0, p.NODE_ID_MAX), serial=st.integers(0, 2**48 - 1))
def test_address_and_version_round_trip(node: int, serial: int) -> None:
    assert p.decode_address(p.encode_address(node, serial)) == (node, serial)
    version = p.Version(2, 4, 1, 0, 0, 6, 10, 0)
    assert p.decode_version(p.encode_version(version)).firmware == "0.6.10"


def test_error_names_name_every_flag() -> None:
    assert p.error_names(0) == "NONE"
    assert p.error_names(0x20 | 0x2000000) == "DRV_FAULT | ESTOP_REQUESTED"
    assert p.error_names(0x80) == "0x80"
    with pytest.raises(DriveCommunicationError, match="Heartbeat: 3 bytes"):
        p.decode_heartbeat(b"\0\0\0")
    with pytest.raises(ValueError, match="torque feed-forward 40"):
        p.encode_input_pos(0.0, 0.0, 40.0)
    assert struct.unpack("<f", p.encode_float(math.pi))[0] == p.float32(math.pi)


# -- the backend over the emulator -------------------------------------------------------
def test_bring_up_and_state_machine(profile: UnitProfile) -> None:
    with odrive_emulator(profile, seed=1, serial=0xABCD) as (emulator, station):
        with OdriveDrive(station, limits=profile.limits) as drive:
            info = drive.info
            assert (info.vendor, info.firmware_version, info.serial) == (
                "ODrive Robotics", "0.6.10", "00000000ABCD")
            assert info.max_sample_rate_hz == FS_HZ
            assert info.transport.startswith("odrive cansimple virtual gimbal-hil-")
            assert emulator.vel_limit_turns_s == pytest.approx(3.0 * 1.25 / (2 * math.pi))
            assert emulator.axis_state == p.AxisState.IDLE
            assert drive.status().state.value == "disabled"
            drive.enable(Mode.TORQUE)
            assert emulator.axis_state == p.AxisState.CLOSED_LOOP_CONTROL
            assert emulator.control_mode == p.ControlMode.TORQUE_CONTROL
            assert drive.status().state.value == "enabled"
            drive.disable()
            assert emulator.axis_state == p.AxisState.IDLE
            drive.enable()
            assert emulator.control_mode == p.ControlMode.VELOCITY_CONTROL
        assert emulator.axis_state == p.AxisState.IDLE  # close leaves it IDLE


def test_velocity_run_is_recorded_in_si_units_at_the_feedback_rate(
        profile: UnitProfile) -> None:
    excitation = sine(0.8, fs_hz=FS_HZ, periods=2)
    with odrive_emulator(profile, seed=2) as (emulator, station):  # noqa: SIM117
        with OdriveDrive(station, limits=profile.limits) as drive:
            drive.enable()
            recording = drive.run(excitation)
            truth_rad = emulator.plant.position_rad
            periods = emulator.periods
    n = len(excitation.command)
    assert len(recording) == n
    np.testing.assert_allclose(recording.time_s, np.arange(n) / FS_HZ)
    velocity = recording.columns["velocity_rad_s"]
    command = recording.columns["velocity_cmd_rad_s"]
    np.testing.assert_array_equal(command, excitation.command)
    assert np.corrcoef(velocity, command)[0, 1] > 0.98
    assert np.max(np.abs(velocity)) == pytest.approx(0.8, rel=0.1)  # rad/s, not turns/s
    position = recording.columns["position_rad"]
    assert abs(position[-1] - truth_rad) < 0.005  # rad: the plant's own angle
    assert np.max(np.abs(position)) == pytest.approx(2 * 0.8 / (2 * math.pi * 2), rel=0.15)
    torque, current = recording.columns["torque_nm"], recording.columns["current_a"]
    assert np.max(np.abs(torque)) > 0.02  # N·m: J·ω·2πf + friction
    assert np.corrcoef(torque, 0.1 * current)[0, 1] > 0.95  # K_t = 0.1 N·m/A
    meta = recording.metadata
    assert meta["torque_source"].startswith("Get_Torques Torque_Target")
    assert (meta["lost_samples"], meta["pacing"], meta["feedback_period_s"]) == (
        "0", "lockstep", "0.002")
    assert meta["control_period_s"] == "0.00025"
    assert periods >= n  # one emulated period per row at least


def test_torque_and_position_runs(profile: UnitProfile) -> None:
    t = np.arange(100) / FS_HZ
    torque = Excitation(name="pulse", mode=Mode.TORQUE, fs_hz=FS_HZ,
                        command=np.where(t < 0.1, 0.05, -0.05))
    with odrive_emulator(profile, seed=3) as (emulator, station):  # noqa: SIM117
        with OdriveDrive(station, limits=profile.limits) as drive:
            drive.enable(Mode.TORQUE)
            pushed = drive.run(torque)
            assert emulator.control_mode == p.ControlMode.TORQUE_CONTROL
            start = drive.status().position_rad
            move = Excitation(name="move", mode=Mode.POSITION, fs_hz=FS_HZ,
                              command=start + 0.1 * (1 - np.cos(np.pi * t / t[-1])) / 2)
            moved = drive.run(move)
            assert emulator.control_mode == p.ControlMode.POSITION_CONTROL
    assert np.max(pushed.columns["velocity_rad_s"]) > 0.2  # 0.05 N·m on 3.6e-3 kg·m²
    assert moved.columns["position_rad"][-1] == pytest.approx(start + 0.1, abs=0.02)


def test_a_lockstep_run_does_not_depend_on_how_fast_the_frames_come(
        profile: UnitProfile) -> None:
    """Lockstep has no wall clock: feedback frames that come late (past the host's brief
    wait, so it asks the node to settle) give the same rows, bit for bit, through a hold
    and a change of mode between the runs."""
    t = np.arange(200) / FS_HZ
    runs = []
    for faults in (None, OdriveFaults(late_frames_every=7, late_frames_s=0.015)):
        with odrive_emulator(profile, seed=4, faults=faults) as (emulator, station):  # noqa: SIM117
            with OdriveDrive(station, limits=profile.limits) as drive:
                drive.enable()
                first = drive.run(sine(0.6, fs_hz=FS_HZ, periods=1))
                start = drive.status().position_rad
                move = Excitation(name="move", mode=Mode.POSITION, fs_hz=FS_HZ,
                                  command=start - 0.05 * (1 - np.cos(np.pi * t / t[-1])) / 2)
                moved = drive.run(move)
                again = drive.run(sine(0.6, fs_hz=FS_HZ, periods=1))
                runs.append(([first, moved, again], emulator.periods, emulator.setpoints))
    (punctual, periods, setpoints), (late, late_periods, late_setpoints) = runs
    assert (late_periods, late_setpoints) == (periods, setpoints)
    assert periods == setpoints  # one period per setpoint, each answered before the next
    for ran, ran_late in zip(punctual, late, strict=True):
        assert ran.metadata["lost_samples"] == ran_late.metadata["lost_samples"] == "0"
        for name, column in ran.columns.items():
            np.testing.assert_array_equal(column, ran_late.columns[name], err_msg=name)


def test_an_axis_error_is_a_fault_naming_it(profile: UnitProfile) -> None:
    faults = OdriveFaults(axis_error_after_s=0.3, axis_error=int(p.OdriveError.DRV_FAULT))
    with odrive_emulator(profile, seed=1, faults=faults) as (emulator, station):  # noqa: SIM117
        with OdriveDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveFaultError, match="axis error DRV_FAULT at t = ") as caught:
                drive.run(sine(0.5, fs_hz=FS_HZ, periods=2))
            assert caught.value.code == 0x20
            assert "disarm reason DRV_FAULT" in str(caught.value)
            partial = caught.value.partial_recording
            assert partial is not None
            assert 0.2 < partial.time_s[-1] < 0.6  # a heartbeat after the trip
            assert emulator.axis_state == p.AxisState.IDLE
            drive.enable()  # Clear_Errors, then closed loop again
            assert emulator.active_errors == 0
            assert emulator.axis_state == p.AxisState.CLOSED_LOOP_CONTROL


def test_a_stopped_heartbeat_is_a_communication_error(profile: UnitProfile) -> None:
    faults = OdriveFaults(heartbeat_stops_after_s=0.2)
    changes = {"quick_stop_timeout_s": 0.2}
    with odrive_emulator(profile, seed=1, faults=faults, station_changes=changes) as (  # noqa: SIM117
            emulator, station):
        with OdriveDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveCommunicationError, match=r"no heartbeat for 0\.5"):
                drive.run(sine(0.5, fs_hz=FS_HZ, periods=4))
            # IDLE cannot be confirmed without a heartbeat: Estop (the emulator's thread
            # takes it from the bus after the backend has returned)
            assert eventually(lambda: emulator.axis_state == p.AxisState.IDLE)
            assert emulator.active_errors & p.OdriveError.ESTOP_REQUESTED


def test_lost_rows_are_gaps_and_too_many_end_the_run(profile: UnitProfile) -> None:
    few = OdriveFaults(drop_torques_every=97)
    with odrive_emulator(profile, seed=1, faults=few) as (_, station):  # noqa: SIM117
        with OdriveDrive(station, limits=profile.limits) as drive:
            drive.enable()
            recording = drive.run(sine(0.5, fs_hz=FS_HZ, periods=2))
    lost = int(recording.metadata["lost_samples"])
    assert 4 <= lost <= 6  # one period in 97 of 500: within 2 % (10 rows)
    assert len(recording) == 500 - lost
    assert np.max(np.diff(recording.time_s)) == pytest.approx(2 / FS_HZ)
    many = OdriveFaults(drop_torques_every=10)
    with odrive_emulator(profile, seed=1, faults=many) as (emulator, station):  # noqa: SIM117
        with OdriveDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveCommunicationError, match=r"11 of 500 rows .* lost"):
                drive.run(sine(0.5, fs_hz=FS_HZ, periods=2))
            assert emulator.axis_state == p.AxisState.IDLE


def test_a_runaway_trips_the_motion_monitor(profile: UnitProfile) -> None:
    push = Excitation(name="push", mode=Mode.TORQUE, fs_hz=FS_HZ, command=np.full(1000, 0.4))
    with odrive_emulator(profile, seed=1) as (emulator, station):  # noqa: SIM117
        with OdriveDrive(station, limits=profile.limits) as drive:
            drive.enable(Mode.TORQUE)
            with pytest.raises(LimitViolationError, match=r"velocity .* exceeds the limit 3 rad"):
                drive.run(push)
            assert emulator.axis_state == p.AxisState.IDLE
            assert abs(emulator.plant.velocity_rad_s) < 0.05  # braked, then IDLE
            assert drive.status().state.value == "disabled"  # IDLE after every error


# -- the station file and the bring-up checks -------------------------------------------
STATION = """
[odrive]
interface = "virtual"
channel = "x"
node_id = 3
torque_constant_nm_a = 0.1
"""


@pytest.mark.parametrize(("old", "new", "message"), [
    ("node_id = 3", "node_id = 99", r"\[odrive\] 'node_id': must be 0\.\.63 \(six bits\), got 99"),
    ("torque_constant_nm_a = 0.1", "", r"\[odrive\] lacks 'torque_constant_nm_a'"),
    ('channel = "x"', 'channel = "x"\nencoder_period = 2',
     r"\[odrive\] has an unknown setting 'encoder_period' \(did you mean 'encoder_period_ms'"),
    ("node_id = 3", "node_id = 3\niq_period_ms = 5",
     r"\[odrive\] 'iq_period_ms': must equal encoder_period_ms \(2 ms\)"),
    ("node_id = 3", 'node_id = 3\npacing = "sync"',
     r"\[odrive\] 'pacing': must be one of realtime, lockstep, got 'sync'"),
    ("node_id = 3", "node_id = 3\nheartbeat_timeout_s = 0.1",
     r"'heartbeat_timeout_s': must be more than two heartbeat periods \(200 ms\)"),
    ("node_id = 3", "node_id = 3\nbitrate = 125000\nencoder_period_ms = 1\n"
                    "iq_period_ms = 1\ntorques_period_ms = 1",
     r"'encoder_period_ms': the cyclic messages and commands take 433% of a 125 kbit/s"),
], ids=["node-id", "missing-kt", "misspelt", "iq-period", "pacing", "heartbeat", "bus-load"])
def test_a_bad_station_file_is_refused_in_one_line(tmp_path: Path, old: str, new: str,
                                                   message: str) -> None:
    path = tmp_path / "station.toml"
    assert old in STATION
    path.write_text(STATION.replace(old, new), encoding="utf-8")
    with pytest.raises(ProfileError, match=message) as caught:
        load_station(path)
    text = str(caught.value)
    assert "\n" not in text
    assert text.startswith(f"{path}: [odrive]")


def test_equipment_an_odrive_cannot_serve_is_refused(tmp_path: Path,
                                                    profile: UnitProfile) -> None:
    path = tmp_path / "station.toml"
    path.write_text(STATION + "\n[locked_rotor]\noutput_bit = 0\ncheck_torque_nm = 0.05\n",
                    encoding="utf-8")
    station = load_station(path)
    assert isinstance(station, OdriveStation)
    with pytest.raises(ProfileError, match=r"station\.toml: \[locked_rotor\] is not served "
                                           r"over an ODrive"):
        OdriveDrive(station, limits=profile.limits)


def test_the_shipped_stations_load() -> None:
    example = load_station(builtin_station("station_odrive_example.toml"))
    emulator = load_station(builtin_station("station_odrive_emulator.toml"))
    assert isinstance(example, OdriveStation)
    assert isinstance(emulator, OdriveStation)
    assert (example.pacing, emulator.pacing) == ("realtime", "lockstep")
    assert example.bus_load < 0.6


def test_a_heartbeat_other_than_the_stations_is_refused(profile: UnitProfile) -> None:
    channel = f"odrive-test-{uuid.uuid4().hex[:8]}"
    assert profile.plant is not None
    station = dataclasses.replace(
        load_station(builtin_station("station_odrive_emulator.toml")), channel=channel)
    assert isinstance(station, OdriveStation)
    for period_ms, message in ((50, r"heartbeat_period_ms = 100: .* sends every 50 ms "
                                    r"\(odrivetool: axis0\.config\.can\.heartbeat_msg_rate_ms"),
                               (0, r"heartbeat_period_ms = 100: .* sent no heartbeat")):
        with OdriveEmulator(profile.plant, firmware=profile.firmware, fs_hz=4000.0, seed=1,
                            channel=channel, heartbeat_period_ms=period_ms) as emulator:
            with pytest.raises(ProfileError, match=message):
                OdriveDrive(station, limits=profile.limits)
            assert emulator.axis_state == p.AxisState.IDLE


def test_a_stop_signal_brakes_the_axis_and_keeps_the_rows(
        profile: UnitProfile, monkeypatch: pytest.MonkeyPatch) -> None:
    with odrive_emulator(profile, seed=1) as (emulator, station):  # noqa: SIM117
        with OdriveDrive(station, limits=profile.limits) as drive:
            drive.enable()
            send = drive.link.command
            sent = [0]

            def command(cmd: int, data: bytes) -> None:  # SIGINT arrives at the 300th setpoint
                sent[0] += 1
                if sent[0] == 300:
                    raise KeyboardInterrupt
                send(cmd, data)

            monkeypatch.setattr(drive.link, "command", command)
            with pytest.raises(Interrupted) as caught:
                drive.run(sine(1.0, fs_hz=FS_HZ, periods=2, frequency_hz=1.0))
            monkeypatch.undo()
            partial = caught.value.partial_recording
            assert partial is not None
            assert len(partial) == 300
            assert emulator.axis_state == p.AxisState.IDLE
            assert abs(emulator.plant.velocity_rad_s) < 0.05  # braked before IDLE
            assert emulator.active_errors == 0  # no Estop was needed
