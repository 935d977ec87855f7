"""A drive kind is one object (issue 25, defect 5): whether it is simulated, whether it
needs a station file and of which bus, how it opens; the certificate's
``conditions.simulated`` follows it (an emulator run was labelled real)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil.drives.kinds import DRIVE_KINDS, KINDS, SIMULATED_KINDS, DriveKind, drive_kind
from hil.errors import ProfileError
from tests.helpers import subset_profile

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = pytest.mark.realtime


def test_each_kind_knows_what_it_is() -> None:
    assert DRIVE_KINDS == ("sim", "canopen-emulator", "modbus-emulator", "canopen", "modbus",
                           "odrive-emulator", "odrive")
    assert SIMULATED_KINDS == ("sim", "canopen-emulator", "modbus-emulator", "odrive-emulator")
    assert {k.name for k in KINDS.values() if k.needs_station} == {"canopen", "modbus",
                                                                    "odrive"}
    assert drive_kind("odrive-emulator").station_kind == "odrive"
    assert drive_kind("canopen-emulator") == DriveKind(
        name="canopen-emulator", simulated=True, opens="emulator", station_kind="canopen")
    assert drive_kind("modbus").station_kind == "modbus"
    assert drive_kind("sim").station_kind is None
    with pytest.raises(ProfileError, match=r"unknown drive kind 'simm'.*known: sim, "):
        drive_kind("simm")


def test_open_drive_refuses_an_unknown_kind_in_one_line() -> None:
    from hil.drives.connect import open_drive
    from hil.profile import load_profile

    with pytest.raises(ProfileError, match="unknown drive kind 'can'"), open_drive(
            "can", profile=load_profile(), unit_serial="X"):
        pass


@pytest.mark.slow
def test_a_canopen_emulator_certificate_says_simulated(tmp_path: Path) -> None:
    """Failed before: ``"simulated": drive_kind == "sim"`` labelled it a real unit."""
    profile = subset_profile(tmp_path, "standstill")
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "canopen-emulator",
         "--profile", str(profile), "--unit-serial", "EMU-K", "--out", str(tmp_path / "out"),
         "--", "--store", "off", "--no-documents"],
        capture_output=True, text=True, timeout=600, check=False, cwd=tmp_path,
    )
    path = tmp_path / "out" / "EMU-K" / "certificate.json"
    assert path.is_file(), done.stdout + done.stderr
    cert = json.loads(path.read_text(encoding="utf-8"))
    assert cert["conditions"] == {"drive_kind": "canopen-emulator", "simulated": True}
