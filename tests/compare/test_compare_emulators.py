"""The same comparison over the protocol emulators, the firmware variant set through the
profile: CANopen (current-loop protocol, its time constant doubled) and Modbus (the J/B/T_c
sines, identical firmware, two seeds; the current loop cannot be measured at Modbus's
100 Hz). One protocol each keeps the cost to a few seconds of CPU; an emulator's per-run
endpoint (virtual CAN channel, loopback port) is not a station difference."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from hil.cli import main
from hil.config import builtin_fixture
from tests.compare.firmware_variants import firmware_setting, with_firmware, write_profile
from tests.helpers import modbus_bench_station

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = [pytest.mark.slow, pytest.mark.realtime]

PROFILE = "demo_gimbal_elevation"


def calibrate(document: dict[str, Any], out: Path, *, drive: str, only: str,
              seed: int = 0) -> Path:
    station = builtin_fixture(f"station_{drive.removesuffix('-emulator')}_emulator.toml")
    if drive == "modbus-emulator":  # comparing firmware is this file's business, a host
        # pause the timing tests': setpoints sent 6 periods ahead, as test_locked_rotor's
        station = modbus_bench_station(out / "bench.toml")
    profile = write_profile(document, out / "profile.toml")
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", drive, "--station",
         str(station), "--profile", str(profile), "--unit-serial", "EMU-1", "--seed",
         str(seed), "--out", str(out), "--", "-k", only, "--no-documents", "--store", "off"],
        capture_output=True, text=True, timeout=600, check=False,
    )
    path = out / "EMU-1" / "certificate.json"
    assert path.is_file(), done.stdout + done.stderr
    certificate = json.loads(path.read_text(encoding="utf-8"))
    # a refused run (the host fell behind its field bus) says why here, not as a NEW later
    # (the other protocols were deselected: not measured by design)
    refused = [m for m in certificate["not_measured"] if m["protocol"] == only]
    assert not refused, (refused, done.stderr[-2000:])
    return path


def compare(baseline: Path, candidate: Path, out: Path, capsys: pytest.CaptureFixture[str],
            *options: str) -> tuple[int, dict[str, str], str]:
    code = main(["compare", str(baseline), str(candidate), "--json", str(out), *options])
    rows = json.loads(out.read_text(encoding="utf-8"))["results"]
    return code, {r["parameter"]: r["verdict"] for r in rows}, capsys.readouterr().err


def test_canopen_a_slower_current_loop_is_worse(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    tau_s = firmware_setting(PROFILE, "current_loop_time_constant_s")
    base = calibrate(with_firmware(PROFILE), tmp_path / "base", drive="canopen-emulator",
                     only="current_loop")
    slow = calibrate(with_firmware(PROFILE, current_loop_time_constant_s=2 * tau_s),
                     tmp_path / "slow", drive="canopen-emulator", only="current_loop", seed=1)
    code, verdicts, err = compare(base, slow, tmp_path / "c.json", capsys)
    assert (code, verdicts) == (1, {"current_loop_time_constant_ms": "WORSE"})
    assert "warning" not in err


def test_modbus_identical_firmware_flags_nothing(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Regression (issue 11): on a loaded host the polls fall behind at random; with a
    one-period setpoint ramp each late poll held the setpoint, a jerk the 100 Hz rows cannot
    resolve, and J read up to 5.5 % low (CHANGED in 2 of 4 full-suite runs). The setpoint is
    now sent ahead (station ``setpoint_lead_periods``), and a run whose host fell behind
    even that is refused (``setpoint_holds``), not measured.

    The Modbus emulator runs against the wall clock: two runs differ beyond their seeds, and
    at compare's default family-wise α = 0.05 two runs of one unit are flagged in 1 of 20
    comparisons by design (the amplitude spread CHANGED in one CI run, its u right: sd 0.16 %
    over 10 seeds against a median u of 0.16 %). One comparison is judged at α = 10⁻³; the
    bug this guards (J 5.5 % low, u 0.75 %) lies far beyond that."""
    runs = [calibrate(with_firmware(PROFILE), tmp_path / f"s{seed}", drive="modbus-emulator",
                      only="inertia_friction", seed=seed) for seed in (1, 2)]
    code, verdicts, err = compare(*runs, tmp_path / "c.json", capsys, "--alpha", "0.001")
    assert code == 0, (verdicts, err)
    assert set(verdicts) >= {"inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm"}
    assert set(verdicts.values()) == {"SAME"}
    assert "warning" not in err
