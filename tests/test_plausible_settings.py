"""Issue 26, item 14: implausible settings are refused when the profile loads (or when a
protocol reads its table), in one line naming file, table and key; what a drive cannot
represent is refused at bring-up in one line. Each input was accepted before (or gave an
error that named no key, or a raw ``struct.error``)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from hil.characterise.processes import run_command
from hil.config import builtin_fixture
from hil.drives.base import Capability, DriveInfo
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.emulated import canopen_emulator
from hil.errors import DriveStateError, ProfileError
from hil.motion import Mode
from hil.profile import UnitProfile, load_profile
from hil.suite import current_loop, inertia_friction, stribeck

ELEVATION = builtin_fixture("demo_gimbal_elevation.toml")


def _set(text: str, table: str, key: str, value: str) -> str:
    """``text`` with ``key`` of ``[table]`` set to ``value`` (TOML), the rest untouched."""
    head = f"[{table}]\n"
    start = text.index(head) + len(head)
    end = text.find("\n[", start)
    end = len(text) if end < 0 else end
    body, count = re.subn(rf"(?m)^{re.escape(key)}\s*=.*$", f"{key} = {value}", text[start:end])
    assert count == 1, (table, key)
    return text[:start] + body + text[end:]


def _profile_file(tmp_path: Path, changes: list[tuple[str, str, str]]) -> Path:
    text = ELEVATION.read_text(encoding="utf-8")
    for table, key, value in changes:
        text = _set(text, table, key, value)
    path = tmp_path / "unit.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _info(profile: UnitProfile) -> DriveInfo:
    return DriveInfo(vendor="", model="", firmware_version="", serial="",
                     rated_torque_nm=profile.limits.torque_nm, limits=profile.limits,
                     modes=tuple(Mode), max_sample_rate_hz=profile.sample_rate_hz,
                     capabilities=frozenset(Capability), transport="planned")


SPECS = {"inertia_friction": inertia_friction.Spec, "stribeck": stribeck.Spec,
         "current_loop": current_loop.Spec}

# (changes, the protocol whose spec reads them or None: refused at load, expected message)
CASES = [
    ([("drive", "sample_rate_hz", "1")], None, "[drive] sample_rate_hz = 1: must be ≥ 100 Hz"),
    ([("drive", "sample_rate_hz", "1e9")], None,
     "[drive] sample_rate_hz = 1e+09: must be ≤ 100000 Hz"),
    ([("limits", "velocity_rad_s", "1e6")], None,
     "[limits] velocity_rad_s = 1e+06: must be ≤ 100 rad/s"),
    ([("limits", "travel_min_rad", "-1000"), ("limits", "travel_max_rad", "1000")], None,
     "[limits] travel_min_rad = -1000: must be ≥ -62.8319 rad"),
    ([("plant", "encoder_counts_per_rev", "-524288")], None,
     "[plant] encoder_counts_per_rev = -524288: must be ≥ 0 counts per revolution"),
    ([("plant", "stribeck_velocity_rad_s", "-0.02")], None,
     "[plant] stribeck_velocity_rad_s = -0.02: must be > 0 rad/s"),
    ([("protocols.stribeck", "speeds_rad_s", "[0.4, -0.2, 0.1]")], "stribeck",
     "[protocols.stribeck] speeds_rad_s = -0.2 (item 2): must be > 0 rad/s"),
    ([("protocols.current_loop", "frequencies_hz", "[100.0, 5e5]")], "current_loop",
     "[protocols.current_loop] frequencies_hz = 500000 (item 2): must be ≤ 5000 Hz"),
    ([("protocols.inertia_friction", "frequency_hz", "-2")], "inertia_friction",
     "[protocols.inertia_friction] frequency_hz = -2: must be > 0 Hz"),
    ([("protocols.inertia_friction", "periods", "0")], "inertia_friction",
     "[protocols.inertia_friction] periods = 0: must be ≥ 2 periods"),
]


@pytest.mark.parametrize(("changes", "protocol", "expected"), CASES,
                         ids=[c[0][0][1] + "=" + c[0][0][2] for c in CASES])
def test_an_implausible_setting_is_refused_naming_file_table_and_key(
    tmp_path: Path, changes: list[tuple[str, str, str]], protocol: str | None, expected: str
) -> None:
    path = _profile_file(tmp_path, changes)

    def read() -> None:
        profile = load_profile(path)
        assert protocol is not None, "loaded"
        SPECS[protocol].from_profile(profile, _info(profile))

    with pytest.raises(ProfileError) as caught:
        read()
    message = str(caught.value)
    assert message == f"{path}: {expected}"
    assert "\n" not in message


def test_the_demo_profiles_are_plausible() -> None:
    for name in ("demo_gimbal_elevation", "demo_gimbal_azimuth"):
        profile = load_profile(name)
        for protocol, spec in SPECS.items():
            spec.from_profile(profile, _info(profile))
            assert protocol in profile.protocols


@pytest.mark.parametrize(("changes", "expected"), [
    ([("drive", "sample_rate_hz", "1")], "sample_rate_hz = 1: must be ≥ 100 Hz"),
    ([("limits", "velocity_rad_s", "1e6")], "velocity_rad_s = 1e+06: must be ≤ 100 rad/s"),
])
def test_calibrate_refuses_it_in_one_line_before_motion(
    tmp_path: Path, changes: list[tuple[str, str, str]], expected: str
) -> None:
    path = _profile_file(tmp_path, changes)
    done = run_command(
        ["calibrate", "--drive", "sim", "--unit-serial",
         "P-1", "--profile", str(path), "--out", str(tmp_path / "out"), "--", "--store", "off",
         "--no-documents", "-p", "no:cacheprovider"],
        timeout_s=300, cwd=tmp_path,
    )
    output = done.stdout + done.stderr
    assert done.returncode != 0, output
    assert "Traceback" not in output
    assert [line for line in output.splitlines() if expected in line], output
    assert not (tmp_path / "out" / "P-1" / "certificate.json").exists()  # nothing ran


@pytest.mark.parametrize(("field", "value", "expected"), [
    # a torque limit of 200 × rated is plausible but beyond 0x6072 (UNSIGNED16 ‰ of rated):
    # it used to be clamped silently to 65.5 × rated
    ("torque_nm", 100.0, r"torque limit 100 N·m \(‰ of rated\) is 200000 in 0x6072:00 "
                         r"\(UNSIGNED16, 0\.\.65535\): the drive cannot represent it"),
    # a velocity limit past 0x607F's UNSIGNED32 (was a raw struct.error)
    ("velocity_rad_s", 1e6, r"velocity limit 1e\+06 rad/s is \d+ in 0x607F:00 \(UNSIGNED32"),
])
def test_a_limit_the_drive_cannot_represent_is_refused_at_bring_up(
    field: str, value: float, expected: str
) -> None:
    profile = load_profile()
    limits = dataclasses.replace(profile.limits, **{field: value})
    with canopen_emulator(profile, seed=0) as (_emulator, station), \
            pytest.raises(DriveStateError, match=expected) as caught:
        CanOpenDrive(station, limits=limits)
    assert "\n" not in str(caught.value)
    assert str(caught.value).endswith(station.source)
