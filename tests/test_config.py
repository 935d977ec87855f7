"""Every table of every shipped settings file refuses a misspelt key and a wrong-typed value
with an error naming the file, the table and the key; nothing falls back to a default."""

from __future__ import annotations

import importlib
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import tomli_w

from hil.characterise.processes import run_command
from hil.config import builtin_fixture
from hil.drives.modbus.regmap import load_register_map
from hil.drives.sim import SimDrive
from hil.drives.station import load_station
from hil.errors import ProfileError
from hil.profile import UnitProfile, load_profile

PROFILES = ("demo_gimbal_elevation.toml", "demo_gimbal_azimuth.toml")
STATIONS = (
    "station_canopen_emulator.toml",
    "station_canopen_example.toml",
    "station_canopen_gimbal_emulator.toml",
    "station_modbus_emulator.toml",
    "station_modbus_gimbal_emulator.toml",
)
REGISTER_MAPS = ("regmap_gimbal_hil_servo.toml",)
# python-can's own keyword arguments; a gimbal's axis names (a misspelt one is refused at
# bring-up: the profile's axis has no node, the names there listed)
FREE_FORM = {("canopen", "options"), *((bus, table) for bus in ("canopen", "modbus")
                                       for table in ("axes", "emulated_profiles"))}

Path_ = tuple[str | int, ...]


def _tables(node: Any, path: Path_ = ()) -> Iterator[Path_]:
    """Every table (and inline table in an array) of a parsed document, by path."""
    if isinstance(node, dict):
        if path and tuple(path) not in FREE_FORM:
            yield path
        for key, value in node.items():
            yield from _tables(value, (*path, key))
    elif isinstance(node, list) and node and all(isinstance(v, dict) for v in node):
        for i, item in enumerate(node):
            yield from _tables(item, (*path, i))


def _leaf_keys(table: dict[str, Any]) -> list[str]:
    return [
        k
        for k, v in table.items()
        if not isinstance(v, dict) and not (isinstance(v, list) and v and isinstance(v[0], dict))
    ]


def _at(document: dict[str, Any], path: Path_) -> dict[str, Any]:
    node: Any = document
    for part in path:
        node = node[part]
    return node  # type: ignore[no-any-return]  # the live table, edited in place


def _wrong_type(value: Any) -> Any:
    if isinstance(value, bool):
        return 1
    if isinstance(value, int | float):
        return str(value)
    if isinstance(value, str):
        return 1.5
    return "not a list"


def _table_name(path: Path_) -> str:
    names = [str(p) for p in path if isinstance(p, str)]
    return "[" + ".".join(names) + "]"


def _cases(files: tuple[str, ...]) -> list[Any]:
    cases = []
    for name in files:
        document = tomllib.loads(builtin_fixture(name).read_text(encoding="utf-8"))
        for path in _tables(document):
            table = _at(document, path)
            if not _leaf_keys(table):
                continue
            label = f"{name}:{'.'.join(map(str, path))}"
            cases.append(pytest.param(name, path, id=label))
    return cases


def _load_profile_and_protocols(path: Path) -> None:
    """Load a profile and let every protocol read its own settings table."""
    profile: UnitProfile = load_profile(path)
    assert profile.plant is not None
    drive = SimDrive(profile.plant, firmware=profile.firmware, limits=profile.limits,
                     fs_hz=profile.sample_rate_hz, seed=0)
    info = drive.info
    for name in profile.protocols:
        module = importlib.import_module(f"hil.suite.{name}")
        # a protocol with several excitations chooses its spec class by the table
        read = getattr(module, "spec_from_profile", None) or module.Spec.from_profile
        read(profile, info)


LOADERS: dict[str, Callable[[Path], object]] = {
    **dict.fromkeys(PROFILES, _load_profile_and_protocols),
    **dict.fromkeys(STATIONS, load_station),
    **dict.fromkeys(REGISTER_MAPS, load_register_map),
}


def _write(tmp_path: Path, name: str, document: dict[str, Any]) -> Path:
    path = tmp_path / name
    path.write_text(tomli_w.dumps(document), encoding="utf-8")
    return path


@pytest.mark.parametrize(("name", "path"), _cases(PROFILES + STATIONS + REGISTER_MAPS))
def test_every_table_refuses_a_misspelt_key(tmp_path: Path, name: str, path: Path_) -> None:
    document = tomllib.loads(builtin_fixture(name).read_text(encoding="utf-8"))
    table = _at(document, path)
    key = _leaf_keys(table)[0]
    typo = f"{key}x"
    table[typo] = table[key]
    written = _write(tmp_path, name, document)
    with pytest.raises(ProfileError) as caught:
        LOADERS[name](written)
    message = str(caught.value)
    assert str(written) in message
    assert _table_name(path) in message
    assert f"'{typo}'" in message


@pytest.mark.parametrize(("name", "path"), _cases(PROFILES + STATIONS + REGISTER_MAPS))
def test_every_table_refuses_a_wrong_type(tmp_path: Path, name: str, path: Path_) -> None:
    original = tomllib.loads(builtin_fixture(name).read_text(encoding="utf-8"))
    for key in _leaf_keys(_at(original, path)):
        document = tomllib.loads(builtin_fixture(name).read_text(encoding="utf-8"))
        table = _at(document, path)
        table[key] = _wrong_type(table[key])
        written = _write(tmp_path, name, document)
        with pytest.raises(ProfileError) as caught:
            LOADERS[name](written)
        message = str(caught.value)
        assert str(written) in message, key
        assert _table_name(path) in message, (key, message)
        assert f"'{key}'" in message, message


def _demo_with(tmp_path: Path, old: str, new: str) -> Path:
    text = builtin_fixture("demo_gimbal_elevation.toml").read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "unit.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def test_the_issue_cases_are_refused(tmp_path: Path) -> None:
    typo = _demo_with(tmp_path, "tolerance_pct = 15\n", "tolerance_pct = 15\nmarginl_pct = 20\n")
    with pytest.raises(ProfileError, match=r"\[measurements\.\w+\] has an unknown setting "
                       r"'marginl_pct' \(did you mean 'marginal_pct'\?\)"):
        load_profile(typo)
    string = _demo_with(tmp_path, "torque_nm = 0.5\ntravel", "torque_nm = \"0.5\"\ntravel")
    with pytest.raises(ProfileError, match=r"\[limits\] 'torque_nm': must be a number, got '0.5'"):
        load_profile(string)


def test_a_bad_profile_stops_calibrate_in_one_line_before_any_motion(tmp_path: Path) -> None:
    bad = _demo_with(tmp_path, "travel_max_rad = 1.4\n", "")
    out = tmp_path / "certs"
    done = run_command(
        ["calibrate", "--profile", str(bad), "--out", str(out)],
        timeout_s=300,
    )
    assert done.returncode != 0
    text = done.stdout + done.stderr
    assert "Traceback" not in text
    errors = [line for line in text.splitlines() if "travel_max_rad" in line]
    assert len(errors) == 1, text
    assert str(bad) in errors[0]
    assert "[limits] lacks 'travel_max_rad'" in errors[0]
    assert not out.exists() or not any(out.rglob("*")), "nothing may be written"


def test_a_setpoint_lead_below_one_period_is_refused(tmp_path: Path) -> None:
    text = builtin_fixture("station_modbus_emulator.toml").read_text(encoding="utf-8")
    assert "setpoint_lead_periods = 3" in text
    path = tmp_path / "station.toml"
    path.write_text(text.replace("setpoint_lead_periods = 3", "setpoint_lead_periods = 0"),
                    encoding="utf-8")
    with pytest.raises(ProfileError, match=r"\[modbus\] 'setpoint_lead_periods': must be 1 or "
                       r"more"):
        load_station(path)
