"""A drive whose highest rate is its own recorder: each protocol whose runs fit the recorder
uses it, each with a run that does not (too long, a torque offset) is streamed at the SYNC
rate unless the recorder at its rate / n holds it faster than the link, and the certificate
says which and why (issue 28: the example station's elevation suite stopped at 'the drive
recorder holds 16384')."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from dataclasses import replace
from pathlib import Path

from hil.config import builtin_fixture
from hil.drives.base import DriveInfo, Recorder
from hil.motion import Limits, Mode
from hil.profile import UnitProfile, load_profile
from hil.recording import read_recording
from hil.suite.plan import acquisition_info, planned_motion_s

PROFILE = builtin_fixture("demo_gimbal_elevation.toml")


def _info(profile: UnitProfile, *, recorder_samples: int) -> DriveInfo:
    limits: Limits = profile.limits
    return DriveInfo(vendor="", model="", firmware_version="", serial="",
                     rated_torque_nm=0.5, limits=limits, modes=tuple(Mode),
                     max_sample_rate_hz=4000.0, transport="test",
                     recorder=Recorder(stream_rate_hz=1000.0, samples=recorder_samples))


def test_a_protocol_with_a_run_longer_than_the_recorder_is_streamed() -> None:
    profile = load_profile(PROFILE)
    info = _info(profile, recorder_samples=16384)
    streamed, why = acquisition_info("gravity_cable", profile, info)
    assert streamed.max_sample_rate_hz == 1000.0
    assert streamed.recorder is None
    assert why is not None
    assert "'sweep'" in why
    assert "16,384" in why
    kept, none = acquisition_info("current_loop", profile, info)
    assert kept is info
    assert none is None


def test_a_long_run_stays_on_the_recorder_at_its_rate_divided_when_that_beats_the_link(
) -> None:
    """Above a slow link (a 100 Hz Modbus poll) the gravity sweep (78,900 samples at 4 kHz)
    and the Stribeck staircase are planned on the recorder at the highest 4 kHz / n at
    which they fit; a recorder that plays a torque offset takes tracking at 4 kHz."""
    profile = load_profile(PROFILE)
    info = replace(_info(profile, recorder_samples=16384),
                   recorder=Recorder(stream_rate_hz=100.0, samples=16384, torque_offset=True))
    sweep, why = acquisition_info("gravity_cable", profile, info)
    assert sweep.max_sample_rate_hz == 800.0
    assert sweep.recorder is not None
    assert why is not None
    assert why.startswith("on the drive recorder at 800 Hz (4000 Hz / 5)")
    staircase, _ = acquisition_info("stribeck", profile, info)
    assert staircase.max_sample_rate_hz == 1000.0
    tracking, none = acquisition_info("tracking", profile, info)
    assert (tracking, none) == (info, None)


def test_a_torque_offset_is_streamed_whatever_its_length() -> None:
    profile = load_profile(PROFILE)
    streamed, why = acquisition_info("tracking", profile, _info(profile, recorder_samples=10**9))
    assert streamed.max_sample_rate_hz == 1000.0
    assert why is not None
    assert "torque offset" in why


def test_the_torque_constant_streams_whatever_its_length() -> None:
    """The host reads the station's transducer beside the SYNC stream; the drive recorder
    does not record it (over a gimbal station with ``acquisition = "auto"`` the locked sweeps
    went to the recorder and K_t came out −0.002 ± 0.0095 N·m/A)."""
    profile = load_profile(PROFILE)
    streamed, why = acquisition_info("torque_constant", profile,
                                     _info(profile, recorder_samples=10**9))
    assert streamed.max_sample_rate_hz == 1000.0
    assert why is not None
    assert "torque transducer" in why


def test_the_plan_is_the_motion_each_protocol_runs() -> None:
    """The planned time of a streamed protocol is the streamed motion's (same seconds, the
    samples differ): the planner asks the same question as the run."""
    profile = load_profile(PROFILE)
    small = planned_motion_s(profile, _info(profile, recorder_samples=16384))
    large = planned_motion_s(profile, _info(profile, recorder_samples=10**9))
    assert small.keys() == large.keys()
    assert abs(small["gravity_cable"] - large["gravity_cable"]) < 0.05 * large["gravity_cable"]


def test_the_example_station_completes_over_the_emulator(tmp_path: Path) -> None:
    """The shipped real-axis example (``acquisition = "auto"``) over the CiA 402 emulator:
    the recorder takes the current-loop sines, the gravity sweep and the feedforward
    tracking are streamed, and none of them stops. The emulator's SYNC is its clock, so the
    host paces it in lockstep here (the file's realtime pacing is for a real bus)."""
    example = builtin_fixture("station_canopen_example.toml")
    text = example.read_text(encoding="utf-8").replace(
        'sync_pacing = "realtime"', 'sync_pacing = "lockstep"')
    assert tomllib.loads(text)["canopen"]["acquisition"] == "auto"
    station = tmp_path / "station.toml"
    station.write_text(text, encoding="utf-8")
    only = "current_loop or gravity_cable or tracking"
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "canopen-emulator",
         "--station", str(station), "--profile", str(PROFILE), "--out", str(tmp_path),
         "--", "-k", only, "--no-documents", "--store", "off"],
        capture_output=True, text=True, timeout=600, check=False)
    certificate = json.loads((tmp_path / "SIM-0001" / "certificate.json").read_text())
    ran = {"current_loop", "gravity_cable", "tracking"}
    stopped = [m for m in certificate["not_measured"] if m["protocol"] in ran]
    assert not stopped, (stopped, done.stdout[-3000:])
    recordings = tmp_path / "SIM-0001" / "recordings"

    def acquisition(name: str) -> tuple[str, str]:
        metadata = read_recording(recordings / f"{name}.csv.gz", log_warnings=False).metadata
        return metadata["acquisition"], metadata.get("sync_period_s", "")

    assert acquisition("current_loop__sines") == ("drive recorder", "")
    assert acquisition("gravity_cable__sweep") == ("sync stream", "0.001")
    assert acquisition("tracking__move_ff") == ("sync stream", "0.001")
    protocols = certificate["method"]["protocols"]
    assert any("streamed at 1000 Hz" in line for line in protocols["gravity_cable"]["messages"])
    assert not any("streamed" in line for line in protocols["current_loop"]["messages"])
