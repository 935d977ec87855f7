"""What ``pip install gimbal-hil`` puts on a machine: import names that collide with no other
distribution, the drive libraries as plain dependencies, the profiles as package data."""

from __future__ import annotations

import re
from importlib import metadata, resources

DRIVE_LIBRARIES = {"canopen", "python-can", "pymodbus", "pyserial"}


def test_installed_import_names_collide_with_no_known_distribution() -> None:
    top_level = set(metadata.distribution("gimbal-hil").read_text("top_level.txt").split())
    assert top_level == {"hil", "plant_sim", "gimbal_hil_protocols", "gimbal_hil_fixtures"}
    assert not top_level & {"fixtures", "protocols"}  # both are taken on PyPI


def test_drive_libraries_are_dependencies_not_extras() -> None:
    required = {
        re.split(r"[<>=!~;\[ ]", line, maxsplit=1)[0].lower()
        for line in metadata.requires("gimbal-hil") or []
        if "extra ==" not in line
    }
    assert required >= DRIVE_LIBRARIES


def test_profiles_stations_and_object_dictionary_ship_as_package_data() -> None:
    shipped = resources.files("gimbal_hil_fixtures")
    for name in (
        "demo_gimbal_elevation.toml",
        "demo_gimbal_azimuth.toml",
        "station_canopen_emulator.toml",
        "station_modbus_emulator.toml",
        "regmap_gimbal_hil_servo.toml",
        "gimbal_hil_servo.eds",
    ):
        assert shipped.joinpath(name).is_file(), name
