"""The Modbus drive recorder, through a real pymodbus client and the emulator's real server:
its rows are the plant's control periods (pinned exactly on a frictionless, lag-free axis),
at a divider its torque is the mean over each sample's periods, it plays a torque offset
table, the map's compensation table goes into the drive, a run it cannot hold is refused
before motion, a fault or a stop signal while it plays leaves the drive disabled with what
it captured, a map without its registers means no recorder, and the demo gimbal's fast
protocols over one Modbus server PASS on it (slow).
"""

from __future__ import annotations

import _thread
import dataclasses
import json
import math
import subprocess
import sys
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hil.drives.base import Capability, DriveState, Interrupted
from hil.drives.emulated import MODBUS_STATION, builtin_station, modbus_emulator
from hil.drives.emulator_faults import ModbusFaults
from hil.drives.modbus.drive import ModbusDrive
from hil.drives.modbus.regmap import RECORDER_ABORTED, RECORDER_DONE, load_register_map
from hil.drives.station import ModbusStation, load_station
from hil.errors import DriveFaultError, DriveStateError, ProfileError
from hil.identify.current_loop import acquisition_path, torque_hold_s
from hil.identify.lag_model import ADEQUACY_P
from hil.motion import CompensationTable, Excitation, Mode, PositionHarmonic
from hil.profile import UnitProfile, load_profile
from hil.recording import EVERY_CONTROL_PERIOD, read_recording
from plant_sim.firmware import Firmware
from plant_sim.params import PlantParams

# the wall clock times the emulator's plant and the host's watch: run alone (README)
pytestmark = pytest.mark.realtime

J = 0.004
CONTROL_S = 2.5e-4  # the demo servo's control period (4 kHz)
LSB_RAD = 2 * math.pi / (1 << 19)  # the map's position increment
REGMAP = Path(__file__).parents[2] / "fixtures" / "regmap_gimbal_hil_servo.toml"
AUTO = {"acquisition": "auto"}


def _frictionless(profile: UnitProfile) -> UnitProfile:
    plant = PlantParams(inertia_kg_m2=J, torque_limit_nm=0.5, exact_torque_hold=True)
    return dataclasses.replace(profile, plant=plant, firmware=Firmware())


def _step_position(rows: int, divider: int, k0: int, step_nm: float) -> np.ndarray:
    """Row k's position from the play's start: the exact double integral of the torque
    held per control period n (the table's sample n // divider), measured at the start of
    control period k·divider."""
    fine = np.where(np.arange(rows * divider) // divider >= k0, step_nm, 0.0)
    velocity = np.concatenate([[0.0], np.cumsum(fine) * CONTROL_S / J])
    angle = np.concatenate([[0.0], np.cumsum(velocity[:-1] + velocity[1:]) * CONTROL_S / 2])
    return angle[: rows * divider : divider]


@pytest.mark.parametrize("fs_hz", [4000.0, 1000.0])
def test_torque_step_row_and_position_instant(profile: UnitProfile, fs_hz: float) -> None:
    """Row k is the plant's control period k·n of the play (n = 4 kHz / fs): the torque
    commanded over it (the table's sample k, so the step is in row k0 exactly) and the
    position at its start; one control period earlier or later is many increments away."""
    divider = round(1 / (fs_hz * CONTROL_S))
    step_nm, k0, rows = 0.1, 40 // divider, 400 // divider  # 0.1 s: within the speed limit
    command = np.where(np.arange(rows) >= k0, step_nm, 0.0)
    point = {**AUTO, "torque_sample": "instantaneous"}  # the captured period's torque
    with (
        modbus_emulator(_frictionless(profile), seed=0, station_changes=point) as (emulator, st),
        ModbusDrive(st, limits=profile.limits) as drive,
    ):
        assert drive.info.recorder is not None
        assert drive.info.max_sample_rate_hz == 4000.0
        drive.enable(Mode.TORQUE)
        recording = drive.run(Excitation(name="step", mode=Mode.TORQUE, fs_hz=fs_hz,
                                         command=command))
        assert emulator.recorder is not None
        assert emulator.recorder.state == RECORDER_DONE
        assert drive.status().state is DriveState.ENABLED
    meta = recording.metadata
    assert meta["acquisition"] == "drive recorder"
    assert meta["recorder_divider"] == str(divider)
    assert meta["control_period_s"] == f"{CONTROL_S:g}"
    assert (meta["torque_sample"], meta["command_interpolation"]) == ("instantaneous", "hold")
    assert len(recording) == rows
    assert recording.time_s == pytest.approx(np.arange(rows) / fs_hz, abs=1e-12)
    torque = recording.columns["torque_nm"]
    assert np.all(torque[:k0] == 0.0)
    assert np.all(torque[k0:] == pytest.approx(step_nm, abs=1e-12))
    position = recording.columns["position_rad"] - recording.columns["position_rad"][0]
    expected = _step_position(rows, divider, k0, step_nm)
    assert np.max(np.abs(position - expected)) <= 1.01 * LSB_RAD
    for shift in (-1, 1):  # one control period off: many increments at the end
        fine = _step_position(rows * divider + 2, 1, k0 * divider + shift, step_nm)
        shifted = fine[: rows * divider : divider]
        assert np.max(np.abs(position - shifted)) > 20 * LSB_RAD
    # at 4 kHz the current-loop model takes these rows as the simulator's (every period)
    if divider == 1:
        assert torque_hold_s(meta, fs_hz=fs_hz).hold_s == CONTROL_S
        assert acquisition_path(meta, fs_hz=fs_hz) == EVERY_CONTROL_PERIOD


def test_at_a_divider_the_torque_is_the_mean_over_the_samples_periods(
        profile: UnitProfile) -> None:
    """At 1 kHz (4 periods a sample) with the averaged torque the station asks for by
    default: row k's torque is the mean of the torque commanded over control periods
    4k − 3 … 4k (the streamed torque_mean's definition), so a step at row k0 shows a
    quarter in row k0 and the whole step from row k0 + 1 on; the recording says so."""
    step_nm, k0, rows, divider = 0.1, 10, 100, 4
    command = np.where(np.arange(rows) >= k0, step_nm, 0.0)
    with (
        modbus_emulator(_frictionless(profile), seed=0, station_changes=AUTO) as (_, st),
        ModbusDrive(st, limits=profile.limits) as drive,
    ):
        drive.enable(Mode.TORQUE)
        recording = drive.run(Excitation(name="step", mode=Mode.TORQUE, fs_hz=1000.0,
                                         command=command))
    meta = recording.metadata
    assert (meta["torque_sample"], meta["torque_mean_period_s"]) == ("mean", "0.001")
    torque = recording.columns["torque_nm"]
    assert np.all(torque[:k0] == 0.0)
    assert torque[k0] == pytest.approx(step_nm / divider, abs=1e-12)
    assert np.all(torque[k0 + 1 :] == pytest.approx(step_nm, abs=1e-12))


def test_the_recorder_plays_the_torque_offset_sample_by_sample(profile: UnitProfile) -> None:
    """A run with a torque offset goes to the recorder (the map's offset table): a firmware
    with feedforward adds each sample's offset over that sample's control periods, and
    after the table the torque_offset register's value (0) applies again."""
    rows = 200
    offset = np.where((np.arange(rows) >= 50) & (np.arange(rows) < 150), 0.05, -0.02)
    ff = dataclasses.replace(_frictionless(profile), firmware=Firmware(feedforward=True))
    point = {**AUTO, "torque_sample": "instantaneous"}
    with (
        modbus_emulator(ff, seed=0, station_changes=point) as (emulator, st),
        ModbusDrive(st, limits=profile.limits) as drive,
    ):
        assert drive.info.recorder is not None
        assert drive.info.recorder.torque_offset
        drive.enable(Mode.TORQUE)
        recording = drive.run(Excitation(name="ff", mode=Mode.TORQUE, fs_hz=1000.0,
                                         command=np.zeros(rows), torque_offset_nm=offset))
        assert emulator.recorder is not None
        assert emulator.recorder.with_offset
        after = drive.run(Excitation(name="after", mode=Mode.TORQUE, fs_hz=1000.0,
                                     command=np.zeros(20)))
    assert recording.metadata["acquisition"] == "drive recorder"
    assert recording.columns["torque_nm"] == pytest.approx(offset, abs=1e-12)
    assert np.all(after.columns["torque_nm"] == 0.0)


def test_the_compensation_table_goes_into_the_drive(profile: UnitProfile) -> None:
    """load_compensation writes the map's compensation registers in one request; a firmware
    with cogging compensation then adds Σ A·sin(nθ + φ) to its torque command (at rest,
    torque mode, zero command: the recorded torque is the table at the rotor's angle), and
    a cleared table adds nothing."""
    comp = dataclasses.replace(_frictionless(profile),
                               firmware=Firmware(cogging_compensation=True))
    table = CompensationTable(cogging_nm=(PositionHarmonic(order=3, amplitude=0.01,
                                                           phase_rad=0.4),))
    still = Excitation(name="still", mode=Mode.TORQUE, fs_hz=4000.0, command=np.zeros(8))
    with (
        modbus_emulator(comp, seed=0, station_changes=AUTO) as (_, st),
        ModbusDrive(st, limits=profile.limits) as drive,
    ):
        assert Capability.COMPENSATION_TABLE in drive.info.capabilities
        drive.enable(Mode.TORQUE)
        drive.load_compensation(table)
        loaded = drive.run(still)
        drive.load_compensation(None)
        cleared = drive.run(still)
        too_many = CompensationTable(cogging_nm=tuple(
            PositionHarmonic(order=n, amplitude=1e-4, phase_rad=0.0) for n in range(1, 10)))
        with pytest.raises(DriveStateError, match="has 9 cogging harmonics; the register map"):
            drive.load_compensation(too_many)
    theta = loaded.columns["position_rad"]
    assert loaded.columns["torque_nm"] == pytest.approx(0.01 * np.sin(3 * theta + 0.4),
                                                        abs=6e-4)  # the register's LSB
    assert np.all(cleared.columns["torque_nm"] == 0.0)


def test_a_run_the_recorder_cannot_hold_is_refused_before_motion(profile: UnitProfile) -> None:
    with (
        modbus_emulator(profile, seed=1, station_changes=AUTO) as (emulator, station),
        ModbusDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable(Mode.VELOCITY)
        before = emulator.requests
        start = drive.status().position_rad
        too_long = Excitation(name="long", mode=Mode.VELOCITY, fs_hz=4000.0,
                              command=np.zeros(16385))
        with pytest.raises(DriveStateError, match=r"'long' has 16,385 samples at 4000 Hz; "
                                                  r"the drive recorder holds 16,384: poll it"):
            drive.run(too_long)
        odd = Excitation(name="odd", mode=Mode.VELOCITY, fs_hz=3000.0, command=np.zeros(100))
        with pytest.raises(DriveStateError, match=r"samples at 4000 Hz / n"):
            drive.run(odd)
        assert emulator.recorder is not None
        assert emulator.recorder.state == 0
        assert emulator.requests - before < 10  # the capacity read, a status: no table
        assert drive.status().state is DriveState.ENABLED
        assert drive.status().position_rad == pytest.approx(start, abs=1e-3)


def _sine(fs_hz: float, seconds: float, amplitude_rad_s: float = 0.5) -> Excitation:
    t = np.arange(round(seconds * fs_hz)) / fs_hz
    return Excitation(name="sine", mode=Mode.VELOCITY, fs_hz=fs_hz,
                      command=amplitude_rad_s * np.sin(2 * math.pi * 2.0 * t))


def test_a_fault_while_playing_disables_and_keeps_the_captured_rows(
        profile: UnitProfile) -> None:
    faults = ModbusFaults(drive_fault_after_s=0.8)
    with (
        modbus_emulator(profile, seed=2, faults=faults, station_changes=AUTO) as (emu, st),
        ModbusDrive(st, limits=profile.limits) as drive,
    ):
        drive.enable(Mode.VELOCITY)
        excitation = _sine(4000.0, 2.0)
        with pytest.raises(DriveFaultError, match=r"drive fault at t = .* \(drive recorder\)"
                           ) as caught:
            drive.run(excitation)
        assert caught.value.code == 0x2310
        partial = caught.value.partial_recording
        assert partial is not None
        assert 0 < len(partial) < len(excitation.command)
        assert partial.metadata["acquisition"] == "drive recorder"
        assert emu.recorder is not None
        assert emu.recorder.state == RECORDER_ABORTED
        assert not emu.enabled
        assert drive.states.state is not DriveState.ENABLED


def test_a_stop_signal_while_playing_stops_disables_and_keeps_the_rows(
        profile: UnitProfile) -> None:
    with (
        modbus_emulator(profile, seed=3, station_changes=AUTO) as (emu, station),
        ModbusDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable(Mode.VELOCITY)
        excitation = _sine(4000.0, 3.0)
        timer = threading.Timer(1.0, _thread.interrupt_main)  # SIGINT's KeyboardInterrupt
        timer.start()
        try:
            with pytest.raises(Interrupted) as caught:
                drive.run(excitation)
        finally:
            timer.cancel()
        partial = caught.value.partial_recording
        assert partial is not None
        assert 0 < len(partial) < len(excitation.command)
        assert emu.recorder is not None
        assert emu.recorder.state == RECORDER_ABORTED
        assert not emu.enabled
        assert abs(emu.plant.velocity_rad_s) < 1e-2  # braked, then disabled
        assert drive.states.state is DriveState.DISABLED


def _map_without_recorder(tmp_path: Path, keep: tuple[str, ...] = ()) -> Path:
    text = REGMAP.read_text(encoding="utf-8")
    head, _, tail = text.partition("# The drive recorder")
    kept = [block for block in tail.split("\n[registers.")[1:]
            if block.split("]", 1)[0] in keep]
    path = tmp_path / "regmap.toml"
    path.write_text(head + "".join("\n[registers." + block for block in kept), "utf-8")
    return path


def test_a_map_without_the_recorder_means_no_recorder(tmp_path: Path,
                                                      profile: UnitProfile) -> None:
    bare = _map_without_recorder(tmp_path)
    assert not load_register_map(bare).has_recorder
    base = load_station(builtin_station(MODBUS_STATION))
    assert isinstance(base, ModbusStation)
    base = dataclasses.replace(base, register_map_path=bare, acquisition="auto")
    with (
        modbus_emulator(profile, seed=4, base_station=base) as (emulator, station),
        ModbusDrive(station, limits=profile.limits) as drive,
    ):
        assert emulator.recorder is None
        assert drive.info.recorder is None
        assert drive.info.max_sample_rate_hz <= station.max_poll_rate_hz
        drive.enable(Mode.VELOCITY)
        with pytest.raises(DriveStateError, match=r"sampled at 4000.0 Hz; this Modbus link "
                                                  r"polls at up to"):
            drive.run(_sine(4000.0, 0.1))
    # a station that streams leaves a map's recorder unused
    with (
        modbus_emulator(profile, seed=4, station_changes={"acquisition": "stream"}) as (_, st),
        ModbusDrive(st, limits=profile.limits) as drive,
    ):
        assert drive.info.recorder is None
    # part of a recorder is no recorder: refused, naming what it lacks
    part = _map_without_recorder(tmp_path, keep=("recorder_control", "recorder_state"))
    with pytest.raises(ProfileError, match=r"needs every one of its registers; \[registers\] "
                                           r"lacks recorder_length"):
        load_register_map(part)


def _recorder_truths() -> dict[str, dict[str, float | None]]:
    """The protocols that run on the recorder, and their truths from the demo gimbal's
    plants: τ as drawn, the azimuth's two-mass modes with the elevation level (the angle it
    is held at), f_a = √(k/J_l)/2π and f_r = f_a·√(1 + J_l/J_m)."""
    azimuth = load_profile("demo_gimbal_azimuth")
    elevation = load_profile("demo_gimbal_elevation")
    assert azimuth.plant is not None
    motor = azimuth.plant.inertia_kg_m2
    load = azimuth.plant.load_inertia_kg_m2 + azimuth.plant.inertia_elevation_kg_m2  # cos² 0 = 1
    antiresonance = math.sqrt(azimuth.plant.shaft_stiffness_nm_rad / load) / (2 * math.pi)
    return {
        "azimuth": {
            "current_loop_time_constant_ms": 1e3 * azimuth.firmware.current_loop_time_constant_s,
            "resonance_frequency_hz": antiresonance * math.sqrt(1 + load / motor),
            "antiresonance_frequency_hz": antiresonance, "velocity_bandwidth_hz": None},
        "elevation": {
            "current_loop_time_constant_ms":
                1e3 * elevation.firmware.current_loop_time_constant_s,
            "velocity_bandwidth_hz": None},
    }


def _miss(axis: str, found: dict[str, Any], truth: float, loop: dict[str, Any],
          metadata: Mapping[str, str]) -> str:
    """What a value outside its bound had beside it: enough to tell a tail from a fault
    (CI's tmp_path is gone by the time anyone reads the log)."""
    points = "; ".join(f"{p['frequency_hz']:g} Hz {p['lag_phase_rad']:+.4f} ± "
                       f"{p['lag_phase_u_rad']:.4f}" for p in loop["points"])
    return (f"{axis} {found['parameter']}: {found['value']:.5g} for {truth:.5g}, U "
            f"{found['expanded_uncertainty']:.3g} (k {found['coverage_factor']:.3g}, ν "
            f"{found['degrees_of_freedom']}); lag fit χ²/ν {loop['chi2_per_dof']:.3g}, p "
            f"{loop['lag_model_p_value']:.3g}, dead time {loop['dead_time_ms']}; phases "
            f"{points}; recording {dict(metadata)}")


# One run checks each value against twice its U: a value whose u is right lands outside in
# ~1 of 10⁴ runs for a normal error. τ's error/u is not normal: its weights are estimated
# from 10 blocks per phase, and over the fit's draws (hil.identify.scatter_weights) |t| > 2k
# for 2–3 in 10⁴ of the azimuth's values. Against U itself, a right u fails 1 value in 20,
# and with four values one run in 6: over 28 runs by hand the recorder's error/u had RMS
# 1.03 (elevation τ, one at 2.85) and 1.04 (azimuth τ), over 82 in session 34 0.89 (azimuth
# τ, largest 2.45); U's 95 % is measured over populations (tests/test_coverage.py), not in
# one run. CI once (stop 47) saw the azimuth's τ 2.4 U off (4.8 u, k 2 from the pooled 72
# degrees of freedom): under the drawn fits a 10⁻⁴ event, not reproduced in 82 runs nor in
# 1600 of the simulator; the message now carries the fit's phases to tell a tail from a fault.
SINGLE_RUN_BOUND_U = 2.0
# τ's lag-model check rejected the azimuth's true first-order lag in 2 of 22 runs of this
# test by hand (the second simulator's clean loop: 1 of 40), not its nominal 1 in 100: each
# phase's variance comes from 5 blocks (4 degrees of freedom), so χ² is a sum of F(1, 4)
# terms, heavier-tailed than the χ² table it is read against (issue 30). A rejected run
# certifies τ + dead time with its wider U (k from 2 degrees of freedom), which may reach a
# limit: MARGINAL, as designed. Read against the F null the check loses its power for a
# dead time of 0.3 of a period (tests/identify/test_lag_model.py); more blocks would keep
# it. Not changed yet. Since session 30 τ + dead time is certified wherever the fit finds a
# dead time, rejected or not: on the azimuth's 200–650 Hz band its U is the phases' alone
# and wider than τ's (k from 5 degrees of freedom where its χ²/ν > 1, eight frequencies
# since session 31; from 2 before), which may reach a limit too.


@pytest.mark.slow
def test_the_demo_gimbal_runs_its_fast_protocols_on_the_recorders(tmp_path: Path) -> None:
    """Both axes behind one Modbus server: the current loop, the resonance and the velocity
    FRF run on each unit's drive recorder at 4 kHz and PASS, their values consistent with
    the plants' (a truth given). Only those protocols run: the whole gimbal takes 5 min, too
    long for every CI run, and certified PASS in 2 of 3 runs by hand (docs/drives.md)."""
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--gimbal", "demo_gimbal",
         "--drive", "modbus-emulator", "--station",
         str(REGMAP.parent / "station_modbus_gimbal_emulator.toml"),
         "--unit-serial", "GMB-MR", "--out", str(tmp_path), "--", "--no-documents",
         "--store", "off", "-k", "current_loop or resonance or velocity_loop_frf"],
        capture_output=True, text=True, timeout=1200, check=False)
    folder = tmp_path / "GMB-MR"
    assert (folder / "gimbal-certificate.json").is_file(), (done.stdout[-4000:]
                                                           + done.stderr[-4000:])
    for axis, truths in _recorder_truths().items():
        document = json.loads((folder / axis / "GMB-MR" / "certificate.json").read_text("utf-8"))
        results = {r["parameter"]: r for r in document["results"]}
        loop = document["method"]["details"]["current_loop"]
        sines = read_recording(folder / axis / "GMB-MR" / "recordings"
                               / "current_loop__sines.csv.gz", log_warnings=False)
        assert sines.metadata["acquisition"] == "drive recorder"
        for parameter, truth in truths.items():
            found = results[parameter]
            widened = (parameter == "current_loop_time_constant_ms"
                       and (loop["lag_model_p_value"] < ADEQUACY_P
                            or (loop["dead_time_ms"] or 0.0) > 0.0))
            assert found["outcome"] == ("MARGINAL" if widened and found["outcome"] != "PASS"
                                        else "PASS"), (axis, found, loop)
            if truth is not None:
                error = abs(found["value"] - truth)
                assert error <= SINGLE_RUN_BOUND_U * found["expanded_uncertainty"], \
                    _miss(axis, found, truth, loop, sines.metadata)
        assert sines.metadata["requested_rate_hz"] == "4000"
