"""The CiA 402 backend against the CANopen emulator: real frames on a python-can bus."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import sine
from hil.drives.base import DriveState
from hil.drives.canopen_map import load_object_map
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.cia402.emulator import ENABLED, SWITCH_ON_DISABLED
from hil.drives.connect import open_drive
from hil.drives.emulated import canopen_emulator
from hil.drives.sim import SimDrive
from hil.errors import DriveStateError, LimitViolationError, ProfileError
from hil.identify.inertia_friction import identify_inertia_friction
from hil.identify.sine_run import analyse_sine_run
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile


def _identify(drive: object, fs_hz: float) -> object:
    recordings = []
    for amplitude in (0.5, 1.0):
        recordings.append(drive.run(sine(amplitude, fs_hz=fs_hz, periods=6)))  # type: ignore[attr-defined]
    runs = [analyse_sine_run(r, frequency_hz=2.0, settle_periods=1) for r in recordings]
    return identify_inertia_friction(runs), recordings


def test_sine_over_canopen_agrees_with_simdrive(profile: UnitProfile) -> None:
    """Same plant, same tolerances: J, B, T_c over CANopen frames (1 kHz SYNC) agree with
    the in-process simulator (4 kHz) within their uncertainties."""
    with open_drive("canopen-emulator", profile=profile, unit_serial="GMB-T1", seed=7) as drive:
        assert drive.info.max_sample_rate_hz == pytest.approx(1000.0)
        drive.enable()
        over_can, recordings = _identify(drive, drive.info.max_sample_rate_hz)
    assert profile.plant is not None
    sim = SimDrive(profile.plant, firmware=profile.firmware, limits=profile.limits,
                   fs_hz=profile.sample_rate_hz, seed=7)
    sim.enable()
    in_process, _ = _identify(sim, profile.sample_rate_hz)
    for name in ("inertia", "viscous", "coulomb"):
        a, b = getattr(over_can, name), getattr(in_process, name)
        # within the uncertainty, or within the accuracy the method declares (1 kHz SYNC
        # sampling vs 4 kHz is a small systematic difference: ~0.4 % on J)
        combined = math.hypot(a.standard_uncertainty, b.standard_uncertainty)
        accuracy = profile.measurement(a.name).accuracy_rel or 0.0
        assert abs(a.value - b.value) < max(3 * combined, accuracy * abs(b.value)), (a, b)
        spec = profile.measurement(a.name)
        assert spec.lower_limit < a.value < spec.upper_limit
    rec = recordings[0]
    assert set(rec.columns) >= {
        "time_s",
        "position_rad",
        "velocity_rad_s",
        "torque_nm",
        "velocity_cmd_rad_s",
        "current_a",
    }
    assert np.allclose(np.diff(rec.time_s), 1e-3)  # times from the SYNC count
    assert rec.metadata["drive"] == "canopen node 5"
    assert rec.metadata["firmware"] == profile.firmware.version  # 0x100A, from [firmware]
    assert rec.metadata["operation_mode"] == "9"  # cyclic synchronous velocity
    assert rec.metadata["lost_samples"] == "0"


def test_limits_refused_before_any_motion(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=1) as (emulator, station):
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            syncs, position = emulator.sync_count, emulator.plant.position_rad
            too_fast = sine(2 * profile.limits.velocity_rad_s, fs_hz=1000.0)
            with pytest.raises(LimitViolationError):
                drive.run(too_fast)
            assert emulator.sync_count == syncs  # not one SYNC went out
            assert emulator.plant.position_rad == position
            with pytest.raises(DriveStateError, match="1000 Hz"):
                drive.run(sine(0.5, fs_hz=4000.0))
        assert emulator.state == SWITCH_ON_DISABLED or emulator.state == "READY TO SWITCH ON"


def test_drive_recorder_at_the_loop_rate(profile: UnitProfile) -> None:
    """Above the 1 kHz stream: waveform table down, trace buffer up by segmented SDO."""
    with (
        canopen_emulator(profile, seed=2, station_changes={"acquisition": "auto"}) as (
            _emulator,
            station,
        ),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        assert drive.info.max_sample_rate_hz == pytest.approx(4000.0)
        drive.enable()
        excitation = sine(0.5, fs_hz=4000.0, periods=1)
        recording = drive.run(excitation)
    assert len(recording) == len(excitation.command)
    assert recording.metadata["acquisition"] == "drive recorder"
    assert np.allclose(np.diff(recording.time_s), 1 / 4000.0)
    velocity, command = recording.columns["velocity_rad_s"], excitation.command
    assert np.corrcoef(velocity, command)[0, 1] > 0.95


def test_profile_velocity_when_the_drive_lacks_cyclic_modes(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=3, supported_modes=0x000D) as (emulator, station):  # noqa: SIM117
        with CanOpenDrive(station, limits=profile.limits) as drive:
            assert Mode.POSITION not in drive.info.modes
            drive.enable()
            assert emulator.mode_display == 3
            recording = drive.run(sine(0.5, fs_hz=1000.0, periods=1))
            assert recording.metadata["operation_mode"] == "3"
            torque = Excitation(name="t", mode=Mode.TORQUE, command=np.zeros(50), fs_hz=1000.0)
            drive.run(torque)
            assert emulator.mode_display == 4


def test_quick_stop_brings_the_axis_to_rest(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=4) as (emulator, station):
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            ramp = Excitation(
                name="ramp", mode=Mode.VELOCITY, fs_hz=1000.0, command=np.linspace(0, 1.0, 200)
            )
            drive.run(ramp)  # ends moving at 1 rad/s... then the hold target applies
            drive.quick_stop()
            assert drive.status().state in (DriveState.DISABLED, DriveState.QUICK_STOPPED)
            assert abs(emulator.plant.velocity_rad_s) < 0.05
        assert emulator.state != ENABLED


def test_station_errors_name_the_file(tmp_path: object, profile: UnitProfile) -> None:
    from pathlib import Path

    missing = Path(str(tmp_path)) / "nope.toml"
    with (
        pytest.raises(ProfileError, match=r"nope\.toml"),
        open_drive("canopen", profile=profile, unit_serial="X", station=missing),
    ):
        pass
    bad = Path(str(tmp_path)) / "bad.toml"
    bad.write_text(
        '[canopen]\ninterface = "virtual"\nchannel = "x"\nnode_id = 300\neds = "a.eds"\n'
    )
    with (
        pytest.raises(ProfileError, match=r"bad\.toml"),
        open_drive("canopen", profile=profile, unit_serial="X", station=bad),
    ):
        pass
    with (
        pytest.raises(ProfileError, match="--station"),
        open_drive("modbus", profile=profile, unit_serial="X"),
    ):
        pass


def test_station_keys_torque_sample_and_control_period(tmp_path: object) -> None:
    from pathlib import Path

    from hil.drives.station import load_station

    path = Path(str(tmp_path)) / "s.toml"
    base = (
        '[canopen]\ninterface = "virtual"\nchannel = "x"\nnode_id = 5\n'
        'eds = "gimbal_hil_servo.eds"\n'
    )
    path.write_text(base)
    default = load_station(path)
    assert (default.torque_sample, default.control_period_s) == ("auto", None)  # type: ignore[union-attr]
    path.write_text(base + 'torque_sample = "instantaneous"\ncontrol_period_s = 0.000125\n')
    given = load_station(path)
    assert (given.torque_sample, given.control_period_s) == ("instantaneous", 1.25e-4)  # type: ignore[union-attr]
    for bad in ('torque_sample = "median"\n', "control_period_s = -1\n"):
        path.write_text(base + bad)
        with pytest.raises(ProfileError, match=r"s\.toml"):
            load_station(path)


@pytest.mark.parametrize("station_period_s", [None, 2.5e-4])
def test_control_period_from_the_station_when_the_drive_has_none(
    tmp_path: Path, profile: UnitProfile, station_period_s: float | None
) -> None:
    """A drive whose object map gives no control period and no averaged torque (standard
    objects only, its conventions known): the recording states the station's
    control_period_s, so the current-loop model can use it; without it, it refuses."""
    from hil.config import builtin_fixture
    from hil.errors import IdentificationError
    from hil.identify.current_loop import torque_hold_s

    text = (builtin_fixture("canopen_maps") / "cia402_generic.toml").read_text()
    known = tmp_path / "known_conventions.toml"
    known.write_text(text.replace('position_latch = "unknown"',
                                  'position_latch = "control_period_before_sync"')
                     .replace('torque_reports = "unknown"', 'torque_reports = "demand"'))
    changes = {"object_map": load_object_map(known), "control_period_s": station_period_s}
    with (
        canopen_emulator(profile, seed=5, station_changes=changes) as (_emulator, station),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        assert drive.torque_sample == "instantaneous"  # the map gives no torque_mean
        drive.enable()
        recording = drive.run(sine(0.2, fs_hz=1000.0, periods=1))
    assert recording.metadata["torque_sample"] == "instantaneous"
    assert recording.metadata["torque_reports"] == "demand"
    if station_period_s is None:
        assert "control_period_s" not in recording.metadata
        with pytest.raises(IdentificationError, match="control period"):
            torque_hold_s(recording.metadata, fs_hz=1000.0)
    else:
        assert recording.metadata["control_period_s"] == "0.00025"
        assert torque_hold_s(recording.metadata, fs_hz=1000.0).hold_s == pytest.approx(2.5e-4)


@pytest.mark.parametrize(("key", "value"), [("torque_reports", "measured"),
                                            ("torque_reports", "unknown"),
                                            ("position_latch", "sync")])
def test_the_current_loop_model_refuses_conventions_it_does_not_fit(key: str,
                                                                    value: str) -> None:
    """A drive that reports measured torque (τ read 0.00 ± 0.27 ms) or latches the position
    at the SYNC (τ read −79 %), or whose map does not say: refused, naming the map's key."""
    from hil.errors import IdentificationError
    from hil.identify.current_loop import timing_problem, torque_hold_s

    metadata = {"object_map": "some drive", "torque_sample": "instantaneous",
                "control_period_s": "0.00025", "command_interpolation": "linear",
                "position_latch": "control_period_before_sync", "torque_reports": "demand"}
    assert timing_problem(metadata) is None
    metadata[key] = value
    problem = timing_problem(metadata)
    assert problem is not None
    assert f"{key} = {value!r}" in problem
    with pytest.raises(IdentificationError, match=key):
        torque_hold_s(metadata, fs_hz=1000.0)


def test_station_control_period_must_agree_with_the_drive(profile: UnitProfile) -> None:
    with (
        pytest.raises(DriveStateError, match=r"0x2200:06 UNSIGNED32 is 0\.00025 s"),
        canopen_emulator(profile, seed=6, station_changes={"control_period_s": 5e-4}) as (
            _emulator,
            station,
        ),
        CanOpenDrive(station, limits=profile.limits),
    ):
        pass


def test_mean_torque_required_but_not_offered(profile: UnitProfile) -> None:
    changes = {"object_map": load_object_map("cia402_generic"), "torque_sample": "mean"}
    with (
        pytest.raises(DriveStateError, match="gives no torque_mean"),
        canopen_emulator(profile, seed=7, station_changes=changes) as (_emulator, station),
        CanOpenDrive(station, limits=profile.limits),
    ):
        pass


def test_a_map_giving_an_object_the_drive_lacks_is_refused_before_motion(
        profile: UnitProfile) -> None:
    """The station's map says the drive has a recorder and an averaged torque; the drive
    (the emulator as a standard-objects-only drive) has neither: one line naming the map,
    the role and the drive's answer, and nothing enabled."""
    with canopen_emulator(profile, seed=5,
                          emulated_map=load_object_map("cia402_generic")) as (emulator, station):
        with pytest.raises(DriveStateError) as refused:
            CanOpenDrive(station, limits=profile.limits).__enter__()
        assert emulator.state != ENABLED
    message = str(refused.value)
    assert "\n" not in message
    assert "'gimbal-hil servo emulator'" in message
    assert "0x2077" in message or "0x2200" in message
    assert "does not match this drive" in message


def test_a_map_whose_torque_scale_is_wrong_is_refused(tmp_path: object,
                                                      profile: UnitProfile) -> None:
    """The emulator's map with 0x6076 in µN·m (as an EPOS4's) against a drive in mN·m: its
    rated torque would be 1000 times too small for the unit, refused before motion."""
    from pathlib import Path

    from hil.config import builtin_fixture

    text = (builtin_fixture("canopen_maps") / "gimbal_hil_servo.toml").read_text()
    wrong = Path(str(tmp_path)) / "wrong_scale.toml"
    wrong.write_text(text.replace("rated_torque_per_nm = 1000 ", "rated_torque_per_nm = 1000000 "))
    with (
        canopen_emulator(profile, seed=5,
                         station_changes={"object_map": load_object_map(wrong)},
                         emulated_map=load_object_map("gimbal_hil_servo")) as (_, station),
        pytest.raises(DriveStateError, match=r"scales 0x6076 at 1e\+06 per N·m"),
    ):
        CanOpenDrive(station, limits=profile.limits).__enter__()


def test_a_drive_powered_up_without_a_heartbeat_is_brought_up(profile: UnitProfile) -> None:
    """0x1017 = 0 at power-on (a common factory default): bring-up sets the heartbeat by SDO
    before it waits for one (it failed: "did not confirm NMT PRE-OPERATIONAL by heartbeat
    (last seen: None)"), and the heartbeat then runs at the station's period."""
    with (
        canopen_emulator(profile, seed=6, power_on_heartbeat_ms=0) as (emulator, station),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        assert drive.link.heartbeat_state is not None
        period_ms = int(drive.link.read(0x1017, 0))
        drive.enable()
        recording = drive.run(sine(0.2, fs_hz=drive.info.max_sample_rate_hz, periods=1))
    assert period_ms == round(station.heartbeat_period_s * 1e3) > 0
    assert len(recording.time_s) > 100
    assert emulator.state != ENABLED  # and left disabled


def test_no_node_at_the_id_is_refused_in_one_line(profile: UnitProfile) -> None:
    """Nothing answers at the station's node id: one line naming the node and the object,
    before any motion."""
    from dataclasses import replace

    from hil.errors import DriveCommunicationError

    with canopen_emulator(profile, seed=6) as (_, station):
        absent = replace(station, node_id=station.node_id + 1, sdo_timeout_s=0.2)
        with pytest.raises(DriveCommunicationError) as refused:
            CanOpenDrive(absent, limits=profile.limits).__enter__()
    message = str(refused.value)
    assert "\n" not in message
    assert f"node {absent.node_id}" in message


def test_a_sync_producer_other_than_the_host_in_lockstep_is_refused(tmp_path: Path) -> None:
    """In lockstep the host's SYNC is the emulator's clock: another producer cannot be."""
    from hil.config import builtin_fixture
    from hil.drives.station import load_station

    text = builtin_fixture("station_canopen_emulator.toml").read_text(encoding="utf-8")
    station = tmp_path / "station.toml"
    station.write_text(text.replace('sync_pacing = "lockstep"',
                                    'sync_pacing = "lockstep"\nsync_producer = "periodic"'))
    with pytest.raises(ProfileError) as refused:
        load_station(station)
    assert "sync_producer" in str(refused.value)
    assert "station.toml" in str(refused.value)
