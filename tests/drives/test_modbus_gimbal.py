"""A gimbal behind one Modbus server: the axis under test at its unit id, the other axis's
drive holding it in position mode and moved for real by the host's setpoints; every
drive's watchdog fed; a held axis that stops holding stops the run, naming it."""

from __future__ import annotations

import re

import pytest

from hil.config import builtin_fixture
from hil.drives.base import Capability
from hil.drives.emulated import modbus_emulator
from hil.drives.held import trapezoid_rad
from hil.drives.modbus.drive import ModbusDrive
from hil.drives.station import ModbusStation, load_station
from hil.errors import DriveFaultError, ProfileError
from hil.profile import load_profile
from tests.drives.conftest import sine

STATION = builtin_fixture("station_modbus_gimbal_emulator.toml")


def test_each_axis_is_its_unit_and_the_others_are_held() -> None:
    station = load_station(STATION)
    assert isinstance(station, ModbusStation)
    azimuth, elevation = station.for_axis("azimuth"), station.for_axis("elevation")
    assert (azimuth.unit_id, dict(azimuth.held)) == (1, {"elevation": 2})
    assert (elevation.unit_id, dict(elevation.held)) == (2, {"azimuth": 1})
    with pytest.raises(ProfileError, match=r"\[modbus.axes\] has no address for the "
                                           r"profile's axis 'roll'"):
        station.for_axis("roll")


@pytest.mark.parametrize(("start", "end"), [(0.0, 1.2), (0.3, -1.1), (0.5, 0.5005)])
def test_a_held_axis_moves_on_a_trapezoid(start: float, end: float) -> None:
    path = trapezoid_rad(start, end, speed_rad_s=1.0, accel_rad_s2=4.0, step_s=0.02)
    assert path[-1] == pytest.approx(end, abs=1e-12)
    steps = abs(path[1:] - path[:-1])
    assert steps.max() <= 1.0 * 0.02 + 1e-12  # never above the speed
    assert abs(path[0] - start) <= 0.5 * 4.0 * 0.02**2 + 1e-12  # from rest


# the wall clock times the Modbus polls: run alone, not beside other tests (README)
@pytest.mark.realtime
def test_the_elevation_drive_moves_for_real_and_is_left_disabled() -> None:
    profile = load_profile("demo_gimbal_azimuth")
    station = load_station(STATION)
    assert isinstance(station, ModbusStation)
    with modbus_emulator(profile, seed=5, base_station=station) as (azimuth, on_line):
        elevation = azimuth.held_drives["elevation"]
        with ModbusDrive(on_line, limits=profile.limits) as drive:
            assert Capability.ELEVATION_AXIS in drive.info.capabilities
            assert elevation.enabled  # held from bring-up on
            drive.enable()
            for angle in (0.7, -1.1):
                drive.set_elevation(angle)
                # the elevation drive's own plant stands there, and the azimuth's inertia
                # follows it through the server, not through a parameter
                assert elevation.plant.position_rad == pytest.approx(angle, abs=0.003)
                assert azimuth.plant.params.elevation_rad == pytest.approx(angle, abs=0.003)
            # a run of several watchdog times: the held drive is kept alive meanwhile
            recording = drive.run(sine(0.3, fs_hz=drive.info.max_sample_rate_hz, periods=4))
            held = re.fullmatch(r"elevation unit 2 at ([-+.0-9]+) rad",
                                recording.metadata["held_axes"])
            assert held is not None
            assert float(held[1]) == pytest.approx(-1.1, abs=0.003)
            assert elevation.enabled
            assert elevation.fault_code == 0
        assert not elevation.enabled
        assert not azimuth.enabled


@pytest.mark.realtime
def test_a_held_axis_that_stops_holding_stops_the_run() -> None:
    profile = load_profile("demo_gimbal_azimuth")
    station = load_station(STATION)
    assert isinstance(station, ModbusStation)
    with modbus_emulator(profile, seed=6, base_station=station) as (azimuth, on_line):
        elevation = azimuth.held_drives["elevation"]
        with ModbusDrive(on_line, limits=profile.limits) as drive:
            drive.enable()
            with elevation._lock:
                elevation._trip(0x7500)  # its own fault (a communication error, say)
            with pytest.raises(DriveFaultError, match=r"unit 2: the held elevation axis "
                                                      r"faulted") as caught:
                drive.run(sine(0.3, fs_hz=drive.info.max_sample_rate_hz, periods=2))
            assert caught.value.code == 0x7500
        assert not azimuth.enabled
