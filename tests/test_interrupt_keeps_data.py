"""Issue 26, item 10: Ctrl-C in the middle of an excitation keeps what was acquired. A
SIGINT while a long excitation streams (CANopen) or polls (Modbus) leaves an aborted
certificate listing that excitation's recording as incomplete (``complete: false``) with
its rows and SHA-256, the file beside it. (The simulator runs a whole excitation in one
numba call: a signal is handled between excitations there, nothing to keep.)"""

from __future__ import annotations

import gzip
import hashlib
import json
import signal
import time
from pathlib import Path

import pytest

from tests.calibration_process import RunningCalibration
from tests.helpers import subset_profile

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = pytest.mark.realtime

# the protocol with a long excitation, and the log line saying that excitation started
LONG_RUN = {
    "canopen-emulator": ("stribeck", "staircase", r"node 5: streaming staircase"),
    "modbus-emulator": ("gravity_cable", "sweep", r"polling sweep"),
}


@pytest.mark.parametrize("kind", sorted(LONG_RUN))
def test_sigint_mid_excitation_keeps_the_rows_acquired(tmp_path: Path, kind: str) -> None:
    protocol, excitation, started_line = LONG_RUN[kind]
    profile = subset_profile(tmp_path / "profiles", protocol)
    run = RunningCalibration(tmp_path, ["--drive", kind, "--profile", str(profile),
                                        "--unit-serial", "INT-1", "--out", str(tmp_path / "out")])
    run.wait_for_console("▶ protocol 1")
    run.wait_for_log(started_line)
    time.sleep(1.0)  # about a second of the excitation acquired
    code = run.stop_with(signal.SIGINT)
    console = run.console
    assert code != 0, console
    assert "Traceback" not in console, console
    unit = tmp_path / "out" / "INT-1"
    cert = json.loads((unit / "certificate.json").read_text(encoding="utf-8"))
    assert cert["aborted"] is True
    partial = [raw for raw in cert["raw_data"]
               if raw["protocol"] == protocol and raw["excitation"] == excitation]
    assert len(partial) == 1, cert["raw_data"]
    raw = partial[0]
    assert raw["complete"] is False
    assert raw["samples"] > 0
    path = unit / raw["file"]
    assert path.is_file()
    payload = path.read_bytes()
    assert hashlib.sha256(payload).hexdigest() == raw["sha256"]
    rows = [line for line in gzip.decompress(payload).decode("utf-8").splitlines()
            if line and not line.startswith("#")]
    assert len(rows) - 1 == raw["samples"]  # the header, then one line per sample
