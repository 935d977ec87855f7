"""Acquisition timing of the Modbus backend against the Modbus emulator (real time).

A polled sample is only as good as its time stamp: the host's clock around a request
carries the link's jitter (≈ 1 ms here, ±3 ms tails under load), which turned J, B and T_c
over Modbus into noise. With the drive's ``timestamp`` register the recording is timed by
the drive's control-cycle clock, latched with the feedback it belongs to.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from conftest import sine
from hil.drives.emulated import builtin_station, modbus_emulator, rated_torque_nm
from hil.drives.modbus.drive import ModbusDrive
from hil.drives.modbus.emulator import ModbusEmulator
from hil.drives.modbus.regmap import load_register_map
from hil.drives.station import ModbusStation
from hil.errors import ProfileError
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from plant_sim.model import PlantTrace
from tests.helpers import BENCH_LEAD_PERIODS

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = pytest.mark.realtime
# tests whose subject is not the setpoint lead send 6 periods ahead: one 40–60 ms stall of
# the host (seen on CI's VM; a stall injector refused a 1.5 s sine for 25 ms held at the
# built-in 3) is then bridged, and the run is judged on what it tests
STALL_PROOF = {"setpoint_lead_periods": BENCH_LEAD_PERIODS}

REGMAP = builtin_station("regmap_gimbal_hil_servo.toml")
CONTROL_PERIOD_S = 1 / 4000.0  # the demo unit's drive loop
ERROR_RAD_S = 0.015
REGMAP_TORQUE_MEAN_LSB_NM = (
    1e-6  # torque_mean: int32 µN·m  # see test_samples_are_timed_by_the_drive_clock
)


def _regmap_with(tmp_path: Path, old: str, new: str) -> Path:
    text = REGMAP.read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "regmap.toml"
    path.write_text(text.replace(old, new), encoding="utf-8")
    return path


def _station(regmap: Path, port: int = 1, **changes: Any) -> ModbusStation:
    changes.setdefault("source", "test")
    return ModbusStation(
        transport="tcp",
        register_map_path=regmap,
        port=port,
        timeout_s=1.0,
        **changes,
    )


def test_timing_registers_are_checked(tmp_path: Path, profile: UnitProfile) -> None:
    signed = _regmap_with(tmp_path, 'type = "uint32"                 # wraps', 'type = "int32" #')
    with pytest.raises(ProfileError, match=r"\[registers\.timestamp\].*uint16 or uint32"):
        load_register_map(signed)
    read_only = _regmap_with(tmp_path, 'scale = 1e-5\nunit = "s"\naccess = "rw"', "scale = 1e-5")
    with pytest.raises(ProfileError, match="'setpoint_interpolation_time' must be writable"):
        load_register_map(read_only)
    period = _regmap_with(tmp_path, "control_period_s = 0.00025", "control_period_s = -1")
    with pytest.raises(ProfileError, match=r"regmap\.toml: \[device\] 'control_period_s': must"):
        load_register_map(period)
    # 200: beyond one read of the feedback (125 registers), short of the recorder's (256 on)
    apart = _regmap_with(tmp_path, "address = 8 ", "address = 200 ")
    with pytest.raises(ProfileError, match=r"regmap\.toml.*'timestamp' must be read in one"):
        ModbusDrive(_station(apart), limits=profile.limits)
    mean_apart = _regmap_with(tmp_path, "address = 10 ", "address = 200 ")
    with pytest.raises(ProfileError, match=r"'torque_mean', .*must be read in one"):
        ModbusDrive(_station(mean_apart), limits=profile.limits)
    unsigned = _regmap_with(
        tmp_path, 'type = "int32"                  # up to', 'type = "uint32" #'
    )
    with pytest.raises(ProfileError, match=r"\[registers\.torque_mean\].*int16, int32 or"):
        load_register_map(unsigned)
    alone = _regmap_with(tmp_path, "[registers.torque_mean]  ", "[registers.torque_avg]  ")
    with pytest.raises(ProfileError, match="'torque_mean_window' without 'torque_mean'"):
        load_register_map(alone)
    without = _regmap_with(tmp_path, "[registers.torque_mean", "[registers.torque_avg")
    with pytest.raises(ProfileError, match=r"station\.toml.*'mean' but .* no 'torque_mean'"):
        ModbusDrive(
            _station(without, torque_sample="mean", source="station.toml"), limits=profile.limits
        )


def _derivative_error(recording: Recording) -> float:
    """RMS of Δposition/Δt against the drive's own velocity register between the samples:
    small only if each time stamp is the time of the position it is stored with. Intervals
    spanning a missed poll (a loaded runner's) are left out: their mean slope no longer
    matches the mid-point velocity (0.006 → 0.016 rad/s with 55 ms gaps)."""
    t, p = recording.time_s, recording.position
    v = recording.columns["velocity_rad_s"]
    step = np.diff(t)
    slope = np.diff(p) / step
    lag = 1 / (2 * math.pi * 300.0)  # the drive's velocity filter (300 Hz) lags ≈ 0.5 ms
    middle = 0.5 * (t[1:] + t[:-1]) + lag
    regular = step < 1.5 * np.median(step)
    error = (slope - np.interp(middle, t, v))[regular]
    return float(np.sqrt(np.mean(error**2)))


def test_samples_are_timed_by_the_drive_clock(profile: UnitProfile) -> None:
    """Regression (issue 4): each time stamp is the time of the state stored with it."""
    with (
        modbus_emulator(profile, seed=3, station_changes=STALL_PROOF) as (_, station),
        ModbusDrive(station, limits=profile.limits) as drive,
    ):
        fs = drive.info.max_sample_rate_hz
        drive.enable()
        recording = drive.run(sine(1.0, fs_hz=fs, periods=3))
    assert "the drive's clock" in recording.metadata["acquisition"]
    assert "setpoint interpolated" in recording.metadata["acquisition"]
    assert recording.metadata["torque_sample"] == "mean"  # the map has torque_mean
    assert recording.metadata["command_interpolation"] == "linear"
    assert float(recording.metadata["control_period_s"]) == CONTROL_PERIOD_S
    steps = np.diff(recording.time_s) / CONTROL_PERIOD_S
    assert np.all(steps > 0.5), steps.min()  # one row per drive sample, never the same twice
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)  # on the drive's clock
    # host stamps left 0.03-0.09 rad/s here: a millisecond of stamp error on a 1 rad/s
    # sine is a milliradian of position; the drive's clock leaves encoder and filter residue
    error = _derivative_error(recording)
    assert error < ERROR_RAD_S, (error, fs, len(steps), float(np.max(steps)))


def test_wrapping_drive_clock_is_unwrapped(tmp_path: Path, profile: UnitProfile) -> None:
    """A 16-bit µs counter wraps every 65.5 ms, many times within one run."""
    regmap = _regmap_with(tmp_path, 'type = "uint32"                 # wraps', 'type = "uint16" #')
    assert profile.plant is not None
    emulator = ModbusEmulator(
        profile.plant,
        firmware=profile.firmware,
        fs_hz=profile.sample_rate_hz,
        seed=1,
        register_map=regmap,
        rated_torque_nm=rated_torque_nm(profile),
    )
    with emulator, ModbusDrive(_station(regmap, emulator.port), limits=profile.limits) as drive:
        assert drive.map["timestamp"].modulus == 1 << 16
        fs = min(drive.info.max_sample_rate_hz, 100.0)
        drive.enable()
        excitation = sine(0.5, fs_hz=fs, periods=1)
        recording = drive.run(excitation)
    # Which command sample each row carried (rows are an ordered subsequence of the
    # command): the rows' drive-clock span must equal the span of those samples' due times.
    # A wrong wrap count is off by a whole wrap (65.5 ms); the read lands half a period
    # after its sample is due, give or take one period, whatever the host's stalls.
    indices, start = [], 0
    for value in recording.columns["velocity_cmd_rad_s"]:
        start = int(np.flatnonzero(excitation.command[start:] == value)[0]) + start
        indices.append(start)
    due_span_s = (indices[-1] - indices[0]) / fs
    wrap_s = drive.map["timestamp"].modulus * drive.map["timestamp"].scale
    duration = recording.time_s[-1] - recording.time_s[0]
    assert abs(duration - due_span_s) < min(wrap_s / 2, 2 / fs + 0.005), (duration, due_span_s)
    assert duration > 6 * wrap_s  # the run crossed several wraps
    assert _derivative_error(recording) < ERROR_RAD_S


def test_setpoint_is_interpolated_by_the_drive(profile: UnitProfile) -> None:
    """A velocity step written with a 0.2 s interpolation time is reached by a 0.2 s ramp
    (the velocity loop alone follows a step within ≈ 20 ms). Read on the drive's clock
    until it shows 0.35 s after the write (not for 0.35 s of the host's)."""
    with (
        modbus_emulator(profile, seed=1) as (_, station),
        ModbusDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable()
        drive.write_value("setpoint_interpolation_time", 0.2)
        t0 = drive.read_values(("timestamp",))["timestamp"]
        drive.write_value("velocity_cmd", 0.4)
        trace: list[tuple[float, float]] = []
        while not trace or trace[-1][0] < 0.35 or sum(t > 0.3 for t, _ in trace) < 3:
            values = drive.read_values(("timestamp", "velocity"))
            trace.append((values["timestamp"] - t0, values["velocity"]))
            time.sleep(0.005)
        drive.write_value("velocity_cmd", 0.0)
    t, v = np.array(trace).T
    early = v[(t > 0.08) & (t < 0.12)]
    assert early.size > 0
    assert np.all((early > 0.12) & (early < 0.28))  # the ramp: 0.2 rad/s at 0.1 s
    assert v[t > 0.3].mean() == pytest.approx(0.4, abs=0.03)


def test_inertia_friction_over_modbus_within_tolerance(profile: UnitProfile) -> None:
    """J and T_c from the calibration protocol over the emulator, twice, each within the
    profile's limits (before the timing fix: J −17 … −30 %, T_c off by up to 70 %).

    The station caps polling at 100 Hz so that a loaded runner still keeps the rate, and
    sends its setpoints 6 periods ahead, as ``test_locked_rotor`` and
    ``test_collector_held`` do: a host pause of 38 ms in a CI dry run (session 33, the
    realtime half alone) outlasted the built-in lead of 3 and stopped the run before J,
    rightly; what a pause does is the business of this file's other tests. B is not judged
    here: two short runs at 100 Hz bound it to ±0.0045 N·m·s/rad (its Cramér–Rao std on a
    loaded runner), wider than its tolerance; the full suite judges it with its U."""
    from hil.suite.inertia_friction import Spec, analyse, excitation

    bench = {"max_poll_rate_hz": 100.0, **STALL_PROOF}
    with (
        modbus_emulator(profile, seed=5, station_changes=bench) as (_, station),
        ModbusDrive(station, limits=profile.limits) as drive,
    ):
        spec = Spec.from_profile(profile, drive.info)
        drive.enable()
        results = [analyse([drive.run(e) for e in excitation(spec)], spec) for _ in range(2)]
    for result in results:
        for estimate in (result.inertia, result.coulomb):
            declared = profile.measurement(estimate.name)
            assert declared.lower_limit < estimate.value < declared.upper_limit, (
                f"{estimate.name} = {estimate.value:.6g} outside "
                f"[{declared.lower_limit:.6g}, {declared.upper_limit:.6g}] at {spec.fs_hz:g} Hz"
            )


class _TorqueLoggingEmulator(ModbusEmulator):
    """The emulator, keeping every control period's commanded torque (by plant step)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.torque_log: list[tuple[np.ndarray, np.ndarray]] = []
        super().__init__(*args, **kwargs)

    def _sample(self, trace: PlantTrace) -> None:
        self.torque_log.append((trace.time_s.copy(), trace.torque_nm.copy()))
        super()._sample(trace)

    def torque_by_step(self) -> np.ndarray:
        steps = np.round(np.concatenate([s for s, _ in self.torque_log]) * self.fs_hz)
        assert np.array_equal(steps, np.arange(steps.size))  # every period, once, in order
        return np.concatenate([torque for _, torque in self.torque_log])


def test_torque_mean_is_the_mean_since_the_previous_row(profile: UnitProfile) -> None:
    """Row k's torque is the mean of the torque commanded per control period over the
    control periods after row k-1's latched sample up to and including row k's, over real
    pymodbus; the window column says how long that was (= the row's time step)."""
    from hil.identify.sine_run import torque_hold_samples

    assert profile.plant is not None
    emulator = _TorqueLoggingEmulator(
        profile.plant,
        firmware=profile.firmware,
        fs_hz=profile.sample_rate_hz,
        seed=2,
        register_map=REGMAP,
        rated_torque_nm=rated_torque_nm(profile),
    )
    with emulator, ModbusDrive(_station(REGMAP, emulator.port), limits=profile.limits) as drive:
        fs = min(drive.info.max_sample_rate_hz, 100.0)
        drive.enable(Mode.TORQUE)
        t = np.arange(round(fs)) / fs
        command = 0.03 * np.sin(2 * math.pi * 3.0 * t) + 0.02 * t  # a sine on a ramp
        recording = drive.run(
            Excitation(name="torque", mode=Mode.TORQUE, fs_hz=fs, command=command)
        )
        drive.disable()
    torque = emulator.torque_by_step()
    meta = recording.metadata
    assert meta["torque_sample"] == "mean"
    window = recording.columns["torque_mean_window_s"]
    # the drive's clock of each row, in control periods (no wrap within this test)
    start = float(meta["drive_clock_at_start_s"])
    last = np.round((start + recording.time_s - recording.time_s[0]) / CONTROL_PERIOD_S)
    periods = np.round(window / CONTROL_PERIOD_S)
    np.testing.assert_allclose(window, periods * CONTROL_PERIOD_S, atol=1e-9)
    np.testing.assert_array_equal(periods[1:], np.diff(last))  # windows tile the run
    assert float(meta["torque_mean_period_s"]) == pytest.approx(np.median(window))
    # the row period the link achieved (a loaded runner polls late: 10.6 ms for 10 ms
    # seen): the windows are the first row's (since the read before the run) and the row
    # steps on the drive's clock, exactly
    np.testing.assert_allclose(window[1:], np.diff(recording.time_s), atol=1e-9)
    cumulative = np.concatenate([[0.0], np.cumsum(torque)])

    def mean_over(end: np.ndarray, count: np.ndarray) -> np.ndarray:
        stop = (end + 1).astype(int)
        return np.asarray((cumulative[stop] - cumulative[stop - count.astype(int)]) / count)

    lsb = REGMAP_TORQUE_MEAN_LSB_NM
    expected = mean_over(last, periods)
    np.testing.assert_allclose(recording.effort, expected, rtol=0, atol=0.51 * lsb)
    # the check can fail: the same window one control period early or late is ≫ 1 LSB off
    for shift in (-1, 1):
        assert np.median(np.abs(recording.effort - mean_over(last + shift, periods))) > 20 * lsb
    # and its centroid is T_c − T_s/2 after the row's position sample (the protocol's hold)
    hold = torque_hold_samples(recording, current_loop_lag_s=0.0)
    step = float(np.median(np.diff(recording.time_s)))
    assert hold * step == pytest.approx(CONTROL_PERIOD_S - float(np.median(window)) / 2)


def test_instantaneous_torque_on_request(profile: UnitProfile) -> None:
    """``torque_sample = "instantaneous"`` keeps the torque register (one control period)."""
    with (
        modbus_emulator(profile, seed=4, station_changes={"torque_sample": "instantaneous",
                                                          **STALL_PROOF}) as (_, station),
        ModbusDrive(station, limits=profile.limits) as drive,
    ):
        fs = min(drive.info.max_sample_rate_hz, 100.0)
        drive.enable()
        recording = drive.run(sine(0.5, fs_hz=fs, periods=1))
    assert recording.metadata["torque_sample"] == "instantaneous"
    assert "torque_mean_period_s" not in recording.metadata
    assert "torque_mean_window_s" not in recording.columns


def test_a_master_behind_its_setpoint_lead_is_refused_in_one_line() -> None:
    """A run whose setpoint held (writes later than the drive's ramp lasted) for more than
    1 % of it is not the planned excitation: a communication error naming the lead, the
    hold and the station file; a hold within the allowance passes."""
    from hil.drives.modbus.acquire import PolledRun, setpoint_holds

    station = ModbusStation(transport="tcp", register_map_path=REGMAP, source="bench.toml")
    excitation = sine(1.0, fs_hz=100.0, periods=10)  # 5 s
    assert setpoint_holds(excitation, PolledRun(setpoint_held_s=0.04), station, "drive") is None
    error = setpoint_holds(excitation, PolledRun(setpoint_held_s=0.06, longest_pause_s=0.07),
                           station, "drive")
    assert error is not None
    message = str(error)
    assert "\n" not in message
    assert "held for 60 ms of 5 s" in message
    assert "lead (3 periods)" in message
    assert "setpoint_lead_periods in bench.toml (to 8 for pauses like this one)" in message


def test_a_positioning_move_behind_its_lead_is_not_refused(
        caplog: pytest.LogCaptureFixture) -> None:
    """A move only takes the axis somewhere: a host stall that held its setpoint delays its
    arrival, and no protocol reads its rows, so it is logged, not refused; the same command
    as an analysed excitation is refused."""
    from hil.drives.modbus.acquire import PolledRun, setpoint_holds
    from hil.suite.travel import move_excitation

    station = ModbusStation(transport="tcp", register_map_path=REGMAP, source="bench.toml")
    move = move_excitation("move_to_start", 0.0, 0.3, fs_hz=100.0, speed_rad_s=1.0, hold_s=0.1)
    held = PolledRun(setpoint_held_s=0.01, longest_pause_s=0.04)  # one 40 ms stall
    assert move.positioning
    assert held.setpoint_held_s > 0.01 * move.duration_s
    with caplog.at_level(logging.WARNING, logger="hil.drives.modbus.acquire"):
        assert setpoint_holds(move, held, station, "drive") is None
    assert "a positioning move, not refused" in caplog.text
    analysed = dataclasses.replace(move, name="sines", metadata={})
    assert not analysed.positioning
    assert setpoint_holds(analysed, held, station, "drive") is not None


def test_an_emulator_takes_the_station_files_settings(tmp_path: Path,
                                                      profile: UnitProfile) -> None:
    """``--drive modbus-emulator --station FILE``: the file's settings at the emulator's
    endpoint (they were ignored: the built-in station was used whatever the file said); a
    CANopen file for a Modbus emulator is refused."""
    from hil.drives.connect import open_drive

    text = builtin_station("station_modbus_emulator.toml").read_text(encoding="utf-8")
    path = tmp_path / "station.toml"
    path.write_text(text.replace("setpoint_lead_periods = 3 ", "setpoint_lead_periods = 5 ")
                    .replace('register_map = "', f'register_map = "{REGMAP.parent}/'),
                    encoding="utf-8")
    with open_drive("modbus-emulator", profile=profile, unit_serial="S", station=path) as drive:
        assert isinstance(drive, ModbusDrive)
        assert drive.link.station.setpoint_lead_periods == 5  # the built-in file says 3
    with (
        pytest.raises(ProfileError, match="not a modbus station file"),
        open_drive("modbus-emulator", profile=profile, unit_serial="S",
                   station=builtin_station("station_canopen_emulator.toml")),
    ):
        pass
