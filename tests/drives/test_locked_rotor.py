"""K_t on a field-bus station (issue 28): a shaft torque transducer read over Modbus TCP
from its amplifier, a locked-rotor clamp engaged by a drive output and confirmed by a check
move, both declared in the station file and emulated for the tests. K_t over the CANopen
and Modbus emulators agrees with the simulator's within U, and with the plant's; the
transducer's own certificate enters K_t's budget as a Type B line."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from conftest import sine
from hil.config import builtin_fixture
from hil.drives.base import Capability
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.cia402.emulator import ENABLED
from hil.drives.emulated import canopen_emulator
from hil.drives.equipment import Equipment
from hil.drives.station import load_station
from hil.errors import DriveCommunicationError, DriveStateError, ProfileError
from hil.profile import UnitProfile, load_profile
from tests.helpers import modbus_bench_station

PROFILE = builtin_fixture("demo_gimbal_elevation.toml")


def kt_result(tmp_path: Path, drive: str, *station: str) -> dict[str, Any]:
    out = tmp_path / drive
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", drive, "--profile",
         str(PROFILE), "--out", str(out), *station, "--", "-k", "torque_constant",
         "--no-documents", "--store", "off"],
        capture_output=True, text=True, timeout=600, check=False)
    path = out / "SIM-0001" / "certificate.json"
    assert path.is_file(), done.stdout[-3000:] + done.stderr[-3000:]
    results = {r["parameter"]: r for r in json.loads(path.read_text())["results"]}
    assert "torque_constant_nm_a" in results, done.stdout[-3000:]
    return dict(results["torque_constant_nm_a"])


def check_agreement(field: dict[str, Any], simulated: dict[str, Any]) -> None:
    truth = load_profile(PROFILE).plant
    assert truth is not None
    assert abs(field["value"] - simulated["value"]) <= field["expanded_uncertainty"]
    true_kt = truth.torque_constant_nm_a * (1 + truth.torque_constant_error_rel)
    assert abs(field["value"] - true_kt) <= field["expanded_uncertainty"]
    sensor = [line for line in field["budget"] if "torque sensor" in line["component"]]
    assert len(sensor) == 1
    assert sensor[0]["type"] == "B"
    assert "EMU-TT-" in sensor[0]["component"]  # the transducer's certificate, named
    assert sensor[0]["standard_uncertainty"] == pytest.approx(0.1 / 100 / 2)


def test_kt_over_the_canopen_emulator_agrees_with_the_simulator(tmp_path: Path) -> None:
    check_agreement(kt_result(tmp_path, "canopen-emulator"), kt_result(tmp_path, "sim"))


@pytest.mark.realtime
def test_kt_over_the_modbus_emulator_agrees_with_the_simulator(tmp_path: Path) -> None:
    """This bench sends its setpoints 6 periods ahead (60 ms at 100 Hz), as
    ``tests/drives/test_collector_held.py`` does: the test is about K_t, and a host pause of
    50 ms on CI's shared runner (a dry run of session 20; 2 of 22 runs in session 19, in
    the moves between locked sweeps) stopped it before K_t, rightly. What a pause does to a
    run is ``tests/drives/test_modbus_timing.py``'s business."""
    bench = modbus_bench_station(tmp_path / "bench.toml")
    check_agreement(kt_result(tmp_path, "modbus-emulator", "--station", str(bench)),
                    kt_result(tmp_path, "sim"))


def test_a_clamp_that_does_not_hold_is_refused(profile: UnitProfile) -> None:
    """The bench's clamp is wired to another output than the station says: the check move
    (a torque ramp to 0.05 N·m) turns the axis, the clamp is refused naming the figure and
    the station's output_bit, and nothing is driven against it."""
    with canopen_emulator(profile, seed=3, clamp_output_bit=17) as (emulator, station):
        assert station.equipment.locked_rotor is not None
        assert station.equipment.locked_rotor.output_bit == 16
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveStateError) as refused, drive.locked_rotor():
                pytest.fail("the clamp did not hold, yet the block ran")
            assert not emulator.plant.params.locked_rotor
        assert emulator.state != ENABLED
    message = str(refused.value)
    assert "did not hold" in message
    assert "output_bit 16" in message


def test_runs_inside_the_clamp_carry_the_shaft_torque(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=4) as (emulator, station):
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            assert {Capability.TORQUE_SENSOR, Capability.LOCKED_ROTOR} <= drive.info.capabilities
            free = drive.run(sine(0.1, fs_hz=1000.0, periods=1))
            with drive.locked_rotor():
                assert emulator.plant.params.locked_rotor
                held = drive.run(sine(0.1, fs_hz=1000.0, periods=1))
            assert not emulator.plant.params.locked_rotor
        assert emulator.transducer.reads > len(held) / 2
    assert "load_torque_nm" not in free.columns
    assert "load_torque_nm" in held.columns
    assert "EMU-TT-0001" in held.metadata["shaft_torque"]


def test_a_transducer_that_does_not_answer_is_one_line(profile: UnitProfile) -> None:
    with canopen_emulator(profile, seed=5) as (_, station):
        transducer = station.equipment.torque_transducer
        assert transducer is not None
        silent = dataclasses.replace(station, equipment=Equipment(
            torque_transducer=dataclasses.replace(transducer, port=1),
            locked_rotor=station.equipment.locked_rotor))
        with CanOpenDrive(silent, limits=profile.limits) as drive:
            drive.enable()
            with pytest.raises(DriveCommunicationError) as refused, drive.locked_rotor():
                pytest.fail("no transducer, yet the block ran")
    message = str(refused.value)
    assert "\n" not in message
    assert "127.0.0.1:1" in message


@pytest.mark.parametrize(("table", "named"), [
    ("[locked_rotor]\noutput_bit = 40\ncheck_torque_nm = 0.05\n", "output_bit"),
    ("[locked_rotor]\noutput_bit = 1\n", "check_torque_nm"),
    ("[torque_transducer]\nrelative_uncertainty_pct = 0.1\n", "certificate"),
    ("[torque_transducer]\ncertificate = \"X\"\nrelative_uncertainty_pct = 0.1\nprot = 5\n",
     "prot"),
])
def test_bad_equipment_is_one_line(tmp_path: Path, table: str, named: str) -> None:
    text = builtin_fixture("station_modbus_emulator.toml").read_text(encoding="utf-8")
    base = text.split("\n[torque_transducer]")[0].rsplit("\n# The bench", 1)[0]
    station = tmp_path / "station.toml"
    station.write_text(base + "\n" + table, encoding="utf-8")
    with pytest.raises(ProfileError) as refused:
        load_station(station)
    message = str(refused.value)
    assert "\n" not in message
    assert "station.toml" in message
    assert named in message


def test_a_station_without_a_clamp_skips_kt_naming_it(tmp_path: Path) -> None:
    text = builtin_fixture("station_canopen_emulator.toml").read_text(encoding="utf-8")
    station = tmp_path / "station.toml"
    station.write_text(text.split("\n[locked_rotor]")[0], encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "canopen-emulator",
         "--station", str(station), "--profile", str(PROFILE), "--out", str(tmp_path), "--",
         "-k", "torque_constant", "--no-documents", "--store", "off"],
        capture_output=True, text=True, timeout=600, check=False)
    certificate = json.loads((tmp_path / "SIM-0001" / "certificate.json").read_text())
    reasons = {m["reason"] for m in certificate["not_measured"]
               if m["protocol"] == "torque_constant"}
    assert reasons, done.stdout[-2000:]
    assert all(Capability.LOCKED_ROTOR.value in r for r in reasons)
    assert not any(Capability.TORQUE_SENSOR.value in r for r in reasons)
